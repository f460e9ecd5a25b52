"""``np.unique(rows, axis=0)`` of integer rows, through one int64 key per row.

NumPy finds unique rows by sorting a structured view of them, several times slower than
sorting one integer per row. Integer rows whose columns span few enough values are
packed into one int64 (mixed radix, the first column most significant), so the keys
sort as the rows do (lexicographically) and the answer is the same, in the same order.
Rows that do not fit take NumPy's way.
"""

import numpy as np

__all__ = ["prefix_counts", "unique_rows"]

_MAX_KEY = np.iinfo(np.int64).max


def _packed(rows):
    """``(keys, low, spans)``, or None when the rows cannot be packed into int64."""
    if rows.ndim != 2 or rows.dtype.kind not in "iu" or not rows.size:
        return None
    low = [int(v) for v in rows.min(axis=0)]
    high = [int(v) for v in rows.max(axis=0)]
    spans = [h - lo + 1 for lo, h in zip(low, high, strict=True)]
    if np.prod(spans, dtype=object) > _MAX_KEY:
        return None
    keys = np.zeros(len(rows), dtype=np.int64)
    for column, (lo, span) in enumerate(zip(low, spans, strict=True)):
        keys *= span
        keys += rows[:, column].astype(np.int64) - lo
    return keys, low, spans


def unique_rows(rows, *, return_index=False, return_inverse=False, return_counts=False):
    """The same as ``np.unique(rows, axis=0, ...)`` for an integer array ``(n, d)``.

    Parameters
    ----------
    rows : ndarray of shape (n, d)
    return_index, return_inverse, return_counts : bool, default=False
        As :func:`numpy.unique` (``return_index`` gives every row's first occurrence).

    Returns
    -------
    unique : ndarray of shape (k, d)
        The distinct rows, sorted lexicographically, of the dtype of ``rows``.
    index, inverse, counts : ndarray
        Those asked for, in this order.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.unique_rows import unique_rows
    >>> unique_rows(np.array([[2, -1], [0, 5], [2, -1]]), return_counts=True)
    (array([[ 0,  5],
           [ 2, -1]]), array([1, 2]))
    """
    rows = np.asarray(rows)
    packed = _packed(rows)
    if packed is None:
        return np.unique(
            rows,
            axis=0,
            return_index=return_index,
            return_inverse=return_inverse,
            return_counts=return_counts,
        )
    keys, low, spans = packed
    distinct, extras = _unique_keys(keys, return_index, return_inverse, return_counts)
    unique = _unpacked(distinct, low, spans, rows.dtype)
    return (unique, *extras) if extras else unique


def _unpacked(keys, low, spans, dtype):
    """The rows whose packed keys (:func:`_packed`) are ``keys``."""
    unique = np.empty((len(keys), len(spans)), dtype=dtype)
    rest = keys.copy()
    for column in range(len(spans) - 1, -1, -1):
        rest, digit = np.divmod(rest, spans[column])
        unique[:, column] = digit + low[column]
    return unique


def _unique_keys(keys, return_index, return_inverse, return_counts):
    """``np.unique`` of int64 keys by a sort (NumPy's own takes 30 times longer on them)."""
    n = len(keys)
    order = None
    if return_index or return_inverse:
        # Stable where an index must be a first occurrence.
        order = np.argsort(keys, kind="stable" if return_index else None)
        ordered = keys[order]
    else:
        ordered = np.sort(keys)
    first = np.ones(n, dtype=bool)
    np.not_equal(ordered[1:], ordered[:-1], out=first[1:])
    extras = []
    if return_index:
        extras.append(order[first])
    if return_inverse:
        inverse = np.empty(n, dtype=np.intp)
        inverse[order] = np.cumsum(first) - 1
        extras.append(inverse)
    if return_counts:
        extras.append(np.diff(np.append(np.flatnonzero(first), n)))
    return ordered[first], extras


def prefix_counts(rows, width):
    """The distinct rows of ``rows[:, :width]`` and how many distinct full rows each
    begins: ``unique_rows(unique_rows(rows)[:, :width], return_counts=True)``, with one
    sort where the rows pack (the packed keys of the full rows, divided by the span of
    the other columns, are those of their first ``width`` columns, already sorted).

    Examples
    --------
    A voter (the last column) counts once per bin (the first two):

    >>> import numpy as np
    >>> from mmreg._array.unique_rows import prefix_counts
    >>> prefix_counts(np.array([[1, 2, 7], [1, 2, 7], [1, 2, 8], [0, 5, 7]]), 2)
    (array([[0, 5],
           [1, 2]]), array([1, 2]))
    """
    rows = np.asarray(rows)
    packed = _packed(rows)
    if packed is None:
        return unique_rows(unique_rows(rows)[:, :width], return_counts=True)
    keys, low, spans = packed
    distinct, _ = _unique_keys(keys, False, False, False)
    # Sorted already: the prefixes' runs are their counts.
    prefix = distinct // int(np.prod(spans[width:], dtype=np.int64))
    first = np.ones(len(prefix), dtype=bool)
    np.not_equal(prefix[1:], prefix[:-1], out=first[1:])
    counts = np.diff(np.append(np.flatnonzero(first), len(prefix)))
    return _unpacked(prefix[first], low[:width], spans[:width], rows.dtype), counts
