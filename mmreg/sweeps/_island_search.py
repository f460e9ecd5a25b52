"""Every island's motion: the ego motion unless another one clearly explains it.

The first sweep's islands (:mod:`mmreg.sweeps._islands`) are aligned to the second sweep
from the ego motion and from the peaks of a histogram of translations towards nearby
points of the second sweep (as ICP-Flow does), all as one multi-body ICP; each keeps the
ego motion unless its best alternative wins by a clear margin
(:mod:`mmreg.sweeps._island_motions`). Islands that nothing within the reach explains
search again twice as far when the reach is a guess; a moving island that tears a part
of it off its surfaces is refused (:mod:`mmreg.sweeps._torn_islands`); the small objects
that move a few sampling spacings are found point by point (:mod:`mmreg.sweeps._slow_movers`)
and become islands of their own.
"""

import copy
import functools
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from mmreg._array.geometry import climb, departures
from mmreg._array.grouping import group_centroids
from mmreg._array.motion import _group_median
from mmreg.sweeps._ambiguous_shapes import is_line, slides_in_plane
from mmreg.sweeps._icp import SurfaceNormals, multi_body_icp, subsample_groups
from mmreg.sweeps._island_motions import (
    choose_island_motions,
    driven_through,
    ego_fit,
    facing_away,
    start_draws,
    translation_starts,
)
from mmreg.sweeps._slow_movers import beyond_spacing, slow_movers
from mmreg.sweeps._torn_islands import torn_islands

__all__ = ["island_motions"]

# Points per island in the ICP of its hypotheses, and the translation histogram's bins
# (in units of max_distance).
_HYPOTHESIS_POINTS = 128
_BIN = 0.25
# Gauss-Newton steps of the hypotheses' ICP (the chosen motions are refined again after
# the estimator, on up to max_points points).
_HYPOTHESIS_ITER = 15
# A climb or a slide is measured against this many of the ego ICP's residual scales.
SLIDE_SCALES = 3.0
# "auto" max_displacement: how many times islands that nothing within the reach explains
# search again, each time twice as far.
WIDENINGS = 1
# z-up LiDAR sweeps: the steepest climb (rise over run, relative to the static world) of
# an island's motion: roads climb 1 in 10 or less, very few over 1 in 5.
_MAX_GRADE = 0.25
# The searches on weaker evidence (slow movers, a motion of a spacing or two; the wider
# reach, eight times the volume to match by chance) take islands of this many times
# min_island_size (30 points at the default).
_WEAK_EVIDENCE_SIZES = 2.5


class _IslandSearch(NamedTuple):
    """What every search for the islands' motions shares (see ``_island_hypotheses``)."""

    a: np.ndarray  # the first sweep
    sweep: np.ndarray  # the second sweep
    islands2: np.ndarray  # the second sweep's islands
    n_islands2: int
    target: tuple  # (sweep, its tree, its SurfaceNormals)
    ego: tuple  # (R, t) at which the islands are tested
    sigma: float  # the ego ICP's robust residual scale
    at_rest: np.ndarray  # the first sweep where the ego motion puts it
    resting: cKDTree  # of at_rest[inside]
    inside: np.ndarray  # the first sweep's points that lie on an island
    rest_normals: SurfaceNormals | None  # of at_rest[inside]; None unless z-up sweeps
    settings: tuple  # PairSettings


