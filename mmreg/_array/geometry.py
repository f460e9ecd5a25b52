"""Rigid-motion geometry on arrays: batched Horn/Kabsch, residuals, rotation angles.

Pure functions with no estimator state, shared by the EM estimator, every baseline,
the metrics and the theory checks. Every function works in any dimension ``d >= 1``
(points are rows of ``(n, d)`` arrays); the package mostly uses ``d = 3``.
"""

from dataclasses import dataclass

import numpy as np

__all__ = [
    "apply_motions",
    "column_bounds",
    "rows_in_box",
    "degenerate_groups",
    "departures",
    "fit_rigid",
    "fit_rigid_grouped",
    "fit_rigid_rows",
    "moved_rows",
    "own_residuals",
    "residual_table",
    "residuals",
    "rotation_angle",
    "row_medians",
    "squared_residuals_all",
]


def fit_rigid_grouped(a, b, labels, n_groups):
    """Least-squares rigid motion ``b ~ R a + t`` for every group at once (Horn/Arun/Kabsch).

    For each group ``j`` this solves ``min_{R in SO(d), t} sum_i ||b_i - R a_i - t||^2`` over
    the rows with ``labels == j``, with one batched SVD of the ``d x d`` cross-covariances.
    The reflection case is corrected (Umeyama's sign fix), so every returned matrix is a
    proper rotation with determinant ``+1``, also for degenerate (collinear, coincident or
    single-point) groups, whose rotation is then one of many optimal ones.

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
        Corresponding points.
    labels : ndarray of shape (n,)
        Group of each correspondence in ``0..n_groups-1``; negative labels are ignored.
    n_groups : int
        Number of groups.

    Returns
    -------
    rotations : ndarray of shape (n_groups, d, d)
    translations : ndarray of shape (n_groups, d)
    counts : ndarray of shape (n_groups,)
        Number of correspondences in each group. Empty groups get the identity motion.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.geometry import fit_rigid_grouped
    >>> a = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> R, t, counts = fit_rigid_grouped(a, a + [1, 2, 3], np.zeros(4, int), 1)
    >>> np.round(t, 6)
    array([[1., 2., 3.]])
    """
    labels = np.asarray(labels)
    keep = labels >= 0
    a_rows = np.asarray(a, dtype=float)[keep].T
    b_rows = np.asarray(b, dtype=float)[keep].T
    fit = fit_rigid_rows(a_rows, b_rows, labels[keep], n_groups)
    return fit.rotations, fit.translations, fit.counts


@dataclass
class GroupedFit:
    """What :func:`fit_rigid_rows` returns."""

    rotations: np.ndarray
    translations: np.ndarray
    counts: np.ndarray
    centroids: np.ndarray
    """Centroid of each group's a-points, ``(n_groups, d)``."""
    centred: np.ndarray
    """Each a-point less its group's centroid, ``(d, n)``."""
    residuals: np.ndarray
    """``b - R a - t`` of each correspondence under its group's motion, ``(d, n)``."""


