"""Raw sweeps: small objects that move less than the ego motion's inlier band.

An island keeps the ego motion unless another motion explains clearly more of its
points (:mod:`mmreg.sweeps._island_motions`); an object that moves a few times the sweeps'
sampling spacing (a pedestrian, 0.1-0.2 m between sweeps) stays within the band in
which the ego motion already explains a point, and it often shares an island with the
static structure it walks past. Here the test is made per point and in units of the
second sweep's sampling spacing instead (as ICP-Flow does, the objects are aligned by
ICP from the ego motion; unlike it, a static piece must not get a motion of its own):

1. **Seeds**: after the ego motion, a point is *unexplained* when its nearest point of
   the second sweep is more than 2 spacings away (the spacing there: the distance
   from that point to its own nearest neighbour in the second sweep) and, where the
   second sweep is a surface there, more than one spacing off its plane (a wall seen
   behind a moving object in one sweep only lies on the plane, far from its points);
   or, where the second sweep is a surface, more than one spacing from its nearest
   point and more than 3 robust residual scales of the ego motion off its plane (a
   body that moves less than two spacings along its faces' normals).
   The unexplained points that no moving island holds are cut into tight islands
   (voxels of side ``cell``, half the islands').
2. **Motion**: every seed is aligned to the second sweep by the robust multi-body ICP
   (:mod:`mmreg.sweeps._icp`), started at the ego motion. A seed that fails the tests
   below from there but is a thing apart starts again from its own translation starts
   (the caller's ``starts``, as the islands' search makes them) and keeps the start that
   passes the tests, ends within ``reach``, climbs no steeper than ``max_grade`` and
   explains most of it. Apart: it holds at least half of its island of ``cell``
   voxels, or, if it is not flat, of voxels of half that side; and it is not a line. A
   walker 1 m beside a pole shares the pole's island, whose motion the pole decides (it
   slides along itself), and at 2 Hz it moves 0.7 m, beyond the reach of an ICP started
   at the ego motion; 0.6 m from a parked car it shares even the car's ``cell`` island.
3. **Tests** (all must hold):

   * *residual drop*: at least 60% of the seed's points are explained after the ICP,
     within 2 of their own spacings in the first sweep (a body that moves a few
     spacings is seen again from about where it was, about as densely: a much
     sparser landing place, isolated returns, explains nothing); every one of them
     was unexplained before (the rest are parts the second sweep does not see);
   * *departure*: the ICP moves the seed's points (median) by more than one spacing
     (median over its matches) and 3 robust residual scales of the ego motion away
     from where the ego motion puts them: what the seeds' rule can see;
   * *the landing place is new*: of the second sweep's points that the moved seed
     lands on, fewer than half are explained by the first sweep moved by the ego
     motion, by the seeds' rule (spacings and planes of the first sweep). A static
     strip that the ICP slides onto a neighbouring static surface lands on points
     that were there already; an object lands where nothing was, or, when it moves
     less than its size, on its old place shifted off its faces' planes. This is
     the test that separates the two on the shared Argoverse 2 pairs.

4. **Members**: within the seed's ``cell`` islands, the points that the new motion
   explains and the ego motion does not; then, over at most 10 rounds, the points that
   both explain join where at least half of their 8 nearest neighbours (in the same
   seed's islands) have joined. The object grows over its own surface (its faces
   parallel to its motion are explained by both), and a wall it touches along a line
   stays with the static world.
"""

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from mmreg._array.geometry import climb, departures
from mmreg._array.grouping import group_centroids
from mmreg._array.motion import _group_median
from mmreg._array.unique_rows import unique_rows
from mmreg.sweeps._ambiguous_shapes import shapes
from mmreg.sweeps._explained import (
    EXPLAINED_SPACINGS,
    OFF_PLANE_SCALES,
    spacing_ratio,
    unexplained_mask,
)
from mmreg.sweeps._icp import SurfaceNormals, multi_body_icp, subsample_groups
from mmreg.sweeps._islands import voxel_islands

__all__ = ["beyond_spacing", "slow_movers"]