def island_motions(first, second, ego, sigma, settings, rng):
    """Every island's motion: the ego motion unless another one clearly explains it.

    ``first`` and ``second``: the :class:`~mmreg.sweeps._sweep_state.SweepState` of the
    sweeps' points that make objects (off the ground); ``ego`` and ``sigma``: the ego
    motion and its residual scale; ``settings``: a
    :class:`~mmreg.sweeps._settings.PairSettings`. Returns the islands of the first
    sweep (slow movers numbered after them), their rotations and translations, and
    whether each moves relative to the ego motion.
    """
    a = first.points
    sweep, tree, normals = second.target()
    islands, n_islands = first.islands(settings.island_radius, settings.min_island_size)
    islands2, n_islands2 = second.islands(settings.island_radius, settings.min_island_size)
    at_rest = a @ ego[0].T + ego[1]  # the first sweep where the ego motion puts it
    inside = np.flatnonzero(islands >= 0)
    resting = cKDTree(at_rest[inside])
    # The islands' surfaces where the ego motion puts them (their normals on demand).
    rest_normals = None
    if first.is_z_up():
        rest_normals = SurfaceNormals(at_rest[inside], resting, 10, settings.workers)
    search = _IslandSearch(
        a,
        sweep,
        islands2,
        n_islands2,
        (sweep, tree, normals),
        ego,
        sigma,
        at_rest,
        resting,
        inside,
        rest_normals,
        settings,
    )
    reach = settings.max_displacement
    moving, rotations, translations, unexplained, explained = _island_hypotheses(
        islands, n_islands, search, reach, rng
    )
    if settings.auto_reach and settings.widen:
        # The reach is a guess at the traffic's speed times the sweeps' interval, which
        # the points do not give: a slow ego car 0.5 s apart leaves a 5 m mover beyond
        # it. Islands that neither the ego motion nor any motion within the reach
        # explains (most of their points) search again, alone, twice as far (a copy
        # of the random state, so that the steps after see the same draws whether or
        # not one searches). Within the reach such a car can still find a motion
        # that lays half of it on something else and passes as a mover.
        wide_rng = copy.deepcopy(rng)
        # Twice as far, a chance match is likelier: only islands of a few times
        # the smallest size search there.
        sizes = np.bincount(islands[islands >= 0], minlength=n_islands)
        large = sizes >= _WEAK_EVIDENCE_SIZES * settings.min_island_size
        for _ in range(WIDENINGS):
            lost = unexplained & (~moving | (explained < 0.5)) & large
            if not lost.any():
                break
            reach *= 2.0
            number = np.cumsum(lost) - 1
            subset = np.where(islands >= 0, np.where(lost, number, -1)[islands], -1)
            found, sub_r, sub_t, sub_unexplained, sub_explained = _island_hypotheses(
                subset, int(lost.sum()), search, reach, wide_rng, last=True
            )
            where = np.flatnonzero(lost)
            # Twice as far, a flat patch finds more of its plane to slide along and
            # a pole more poles to match.
            found &= ~slides_in_plane(a, subset, len(where), (sub_r, sub_t), ego)
            found &= ~is_line(a, subset, len(where))
            # A motion found twice as far replaces one found within the reach only
            # where it explains more of the island.
            found &= ~moving[where] | (sub_explained > explained[where])
            moving[where[found]] = True
            rotations[where[found]], translations[where[found]] = sub_r[found], sub_t[found]
            explained[where[found]] = sub_explained[found]
            unexplained[where] = sub_unexplained
    # An island's motion must not explain a part of it clearly worse than the ego
    # motion does: a walker beside a pole shares its island, whose ICP may follow
    # the walker and take the pole along. Refused, the island stays at rest and the
    # walker is found point by point (below).
    if moving.any():
        torn = torn_islands(
            a,
            islands,
            n_islands,
            moving,
            (rotations, translations),
            at_rest,
            (sweep, tree, normals),
            0.5 * settings.island_radius,
            int(np.ceil(_WEAK_EVIDENCE_SIZES * settings.min_island_size)),
        )
        moving &= ~torn
        rotations[torn], translations[torn] = ego
    # Objects that move by a few sampling spacings stay within the ego motion's
    # band and often share an island with a static structure: found point by point
    # among the points no moving island holds, they become islands of their own.
    free = islands < 0  # and the islands at rest (none at all: every point)
    free[~free] = ~moving[islands[~free]]
    slow, slow_rotations, slow_translations = slow_movers(
        a,
        free,
        ego,
        sigma,
        (sweep, tree, normals),
        resting,
        cell=0.5 * settings.island_radius,
        min_size=int(np.ceil(_WEAK_EVIDENCE_SIZES * settings.min_island_size)),
        max_points=2 * _HYPOTHESIS_POINTS,
        max_distance=settings.max_distance,
        max_iter=min(settings.max_icp_iter, _HYPOTHESIS_ITER),
        tol=settings.tol,
        random_state=rng,
        moved=at_rest,
        # A seed apart from everything else that fails from the ego motion starts
        # again where an island would (a copy of the random state: the steps after
        # draw alike whether or not a seed does).
        starts=functools.partial(
            translation_starts,
            a,
            sweep=sweep,
            islands2=search.islands2,
            n_islands2=search.n_islands2,
            ego=ego,
            max_displacement=settings.max_displacement,
            bin_size=_BIN * settings.max_distance,
            random_state=copy.deepcopy(rng),
            moved=at_rest,
        ),
        reach=settings.max_displacement,
        max_grade=None if rest_normals is None else _MAX_GRADE,
        rest_normals=rest_normals,
    )
    if len(slow_rotations):
        islands = np.where(slow >= 0, n_islands + slow, islands)
        rotations = np.concatenate([rotations, slow_rotations])
        translations = np.concatenate([translations, slow_translations])
        moving = np.concatenate([moving, np.ones(len(slow_rotations), dtype=bool)])
    return islands, rotations, translations, moving