def fit_rigid_rows(a_rows, b_rows, labels, n_groups):
    """:func:`fit_rigid_grouped` on coordinate rows, with the by-products an EM needs.

    The workhorse of the EM's M-step: coordinates are rows of ``(d, n)`` arrays, so that
    every per-point operation, and every per-group sum (a weighted ``np.bincount``), runs
    over contiguous rows.

    Parameters
    ----------
    a_rows, b_rows : ndarray of shape (d, n)
        Corresponding points, one coordinate per row.
    labels : ndarray of shape (n,)
        Group of each correspondence in ``0..n_groups-1`` (no negative labels).
    n_groups : int

    Returns
    -------
    GroupedFit
        Motions and counts as :func:`fit_rigid_grouped`; the residuals are computed from
        the centred points (no cancellation far from the origin).
    """
    d = len(a_rows)
    labels = np.asarray(labels, dtype=np.intp)
    counts = np.bincount(labels, minlength=n_groups)[:n_groups]
    safe = np.maximum(counts, 1)

    def sums(row):
        # One pass per row, adding each group's values in their order.
        return np.bincount(labels, weights=row, minlength=n_groups)[:n_groups]

    centroid_a = np.stack([sums(row) for row in a_rows]) / safe  # (d, n_groups)
    centroid_b = np.stack([sums(row) for row in b_rows]) / safe
    # Centre before forming outer products: sum(a b^T) - m ca cb^T cancels badly far
    # from the origin.
    ca = a_rows - np.take(centroid_a, labels, axis=1)
    cb = b_rows - np.take(centroid_b, labels, axis=1)
    cross = np.empty((n_groups, d, d))
    product = np.empty(len(labels))
    for p in range(d):
        for q in range(d):
            cross[:, p, q] = sums(np.multiply(ca[p], cb[q], out=product))
    u, _, vt = np.linalg.svd(cross)
    v = np.swapaxes(vt, -1, -2)
    ut = np.swapaxes(u, -1, -2)
    sign = np.sign(np.linalg.det(v @ ut))
    sign[sign == 0] = 1.0
    v[:, :, -1] *= sign[:, None]
    # R = V diag(1, ..., sign) U^T and t = centroid_b - R centroid_a, group by group with
    # elementwise operations: a group's motion does not depend on the other groups fitted
    # with it (a batched product may round differently for different batch sizes).
    rotations = np.zeros((n_groups, d, d))
    for p in range(d):
        for q in range(d):
            for r in range(d):
                rotations[:, p, q] += v[:, p, r] * ut[:, r, q]
    rotations[counts == 0] = np.eye(d)
    translations = centroid_b.T.copy()
    for p in range(d):
        for q in range(d):
            translations[:, p] -= rotations[:, p, q] * centroid_a[q]
    # b - R a - t = (b - centroid_b) - R (a - centroid_a).
    residuals = cb
    per_point = np.take(rotations.reshape(n_groups, d * d).T, labels, axis=1)
    for p in range(d):
        for q in range(d):
            residuals[p] -= per_point[p * d + q] * ca[q]
    return GroupedFit(rotations, translations, counts, centroid_a.T, ca, residuals)


def fit_rigid(a, b):
    """Least-squares rigid motion ``b ~ R a + t`` of one set of correspondences.

    Parameters
    ----------
    a, b : ndarray of shape (n, d)

    Returns
    -------
    rotation : ndarray of shape (d, d)
        A proper rotation (determinant ``+1``).
    translation : ndarray of shape (d,)

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.geometry import fit_rigid
    >>> a = np.random.default_rng(0).normal(size=(10, 3))
    >>> R, t = fit_rigid(a, a @ np.diag([1., -1, -1]).T)
    >>> np.round(R, 6) + 0.0
    array([[ 1.,  0.,  0.],
           [ 0., -1.,  0.],
           [ 0.,  0., -1.]])
    """
    a = np.asarray(a, dtype=float)
    rotations, translations, _ = fit_rigid_grouped(a, b, np.zeros(len(a), dtype=np.intp), 1)
    return rotations[0], translations[0]


def column_bounds(points):
    """The smallest and largest value of every column of ``points`` (n >= 1 rows).

    The same values as ``points.min(axis=0)`` and ``points.max(axis=0)``, column by
    column: numpy reduces a tall ``(n, 3)`` array along its rows several times slower
    than it reduces its columns one at a time.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.geometry import column_bounds
    >>> column_bounds(np.array([[0.0, 5.0], [2.0, -1.0]]))
    (array([ 0., -1.]), array([2., 5.]))
    """
    points = np.asarray(points)
    columns = range(points.shape[1])
    low = np.array([points[:, j].min() for j in columns], dtype=points.dtype)
    high = np.array([points[:, j].max() for j in columns], dtype=points.dtype)
    return low, high


