"""Raw sweeps: which islands of the first sweep move, and how, before any clustering.

Every island of the first sweep gets a few starting translations (relative to the ego
motion), as ICP-Flow does: offsets between its centroid and the centroids of nearby
islands of the second sweep, and the peaks of a histogram of offsets from its points to
the second sweep's points within the largest displacement. After ICP from each start,
an island keeps the ego motion unless

* the best alternative explains its points better by more than the price of its six
  parameters (BIC: ``3 log n``), under a robust point-to-plane likelihood whose scale is
  three times the ego motion's robust residual scale on the whole sweep,
* it explains (residual under three scales) a tenth more of the island's points than
  the ego motion, a quarter of those the ego motion leaves unexplained, and more than
  six (its six parameters fit as many by chance), and
* the alternative moves the island relative to the ego motion by mmreg's own rule
  (:func:`mmreg._array.motion.moving_clusters`: median displacement over three times the
  residual scale), with the points' feet on the second sweep's surface as the
  correspondences.

A static island always fits a little better with its own six parameters (a different
scan pattern, occlusions); the price and the motion rule keep it static, so the static
world reaches the estimator as one motion.
"""

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree
from sklearn.utils import check_random_state

from mmreg._array.grouping import group_centroids
from mmreg._array.motion import moving_clusters
from mmreg._array.unique_rows import prefix_counts
from mmreg.sweeps._icp import subsample_groups

__all__ = [
    "EgoFit",
    "choose_island_motions",
    "driven_through",
    "ego_fit",
    "facing_away",
    "point_costs",
    "start_draws",
    "translation_starts",
]

# Robust cost: squared residual in units of the scale, capped here (an unmatched point
# costs the cap).
_CAP = 3.0
# The likelihood's scale in units of the ego ICP's robust scale.
_SCALE_FACTOR = 3.0
# An alternative must explain (cost under the cap) this much larger a share of the
# island's points than the ego motion does, and this share of those the ego motion
# leaves unexplained (an object that moves less than its length still overlaps its
# old place).
_MIN_EXPLAINED = 0.1
_MIN_RECOVERED = 0.25
# BIC price of an island's own motion: six parameters, (6 / 2) log n.
_PARAMETERS = 6
# Starts per island: centroid offsets to this many islands of the second sweep, and this
# many histogram peaks.
_CENTROID_STARTS = 2
_PEAKS = 2
# Points per island that vote in the histogram, and the sample of the second sweep they
# vote towards (a dense patch would list millions of pairs).
_VOTERS = 32
_VOTE_SAMPLE = 10000
# An alternative may land on other islands' static views with at most this share of its
# matched points.
_MAX_TAKEN = 0.5
# Neighbourhoods of the second sweep flatter than this are lines: distance to the point.
_MIN_FLATNESS = 0.2


