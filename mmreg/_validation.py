"""Input checks shared by every estimator: stacked correspondences and label arrays."""

import numpy as np

__all__ = ["MAX_ABS_COORDINATE", "check_coordinate_range", "check_labels", "compact_labels"]
__all__ += ["MAX_INCOHERENCE", "NotCorrespondencesError", "check_paired", "invalid_rows"]
__all__ += ["are_rotations", "check_ego_motion", "split_correspondences"]

#: Rows of correspondences pair a point with where it went, so neighbouring a-points
#: move alike. Stacked rows whose flows ``b - a`` differ between nearest a-points by a
#: median of more than this fraction of the scene's median radius (and more than ``tau``)
#: are not correspondences. Shared scenes: real and generated flows reach 0.02
#: (FlyingThings3D-like, noisy) and 0.27 (make_scene with 50 % wrong correspondences);
#: two sweeps sampled independently and passed row by row reach 1.24-1.85. The flows
#: must also differ by more than ``NEIGHBOUR_SPACINGS`` times the median distance between
#: nearest a-points: a rigid motion moves two neighbours apart by at most twice their
#: distance (sparse points, e.g. a handful of rows, turned far).
MAX_INCOHERENCE = 0.5
NEIGHBOUR_SPACINGS = 4.0
# Rows whose medians check_paired takes.
_PAIRED_SAMPLE = 4096

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


def invalid_rows(X):
    """Rows of stacked correspondences ``[a | b]`` that hold no measurement.

    A row is invalid if it holds NaN (padding of a fixed-size array) or if its a-point
    or its b-point lies exactly at the origin together with another row's (a LiDAR
    driver writes its failed returns there, as thousands of copies of ``(0, 0, 0)``;
    one point at the origin, as hand-made data often has, is kept).

    Parameters
    ----------
    X : ndarray of shape (n, 2 * d)
        Stacked correspondences, NaN allowed.

    Returns
    -------
    invalid : ndarray of shape (n,), dtype bool

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._validation import invalid_rows
    >>> X = np.array([[0.0, 0, 0, 1, 1, 1], [1, 2, 3, 1, 2, 4], [np.nan] * 6,
    ...               [0, 0, 0, 2, 2, 2]])
    >>> invalid_rows(X).tolist()
    [True, False, True, True]
    >>> invalid_rows(X[:2]).tolist()  # one a-point at the origin is a point
    [False, False]
    """
    X = np.asarray(X, dtype=float)
    invalid = np.isnan(X).any(axis=1)
    d = X.shape[1] // 2
    for half in (X[:, :d], X[:, d:]):
        invalid |= _failed_returns(half, invalid)
    return invalid


def _failed_returns(points, invalid):
    """The rows of ``points`` at the origin (``invalid`` ones aside), where more than one
    lies there: a LiDAR driver's failed returns; one point there is a point."""
    at_origin = ~np.any(points != 0, axis=1) & ~invalid
    return at_origin if np.count_nonzero(at_origin) > 1 else np.zeros_like(invalid)


def invalid_points(points):
    """Rows of a point set ``(n, d)`` that hold no return: :func:`invalid_rows` of the
    rows stacked with themselves, ``[points | points]``, without the copy.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._validation import invalid_points
    >>> invalid_points(np.array([[0.0, 0, 0], [1, 2, 3], [np.nan, 0, 0], [0, 0, 0]])).tolist()
    [True, False, True, True]
    """
    points = np.asarray(points, dtype=float)
    invalid = np.isnan(points).any(axis=1)
    return invalid | _failed_returns(points, invalid)


def no_return(values):
    """Rows that hold no measurement, of points (odd columns: :func:`invalid_points`) or
    of correspondences ``[a | b]`` (even columns: :func:`invalid_rows`).

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._validation import no_return
    >>> no_return(np.array([[0.0, 0, 0], [1, 2, 3], [0, 0, 0]])).tolist()
    [True, False, True]
    """
    values = np.asarray(values, dtype=float)
    return invalid_rows(values) if values.shape[1] % 2 == 0 else invalid_points(values)


class NotCorrespondencesError(ValueError):
    """Stacked rows ``[a | b]`` that pair points across the scene (see :func:`check_paired`)."""


