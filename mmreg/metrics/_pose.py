"""Pose accuracy: ground-truth poses from clusters, rotation and translation errors."""

import warnings

import numpy as np
from sklearn.exceptions import UndefinedMetricWarning

from mmreg._array.geometry import fit_rigid_grouped, rotation_angle
from mmreg._validation import check_labels
from mmreg._warnings import user_stacklevel
from mmreg.metrics._checks import check_correspondences, check_label_pair, check_transforms
from mmreg.metrics._clustering import contingency

__all__ = ["estimated_poses", "ground_truth_poses", "rotation_error", "translation_error"]


def ground_truth_poses(X, labels, n_objects=None):
    """Rigid motion of every ground-truth object, by Horn's method on its correspondences.

    This is how the paper obtains ground-truth poses on FlyingThings3D and KITTI: each
    object's a-points are registered to their b-points (displaced by the ground-truth
    scene flow) with the least-squares rigid motion ``b ~ R a + t``. On noiseless
    correspondences it recovers the true motions exactly.

    Parameters
    ----------
    X : array-like of shape (n_samples, 2 * d)
        Stacked correspondences ``[a | b]``.
    labels : array-like of shape (n_samples,)
        Object of each correspondence; negative labels (outliers) are ignored.
    n_objects : int, default=None
        Number of motions to return; None means ``labels.max() + 1``. Objects without
        correspondences get the identity motion.

    Returns
    -------
    rotations : ndarray of shape (n_objects, d, d)
        Proper rotations (determinant ``+1``).
    translations : ndarray of shape (n_objects, d)

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.datasets import make_scene
    >>> from mmreg.metrics import ground_truth_poses
    >>> scene = make_scene(n_objects=3, n_points=300, random_state=0)
    >>> rotations, translations = ground_truth_poses(scene.X, scene.labels)
    >>> bool(np.allclose(rotations, scene.rotations) and
    ...      np.allclose(translations, scene.translations))
    True
    """
    arr = np.asarray(labels)
    labels = check_labels(arr, len(arr) if arr.ndim else 0, name="labels")
    a, b = check_correspondences(X, len(labels))
    top = int(labels.max()) + 1 if len(labels) else 0
    if n_objects is None:
        n_objects = top
    elif n_objects < top:
        raise ValueError(f"n_objects={n_objects} is too few for labels up to {top - 1}.")
    rotations, translations, _ = fit_rigid_grouped(a, b, labels, n_objects)
    return rotations, translations


def _pose_errors(labels_true, labels_pred, transforms_true, transforms_pred):
    """Weighted rotation (degrees) and translation errors; see :func:`rotation_error`."""
    labels_true, labels_pred = check_label_pair(labels_true, labels_pred)
    rot_true, trans_true = check_transforms(
        transforms_true, labels_true, None, name="transforms_true"
    )
    rot_pred, trans_pred = check_transforms(
        transforms_pred, labels_pred, rot_true.shape[1], name="transforms_pred"
    )
    table = contingency(labels_true, labels_pred)
    true = table.classes_true[table.rows]
    pred = table.classes_pred[table.cols]
    # Neither outlier set has a pose: drop the estimated outliers, and weigh each
    # estimated cluster's errors over the true objects it meets, ignoring true outliers.
    keep = (true >= 0) & (pred >= 0)
    true, pred, counts, cols = true[keep], pred[keep], table.counts[keep], table.cols[keep]
    if len(counts) == 0:
        warnings.warn(
            "No estimated cluster shares a correspondence with a ground-truth object, so "
            "the pose errors are undefined; returning NaN.",
            UndefinedMetricWarning,
            stacklevel=user_stacklevel(),
        )
        return np.nan, np.nan
    scored, inverse = np.unique(cols, return_inverse=True)
    weights = counts / np.bincount(inverse, weights=counts)[inverse]
    rot_err = rotation_angle(rot_pred[pred], rot_true[true])
    trans_err = np.linalg.norm(trans_pred[pred] - trans_true[true], axis=1)
    per_cluster_rot = np.bincount(inverse, weights=weights * rot_err)
    per_cluster_trans = np.bincount(inverse, weights=weights * trans_err)
    return float(per_cluster_rot.mean()), float(per_cluster_trans.mean())


