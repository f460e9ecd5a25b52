"""How many true objects an estimate recovers: the count that the paper's IoU hides."""

import numpy as np
from scipy.sparse import coo_matrix

from mmreg._validation import check_labels

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
    keep = pred >= 0
    wanted = np.unique(truth[truth >= 0]) if objects is None else np.asarray(objects)
    if not len(wanted):
        return float("nan")
    true_ids, t = np.unique(truth, return_inverse=True)
    pred_ids, p = np.unique(pred[keep], return_inverse=True)
    overlap = coo_matrix(
        (np.ones(keep.sum()), (t[keep], p)), shape=(len(true_ids), len(pred_ids))
    ).toarray()
    true_sizes = np.bincount(t, minlength=len(true_ids))
    pred_sizes = np.bincount(p, minlength=len(pred_ids))
    union = true_sizes[:, None] + pred_sizes[None, :] - overlap
    with np.errstate(invalid="ignore", divide="ignore"):
        best = np.where(union > 0, overlap / union, 0.0).max(axis=1, initial=0.0)
    rows = np.searchsorted(true_ids, wanted)
    present = (rows < len(true_ids)) & (true_ids[np.minimum(rows, len(true_ids) - 1)] == wanted)
    found = np.zeros(len(wanted), dtype=bool)
    found[present] = best[rows[present]] >= min_iou
    return float(found.mean())