def check_paired(a, b, tau=None, nearest=None, spacing=None):
    """Raise ValueError if ``a`` and ``b`` are two point clouds rather than correspondences.

    Rows of correspondences pair a point with where it went: neighbouring a-points move
    alike, however far (a rigid motion moves two neighbours by at most twice their
    distance apart; a wrong match by its own error). Two point clouds sampled
    independently and passed row by row pair each point with one anywhere in the scene,
    so neighbouring a-points "move" by unrelated amounts. They are refused when the
    median distance between the flows ``b - a`` of nearest a-points exceeds ``tau`` (if
    given), :data:`MAX_INCOHERENCE` times the median distance of the a-points from their
    coordinate-wise median, and :data:`NEIGHBOUR_SPACINGS` times the median distance
    between nearest a-points (which bounds how far a rigid motion moves two neighbours
    apart).

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
        Finite points.
    tau : float or None, default=None
        The estimator's distance gate.
    nearest, spacing : ndarray of shape (n,), default=None
        Row of each a-point's nearest other a-point and its distance, if known (else a
        KD-tree finds them).

    Raises
    ------
    NotCorrespondencesError
        A ValueError naming the incoherence found and what to use for two sweeps instead.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._validation import check_paired
    >>> rng = np.random.default_rng(0)
    >>> a = rng.uniform(-20, 20, (1000, 3))
    >>> check_paired(a, a + [30.0, 0, 0], tau=1.5)  # one motion, however far
    >>> check_paired(a, rng.uniform(-20, 20, (1000, 3)), tau=1.5)
    Traceback (most recent call last):
    ...
    mmreg._validation.NotCorrespondencesError: X does not look like correspondences: ...
    """
    if len(a) < 2:
        return
    # Medians over evenly spread rows: as good as all of them, and a fraction of the cost.
    sample = np.unique(np.linspace(0, len(a) - 1, min(len(a), _PAIRED_SAMPLE)).astype(np.intp))
    if nearest is None:
        from scipy.spatial import cKDTree  # here: importing this module stays light

        spacing, nearest = cKDTree(a).query(a[sample], k=2)
        spacing, nearest = spacing[:, 1], nearest[:, 1]
    else:
        spacing, nearest = spacing[sample], nearest[sample]
    flow = b - a
    incoherence = float(np.median(np.linalg.norm(flow[sample] - flow[nearest], axis=1)))
    radius = float(np.median(np.linalg.norm(a[sample] - np.median(a, axis=0), axis=1)))
    if incoherence <= MAX_INCOHERENCE * radius:
        return
    if tau is not None and incoherence <= tau:
        return
    if incoherence <= NEIGHBOUR_SPACINGS * float(np.median(spacing)):
        return
    if radius == 0:  # no scene to measure the flows against: one point sent everywhere
        shared = int(np.count_nonzero(np.all(a == np.median(a, axis=0), axis=1)))
        raise NotCorrespondencesError(
            f"X does not look like correspondences: {shared} of its {len(a)} rows share one "
            f"a-point ({', '.join(f'{v:g}' for v in np.median(a, axis=0))}) while their "
            f"b-points differ (the flows b - a of nearest a-points differ by {incoherence:.3g}, "
            "median): one point cannot move to several places. Each row must pair a "
            "distinct point with where it went; remove the repeated rows."
        )
    raise NotCorrespondencesError(
        "X does not look like correspondences: the flows b - a of nearest a-points differ "
        f"by {incoherence:.3g} (median), "
        + (f"more than tau={tau:g} and " if tau is not None else "")
        + f"{incoherence / radius:.1f} times the scene's median radius ({radius:.3g}), as "
        "when two point clouds sampled independently are stacked row by row. Each row "
        "must pair a point with where it went (a match, or a + flow). For two raw sweeps "
        "use SweepRegistration (mmreg register SWEEP0 --sweep SWEEP1, or mmreg run --pairs "
        "sweeps)."
    )


# A given rotation is one within this: R^T R = I to it (odometry's poses, written to a
# few digits, are: KITTI's with 7 significant digits, errors near 1e-6).
ROTATION_TOLERANCE = 1e-4


def are_rotations(matrices):
    """Whether each of ``matrices`` (``(..., d, d)``) is a rotation to
    ``ROTATION_TOLERANCE``: every entry of ``R^T R - I`` within it, and ``det R > 0``.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._validation import are_rotations
    >>> are_rotations(np.stack([np.eye(3), np.diag([1.0, 1.0, -1.0]), 2 * np.eye(3)]))
    array([ True, False, False])
    """
    matrices = np.asarray(matrices, dtype=float)
    gram = np.swapaxes(matrices, -1, -2) @ matrices
    close = np.all(np.abs(gram - np.eye(matrices.shape[-1])) <= ROTATION_TOLERANCE, axis=(-2, -1))
    return close & (np.linalg.det(matrices) > 0)


def check_ego_motion(ego_motion, d=3):
    """``ego_motion`` as ``(R, t)`` of shapes ``(d, d)`` and ``(d,)``, from ``(R, t)`` or a
    homogeneous ``(d + 1, d + 1)`` matrix; None stays None. One clear error otherwise.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._validation import check_ego_motion
    >>> R, t = check_ego_motion(np.eye(4), 3)
    >>> R.shape, t.shape
    ((3, 3), (3,))
    """
    if ego_motion is None:
        return None
    if isinstance(ego_motion, np.ndarray) or not isinstance(ego_motion, (tuple, list)):
        try:
            matrix = np.asarray(ego_motion, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(
                f"ego_motion must be (R, t) or a ({d + 1}, {d + 1}) homogeneous matrix; got "
                f"{ego_motion!r}."
            ) from None
        if matrix.shape != (d + 1, d + 1):
            raise ValueError(
                f"ego_motion must be (R, t) or a ({d + 1}, {d + 1}) homogeneous matrix; got "
                f"an array of shape {matrix.shape}."
            )
        rotation, translation = matrix[:d, :d], matrix[:d, d]
    elif len(ego_motion) != 2:
        raise ValueError(f"ego_motion must be (R, t); got a sequence of {len(ego_motion)}.")
    else:
        try:
            rotation = np.asarray(ego_motion[0], dtype=float)
            translation = np.asarray(ego_motion[1], dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"ego_motion must be (R, t) of numbers; got {ego_motion!r}.") from None
    if rotation.shape != (d, d) or translation.shape != (d,):
        raise ValueError(
            f"ego_motion must be (R, t) with R of shape ({d}, {d}) and t of shape ({d},); got "
            f"{rotation.shape} and {translation.shape}."
        )
    if not (np.all(np.isfinite(rotation)) and np.all(np.isfinite(translation))):
        raise ValueError("ego_motion holds NaN or infinite values.")
    if not are_rotations(rotation):
        raise ValueError(
            f"ego_motion's R is not a rotation (R^T R = I and det R = 1 within "
            f"{ROTATION_TOLERANCE:g}); "
            "give the static world's motion from the first frame to the second, b = R a + t."
        )
    return rotation, translation
