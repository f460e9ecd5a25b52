"""Which clusters move: the static world and the clusters whose motion differs from it.

A registration gives every cluster ``j`` a rigid motion ``b ~ R_j a + t_j``. When the
camera moves, the static world moves too, so "moving" means *moving relative to the static
world*, taken to be the largest cluster. A cluster moves when the static world's motion
would carry its a-points clearly further from where its own motion takes them than its
correspondences scatter about its own motion.

Both sides of that comparison are robust statistics, so wrong correspondences in a
cluster (gross errors the variant kept, e.g. ``variant="paper"``) neither hide a moving
object nor make a static one look moving:

* the displacement of cluster ``j`` is the **median** over its points of
  ``|(R_j a_i + t_j) - (R_s a_i + t_s)|`` (``s`` the static cluster); it depends on the
  a-points and the two motions only;
* its residual scale is the RMS of ``|R_j a_i + t_j - b_i|`` over its **inliers**: the
  points whose residual is at most the median plus 3 robust standard deviations
  (``1.4826`` times the median absolute deviation) of the cluster's residuals, floored at
  ``1e-6`` times the RMS spread of all b-points so that noiseless data is well posed.

A cluster moves when its displacement exceeds :data:`MOVING_FACTOR` (3) times its
residual scale.
"""

import numpy as np

from mmreg._array.geometry import moved_rows
from mmreg._array.grouping import middle_values

__all__ = [
    "MOVING_FACTOR",
    "motion_statistics",
    "moving_clusters",
    "moving_from_statistics",
    "static_cluster",
]

#: A cluster moves when its displacement exceeds this many times its residual scale.
MOVING_FACTOR = 3.0
# Inliers: residual <= median + _INLIER_SIGMAS * 1.4826 * MAD (of the cluster's residuals).
_INLIER_SIGMAS = 3.0
_MAD_TO_SIGMA = 1.4826
# The residual scale is floored at this fraction of the RMS spread of the b-points.
_RELATIVE_FLOOR = 1e-6


def static_cluster(labels):
    """The static world: the largest cluster (ties: the smallest label), or -1 if none.

    Parameters
    ----------
    labels : array-like of shape (n,)
        Cluster of every correspondence, negative for outliers.

    Returns
    -------
    static : int
        The label of the largest cluster; ``-1`` when no correspondence is clustered.

    Examples
    --------
    >>> from mmreg._array.motion import static_cluster
    >>> static_cluster([2, 2, 0, 1, 1, -1, -1, -1])
    1
    >>> static_cluster([-1, -1])
    -1
    """
    labels = np.asarray(labels).ravel()
    sizes = np.bincount(labels[labels >= 0].astype(np.intp))
    if not sizes.size or sizes.max() == 0:
        return -1
    return int(np.argmax(sizes))  # the first of ties: the smallest label


def _group_median(values, groups, n_groups):
    """Median of ``values`` within each group ``0..n_groups-1`` (NaN for an empty group)."""
    low, high = middle_values(values, groups, n_groups)
    return 0.5 * (low + high)


def _row_norms(rows):
    """Euclidean norm of each column of ``rows`` (d, n), in place: the squares summed in
    the order ``np.linalg.norm(..., axis=1)`` sums them over the rows of an (n, d) array."""
    total = np.square(rows[0])
    for row in rows[1:]:
        total += np.square(row, out=row)
    return np.sqrt(total, out=total)