# Points of the neighbourhoods whose PCA gives the first sweep's normals (as the ICP's).
_NORMAL_POINTS = 10
# Share of a seed's points the new motion must explain.
_MIN_EXPLAINED = 0.6
# The new motion departs from the ego motion by more than this many spacings, and
# this many ego residual scales.
_MIN_SPACINGS = 2.0
# A slow mover's motion departs from the ego motion by more than this many spacings
# (and OFF_PLANE_SCALES scales): a point that far and off its plane is one the seeds'
# rule calls unexplained.
_MIN_DEPARTURE = 1.0
# Largest share of the landing points that the first sweep at rest explains.
_MAX_RESTING = 0.5
# Members: points both motions explain join where half of their nearest neighbours
# have, in at most this many rounds.
_NEIGHBOURS = 8
_JOIN = 0.5
_GROWTH_STEPS = 10
# A seed that the ego start fails starts again where it holds this share of its island
# of ``cell`` voxels or, if it is not flat, of voxels of _APART times that side.
_DETACHED = 0.5
_APART = 0.5


def _own_spacing(points, tree):
    """Distance from each point to its nearest other point of the set ``tree`` holds.

    ``points`` may belong to that set (then the nearest at distance zero is itself) or
    not.
    """
    distance, _ = tree.query(points, k=2)
    return np.where(distance[:, 0] > 0, distance[:, 0], distance[:, 1])


def beyond_spacing(points, groups, n_groups, motions, ego, tree, sweep, normals=None):
    """Whether each group's motion moves its points more than 2 spacings from the ego's.

    The displacement (median over the group's points) between where its own motion and
    the ego motion put them, against the second sweep's spacing (median) where its own
    motion puts them: a far, sparse piece that the ICP shifts by less than its
    sampling spacing has not moved.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
    groups : ndarray of shape (n,)
        Group of every point in ``0..n_groups-1``.
    n_groups : int
    motions : tuple of ndarray
        ``(rotations, translations)``, one per group.
    ego : tuple of ndarray
        ``(R, t)`` of the ego motion.
    tree : cKDTree of ``sweep``
    sweep : ndarray of shape (m, 3)
    normals : SurfaceNormals of ``sweep`` or None
        Its spacings are kept there.

    Returns
    -------
    beyond : ndarray of bool, shape (n_groups,)
    """
    rotations, translations = motions
    moved = np.einsum("nij,nj->ni", rotations[groups], points) + translations[groups]
    _, _, spacing = spacing_ratio(moved, tree, sweep, normals)
    resting = points @ ego[0].T + ego[1]
    departure = _group_median(np.linalg.norm(moved - resting, axis=1), groups, n_groups)
    return departure > _MIN_SPACINGS * _group_median(spacing, groups, n_groups)