def translation_starts(
    a,
    islands,
    n_islands,
    sweep,
    islands2,
    n_islands2,
    ego,
    *,
    max_displacement,
    bin_size,
    random_state=None,
    moved=None,
    draws=None,
    wanted=None,
):
    """Starting translations of every island, relative to the ego motion.

    Parameters
    ----------
    a : ndarray of shape (n, 3)
        The first sweep.
    islands : ndarray of shape (n,)
        Island of every point of ``a`` (``-1``: none).
    n_islands : int
    sweep : ndarray of shape (m, 3)
        The second sweep.
    islands2 : ndarray of shape (m,)
        Island of every point of ``sweep``.
    n_islands2 : int
    ego : tuple of ndarray
        ``(R, t)`` of the ego motion.
    max_displacement : float
        Largest motion of an object relative to the ego motion.
    bin_size : float
        Side of the histogram's bins.
    random_state : int, RandomState instance or None
    moved : ndarray of shape (n, 3) or None
        ``a`` moved by the ego motion, when the caller has it already.
    draws : tuple or None
        :func:`start_draws` of ``islands``, ``n_islands`` and ``len(sweep)``, made
        earlier by a caller that draws more from ``random_state`` before it knows
        ``wanted``; None: drawn here.
    wanted : ndarray of bool of shape (n_islands,) or None
        The islands whose histogram peaks are wanted (the others get none; each
        island's peaks are its own voters' alone, so the wanted ones get the same
        starts); None: all.

    Returns
    -------
    starts : ndarray of shape (n_islands, n_starts, 3)
        Translations added to the ego motion's; the first is zero (the ego motion
        itself); NaN where an island has fewer starts.

    Examples
    --------
    An island moved by 2 m along x, its twin in the second sweep.

    >>> import numpy as np
    >>> from mmreg.sweeps._island_motions import translation_starts
    >>> rng = np.random.default_rng(0)
    >>> a = rng.uniform(0, 1, (200, 3))
    >>> sweep = a + [2.0, 0.0, 0.0]
    >>> ego = (np.eye(3), np.zeros(3))
    >>> starts = translation_starts(a, np.zeros(200, int), 1, sweep, np.zeros(200, int), 1,
    ...                             ego, max_displacement=3.0, bin_size=0.25, random_state=0)
    >>> bool(np.any(np.linalg.norm(starts[0] - [2.0, 0.0, 0.0], axis=1) < 0.2))
    True
    """
    if draws is None:
        draws = start_draws(islands, n_islands, len(sweep), random_state)
    if moved is None:
        moved = a @ ego[0].T + ego[1]
    starts = np.full((n_islands, 1 + _CENTROID_STARTS + _PEAKS, 3), np.nan)
    starts[:, 0] = 0.0
    if n_islands == 0:
        return starts
    # Centroid offsets to the nearest islands of the second sweep.
    centroids, _ = group_centroids(moved, islands, n_islands)
    if n_islands2:
        centroids2, _ = group_centroids(sweep, islands2, n_islands2)
        k = min(_CENTROID_STARTS, n_islands2)
        distance, nearest = cKDTree(centroids2).query(
            centroids, k=k, distance_upper_bound=max_displacement
        )
        distance, nearest = distance.reshape(n_islands, k), nearest.reshape(n_islands, k)
        near = np.isfinite(distance)
        offsets = centroids2[np.minimum(nearest, n_islands2 - 1)] - centroids[:, None]
        starts[:, 1 : 1 + k] = np.where(near[:, :, None], offsets, np.nan)
    # Histogram peaks of the offsets from each island's voters to the sweep's points.
    voters, sample = draws
    if wanted is not None:
        voters = voters[wanted[islands[voters]]]
        if not len(voters):
            return starts
    sample = sweep[sample]
    pairs = (
        cKDTree(moved[voters])
        .sparse_distance_matrix(cKDTree(sample), max_displacement, output_type="ndarray")
        .view(np.recarray)
    )
    if not len(pairs):
        return starts
    source, target = pairs.i.astype(np.intp), pairs.j.astype(np.intp)
    offsets = sample[target] - moved[voters][source]
    bins = np.floor(offsets / bin_size).astype(np.int64)
    # Every voter votes once per bin: a dense patch of the sweep must not outvote.
    votes, count = prefix_counts(np.column_stack([islands[voters][source], bins, source]), 4)
    order = np.lexsort((-count, votes[:, 0]))
    votes = votes[order]
    first = np.searchsorted(votes[:, 0], votes[:, 0], side="left")
    rank = np.arange(len(votes)) - first
    top = rank < _PEAKS
    starts[votes[top, 0], 1 + _CENTROID_STARTS + rank[top]] = (votes[top, 1:4] + 0.5) * bin_size
    return starts


def start_draws(islands, n_islands, n_sweep, random_state=None):
    """What :func:`translation_starts` draws at random: ``(voters, sample)``, the voters
    of every island (rows of the first sweep) and the sample of the second sweep's
    ``n_sweep`` rows they vote towards; None where there is no island (nothing drawn).

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.sweeps._island_motions import start_draws
    >>> voters, sample = start_draws(np.repeat([0, 1], 50), 2, 20000, random_state=0)
    >>> len(voters), len(sample)
    (64, 10000)
    """
    if n_islands == 0:
        return None
    rng = check_random_state(random_state)
    voters = subsample_groups(islands, _VOTERS, rng)
    return voters, rng.choice(n_sweep, min(n_sweep, _VOTE_SAMPLE), replace=False)