def motion_statistics(a, b, labels, rotations, translations, static):
    """Per cluster: median displacement relative to the static world, residual scale.

    Parameters
    ----------
    a, b : array-like of shape (n, d)
        The correspondences ``(a_i, b_i)``.
    labels : array-like of shape (n,)
        Cluster of every correspondence in ``0..K-1``, negative for outliers.
    rotations : array-like of shape (K, d, d)
    translations : array-like of shape (K, d)
        The motion of every cluster, ``b ~ R_j a + t_j``.
    static : int
        Label of the static world (see :func:`static_cluster`), ``-1`` for none.

    Returns
    -------
    displacement : ndarray of shape (K,)
        Median over the cluster's points of the distance between where its own motion
        and the static world's motion take them; 0 for the static cluster, NaN for an
        empty cluster or when there is no static cluster.
    scale : ndarray of shape (K,)
        RMS residual of the cluster's inliers (see the module notes), floored; NaN for
        an empty cluster.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.motion import motion_statistics
    >>> a = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 0], [6, 5, 0], [5, 6, 0]])
    >>> b = a + np.array([[0.0, 0, 0]] * 3 + [[2.0, 0, 0]] * 3)  # the second moves 2 along x
    >>> labels = np.array([0, 0, 0, 1, 1, 1])
    >>> rotations = np.stack([np.eye(3), np.eye(3)])
    >>> translations = np.array([[0.0, 0, 0], [2, 0, 0]])
    >>> displacement, scale = motion_statistics(a, b, labels, rotations, translations, 0)
    >>> displacement.tolist()
    [0.0, 2.0]
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    labels = np.asarray(labels).ravel().astype(np.intp)
    rotations = np.asarray(rotations, dtype=float)
    translations = np.asarray(translations, dtype=float)
    n_clusters = len(rotations)
    if a.ndim != 2 or b.shape != a.shape or labels.shape != (len(a),):
        raise ValueError(
            f"a and b must have the same shape (n, d) and labels shape (n,); got {a.shape}, "
            f"{b.shape} and {labels.shape}."
        )
    d = a.shape[1]
    if rotations.shape != (n_clusters, d, d) or translations.shape != (n_clusters, d):
        raise ValueError(
            f"rotations must have shape (K, {d}, {d}) and translations (K, {d}); got "
            f"{rotations.shape} and {translations.shape}."
        )
    if labels.size and labels.max() >= n_clusters:
        raise ValueError(f"labels go up to {labels.max()} but there are {n_clusters} motions.")
    displacement = np.full(n_clusters, np.nan)
    scale = np.full(n_clusters, np.nan)
    members = np.flatnonzero(labels >= 0)
    if not n_clusters or not len(members):
        return displacement, scale
    group = labels[members]
    everyone = len(members) == len(a)  # no outliers: no copy of the rows
    pa = a if everyone else a[members]
    # Coordinates as rows: contiguous passes, and no (n, d, d) copy of the rotations.
    own = moved_rows(rotations, translations, group, np.ascontiguousarray(pa.T))
    residual = _row_norms(own - np.ascontiguousarray((b if everyone else b[members]).T))

    # Residual scale: RMS over the inliers (median + 3 robust sigmas), floored.
    median = _group_median(residual, group, n_clusters)
    mad = _group_median(np.abs(residual - median[group]), group, n_clusters)
    inlier = residual <= (median + _INLIER_SIGMAS * _MAD_TO_SIGMA * mad)[group]
    counts = np.bincount(group[inlier], minlength=n_clusters)
    sums = np.bincount(group[inlier], weights=residual[inlier] ** 2, minlength=n_clusters)
    spread = np.sqrt(np.mean(np.sum((b - b.mean(axis=0)) ** 2, axis=1))) if len(b) else 0.0
    floor = max(_RELATIVE_FLOOR * float(spread), np.finfo(float).tiny)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(counts > 0, np.sqrt(sums / np.maximum(counts, 1)), np.nan)
    scale = np.where(np.isnan(scale), np.nan, np.maximum(scale, floor))

    if 0 <= static < n_clusters:
        # einsum, not pa @ R.T: OpenBLAS threads make that product of a 3 x 3 matrix
        # 10-30x slower when the cores are busy.
        by_static = np.einsum("ij,kj->ik", pa, rotations[static]) + translations[static]
        gap = _row_norms(own - np.ascontiguousarray(by_static.T))
        displacement = _group_median(gap, group, n_clusters)
        if np.isfinite(displacement[static]):
            displacement[static] = 0.0
    return displacement, scale


def moving_clusters(a, b, labels, rotations, translations, static):
    """Whether each cluster moves relative to the static world, by robust statistics.

    A cluster moves when the median distance between where the static world's motion
    and its own motion carry its points exceeds :data:`MOVING_FACTOR` (3) times the RMS
    residual of its inliers (see the module notes and :func:`motion_statistics`), so
    wrong correspondences in the cluster do not inflate its residual scale.

    Parameters
    ----------
    a, b : array-like of shape (n, d)
        The correspondences ``(a_i, b_i)``.
    labels : array-like of shape (n,)
        Cluster of every correspondence in ``0..K-1``, negative for outliers.
    rotations : array-like of shape (K, d, d)
    translations : array-like of shape (K, d)
        The motion of every cluster, ``b ~ R_j a + t_j``.
    static : int
        Label of the static world, e.g. ``static_cluster(labels)``; ``-1``: none.

    Returns
    -------
    moving : ndarray of bool, shape (K,)
        False for the static cluster, for empty clusters and for every cluster when
        there is no static cluster.

    Examples
    --------
    A static block and a block turned 15 degrees and moved 1 m, with a third of its
    correspondences wrong by up to 30 m: the wrong ones do not hide the motion.

    >>> import numpy as np
    >>> from mmreg._array.motion import moving_clusters, static_cluster
    >>> rng = np.random.default_rng(0)
    >>> a = np.vstack([rng.uniform(0, 10, (300, 3)), rng.uniform(20, 24, (90, 3))])
    >>> labels = np.repeat([0, 1], [300, 90])
    >>> c, s = np.cos(np.radians(15)), np.sin(np.radians(15))
    >>> turn = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    >>> rotations, translations = np.stack([np.eye(3), turn]), np.array([[0, 0, 0], [1, 0, 0]])
    >>> b = np.einsum("nij,nj->ni", rotations[labels], a) + translations[labels]
    >>> b += rng.normal(0, 0.02, b.shape)
    >>> b[300:330] += rng.uniform(-30, 30, (30, 3))  # wrong correspondences
    >>> moving_clusters(a, b, labels, rotations, translations, static_cluster(labels)).tolist()
    [False, True]
    """
    displacement, scale = motion_statistics(a, b, labels, rotations, translations, static)
    return moving_from_statistics(displacement, scale, static)


def moving_from_statistics(displacement, scale, static):
    """:func:`moving_clusters` from the output of :func:`motion_statistics` (one pass)."""
    with np.errstate(invalid="ignore"):
        moving = displacement > MOVING_FACTOR * scale
    moving = np.asarray(moving, dtype=bool) & np.isfinite(displacement) & np.isfinite(scale)
    if 0 <= static < len(moving):
        moving[static] = False
    return moving