def slow_movers(
    a,
    free,
    ego,
    scale,
    target,
    resting,
    *,
    cell,
    min_size,
    max_points,
    max_distance,
    max_iter,
    tol,
    random_state,
    moved=None,
    starts=None,
    reach=np.inf,
    max_grade=None,
    rest_normals=None,
):
    """Small objects that move by a few sampling spacings, found point by point.

    Parameters
    ----------
    a : ndarray of shape (n, 3)
        The first sweep.
    free : ndarray of bool, shape (n,)
        Points that may join a slow mover (those no moving island holds).
    ego : tuple of ndarray
        ``(R, t)`` of the ego motion.
    scale : float
        The ego ICP's robust residual scale.
    target : tuple
        ``(sweep, tree, normals)``: the second sweep, its cKDTree and its
        :class:`mmreg.sweeps._icp.SurfaceNormals`.
    resting : cKDTree
        The first sweep's points moved by the ego motion.
    cell : float
        Side of the voxels of the seeds' islands.
    min_size : int
        Fewest points of a seed and of a mover.
    max_points : int
        Points per seed in its ICP.
    max_distance, max_iter, tol
        Of the ICP (:func:`mmreg.sweeps._icp.multi_body_icp`).
    random_state : RandomState
    moved : ndarray of shape (n, 3) or None
        ``a`` moved by the ego motion, when the caller has it already.
    starts : callable or None, default=None
        ``starts(groups, n_groups)``: translations ``(n_groups, n_starts, 3)`` added to
        the ego motion's (NaN: none; the first, the ego motion's own, is skipped), from
        which the seeds that fail from the ego motion start again, e.g.
        :func:`mmreg.sweeps._island_motions.translation_starts` with the rest of its
        arguments given. None: the ego motion only.
    reach : float, default=inf
        Where the seeds start again, a motion that ends farther than this from the ego
        motion (the seed's centroid) is refused, as an island's is (the starts lie
        within it).
    max_grade : float or None, default=None
        Where the seeds start again, a motion that climbs steeper than this (height
        over the horizontal distance, beyond the noise or the seed's spacing) is
        refused: traffic moves along the ground. None: no test (sweeps not z-up).
    rest_normals : SurfaceNormals or None, default=None
        The normals of ``resting``'s points (10 neighbours) where the caller keeps them,
        so that the two share what each computes; None: made here.

    Returns
    -------
    labels : ndarray of shape (n,)
        Slow mover of every point in ``0..K-1``, ``-1`` for none.
    rotations : ndarray of shape (K, 3, 3)
    translations : ndarray of shape (K, 3)

    Examples
    --------
    A 1 m box 0.3 m beside a wall, moved by 0.12 m (three sampling spacings of the
    second sweep) along the wall; the wall stays.

    >>> import numpy as np
    >>> from scipy.spatial import cKDTree
    >>> from mmreg.sweeps._icp import SurfaceNormals
    >>> from mmreg.sweeps._slow_movers import slow_movers
    >>> g = np.arange(0, 4, 0.04)
    >>> wall = np.stack(np.meshgrid(g, [0.0], g, indexing="ij"), -1).reshape(-1, 3)
    >>> s = np.arange(0, 1, 0.04)
    >>> face = np.stack(np.meshgrid(s, [0.0], s, indexing="ij"), -1).reshape(-1, 3)
    >>> box = np.vstack([face, face[:, [1, 0, 2]], face[:, [0, 2, 1]]]) + [1, 0.3, 0]
    >>> a = np.vstack([wall, box])
    >>> sweep = np.vstack([wall, box + [0.12, 0.0, 0.0]])
    >>> tree = cKDTree(sweep)
    >>> ego = (np.eye(3), np.zeros(3))
    >>> labels, R, t = slow_movers(
    ...     a, np.ones(len(a), bool), ego, 0.005, (sweep, tree, SurfaceNormals(sweep, tree, 10)),
    ...     cKDTree(a), cell=0.25, min_size=30, max_points=256, max_distance=1.0,
    ...     max_iter=30, tol=1e-4, random_state=np.random.RandomState(0))
    >>> int(labels.max()), np.round(t[0], 2) + 0.0
    (0, array([0.12, 0.  , 0.  ]))
    >>> bool(np.all(labels[: len(wall)] == -1))
    True
    """
    n = len(a)
    sweep, tree, normals = target
    none = (np.full(n, -1, dtype=np.intp), np.zeros((0, 3, 3)), np.zeros((0, 3)))
    if moved is None:
        moved = a @ ego[0].T + ego[1]
    unexplained, _ = unexplained_mask(moved, tree, sweep, normals, scale)
    candidates = np.flatnonzero(free & unexplained)
    if len(candidates) < min_size:
        return none
    seeds = np.full(n, -1, dtype=np.intp)
    seeds[candidates], n_seeds = voxel_islands(a[candidates], cell, min_size)
    if not n_seeds:
        return none
    chosen = subsample_groups(seeds, max_points, random_state)
    group = np.full(n, -1, dtype=np.intp)
    group[chosen] = seeds[chosen]
    result = multi_body_icp(
        a,
        group,
        np.broadcast_to(ego[0], (n_seeds, 3, 3)).copy(),
        np.broadcast_to(ego[1], (n_seeds, 3)).copy(),
        sweep,
        tree=tree,
        normals=normals,
        max_distance=max_distance,
        max_iter=max_iter,
        tol=tol,
        measure=False,
    )
    R, t = result.rotations, result.translations
    own = _own_spacing(moved[chosen], resting)
    if rest_normals is None:
        rest_normals = SurfaceNormals(resting.data, resting, _NORMAL_POINTS)
    tests = _SeedTests(a, moved, target, resting, rest_normals, scale, min_size)
    passed, _ = tests(chosen, seeds[chosen], n_seeds, (R, t), own)
    cells = None  # the first sweep's islands of voxels of side ``cell``, when needed
    if starts is not None and not passed.all():
        # A thing apart that the ego start fails may move beyond that ICP's reach: a
        # walker beside a pole shares the pole's island, whose motion the pole decides
        # (it slides along itself). Apart at the seeds' voxel side, or at half of it if
        # not flat: that keeps a walker 0.6 m from a parked car apart, but not a wall's
        # piece that the sampling cuts off at a corner (matched 6 m away). A line
        # matches anywhere along itself.
        cells, _ = voxel_islands(a, cell, 1)
        apart, _ = voxel_islands(a, _APART * cell, 1)
        flat, line = shapes(a, seeds, n_seeds)
        retry = np.flatnonzero(
            ~passed
            & (_detached(seeds, n_seeds, cells) | (_detached(seeds, n_seeds, apart) & ~flat))
            & ~line
        )
        if len(retry):
            icp = {"max_distance": max_distance, "max_iter": max_iter, "tol": tol}
            found, motions = _restart(
                chosen,
                seeds,
                retry,
                starts(_renumbered(seeds, retry), len(retry)),
                own,
                ego,
                tests,
                icp,
                (reach, max_grade),
            )
            R, t = R.copy(), t.copy()
            R[retry[found]], t[retry[found]] = motions[0][found], motions[1][found]
            passed[retry[found]] = True
    accepted = np.flatnonzero(passed)
    if not len(accepted):
        return none
    if cells is None:
        cells, _ = voxel_islands(a, cell, 1)
    return _members(a, free, unexplained, seeds, accepted, R, t, target, cells, min_size)


