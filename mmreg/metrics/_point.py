"""Per-point error: Chamfer distance between true and estimated moved objects."""

import warnings

import numpy as np
from scipy.spatial import cKDTree
from sklearn.exceptions import UndefinedMetricWarning
from sklearn.utils import check_array

from mmreg._array.geometry import apply_motions
from mmreg._warnings import user_stacklevel
from mmreg.metrics._checks import check_correspondences, check_label_pair, check_transforms
from mmreg.metrics._clustering import contingency, match_clusters

__all__ = ["chamfer_distance", "per_point_error"]


def _one_sided(tree, points):
    """Mean distance from each of ``points`` to its nearest neighbour in ``tree``."""
    return float(np.mean(tree.query(points)[0]))


def _chamfer(tree_p, tree_q):
    return 0.5 * (_one_sided(tree_q, tree_p.data) + _one_sided(tree_p, tree_q.data))


def chamfer_distance(points_p, points_q):
    """Symmetric Chamfer distance: the mean of the two mean nearest-neighbour distances.

    .. math::

        d_{CD}(P, Q) = \\frac{1}{2} \\left( \\frac{1}{|P|} \\sum_{p \\in P}
        \\min_{q \\in Q} \\|p - q\\| + \\frac{1}{|Q|} \\sum_{q \\in Q}
        \\min_{p \\in P} \\|q - p\\| \\right)

    Distances are Euclidean, not squared, so the result is in the units of the points,
    like the paper's per-point error in metres. Nearest neighbours come from KD-trees
    (:class:`scipy.spatial.cKDTree`), ``O((|P| + |Q|) log(|P| + |Q|))``.

    Parameters
    ----------
    points_p : array-like of shape (n_p, d)
    points_q : array-like of shape (n_q, d)

    Returns
    -------
    distance : float

    Examples
    --------
    >>> from mmreg.metrics import chamfer_distance
    >>> chamfer_distance([[0., 0], [1, 0]], [[0., 0], [1, 0]])
    0.0
    >>> chamfer_distance([[0., 0]], [[0., 0], [4, 0]])   # (0 + (0 + 4) / 2) / 2
    1.0
    """
    p = check_array(points_p, dtype=np.float64, input_name="points_p")
    q = check_array(points_q, dtype=np.float64, input_name="points_q")
    if p.shape[1] != q.shape[1]:
        raise ValueError(
            f"points_p and points_q must have the same dimension; got {p.shape[1]} "
            f"and {q.shape[1]}."
        )
    return _chamfer(cKDTree(p), cKDTree(q))


def per_point_error(X, labels_true, labels_pred, transforms_true, transforms_pred):
    """Mean Chamfer distance between each estimated moved object and its true match.

    Following Jin et al. (ICRA 2024, Section V-B): the a-points are segmented by the true
    clusters ``G_k`` and each object is moved by its true motion, ``R_k a + t_k``; the
    a-points are segmented by the estimated clusters ``H_j`` and each is moved by its
    estimated motion, ``R_j a + t_j``. Each estimated object is matched to the true
    object with which it shares the most correspondences (ties as in
    :func:`iou_score`), and the per-point error is the mean over estimated objects of the
    symmetric :func:`chamfer_distance` between the two moved point sets.

    Outliers have no motion, on either side: the estimated outliers (``-1``) are not an
    object, and the true outliers are not an object an estimated one can be matched to.
    A true outlier inside an estimated object is still moved with that object, so the
    distance penalises it. An estimated object made only of true outliers has no match
    and is not counted (the IoU penalises it). If no estimated object has a match the
    error is undefined: NaN, with an :class:`~sklearn.exceptions.UndefinedMetricWarning`.

    Parameters
    ----------
    X : array-like of shape (n_samples, 2 * d)
        Stacked correspondences ``[a | b]``; only the a-points are used.
    labels_true : array-like of shape (n_samples,)
        Ground-truth object of each correspondence, ``-1`` for outliers.
    labels_pred : array-like of shape (n_samples,)
        Estimated cluster of each correspondence, ``-1`` for outliers.
    transforms_true : tuple of (array-like of shape (K_true, d, d), \\
            array-like of shape (K_true, d))
        ``(rotations, translations)`` of the objects. Use :func:`ground_truth_poses`
        when only the ground-truth clusters are known.
    transforms_pred : tuple of (array-like of shape (K_pred, d, d), \\
            array-like of shape (K_pred, d))
        ``(rotations_, translations_)`` of the estimated clusters.

    Returns
    -------
    error : float
        In the units of the points.

    Notes
    -----
    One KD-tree per true and per estimated object; an object matched by several
    estimated ones is queried once per match, so the cost is
    ``O(sum_j (|H_j| + |G_m(j)|) log n)``.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.metrics import per_point_error
    >>> a = np.array([[0., 0, 0], [1, 0, 0], [5, 0, 0], [6, 0, 0]])
    >>> X = np.hstack([a, a])                       # nothing moves
    >>> identity = (np.stack([np.eye(3)] * 2), np.zeros((2, 3)))
    >>> per_point_error(X, [0, 0, 1, 1], [1, 1, 0, 0], identity, identity)
    0.0
    >>> shifted = (np.stack([np.eye(3)] * 2), np.array([[0., 0, 0], [0, 2, 0]]))
    >>> per_point_error(X, [0, 0, 1, 1], [0, 0, 1, 1], identity, shifted)  # (0 + 2) / 2
    1.0
    """
    labels_true, labels_pred = check_label_pair(labels_true, labels_pred)
    a, _ = check_correspondences(X, len(labels_true))
    rot_true, trans_true = check_transforms(
        transforms_true, labels_true, a.shape[1], name="transforms_true"
    )
    rot_pred, trans_pred = check_transforms(
        transforms_pred, labels_pred, a.shape[1], name="transforms_pred"
    )
    table = contingency(labels_true, labels_pred)
    cols, rows, _ = match_clusters(table, true_outliers=False)
    keep = table.classes_pred[cols] >= 0
    cols, rows = cols[keep], rows[keep]
    if len(cols) == 0:
        warnings.warn(
            "No estimated object shares a correspondence with a ground-truth object, so "
            "the per-point error is undefined; returning NaN.",
            UndefinedMetricWarning,
            stacklevel=user_stacklevel(),
        )
        return np.nan
    moved_true = apply_motions(a, rot_true, trans_true, labels_true)
    moved_pred = apply_motions(a, rot_pred, trans_pred, labels_pred)
    # Rows grouped by cluster once, instead of one boolean mask per cluster.
    groups_true = _groups(labels_true, table.classes_true)
    groups_pred = _groups(labels_pred, table.classes_pred)
    trees_true = {}
    distances = np.empty(len(cols))
    for i, (col, row) in enumerate(zip(cols, rows, strict=True)):
        if row not in trees_true:
            trees_true[row] = cKDTree(moved_true[groups_true[row]])
        tree_pred = cKDTree(moved_pred[groups_pred[col]])
        distances[i] = _chamfer(tree_pred, trees_true[row])
    return float(distances.mean())


def _groups(labels, classes):
    """Row indices of each class of ``labels``, in the order of ``classes`` (sorted)."""
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], classes[1:])
    return np.split(order, bounds)
