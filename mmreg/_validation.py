"""Input checks shared by every estimator: stacked correspondences and label arrays."""

import numpy as np

__all__ = ["check_labels", "compact_labels", "split_correspondences"]


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
        correspondence ``b_i`` of the same dimension.
    """
    n_columns = X.shape[1]
    if n_columns % 2:
        raise ValueError(
            "X must hold stacked correspondences [a | b] with an even number of columns "
            f"2*d (6 for 3-D points); got X with n_features = {n_columns}."
        )
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