def point_costs(moved, target, *, max_distance, scale):
    """Robust cost of every moved point against the second sweep, and its foot there.

    The residual is the point-to-plane distance to the nearest point of the sweep (the
    distance to the point itself where the neighbourhood is a line); the cost is its
    square in units of ``scale``, capped at ``3**2``, which is also the cost of a point
    with no neighbour within ``max_distance``.

    Parameters
    ----------
    moved : ndarray of shape (n, 3)
    target : tuple
        ``(sweep, tree, normals)``: the second sweep, its cKDTree and its
        :class:`mmreg.sweeps._icp.SurfaceNormals`.
    max_distance : float
    scale : float

    Returns
    -------
    cost : ndarray of shape (n,)
    foot : ndarray of shape (n, 3)
        Where the residual ends on the sweep's surface (NaN when unmatched).
    """
    sweep, tree, normals = target
    distance, nearest = tree.query(moved, distance_upper_bound=max_distance)
    matched = np.isfinite(distance)
    cost = np.full(len(moved), _CAP**2)
    foot = np.full(moved.shape, np.nan)
    rows = np.flatnonzero(matched)
    if len(rows):
        q = sweep[nearest[rows]]
        normal, _, flatness = normals(nearest[rows])
        plane = flatness >= _MIN_FLATNESS
        along = np.einsum("ni,ni->n", normal, moved[rows] - q)
        residual = np.where(plane, np.abs(along), distance[rows])
        cost[rows] = np.minimum((residual / scale) ** 2, _CAP**2)
        foot[rows] = np.where(plane[:, None], moved[rows] - along[:, None] * normal, q)
    return cost, foot