def _island_hypotheses(islands, n_islands, search, reach, rng, last=False):
    """Each island's motion hypotheses within ``reach``, and the one it keeps.

    The ICPs start within ``reach`` and, but in the ``last`` search, end there.

    ``search`` holds what every search shares (:class:`_IslandSearch`). Returns
    whether each island moves, its rotation and translation (the ego motion's where
    it does not), whether the ego motion leaves most of its points unexplained, and
    the share of its points that its motion explains (where it moves).
    """
    a, sweep, ego, sigma = search.a, search.sweep, search.ego, search.sigma
    at_rest, inside, rest_normals = search.at_rest, search.inside, search.rest_normals
    _, tree, normals = search.target
    settings = search.settings
    # The starts' draws come first (the random state's order), their histograms once
    # the islands that need no hypotheses are known.
    draws = start_draws(islands, n_islands, len(sweep), rng)
    chosen = subsample_groups(islands, _HYPOTHESIS_POINTS, rng)
    # Islands the ego motion explains too well for any motion to be chosen over it
    # need no ICP (most of the static world: half to three quarters of the islands).
    target = (sweep, tree, normals)
    fit = ego_fit(
        a[chosen],
        islands[chosen],
        n_islands,
        ego,
        sigma,
        target,
        max_distance=settings.max_distance,
    )
    # Faces the second sensor cannot see, where the ego motion puts them, are no
    # sign of motion (a building's end wall driven past, 2 Hz keyframes), unless
    # the sensor drove through them (the rear of the car ahead): asked of the
    # islands the ego motion does not already explain, in LiDAR sweeps as a sensor
    # writes them (z up, each sensor at its sweep's origin).
    open_ = np.flatnonzero(~fit.hopeless()[islands[chosen]])
    # The noise of a climb: the ego's residual, or the islands' own sampling spacing.
    rise_noise = np.full(n_islands, SLIDE_SCALES * sigma)
    if len(open_) and rest_normals is not None:
        rest = at_rest[chosen[open_]]
        position = np.searchsorted(inside, chosen[open_])
        normal, _, _ = rest_normals(position)
        spacing = _group_median(rest_normals.spacing(position), islands[chosen[open_]], n_islands)
        rise_noise = np.fmax(rise_noise, spacing)
        hidden = np.zeros(len(chosen), dtype=bool)
        hidden[open_] = facing_away(rest, normal, ego[1], np.zeros(3))
        through = driven_through(
            rest, islands[chosen[open_]], n_islands, ego[1], np.zeros(3), settings.island_radius
        )
        hidden[open_] &= ~through[islands[chosen[open_]]]
        fit = fit.with_hidden(islands[chosen], hidden)
    hopeless = fit.hopeless()
    starts = translation_starts(
        a,
        islands,
        n_islands,
        sweep,
        search.islands2,
        search.n_islands2,
        ego,
        max_displacement=reach,
        bin_size=_BIN * settings.max_distance,
        moved=at_rest,
        draws=draws,
        wanted=~hopeless,
    )
    n_starts = starts.shape[1]
    # Every (island, start) pair is one cluster of one multi-body ICP.
    rows = np.repeat(chosen, n_starts)
    pair = islands[rows] * n_starts + np.tile(np.arange(n_starts), len(chosen))
    valid = np.isfinite(starts).all(axis=2).ravel()
    pair = np.where(valid[pair] & ~hopeless[islands[rows]], pair, -1)
    n_pairs = n_islands * n_starts
    rotations = np.broadcast_to(ego[0], (n_pairs, 3, 3)).copy()
    translations = ego[1] + np.nan_to_num(starts).reshape(n_pairs, 3)
    result = multi_body_icp(
        a[rows],
        pair,
        rotations,
        translations,
        sweep,
        tree=tree,
        normals=normals,
        max_distance=settings.max_distance,
        max_iter=min(settings.max_icp_iter, _HYPOTHESIS_ITER),
        tol=settings.tol,
        measure=False,
        workers=settings.workers,
    )
    motions = (result.rotations, result.translations)
    # The reach bounds where the ICP ends, not only where it starts: one that slid a
    # car's faces along themselves out of the reach found no motion within it (and
    # the island searches again, farther, where the reach is a guess). The last
    # search keeps what it finds: a sparse car's rings slide it past any bound.
    centroids, _ = group_centroids(a[chosen], islands[chosen], n_islands)
    centre = np.repeat(centroids, n_starts, axis=0)
    offset = departures(centre, result.rotations, result.translations, ego)
    if not last:
        valid &= ~(np.linalg.norm(offset, axis=1) > reach)
    if rest_normals is not None:
        # Traffic moves along the ground: a climb steeper than 1 in 4 (beyond the
        # noise, or a spacing) is the rings of a sparse sensor slid onto each other.
        valid &= ~(climb(offset, _MAX_GRADE) > np.repeat(rise_noise, n_starts))
    moving, pick, explained = choose_island_motions(
        a[chosen],
        islands[chosen],
        n_islands,
        ego,
        motions,
        valid.reshape(n_islands, n_starts) & ~hopeless[:, None],
        sigma,
        target,
        (search.resting, islands[inside], 0.5 * settings.island_radius),
        max_distance=settings.max_distance,
        fit=fit,
    )
    rotations = np.broadcast_to(ego[0], (n_islands, 3, 3)).copy()
    translations = np.broadcast_to(ego[1], (n_islands, 3)).copy()
    rotations[moving] = result.rotations[pick[moving]]
    translations[moving] = result.translations[pick[moving]]
    # A far, sparse island that its motion shifts by less than two of the second
    # sweep's sampling spacings has not moved (its better fit is another sampling).
    if moving.any():
        moving &= beyond_spacing(
            a[chosen],
            islands[chosen],
            n_islands,
            (rotations, translations),
            ego,
            tree,
            sweep,
            normals,
        )
        rotations[~moving], translations[~moving] = ego
    return moving, rotations, translations, fit.mostly_unexplained(), explained