def _renumbered(seeds, subset):
    """``seeds`` with the seeds of ``subset`` numbered ``0..len(subset)-1``, others -1."""
    number = np.full(max(seeds.max() + 1, 1), -1, dtype=np.intp)
    number[subset] = np.arange(len(subset))
    return np.where(seeds >= 0, number[np.maximum(seeds, 0)], -1)


def _restart(chosen, seeds, retry, offsets, own, ego, tests, icp, bounds):
    """The seeds ``retry`` aligned again from their translation starts ``offsets``.

    Each keeps the start whose ICP passes every test, ends within ``bounds``'s reach of
    the ego motion (as an island's must) and, with its grade, climbs no steeper
    (traffic moves along the ground), and explains most of its points. Returns whether
    each found one, and its rotations and translations.
    """
    reach, max_grade = bounds
    a, sweep, (_, tree, normals) = tests.a, tests.target[0], tests.target
    n_retry, n_starts = offsets.shape[:2]
    offsets = offsets.copy()
    offsets[:, 0] = np.nan  # the ego start, tried already
    number = _renumbered(seeds, retry)
    again = np.flatnonzero(number[chosen] >= 0)
    rows = np.repeat(chosen[again], n_starts)
    pair = number[rows] * n_starts + np.tile(np.arange(n_starts), len(again))
    valid = np.isfinite(offsets).all(axis=2).ravel()
    n_pairs = n_retry * n_starts
    result = multi_body_icp(
        a[rows],
        np.where(valid[pair], pair, -1),
        np.broadcast_to(ego[0], (n_pairs, 3, 3)).copy(),
        ego[1] + np.nan_to_num(offsets).reshape(n_pairs, 3),
        sweep,
        tree=tree,
        normals=normals,
        measure=False,
        **icp,
    )
    motions = (result.rotations, result.translations)
    passed, share = tests(rows, pair, n_pairs, motions, np.repeat(own[again], n_starts))
    groups = number[chosen[again]]
    centre, _ = group_centroids(a[chosen[again]], groups, n_retry)
    offset = departures(np.repeat(centre, n_starts, axis=0), *motions, ego)
    passed &= ~(np.linalg.norm(offset, axis=1) > reach)
    if max_grade is not None:
        noise = np.fmax(OFF_PLANE_SCALES * tests.scale, _group_median(own[again], groups, n_retry))
        passed &= ~(climb(offset, max_grade) > np.repeat(noise, n_starts))
    score = np.where(passed & valid, share, -np.inf).reshape(n_retry, n_starts)
    best = np.arange(n_retry) * n_starts + np.argmax(score, axis=1)
    found = np.isfinite(score.max(axis=1))
    return found, (motions[0][best], motions[1][best])