def rows_in_box(points, low, high, rows=None):
    """The rows of ``points`` (among ``rows``, ascending) inside the box ``[low, high]``.

    ``np.flatnonzero(np.all((points >= low) & (points <= high), axis=1))``, tested a
    column at a time on the rows still inside: a box around one object holds a small
    share of a sweep, so the later columns cost little.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.geometry import rows_in_box
    >>> points = np.array([[0.0, 0, 0], [1, 1, 1], [1, 5, 1], [2, 2, 2]])
    >>> rows_in_box(points, [0.5, 0.5, 0.5], [2.0, 2.0, 2.0]).tolist()
    [1, 3]
    >>> rows_in_box(points, [0.5, 0.5, 0.5], [2.0, 2.0, 2.0], rows=np.array([2, 3])).tolist()
    [3]
    """
    points = np.asarray(points)
    low, high = np.asarray(low), np.asarray(high)
    if rows is None:
        column = points[:, 0]
        rows = np.flatnonzero((column >= low[0]) & (column <= high[0]))
    else:
        rows = np.asarray(rows, dtype=np.intp)
        column = points[rows, 0]
        rows = rows[(column >= low[0]) & (column <= high[0])]
    for j in range(1, points.shape[1]):
        column = points[rows, j]
        rows = rows[(column >= low[j]) & (column <= high[j])]
    return rows


# Widest rows row_medians sorts by compare-exchanges of whole columns.
_MAX_NETWORK_WIDTH = 16


