"""Input checks shared by every estimator: stacked correspondences and label arrays."""

import numpy as np

__all__ = ["MAX_ABS_COORDINATE", "check_coordinate_range", "check_labels", "compact_labels"]
__all__ += ["split_correspondences"]

#: The largest coordinate magnitude accepted. Squared distances, and their sums over the
#: points of a cluster, must stay far from overflowing float64 (largest 1.8e308, whose
#: square root is 1.3e154): at 1e100 a squared distance is at most about 1e201, and sums
#: over any realistic number of points stay finite. Larger values (1e150 and more) made
#: the estimators fail deep inside with unrelated messages, or hang.
MAX_ABS_COORDINATE = 1e100


def check_coordinate_range(X, *, name="X"):
    """Raise ValueError unless every value of ``X`` lies within +-:data:`MAX_ABS_COORDINATE`.

    Parameters
    ----------
    X : ndarray
        Finite floats (NaN is left to the caller's finiteness check).
    name : str, default="X"
        What ``X`` is, for the message.

    Raises
    ------
    ValueError
        Naming the largest magnitude found and the limit.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._validation import check_coordinate_range
    >>> check_coordinate_range(np.array([[1.0, -2e99]]))
    >>> check_coordinate_range(np.array([[1.0, 3e150]]))
    Traceback (most recent call last):
    ...
    ValueError: values of X reach 3e+150 in magnitude; coordinates must lie within ...
    """
    X = np.asarray(X)
    if X.size == 0 or X.dtype.kind not in "iuf":
        return
    largest = max(abs(float(X.max())), abs(float(X.min())))  # NaN: never larger
    if largest > MAX_ABS_COORDINATE:
        raise ValueError(
            f"values of {name} reach {float(largest):.3g} in magnitude; coordinates must lie "
            f"within +-{MAX_ABS_COORDINATE:.0e} so that squared distances do not overflow. "
            "Rescale the points (e.g. to metres)."
        )


def split_correspondences(X):
    """Split validated stacked correspondences ``[a | b]`` into ``(a, b)``.

    Parameters
    ----------
    X : ndarray of shape (n, 2 * d)
        Already converted to a finite 2-D float array (e.g. by ``validate_data``).

    Returns
    -------
    a, b : ndarray of shape (n, d)

    Raises
    ------
    ValueError
        If the number of columns is odd: each row must hold a point ``a_i`` and its
        correspondence ``b_i`` of the same dimension; or if a value exceeds
        :data:`MAX_ABS_COORDINATE` in magnitude (see :func:`check_coordinate_range`).
    """
    n_columns = X.shape[1]
    if n_columns % 2:
        raise ValueError(
            "X must hold stacked correspondences [a | b] with an even number of columns "
            f"2*d (6 for 3-D points); got X with n_features = {n_columns}."
        )
    check_coordinate_range(X)
    d = n_columns // 2
    return X[:, :d], X[:, d:]


def check_labels(labels, n_samples, *, name="labels"):
    """Validate an integer label array of length ``n_samples``; negative means unassigned.

    Returns the labels as an ``intp`` array. Raises ``TypeError`` for labels that are not
    integers and ``ValueError`` for a wrong shape or length or for NaN/infinity.
    """
    arr = np.asarray(labels)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be 1-D; got an array of shape {arr.shape}.")
    if len(arr) != n_samples:
        raise ValueError(
            f"{name} has length {len(arr)} but X has {n_samples} correspondences; "
            "one label per correspondence is needed."
        )
    if arr.dtype.kind == "f":
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} contains NaN or infinity.")
        if not np.all(arr == np.round(arr)):
            raise TypeError(f"{name} must be integers; got non-integer values.")
    elif arr.dtype.kind not in "iu":
        raise TypeError(f"{name} must be an array of integers; got dtype {arr.dtype}.")
    return arr.astype(np.intp)


def compact_labels(labels):
    """Renumber the non-negative labels to ``0..K-1`` in increasing order; negatives to -1.

    Returns
    -------
    compact : ndarray of shape (n,)
    n_clusters : int
    """
    labels = np.asarray(labels)
    out = np.full(labels.shape, -1, dtype=np.intp)
    keep = labels >= 0
    uniques, inverse = np.unique(labels[keep], return_inverse=True)
    out[keep] = inverse
    return out, len(uniques)