def choose_island_motions(
    points,
    groups,
    n_islands,
    ego,
    motions,
    valid,
    scale,
    target,
    claims,
    *,
    max_distance,
    fit=None,
):
    """Which islands move, and which of their ICP results they keep.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
        Points of the first sweep (a sample of every island).
    groups : ndarray of shape (n,)
        Island of every point in ``0..n_islands-1``.
    n_islands : int
    ego : tuple of ndarray
        ``(R, t)`` of the ego motion.
    motions : tuple of ndarray
        ``(rotations, translations)`` of shape ``(n_islands * n_starts, 3, 3)`` and
        ``(n_islands * n_starts, 3)``: the ICP result of start ``s`` of island ``i`` at
        ``i * n_starts + s``.
    valid : ndarray of bool, shape (n_islands, n_starts)
        Which starts to judge (an island with none keeps the ego motion).
    scale : float
        Residual scale of the ego motion (point-to-plane), the likelihood's scale.
    target : tuple
        ``(sweep, tree, normals)``, as :func:`point_costs` takes it.
    claims : tuple
        ``(tree, islands, reach)``: a cKDTree of the first sweep's island points moved by
        the ego motion, their islands, and the distance within which a point of the
        second sweep is the static view of one of them.
    max_distance : float
    fit : EgoFit or None, default=None
        :func:`ego_fit` of the same points, when the caller has it already.

    Returns
    -------
    moving : ndarray of bool, shape (n_islands,)
    pick : ndarray of shape (n_islands,)
        Index into ``motions`` of each island's best alternative (meaningful where
        ``moving``).
    explained : ndarray of shape (n_islands,)
        Share of each island's points that its best alternative explains (cost under
        the cap; meaningful where ``moving``).
    """
    rotations, translations = motions
    n_starts = valid.shape[1]
    if fit is None:
        fit = ego_fit(points, groups, n_islands, ego, scale, target, max_distance=max_distance)
    scale = _likelihood_scale(scale)
    static_cost, sizes, static_inliers = fit
    # Only islands with a start to judge are weighed (most of the static world has
    # none: the ego motion explains it too well for any alternative to win).
    open_points = np.flatnonzero(valid.any(axis=1)[groups])
    rows = np.repeat(open_points, n_starts)
    index = groups[rows] * n_starts + np.tile(np.arange(n_starts), len(open_points))
    moved = np.einsum("nij,nj->ni", rotations[index], points[rows]) + translations[index]
    cost, foot = point_costs(moved, target, max_distance=max_distance, scale=scale)
    n_pairs = n_islands * n_starts
    # Log-likelihood gain of each island's own motion over the ego motion's.
    gain = 0.5 * (
        np.bincount(index, weights=static_cost[rows], minlength=n_pairs)
        - np.bincount(index, weights=cost, minlength=n_pairs)
    )
    price = 0.5 * _PARAMETERS * np.log(np.maximum(sizes, 2))
    # mmreg's rule on the feet as correspondences; cluster 0 is the ego motion.
    matched = np.isfinite(foot[:, 0])
    labels = np.where(matched, index + 1, -1)
    moves = moving_clusters(
        points[rows],
        np.where(matched[:, None], foot, moved),
        labels,
        np.concatenate([ego[0][None], rotations]),
        np.concatenate([ego[1][None], translations]),
        0,
    )[1:]
    # Where an alternative lands on the second sweep's view of *another* island at rest,
    # it explains this island by taking that one's points: not a motion.
    claim_tree, claim_islands, reach = claims
    hit = np.flatnonzero(matched)
    distance, owner = claim_tree.query(foot[hit], distance_upper_bound=reach)
    taken = np.isfinite(distance)
    taken[taken] = claim_islands[owner[taken]] != groups[rows[hit][taken]]
    share = np.bincount(index[hit], weights=taken, minlength=n_pairs) / np.maximum(
        np.bincount(index[hit], minlength=n_pairs), 1
    )
    inliers = np.bincount(index, weights=cost < _CAP**2, minlength=n_pairs)
    more = inliers - np.repeat(static_inliers, n_starts)
    # ... and more of them than its six parameters could fit by chance (a small far
    # island matched to a stray patch 2-3 m away).
    explained = (
        (more >= _MIN_EXPLAINED * np.repeat(sizes, n_starts))
        & (more >= _MIN_RECOVERED * np.repeat(sizes - static_inliers, n_starts))
        & (more > _PARAMETERS)
    )
    eligible = (
        valid.ravel()
        & (gain > np.repeat(price, n_starts))
        & moves
        & explained
        & (share < _MAX_TAKEN)
    ).reshape(n_islands, n_starts)
    score = np.where(eligible, gain.reshape(n_islands, n_starts), -np.inf)
    best = np.argmax(score, axis=1)
    moving = eligible.any(axis=1)
    pick = np.arange(n_islands) * n_starts + best
    return moving, pick, inliers[pick] / np.maximum(sizes, 1)


def _likelihood_scale(scale):
    # The ego ICP's scale is that of its best surfaces (the kernel's inliers); the
    # likelihood's is that of every surface: vegetation, edges, other scan lines.
    return _SCALE_FACTOR * max(float(scale), np.finfo(float).tiny)


class EgoFit(NamedTuple):
    """How the ego motion explains each island: per point, and counted per island."""

    cost: np.ndarray  # of every point, as point_costs gives it
    sizes: np.ndarray  # points per island
    inliers: np.ndarray  # points per island under the cost's cap

    def hopeless(self):
        """Islands no alternative motion can make moving, whatever it is.

        :func:`choose_island_motions` asks an alternative to explain a tenth of an
        island's points more than the ego motion does; where the ego motion already
        explains more than nine tenths, no motion can: those islands need no hypotheses
        (their ICP is skipped, and the choice is the same).
        """
        return self.sizes - self.inliers < _MIN_EXPLAINED * self.sizes

    def mostly_unexplained(self):
        """Islands the ego motion leaves more than half unexplained (cost at the cap)."""
        return 2 * self.inliers < self.sizes

    def with_hidden(self, groups, hidden):
        """The same fit where the points ``hidden`` cost nothing: explained at rest.

        A surface that faces away from the second sensor where the ego motion puts it
        (see :func:`facing_away`) cannot be in the second sweep, so its absence there is
        no sign that it moved: the ego motion explains it as well as any motion.
        """
        cost = np.where(hidden, 0.0, self.cost)
        inliers = np.bincount(groups, weights=cost < _CAP**2, minlength=len(self.sizes))
        return EgoFit(cost, self.sizes, inliers)