def row_medians(values):
    """The median of every row of a narrow ``(n, k)`` array of finite values.

    The same floats as ``np.median(values, axis=1)`` (for an even ``k``, the mean of
    the two middle values): for ``k <= 16`` the rows are sorted by an odd-even
    transposition network of ``np.minimum``/``np.maximum`` over whole columns, which
    costs a few passes over the data where numpy partitions every short row alone.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.geometry import row_medians
    >>> row_medians(np.array([[3.0, 1.0, 2.0, 10.0], [0.0, 0.0, 5.0, 1.0]]))
    array([2.5, 0.5])
    """
    values = np.asarray(values, dtype=float)
    n, k = values.shape
    if k == 0 or k > _MAX_NETWORK_WIDTH:
        return np.median(values, axis=1)
    columns = [values[:, j].copy() for j in range(k)]
    for phase in range(k):
        for j in range(phase % 2, k - 1, 2):
            low = np.minimum(columns[j], columns[j + 1])
            np.maximum(columns[j], columns[j + 1], out=columns[j + 1])
            columns[j] = low
    if k % 2:
        return columns[k // 2]
    return (columns[k // 2 - 1] + columns[k // 2]) / 2


# The order in which numpy's einsum (x86-64) adds the d terms of a length-d contraction
# over a contiguous last axis (d = 2, 3); moved_rows, own_residuals and
# residual_table add them in the same order.
_EINSUM_ORDER = {2: (0, 1), 3: (0, 2, 1)}


def apply_motions(a, rotations, translations, labels):
    """Move each point by the motion of its group: ``R_{l_i} a_i + t_{l_i}``.

    Points with a negative label are returned unchanged.
    """
    a = np.asarray(a, dtype=float)
    labels = np.asarray(labels)
    out = a.copy()
    keep = np.flatnonzero(labels >= 0)
    out[keep] = moved_rows(rotations, translations, labels[keep], a[keep].T).T
    return out


def moved_rows(rotations, translations, labels, a_rows):
    """``R_l a_i + t_l`` of every point under its own motion ``l``, coordinates as rows.

    The direct reading ``einsum("nij,nj->ni", R[labels], a) + t[labels]``, one
    coordinate at a time over contiguous rows and without the ``(n, d, d)`` copy of the
    rotations (less than half the cost); for ``d`` of 2 and 3 the terms are added in
    einsum's order, as in :func:`residual_table`.

    Parameters
    ----------
    rotations : ndarray of shape (K, d, d)
    translations : ndarray of shape (K, d)
    labels : ndarray of int of shape (n,)
        The motion of each point, in ``0..K-1``.
    a_rows : ndarray of shape (d, n)

    Returns
    -------
    ndarray of shape (d, n)
    """
    d = len(a_rows)
    order = _EINSUM_ORDER.get(d, tuple(range(d)))
    entries = np.asarray(rotations, dtype=float).reshape(-1, d * d).T  # (i, j): row i*d + j
    shifts = np.asarray(translations, dtype=float).T
    moved = np.empty((d, len(labels)))
    for i in range(d):
        term = moved[i]
        np.multiply(entries[i * d + order[0]][labels], a_rows[order[0]], out=term)
        for j in order[1:]:
            term += entries[i * d + j][labels] * a_rows[j]
        term += shifts[i][labels]
    return moved


def departures(points, rotations, translations, ego):
    """Where each point's own motion puts it, less where the ego motion puts it.

    Parameters
    ----------
    points : ndarray of shape (K, 3)
    rotations : ndarray of shape (K, 3, 3)
    translations : ndarray of shape (K, 3)
        One motion per point.
    ego : tuple of ndarray
        ``(R, t)`` of the ego motion.

    Returns
    -------
    ndarray of shape (K, 3)

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.geometry import departures
    >>> ego = (np.eye(3), np.array([1.0, 0.0, 0.0]))
    >>> departures(np.zeros((1, 3)), np.eye(3)[None], np.array([[1.0, 2.0, 0.0]]), ego)
    array([[0., 2., 0.]])
    """
    own = np.einsum("kij,kj->ki", rotations, points) + translations
    return own - (points @ ego[0].T + ego[1])


def climb(offsets, grade):
    """How far each offset rises or falls beyond ``grade`` (height over horizontal run).

    Positive where ``offsets`` (e.g. :func:`departures`, z up) climb more steeply than
    ``grade``; traffic moves along the ground.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.geometry import climb
    >>> climb(np.array([[4.0, 0.0, 0.5], [0.4, 0.0, 0.5]]), 0.25)
    array([-0.5,  0.4])
    """
    return np.abs(offsets[:, 2]) - grade * np.linalg.norm(offsets[:, :2], axis=1)


def residuals(a, b, rotations, translations, labels):
    """Residual vectors ``b_i - R_{l_i} a_i - t_{l_i}``; zero rows where the label is negative."""
    b = np.asarray(b, dtype=float)
    moved = apply_motions(a, rotations, translations, labels)
    res = b - moved
    res[np.asarray(labels) < 0] = 0.0
    return res


def residual_table(rotations, translations, a_rows, b_rows, *, origins=None):
    """``||b_i - R_k a_i - t_k||^2`` of every motion ``k`` and correspondence ``i``.

    The direct reading over ``(n, K, d)`` arrays, ``diff = b - einsum("kij,nj->nki",
    R, a) - t`` and ``einsum("nki,nki->nk", diff, diff)``, in ``(K, n)`` layout, one
    coordinate at a time: every operation runs over long contiguous rows, at a fraction
    of the cost. For ``d`` of 2 and 3 the terms are added in the order numpy's einsum
    adds them on x86-64, so there it gives einsum's floats.

    Parameters
    ----------
    rotations : ndarray of shape (K, d, d)
    translations : ndarray of shape (K, d)
    a_rows, b_rows : ndarray of shape (d, n)
        Corresponding points, one coordinate per row.
    origins : ndarray of shape (d, n), default=None
        If given, also the distance ``||R_k a_i + t_k - o_i||`` of every moved point
        from its origin (as ``np.linalg.norm`` over the coordinates gives it).

    Returns
    -------
    table : ndarray of shape (K, n)
    distance : ndarray of shape (K, n)
        Only with ``origins``.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.geometry import residual_table
    >>> a = np.array([[0.0, 1.0], [0.0, 0.0], [0.0, 0.0]])  # the points (0,0,0), (1,0,0)
    >>> residual_table(np.stack([np.eye(3)] * 2), np.array([[0, 0, 0], [1, 0, 0.0]]), a, a)
    array([[0., 0.],
           [1., 1.]])
    """
    d = len(a_rows)
    order = _EINSUM_ORDER.get(d, tuple(range(d)))
    table = None
    squares = [None] * d  # of the distances from the origins, by coordinate
    for i in order:
        term = rotations[:, i, order[0], None] * a_rows[order[0]]
        for j in order[1:]:
            term += rotations[:, i, j, None] * a_rows[j]
        term += translations[:, i, None]
        if origins is not None:
            squares[i] = np.square(term - origins[i])
        np.subtract(b_rows[i], term, out=term)
        term *= term
        if table is None:
            table = term
        else:
            table += term
    if origins is None:
        return table
    distance = squares[0]
    for square in squares[1:]:
        distance += square
    return table, np.sqrt(distance, out=distance)


def own_residuals(rotations, translations, labels, a_rows, b_rows):
    """``||b_i - R_l a_i - t_l||^2`` of every correspondence under its own motion ``l``.

    The direct reading, ``diff = b - einsum("nij,nj->ni", R[labels], a) - t[labels]``
    and ``einsum("ij,ij->i", diff, diff)``, from :func:`moved_rows`; for ``d`` of 2 and
    3 the squares are added in einsum's order, as in :func:`residual_table`.

    Parameters
    ----------
    rotations : ndarray of shape (K, d, d)
    translations : ndarray of shape (K, d)
    labels : ndarray of int of shape (n,)
        The motion of each correspondence, in ``0..K-1``.
    a_rows, b_rows : ndarray of shape (d, n)

    Returns
    -------
    ndarray of shape (n,)
    """
    d = len(a_rows)
    order = _EINSUM_ORDER.get(d, tuple(range(d)))
    moved = moved_rows(rotations, translations, labels, a_rows)
    np.subtract(b_rows, moved, out=moved)
    moved *= moved
    total = moved[order[0]]
    for i in order[1:]:
        total += moved[i]
    return total


def squared_residuals_all(a, b, rotations, translations):
    """Squared residuals of every correspondence under every motion, ``(n, K)``.

    Uses the expansion ``||b - R a - t||^2 = ||b||^2 + ||a||^2 + ||t||^2 - 2 b^T R a
    - 2 b.t + 2 a.(R^T t)`` so that the whole table is one matrix product of an
    ``(n, d^2 + 2d + 2)`` feature matrix with a ``(d^2 + 2d + 2, K)`` motion matrix,
    instead of an ``(n, K, d)`` temporary. The points are centred first, since the
    expansion loses about ``eps * ||x||^2`` of absolute precision. Tiny negative values
    from rounding are clipped to zero.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    n, d = a.shape
    rotations = np.asarray(rotations, dtype=float)
    if n == 0 or len(rotations) == 0:
        return np.zeros((n, len(rotations)))
    # Work in a frame centred on the data: the residuals are unchanged when a and b are
    # shifted and t becomes t + R mean_a - mean_b, but the expansion loses far less.
    mean_a = a.mean(axis=0)
    mean_b = b.mean(axis=0)
    a = a - mean_a
    b = b - mean_b
    translations = np.asarray(translations, dtype=float) + rotations @ mean_a - mean_b
    # The squared norms ride along as two more columns, so that one product gives the
    # whole table without further passes over it.
    width = d * d + 2 * d + 2
    features = np.empty((n, width))
    features[:, : d * d] = (b[:, :, None] * a[:, None, :]).reshape(n, d * d)
    features[:, d * d : d * d + d] = b
    features[:, d * d + d : d * d + 2 * d] = a
    features[:, -2] = np.einsum("ij,ij->i", a, a) + np.einsum("ij,ij->i", b, b)
    features[:, -1] = 1.0
    k = len(rotations)
    coefs = np.empty((width, k))
    coefs[: d * d] = -2.0 * rotations.reshape(k, d * d).T
    coefs[d * d : d * d + d] = -2.0 * translations.T
    coefs[d * d + d : d * d + 2 * d] = 2.0 * np.einsum("kji,kj->ik", rotations, translations)
    coefs[-2] = 1.0
    coefs[-1] = np.einsum("kj,kj->k", translations, translations)
    sq = features @ coefs
    np.maximum(sq, 0.0, out=sq)
    return sq


def degenerate_groups(a, labels, n_groups, *, rtol=1e-10):
    """Groups whose points do not determine a unique rotation.

    A rigid motion is unique when the centred points of a group span at least ``d - 1``
    dimensions (in 3-D: not collinear, not coincident). Returns a boolean mask of the
    groups whose point covariance has rank below ``d - 1`` (relative tolerance ``rtol``).
    """
    rows = np.ascontiguousarray(np.asarray(a, dtype=float).T)
    labels = np.asarray(labels, dtype=np.intp)
    d = len(rows)
    # Unlabelled points go to an extra group, which is dropped at the end.
    lab = np.where(labels < 0, n_groups, labels)
    counts = np.bincount(lab, minlength=n_groups + 1)[: n_groups + 1]
    centroids = np.stack(
        [np.bincount(lab, weights=row, minlength=n_groups + 1) for row in rows]
    ) / np.maximum(counts, 1)
    centred = rows - np.take(centroids, lab, axis=1)
    scatter = np.empty((n_groups + 1, d, d))
    for p in range(d):
        for q in range(p + 1):
            scatter[:, p, q] = scatter[:, q, p] = np.bincount(
                lab, weights=centred[p] * centred[q], minlength=n_groups + 1
            )
    scatter = scatter[:n_groups]
    eig = np.linalg.eigvalsh(scatter)[:, ::-1]
    scale = np.maximum(eig[:, 0], np.finfo(float).tiny)
    rank = np.sum(eig > rtol * scale[:, None], axis=1)
    rank[eig[:, 0] <= 0] = 0
    return rank < d - 1


def rotation_angle(rotations_a, rotations_b=None, *, degrees=True):
    """Geodesic angle between rotations, ``arccos((tr(R_a^T R_b) - 1) / 2)``.

    Parameters
    ----------
    rotations_a : ndarray of shape (..., d, d)
        Rotations in 2-D or 3-D.
    rotations_b : ndarray of shape (..., d, d), default=None
        If None, the angle of ``rotations_a`` itself (its distance to the identity).
    degrees : bool, default=True

    Returns
    -------
    angle : ndarray of shape (...)

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.geometry import rotation_angle
    >>> Rz = np.array([[0., -1, 0], [1, 0, 0], [0, 0, 1]])
    >>> float(rotation_angle(Rz))
    90.0
    """
    rotations_a = np.asarray(rotations_a, dtype=float)
    if rotations_b is None:
        relative = rotations_a
    else:
        relative = np.swapaxes(rotations_a, -1, -2) @ np.asarray(rotations_b, dtype=float)
    # The cosine formula loses all precision near 0 (arccos'(1) is infinite); the
    # skew part gives the sine, and atan2 is accurate over the whole range.
    trace = np.trace(relative, axis1=-2, axis2=-1)
    cos = trace / 2.0 if relative.shape[-1] == 2 else (trace - 1.0) / 2.0
    skew = relative - np.swapaxes(relative, -1, -2)
    sin = np.sqrt(np.sum(skew**2, axis=(-2, -1)) / 8.0)
    angle = np.arctan2(sin, cos)
    return np.degrees(angle) if degrees else angle
