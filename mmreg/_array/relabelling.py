"""How many rows two labellings put in different clusters, whatever their numbering."""

import numpy as np

__all__ = ["rows_moved"]


def rows_moved(before, after):
    """Rows whose cluster differs between two labellings, clusters matched by overlap.

    Each cluster of ``after`` is matched to at most one cluster of ``before`` and vice
    versa, greedily by the number of rows they share (the largest overlaps first); a row
    has stayed when its two clusters are matched. Label ``-1`` (no cluster) is matched
    to itself only. So a renumbering moves nothing, a merge moves the smaller part's
    rows, a split the smaller part's, and a row going to or from ``-1`` moves.

    Parameters
    ----------
    before, after : ndarray of int of shape (n,)
        Cluster of each row, ``-1`` for none; the numbers need not correspond.

    Returns
    -------
    int

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.relabelling import rows_moved
    >>> rows_moved(np.array([0, 0, 1, 1, -1]), np.array([5, 5, 3, 3, -1]))
    0
    >>> rows_moved(np.array([0, 0, 0, 1, 1]), np.array([2, 2, 2, 2, 2]))
    2
    """
    before = np.asarray(before, dtype=np.int64)
    after = np.asarray(after, dtype=np.int64)
    both = (before >= 0) & (after >= 0)
    stayed = int(np.count_nonzero((before < 0) & (after < 0)))
    if both.any():
        width = int(after[both].max()) + 1
        pairs, shared = np.unique(before[both] * width + after[both], return_counts=True)
        # Largest overlaps first; among equal ones, the order of the pairs' keys.
        order = np.argsort(-shared, kind="stable")
        taken_before, taken_after = set(), set()
        for key, count in zip(pairs[order].tolist(), shared[order].tolist(), strict=True):
            old, new = divmod(key, width)
            if old not in taken_before and new not in taken_after:
                taken_before.add(old)
                taken_after.add(new)
                stayed += count
    return len(before) - stayed