def facing_away(points, normals, first_sensor, second_sensor):
    """Whether each point's surface, seen from the first sensor, faces away from the second.

    ``normals`` are the surface's unit normals at ``points`` (either sign); they are
    turned towards ``first_sensor``, which saw the points, and a point faces away from
    ``second_sensor`` where that sensor lies behind its surface's plane: a building's
    end wall that the sensor has driven past, the far side of a box it went round.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.sweeps._island_motions import facing_away
    >>> wall = np.array([[5.0, 20.0, 1.0]])  # a wall facing -x, at x = 5
    >>> normal = np.array([[1.0, 0.0, 0.0]])
    >>> facing_away(wall, normal, np.zeros(3), np.array([3.0, 0.0, 0.0])).tolist()
    [False]
    >>> facing_away(wall, normal, np.zeros(3), np.array([7.0, 0.0, 0.0])).tolist()
    [True]
    """
    towards_first = np.einsum("ni,ni->n", normals, first_sensor - points)
    normals = np.where((towards_first < 0)[:, None], -normals, normals)
    return np.einsum("ni,ni->n", normals, second_sensor - points) < 0


def driven_through(points, groups, n_groups, start, end, reach):
    """Whether the sensor, going from ``start`` to ``end``, passed through each group.

    Seen from above (x and y; z is up), among the group's points beside the sensor's
    path (between its ends): some within ``reach`` of the path, or some on either side
    of it. A static surface the sensor's vehicle drove through is impossible: the rear
    of the car ahead, which the sensor passes where the car stood, moved on.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.sweeps._island_motions import driven_through
    >>> rear = np.array([[4.0, -0.8, 1.0], [4.0, 0.9, 1.0]])  # across the path, 4 m on
    >>> wall = np.array([[4.0, 20.0, 1.0], [4.0, 21.0, 1.0]])  # 20 m to the side
    >>> end = np.array([5.0, 0.0, 0.0])
    >>> driven_through(np.vstack([rear, wall]), np.array([0, 0, 1, 1]), 2, np.zeros(3), end,
    ...                0.5).tolist()
    [True, False]
    """
    start, end = np.asarray(start, dtype=float)[:2], np.asarray(end, dtype=float)[:2]
    step = end - start
    length = float(np.linalg.norm(step))
    if length == 0:
        return np.zeros(n_groups, dtype=bool)
    offset = points[:, :2] - start
    along = offset @ step / length**2
    side = (offset[:, 0] * step[1] - offset[:, 1] * step[0]) / length
    beside = (along >= 0) & (along <= 1)
    groups, side = groups[beside], side[beside]
    near = np.bincount(groups[np.abs(side) < reach], minlength=n_groups) > 0
    left = np.bincount(groups[side > 0], minlength=n_groups) > 0
    right = np.bincount(groups[side < 0], minlength=n_groups) > 0
    return near | (left & right)


def ego_fit(points, groups, n_islands, ego, scale, target, *, max_distance):
    """:class:`EgoFit` of the islands' points under the ego motion.

    Parameters
    ----------
    points, groups, n_islands, ego, scale, target, max_distance
        As :func:`choose_island_motions` takes them.

    Returns
    -------
    EgoFit
    """
    cost, _ = point_costs(
        points @ ego[0].T + ego[1],
        target,
        max_distance=max_distance,
        scale=_likelihood_scale(scale),
    )
    sizes = np.bincount(groups, minlength=n_islands)
    inliers = np.bincount(groups, weights=cost < _CAP**2, minlength=n_islands)
    return EgoFit(cost, sizes, inliers)
