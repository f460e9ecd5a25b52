"""How many true objects an estimate recovers: the count that the paper's IoU hides."""

import numpy as np

from mmreg._validation import check_labels
from mmreg.metrics._clustering import contingency

__all__ = ["objects_found"]


def objects_found(labels_true, labels_pred, *, objects=None, min_iou=0.5):
    """Fraction of the true objects that some estimated cluster recovers.

    Object ``G_k`` is found when an estimated cluster ``H_j`` (not ``-1``) has
    ``|H_j ∩ G_k| / |H_j ∪ G_k| >= min_iou``; with ``min_iou > 0.5`` no cluster can find
    two objects. The paper's :func:`~mmreg.metrics.iou_score` averages over the estimated
    clusters, so one cluster holding a whole street scores high while it finds no moving
    car: report this beside it, on the moving objects (``objects``).

    Parameters
    ----------
    labels_true : array-like of shape (n_samples,)
        Ground-truth object of each correspondence, ``-1`` for outliers.
    labels_pred : array-like of shape (n_samples,)
        Estimated cluster of each correspondence, ``-1`` for outliers.
    objects : array-like of int, default=None
        The true objects to count (e.g. the moving ones); None: every object present.
    min_iou : float, default=0.5

    Returns
    -------
    found : float
        In ``[0, 1]``; NaN when there is no object to find.

    Examples
    --------
    >>> from mmreg.metrics import objects_found
    >>> truth = [0, 0, 0, 0, 1, 1, 2, 2]
    >>> objects_found(truth, [0, 0, 0, 0, 0, 0, 1, 1])       # object 1 swallowed
    0.6666666666666666
    >>> objects_found(truth, [0, 0, 0, 0, 0, 0, 1, 1], objects=[1, 2])
    0.5
    """
    truth = check_labels(labels_true, len(np.asarray(labels_true)), name="labels_true")
    pred = check_labels(labels_pred, len(truth), name="labels_pred")
    wanted = np.unique(truth[truth >= 0]) if objects is None else np.asarray(objects)
    if not len(wanted):
        return float("nan")
    table = contingency(truth, pred)
    cluster = table.classes_pred[table.cols] >= 0
    rows, cols, counts = table.rows[cluster], table.cols[cluster], table.counts[cluster]
    iou = counts / (table.sizes_true[rows] + table.sizes_pred[cols] - counts)
    best = np.zeros(len(table.classes_true))
    np.maximum.at(best, rows, iou)
    true_ids = table.classes_true
    rows = np.searchsorted(true_ids, wanted)
    present = (rows < len(true_ids)) & (true_ids[np.minimum(rows, len(true_ids) - 1)] == wanted)
    found = np.zeros(len(wanted), dtype=bool)
    found[present] = best[rows[present]] >= min_iou
    return float(found.mean())
