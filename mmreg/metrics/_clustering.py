"""Cluster agreement: the paper's IoU and the Hungarian misclassification error.

Both compare ground-truth clusters ``G_k`` (``labels_true``) with estimated clusters ``H_j``
(``labels_pred``) through their contingency table ``|G_k ∩ H_j|``, which is kept sparse:
only the pairs of clusters that share a point are stored.
"""

from typing import NamedTuple

import numpy as np
from scipy.optimize import linear_sum_assignment

from mmreg.metrics._checks import check_label_pair

__all__ = ["iou_score", "match_clusters", "misclassification_error"]


class Contingency(NamedTuple):
    """Non-zero cells of the contingency table of two labellings.

    ``classes_*`` are the sorted distinct labels (``-1`` included when present),
    ``sizes_*`` their numbers of points, ``first_true`` the first row of each true
    cluster; ``rows``, ``cols``, ``counts`` list the cells ``|G_rows ∩ H_cols| = counts > 0``
    (indices into the ``classes_*``).
    """

    classes_true: np.ndarray
    classes_pred: np.ndarray
    sizes_true: np.ndarray
    sizes_pred: np.ndarray
    first_true: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    counts: np.ndarray


def contingency(labels_true, labels_pred):
    """Sparse contingency table of two checked label arrays (see :class:`Contingency`)."""
    classes_true, first_true, inv_true, sizes_true = np.unique(
        labels_true, return_index=True, return_inverse=True, return_counts=True
    )
    classes_pred, inv_pred, sizes_pred = np.unique(
        labels_pred, return_inverse=True, return_counts=True
    )
    n_pred = len(classes_pred)
    cells, counts = np.unique(
        inv_true.astype(np.int64) * n_pred + inv_pred.astype(np.int64), return_counts=True
    )
    return Contingency(
        classes_true,
        classes_pred,
        sizes_true,
        sizes_pred,
        first_true,
        cells // n_pred,
        cells % n_pred,
        counts,
    )


def match_clusters(table, *, true_outliers=True):
    """Match every estimated cluster to the true cluster it shares the most points with.

    Ties go to the smaller true cluster (the one of larger IoU), then to the true cluster
    whose first point comes first, so the matching does not depend on how the clusters are
    numbered.

    Parameters
    ----------
    table : Contingency
    true_outliers : bool, default=True
        Whether the true outliers (label ``-1``) may be matched, as one cluster.

    Returns
    -------
    cols : ndarray of shape (m,)
        Indices into ``table.classes_pred`` of the estimated clusters that share a point
        with an admissible true cluster.
    rows : ndarray of shape (m,)
        Index into ``table.classes_true`` of the matched true cluster of each.
    counts : ndarray of shape (m,)
        Number of shared points.
    """
    keep = np.ones(len(table.rows), dtype=bool)
    if not true_outliers:
        keep &= table.classes_true[table.rows] >= 0
    rows, cols, counts = table.rows[keep], table.cols[keep], table.counts[keep]
    # np.lexsort sorts by its last key first.
    order = np.lexsort((table.first_true[rows], table.sizes_true[rows], -counts, cols))
    cols_sorted = cols[order]
    # The first row of each estimated cluster (none when no pair is admissible).
    first = np.flatnonzero(np.r_[len(cols_sorted) > 0, cols_sorted[1:] != cols_sorted[:-1]])
    best = order[first]
    return cols[best], rows[best], counts[best]


def iou_score(labels_true, labels_pred):
    """Mean intersection over union of the estimated clusters with their matched objects.

    Each estimated cluster ``H_j`` is matched to the ground-truth cluster ``G_k`` with
    which it shares the most points; the score is the mean over the estimated clusters of

    .. math::

        \\mathrm{IoU}(H_j, G_k) = \\frac{|H_j \\cap G_k|}{|H_j \\cup G_k|}
        = \\frac{|H_j \\cap G_k|}{|H_j| + |G_k| - |H_j \\cap G_k|}

    (Jin et al., ICRA 2024, Section V-B). The outlier label ``-1`` counts as one cluster on
    each side: the estimated outliers are one more estimated cluster, and the true
    outliers one more cluster they can be matched to. Several estimated clusters may be
    matched to the same object, so over-segmentation lowers the score; clusters with no
    point (labels that do not occur) are not clusters and do not count.

    Ties in the matching go to the smaller object (the larger IoU), so the score is
    invariant to renumbering the clusters on either side.

    Parameters
    ----------
    labels_true : array-like of shape (n_samples,)
        Ground-truth object of each correspondence, ``-1`` for outliers.
    labels_pred : array-like of shape (n_samples,)
        Estimated cluster of each correspondence, ``-1`` for outliers.

    Returns
    -------
    iou : float
        In ``(0, 1]``; ``1.0`` exactly when the two clusterings agree up to renumbering.

    See Also
    --------
    misclassification_error : Error rate under the best one-to-one matching.

    Examples
    --------
    >>> from mmreg.metrics import iou_score
    >>> iou_score([0, 0, 1, 1], [1, 1, 0, 0])
    1.0
    >>> iou_score([0, 0, 0, 0], [0, 0, 1, 1])    # a split object: 2/4 twice
    0.5
    >>> iou_score([0, 0, 1, 1], [0, 0, 0, 0])    # merged objects: 2/4
    0.5
    """
    labels_true, labels_pred = check_label_pair(labels_true, labels_pred)
    table = contingency(labels_true, labels_pred)
    cols, rows, counts = match_clusters(table)
    union = table.sizes_pred[cols] + table.sizes_true[rows] - counts
    return float(np.mean(counts / union))


def misclassification_error(labels_true, labels_pred):
    """Fraction of correspondences misclassified under the best one-to-one matching.

    The estimated clusters are matched one-to-one to the ground-truth clusters so as to
    maximise the number of correspondences whose estimated cluster is matched to their
    true cluster (the Hungarian method, :func:`scipy.optimize.linear_sum_assignment`);
    the error is

    .. math::

        1 - \\frac{1}{n} \\max_{\\pi} \\sum_j |H_j \\cap G_{\\pi(j)}|

    over one-to-one matchings ``pi``. Surplus clusters on either side stay unmatched, so
    all their correspondences count as errors. The outlier label ``-1`` is one cluster on
    each side, like any other.

    Parameters
    ----------
    labels_true : array-like of shape (n_samples,)
        Ground-truth object of each correspondence, ``-1`` for outliers.
    labels_pred : array-like of shape (n_samples,)
        Estimated cluster of each correspondence, ``-1`` for outliers.

    Returns
    -------
    error : float
        In ``[0, 1)``; ``0.0`` exactly when the clusterings agree up to renumbering.

    Notes
    -----
    The matching works on a dense table of shape ``(K_true, K_pred)`` (distinct labels on
    each side), which is small for any realistic clustering.

    Examples
    --------
    >>> from mmreg.metrics import misclassification_error
    >>> misclassification_error([0, 0, 1, 1], [5, 5, 2, 2])
    0.0
    >>> misclassification_error([0, 0, 1, 1], [0, 0, 0, 1])
    0.25
    """
    labels_true, labels_pred = check_label_pair(labels_true, labels_pred)
    table = contingency(labels_true, labels_pred)
    dense = np.zeros((len(table.classes_true), len(table.classes_pred)), dtype=np.int64)
    dense[table.rows, table.cols] = table.counts
    rows, cols = linear_sum_assignment(dense, maximize=True)
    return float(1.0 - dense[rows, cols].sum() / len(labels_true))