def rotation_error(labels_true, labels_pred, transforms_true, transforms_pred):
    """Mean over estimated clusters of the rotation error against the objects they meet.

    For every estimated cluster ``H_j`` and every ground-truth object ``G_k`` that shares
    a correspondence with it, the error ``e_jk`` is the geodesic angle
    ``arccos((tr(R_j^T R_k) - 1) / 2)`` in degrees; the cluster's error is the average
    weighted by ``|H_j ∩ G_k| / |H_j|``, and the result is the mean over the estimated
    clusters (Jin et al., ICRA 2024, Section V-B):

    .. math::

        \\frac{1}{K} \\sum_j \\sum_k \\frac{|H_j \\cap G_k|}{|H_j|} e_{jk}

    Outliers have no pose, on either side. The estimated outliers (``-1``) are not a
    cluster here, and the true outliers are left out of each cluster's average, whose
    weights are renormalised to ``|H_j ∩ G_k| / |H_j minus the true outliers|``. An
    estimated cluster made only of true outliers has no error and is not counted (the
    IoU penalises it). If no estimated cluster meets a true object the error is
    undefined: NaN, with an :class:`~sklearn.exceptions.UndefinedMetricWarning`.

    Parameters
    ----------
    labels_true : array-like of shape (n_samples,)
        Ground-truth object of each correspondence, ``-1`` for outliers.
    labels_pred : array-like of shape (n_samples,)
        Estimated cluster of each correspondence, ``-1`` for outliers.
    transforms_true : tuple of (array-like of shape (K_true, d, d), \\
            array-like of shape (K_true, d))
        ``(rotations, translations)`` of the objects: ``b = R_k a + t_k``. Use
        :func:`ground_truth_poses` when only the ground-truth clusters are known.
    transforms_pred : tuple of (array-like of shape (K_pred, d, d), \\
            array-like of shape (K_pred, d))
        ``(rotations_, translations_)`` of the estimated clusters.

    Returns
    -------
    error : float
        Degrees, in ``[0, 180]``.

    See Also
    --------
    translation_error : The same average of translation errors.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.metrics import rotation_error
    >>> Rz = np.array([[0., -1, 0], [1, 0, 0], [0, 0, 1]])           # 90 degrees about z
    >>> true = (np.stack([np.eye(3), Rz]), np.array([[0., 0, 0], [4, 0, 0]]))
    >>> pred = (np.stack([np.eye(3)]), np.array([[0., 0, 0]]))
    >>> # one estimated cluster: three points of object 0, one of object 1
    >>> float(rotation_error([0, 0, 0, 1], [0, 0, 0, 0], true, pred))   # 90 / 4
    22.5
    """
    rot_err, _ = _pose_errors(labels_true, labels_pred, transforms_true, transforms_pred)
    return rot_err


def translation_error(labels_true, labels_pred, transforms_true, transforms_pred):
    """Mean over estimated clusters of the translation error against the objects they meet.

    For every estimated cluster ``H_j`` and every ground-truth object ``G_k`` that shares
    a correspondence with it, the error ``e_jk`` is the Euclidean distance
    ``||t_j - t_k||``; the cluster's error is the average weighted by
    ``|H_j ∩ G_k| / |H_j|``, and the result is the mean over the estimated clusters (Jin
    et al., ICRA 2024, Section V-B). Outliers are handled as in :func:`rotation_error`.

    Parameters
    ----------
    labels_true : array-like of shape (n_samples,)
        Ground-truth object of each correspondence, ``-1`` for outliers.
    labels_pred : array-like of shape (n_samples,)
        Estimated cluster of each correspondence, ``-1`` for outliers.
    transforms_true : tuple of (array-like of shape (K_true, d, d), \\
            array-like of shape (K_true, d))
        ``(rotations, translations)`` of the objects: ``b = R_k a + t_k``.
    transforms_pred : tuple of (array-like of shape (K_pred, d, d), \\
            array-like of shape (K_pred, d))
        ``(rotations_, translations_)`` of the estimated clusters.

    Returns
    -------
    error : float
        In the units of the points.

    See Also
    --------
    rotation_error : The same average of rotation errors, with the formula.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.metrics import translation_error
    >>> true = (np.stack([np.eye(3), np.eye(3)]), np.array([[0., 0, 0], [4, 0, 0]]))
    >>> pred = (np.stack([np.eye(3), np.eye(3)]), np.array([[0., 0, 0], [4, 0, 3]]))
    >>> # cluster 0: three points of object 0 and one of object 1 (error 4/4 = 1);
    >>> # cluster 1: two points of object 1 (error 3)
    >>> float(translation_error([0, 0, 0, 1, 1, 1], [0, 0, 0, 0, 1, 1], true, pred))
    2.0
    """
    _, trans_err = _pose_errors(labels_true, labels_pred, transforms_true, transforms_pred)
    return trans_err


def estimated_poses(estimator, X, labels):
    """The motions of a fitted estimator's clusters, as ``(rotations, translations)``.

    Registration estimators store them as ``rotations_`` and ``translations_``; for any
    other clusterer (e.g. a scikit-learn one) they are fitted by Horn's method on its
    clusters ``labels`` of ``X``, which is the paper's "Naive" baseline.
    """
    if hasattr(estimator, "rotations_") and hasattr(estimator, "translations_"):
        return estimator.rotations_, estimator.translations_
    return ground_truth_poses(X, labels)