class _SeedTests(NamedTuple):
    """The tests of a slow mover (the module's step 3), and what they read."""

    a: np.ndarray
    moved: np.ndarray  # ``a`` moved by the ego motion
    target: tuple  # (sweep, its cKDTree, its SurfaceNormals)
    resting: cKDTree  # of the first sweep at rest
    rest_normals: SurfaceNormals  # of the first sweep at rest
    scale: float  # the ego ICP's robust residual scale
    min_size: int

    def __call__(self, rows, groups, n_groups, motions, own):
        """Whether each group's motion passes, and the share of its points it explains.

        ``rows`` of ``a`` in ``groups`` (``0..n_groups-1``); ``motions``: rotations and
        translations per group; ``own``: the first sweep's spacing at each row.
        """
        sweep, tree, normals = self.target
        rotations, translations = motions
        after = np.einsum("nij,nj->ni", rotations[groups], self.a[rows]) + translations[groups]
        ratio_after, landing, spacing = spacing_ratio(after, tree, sweep, normals)
        explained = ratio_after * spacing <= EXPLAINED_SPACINGS * own
        counts = np.maximum(np.bincount(groups, minlength=n_groups), 1)
        share = np.bincount(groups, weights=explained, minlength=n_groups) / counts
        moves = np.linalg.norm(after - self.moved[rows], axis=1)
        departure = _group_median(moves, groups, n_groups)
        group_spacing = _group_median(spacing, groups, n_groups)
        # The second sweep's points the seed lands on, and whether the first sweep at
        # rest explains them, by the rule that chose the seeds (its spacing and planes
        # measured among its own points): a body that moves less than its size lands
        # partly on its old place, but its displaced faces lie off the old ones' planes.
        pairs = unique_rows(np.column_stack([groups[explained], landing[explained]]))
        if len(pairs):
            new, _ = unexplained_mask(
                sweep[pairs[:, 1]], self.resting, self.resting.data, self.rest_normals, self.scale
            )
            at_rest = np.bincount(pairs[:, 0], weights=~new, minlength=n_groups)
            landed = np.bincount(pairs[:, 0], minlength=n_groups)
        else:
            at_rest = landed = np.zeros(n_groups)
        new_place = (landed > 0) & (at_rest < _MAX_RESTING * np.maximum(landed, 1))
        margin = np.maximum(_MIN_DEPARTURE * group_spacing, OFF_PLANE_SCALES * self.scale)
        passed = (
            (share >= _MIN_EXPLAINED) & (departure > margin) & new_place & (counts >= self.min_size)
        )
        return passed, share


def _most_common(keys, values):
    """Each key, the value it pairs with most often (the smallest of equals) and how often."""
    pairs, votes = unique_rows(np.column_stack([keys, values]), return_counts=True)
    order = np.lexsort((-votes, pairs[:, 0]))
    pairs, votes = pairs[order], votes[order]
    first = np.r_[True, pairs[1:, 0] != pairs[:-1, 0]]
    return pairs[first, 0], pairs[first, 1], votes[first]


def _detached(seeds, n_seeds, cells):
    """Whether each seed holds at least half of the cell island that holds most of it
    (a thing apart, not the unexplained part of a larger surface)."""
    inside = np.flatnonzero(seeds >= 0)
    seed, cell, held = _most_common(seeds[inside], cells[inside])
    detached = np.zeros(n_seeds, dtype=bool)
    detached[seed] = held >= _DETACHED * np.bincount(cells)[cell]
    return detached


def _members(a, free, unexplained, seeds, accepted, R, t, target, islands, min_size):
    """Points of the accepted seeds' islands that their motion explains better."""
    n = len(a)
    # Every island goes to the accepted seed with the most points in it.
    in_seed = np.flatnonzero(np.isin(seeds, accepted))
    island, seed, _ = _most_common(islands[in_seed], seeds[in_seed])
    owner = np.full(islands.max() + 1, -1, dtype=np.intp)
    owner[island] = seed
    rows = np.flatnonzero(free & (owner[islands] >= 0))
    k = owner[islands[rows]]
    moved = np.einsum("nij,nj->ni", R[k], a[rows]) + t[k]
    sweep, tree, normals = target
    ratio_new, _, _ = spacing_ratio(moved, tree, sweep, normals)
    # The core: the points the new motion explains and the ego motion does not. Points
    # both explain (a wall the object slides along, the object's faces parallel to
    # its motion) join only where most of their nearest neighbours have joined: the
    # object grows over its own surface, and a wall it touches along a line keeps to
    # the static world.
    member = unexplained[rows] & (ratio_new <= EXPLAINED_SPACINGS)
    either = ratio_new <= EXPLAINED_SPACINGS
    if member.any() and len(rows) > _NEIGHBOURS:
        _, hood = cKDTree(a[rows]).query(a[rows], k=_NEIGHBOURS + 1)
        hood = hood[:, 1:]
        same = k[hood] == k[:, None]
        for _ in range(_GROWTH_STEPS):
            votes = (member[hood] & same).sum(axis=1)
            grown = member | (either & (votes >= _JOIN * _NEIGHBOURS))
            if np.array_equal(grown, member):
                break
            member = grown
    rows, k = rows[member], k[member]
    sizes = np.bincount(k, minlength=len(R))
    kept = accepted[sizes[accepted] >= min_size]
    index = np.full(len(R), -1, dtype=np.intp)
    index[kept] = np.arange(len(kept))
    labels = np.full(n, -1, dtype=np.intp)
    labels[rows] = index[k]
    return labels, R[kept], t[kept]
