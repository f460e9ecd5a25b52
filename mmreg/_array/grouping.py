"""Values sorted within groups: the order behind per-group medians and quantiles, and
the distinct values of integer keys."""

import numpy as np

__all__ = [
    "group_bounds",
    "group_centroids",
    "middle_values",
    "sorted_within_groups",
    "unique_sorted",
]

# Groups this large on average find their middle values by a partition each (linear)
# rather than by one sort of all the values: a loop of a few microseconds a group
# against a sort of some tens of nanoseconds a value.
_PARTITION_SIZE = 64


def _stable_group_order(groups, n_groups):
    """The stable sort of ``groups`` (in ``0..n_groups-1``): a radix sort of 16-bit keys
    for fewer than 32,768 groups."""
    if n_groups <= np.iinfo(np.int16).max:
        groups = groups.astype(np.int16)
    return np.argsort(groups, kind="stable")


def sorted_within_groups(values, groups, n_groups):
    """``values`` sorted by group and, within each group, by value.

    The order of ``np.lexsort((values, groups))``, three to four times faster: sorted by
    value, then stably by group, which for fewer than 32,768 groups is a radix sort.

    Parameters
    ----------
    values : ndarray of shape (n,)
    groups : ndarray of int of shape (n,)
        Group of each value in ``0..n_groups-1``.
    n_groups : int

    Returns
    -------
    sorted_values : ndarray of shape (n,)
    starts, counts : ndarray of shape (n_groups,)
        Where each group's values begin in ``sorted_values``, and how many there are.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.grouping import sorted_within_groups
    >>> sorted_within_groups(np.array([3.0, 1.0, 2.0, 0.0]), np.array([1, 0, 1, 0]), 3)
    (array([0., 1., 2., 3.]), array([0, 2, 4]), array([2, 2, 0]))
    """
    by_value = np.argsort(values)
    order = by_value[_stable_group_order(groups[by_value], n_groups)]
    counts = np.bincount(groups, minlength=n_groups)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    return values[order], starts, counts


def middle_values(values, groups, n_groups):
    """The two middle values of every group, as a sort within each group puts them.

    ``low`` is the value at position ``(c - 1) // 2`` of a group of ``c`` values sorted
    ascending, ``high`` the one at ``c // 2`` (equal for odd ``c``; NaN for an empty
    group): the same floats as :func:`sorted_within_groups` gives there, found by a
    partition of each group where the groups are large.

    Parameters
    ----------
    values : ndarray of shape (n,)
    groups : ndarray of int of shape (n,)
        Group of each value in ``0..n_groups-1``.
    n_groups : int

    Returns
    -------
    low, high : ndarray of shape (n_groups,)

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.grouping import middle_values
    >>> low, high = middle_values(np.array([4.0, 1.0, 3.0, 2.0, 5.0]), np.array([0, 0, 0, 0, 1]), 3)
    >>> low.tolist(), high.tolist()
    ([2.0, 5.0, nan], [3.0, 5.0, nan])
    """
    values = np.asarray(values)
    groups = np.asarray(groups)
    low = np.full(n_groups, np.nan)
    high = np.full(n_groups, np.nan)
    counts = np.bincount(groups, minlength=n_groups)
    full = np.flatnonzero(counts)
    if not len(full):
        return low, high
    if len(values) < _PARTITION_SIZE * len(full):
        sorted_values, starts, counts = sorted_within_groups(values, groups, n_groups)
        low[full] = sorted_values[starts[full] + (counts[full] - 1) // 2]
        high[full] = sorted_values[starts[full] + counts[full] // 2]
        return low, high
    starts = np.cumsum(counts) - counts
    ordered = values if len(full) == 1 else values[_stable_group_order(groups, n_groups)]
    for group, start, count in zip(
        full.tolist(), starts[full].tolist(), counts[full].tolist(), strict=True
    ):
        middle = ((count - 1) // 2, count // 2)
        part = np.partition(ordered[start : start + count], middle)
        low[group], high[group] = part[middle[0]], part[middle[1]]
    return low, high


def group_bounds(points, groups, n_groups):
    """The bounding box of each group's points: ``low, high`` of shape (n_groups, d).

    What ``np.minimum.at`` and ``np.maximum.at`` give (``inf`` and ``-inf`` for an empty
    group), from one stable sort of the groups and one ``reduceat`` each: ``ufunc.at``
    costs ten times as much at millions of points.

    Parameters
    ----------
    points : ndarray of shape (n, d)
    groups : ndarray of int of shape (n,)
        Group of each point in ``0..n_groups-1``.
    n_groups : int

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.grouping import group_bounds
    >>> low, high = group_bounds(np.array([[0.0, 5], [2, 1], [9, 9]]), np.array([0, 0, 2]), 3)
    >>> low.tolist(), high.tolist()
    ([[0.0, 1.0], [inf, inf], [9.0, 9.0]], [[2.0, 5.0], [-inf, -inf], [9.0, 9.0]])
    """
    points = np.asarray(points, dtype=float)
    groups = np.asarray(groups)
    d = points.shape[1]
    low = np.full((n_groups, d), np.inf)
    high = np.full((n_groups, d), -np.inf)
    counts = np.bincount(groups, minlength=n_groups)
    full = np.flatnonzero(counts)
    if not len(full):
        return low, high
    ordered = points[_stable_group_order(groups, n_groups)]
    starts = (np.cumsum(counts) - counts)[full]
    low[full] = np.minimum.reduceat(ordered, starts, axis=0)
    high[full] = np.maximum.reduceat(ordered, starts, axis=0)
    return low, high


def group_centroids(points, labels, n_groups):
    """Centroid and size of every group ``0..n_groups-1`` (NaN centroid when empty).

    Rows with a negative label are left out; one ``bincount`` per coordinate.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.grouping import group_centroids
    >>> centroids, sizes = group_centroids(np.array([[0.0, 0, 0], [2, 0, 0], [5, 5, 5]]),
    ...                                    np.array([0, 0, 1]), 2)
    >>> centroids.tolist(), sizes.tolist()
    ([[1.0, 0.0, 0.0], [5.0, 5.0, 5.0]], [2, 1])
    """
    keep = labels >= 0
    g = labels[keep]
    sizes = np.bincount(g, minlength=n_groups)
    sums = np.stack(
        [
            np.bincount(g, weights=points[keep, axis], minlength=n_groups)
            for axis in range(points.shape[1])
        ],
        axis=1,
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        return sums / sizes[:, None], sizes


def unique_sorted(values):
    """The distinct values of a 1-D integer array, sorted, and where each run of them
    starts in ``np.sort(values)``.

    What ``np.unique(values)`` returns, from one sort: numpy 2's ``np.unique`` goes
    through a hash table that costs ten to forty times a sort of the keys mmreg makes
    (cell and pair codes of tens of thousands of points).

    Parameters
    ----------
    values : ndarray of int of shape (n,)

    Returns
    -------
    uniques : ndarray of shape (m,)
    starts : ndarray of shape (m,)
        For a sorted ``values``, the index of each distinct value's first occurrence
        (``np.unique``'s ``return_index``).

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.grouping import unique_sorted
    >>> unique_sorted(np.array([5, 1, 5, 3, 1]))
    (array([1, 3, 5]), array([0, 2, 3]))
    """
    ordered = np.sort(values)
    first = np.ones(len(ordered), dtype=bool)
    first[1:] = ordered[1:] != ordered[:-1]
    starts = np.flatnonzero(first)
    return ordered[starts], starts
