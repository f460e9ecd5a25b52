"""Two raw sweeps registered, stage by stage, over the sweeps' states.

:func:`register_pair` is the whole pipeline of a raw pair, one line per stage, each
stage a function of its own module over the two sweeps'
:class:`~mmreg.sweeps._sweep_state.SweepState` (which compute what a sweep alone gives
once, for every pair the sweep is in):

1. the ground of both sweeps (:mod:`mmreg.sweeps._ground`);
2. the ego vehicle's body, left out (:mod:`mmreg.sweeps._ego_body`);
3. the ego motion (:mod:`mmreg.sweeps._ego_motion`);
4. the islands' motions, slow movers included (:mod:`mmreg.sweeps._island_search`);
5. rounds of the multi-model estimator and the clusters' ICP
   (:mod:`mmreg.sweeps._cluster_icp`);
6. the clusters that only slide along their surfaces rejoin the static world
   (:mod:`mmreg.sweeps._join_slides`);
7. the motions no road user makes are taken apart (:mod:`mmreg.sweeps._motion_bounds`).

The estimator of step 5 is the caller's (``cluster``): this floor does not import the
estimators.
"""

from typing import NamedTuple

import numpy as np

from mmreg._array.flow import rigid_flow
from mmreg._array.motion import moving_clusters, static_cluster
from mmreg.sweeps._cluster_icp import refine_clusters
from mmreg.sweeps._ego_body import find_ego_body
from mmreg.sweeps._ego_motion import has_small_gicp, pair_ego_motion
from mmreg.sweeps._island_search import WIDENINGS, island_motions
from mmreg.sweeps._join_slides import join_slides
from mmreg.sweeps._motion_bounds import bound_motions

__all__ = ["PairResult", "clusters_of", "register_pair"]

# Fewest points of the second sweep: the normals need neighbourhoods.
MIN_SWEEP_POINTS = 10
# "auto" max_displacement is at least this many times the ego motion's step.
_TRAFFIC_PER_EGO = 1.5
# With capture times: rounds of deskewing (with the last round's motions) and ICP.
DESKEW_ROUNDS = 2


class PairResult(NamedTuple):
    """What :func:`register_pair` finds: per point of the first sweep off the ego body
    (``body``'s False rows; all rows when ``body`` is None), and per cluster."""

    labels: np.ndarray
    estimator: object  # the fitted estimator (last round)
    rotations: np.ndarray
    translations: np.ndarray
    scales: np.ndarray  # the ICP's robust residual scales (NaN: not refined)
    sigmas: np.ndarray  # the estimator's noise scales
    static: int
    n_rounds: int
    impossible: list  # the clusters taken apart, one reason each
    ego: tuple  # (R, t)
    ego_scale: float
    max_displacement: float  # the reach used
    ground: tuple | None  # both sweeps' ground masks (off the body), or None
    body: tuple | None  # both sweeps' body masks (all rows), or None


def clusters_of(estimator, X):
    """Labels, motions, static world and moving flags of a fitted estimator."""
    labels = np.asarray(estimator.labels_)
    rotations = np.asarray(estimator.rotations_, dtype=float)
    translations = np.asarray(estimator.translations_, dtype=float)
    static = getattr(estimator, "static_cluster_", None)
    if static is None:
        static = static_cluster(labels)
    moving = getattr(estimator, "moving_", None)
    if moving is None:
        a, b = X[:, :3], X[:, 3:]
        moving = moving_clusters(a, b, labels, rotations, translations, static)
    return labels, rotations, translations, int(static), np.asarray(moving, dtype=bool)


def _island_clusters(labels, motions):
    """The islands' clusters without an estimator: ``labels`` (0 the static world, ``k``
    the ``k``-th of ``motions``) renumbered over the clusters that hold points, their
    motions, and the static world's cluster (-1 where no point is static)."""
    counts = np.bincount(labels, minlength=len(motions[0]))
    used = np.flatnonzero(counts)
    place = np.cumsum(counts > 0) - 1
    static = 0 if counts[0] else -1
    return place[labels], motions[0][used], motions[1][used], static


def pair_ground(first, second, settings):
    """The ground of both sweeps, or None (kept): found when the first sweep is z-up and
    holds a ground (one removed before leaves remnants that are objects' bottoms)."""
    if settings.ground == "keep" or not first.holds_ground(settings.tau):
        return None
    return first.ground(settings.tau), second.ground(settings.tau)


def register_pair(
    first,
    second,
    settings,
    cluster,
    rng,
    *,
    known=None,
    body=None,
    ground=None,
    timing=None,
):
    """Two raw sweeps registered: objects, their motions and the ego motion.

    Parameters
    ----------
    first, second : SweepState
        The sweeps' states (their valid returns).
    settings : PairSettings
    cluster : callable
        ``cluster(X, init)``: the multi-model estimator fitted on correspondences ``X``
        ``(n, 6)`` from initial clusters ``init`` (the islands, then the last round's);
        None: the islands' clusters as they are (``estimator="passthrough"``).
    rng : RandomState
    known : tuple (R, t) or None
        The ego motion's start (a previous pair's); None: from the identity.
    body : tuple of two bool masks or None
        The ego vehicle's body in each sweep, known; None: searched for.
    ground : tuple of two bool masks or None
        The ground of each sweep, known; None: found (or kept, ``settings.ground``).
    timing : tuple or None
        ``(times, sweep_times, interval)``, the points' capture times; None: none.

    Returns
    -------
    PairResult
    """
    gicp = has_small_gicp()
    masks = pair_ground(first, second, settings) if ground is None else ground
    body = _ego_body(first, second, settings, masks, body, known, gicp)
    if body is not None:
        first, second, masks, timing = _without_body(first, second, settings, masks, timing, body)
        known = body[2]
    ego, probe, sigma = pair_ego_motion(first, second, settings, rng, known=known, gicp=gicp)
    settings = _reach_after(ego, settings)
    objects = _objects(first, second, (ego, probe), sigma, settings, cluster, rng, timing, masks)
    return PairResult(
        *objects,
        ego=ego,
        ego_scale=sigma,
        max_displacement=settings.max_displacement,
        ground=masks,
        body=None if body is None else body[:2],
    )


def _ego_body(first, second, settings, masks, body, known, gicp):
    """``(body, sweep_body, ego)``: the body given (with ``known``, the ego motion's
    start), or found (told apart by GICP's ego motion), or None."""
    if body is not None:  # known (a log's): no search
        return (*body, known) if body[0].any() or body[1].any() else None
    if not gicp:
        return None
    return find_ego_body(first, second, settings, masks, known=known)


def _without_body(first, second, settings, masks, timing, body):
    """The sweeps' states, ground masks and capture times without the ego body's rows."""
    keep, keep_sweep = ~body[0], ~body[1]
    first, second = first.subset(keep), second.subset(keep_sweep)
    if len(second.points) < MIN_SWEEP_POINTS:
        raise ValueError(
            f"sweep has {len(second.points)} points; at least {MIN_SWEEP_POINTS} are "
            "needed (the normals of its surface need neighbourhoods)."
        )
    if masks is None:  # looked for again without the body
        masks = pair_ground(first, second, settings)
    else:
        masks = (masks[0][keep], masks[1][keep_sweep])
    if timing is not None:
        timing = (timing[0][keep], timing[1][keep_sweep], timing[2])
    return first, second, masks, timing


def _reach_after(ego, settings):
    """``settings`` with an ``"auto"`` reach grown to 1.5 ego steps: other traffic moves
    about as fast as the sensor (2 Hz keyframes need a reach that grows with the step)."""
    if not settings.auto_reach:
        return settings
    step = _TRAFFIC_PER_EGO * float(np.linalg.norm(ego[1]))
    return settings._replace(max_displacement=max(settings.max_displacement, step))


def _objects(first, second, egos, sigma, settings, cluster, rng, timing, masks):
    """The objects and their motions: among all points, or off the ground (``masks``,
    the ground joining the static world)."""
    if masks is None:
        return _clusters(first, second, egos, sigma, settings, cluster, rng, timing)
    return _objects_off_ground(first, second, masks, egos, sigma, settings, cluster, rng, timing)


def _objects_off_ground(first, second, masks, egos, sigma, settings, cluster, rng, timing):
    """The objects off the ground; the ground joins the static world.

    The ego motion used the whole sweeps (the ground holds roll, pitch and height); the
    islands, their hypotheses, the estimator and the object ICPs see the points off the
    ground of both sweeps.
    """
    ground, sweep_ground = masks
    off, sweep_off = ~ground, ~sweep_ground
    a, sweep = first.points, second.points
    if off.sum() < 3 or sweep_off.sum() < MIN_SWEEP_POINTS:
        raise ValueError(
            f"{ground.sum()} of {len(a)} points of the first sweep and "
            f"{sweep_ground.sum()} of {len(sweep)} of the second were taken for the "
            "ground, leaving too few to register; pass ground='keep'."
        )
    if timing is not None:
        timing = (timing[0][off], timing[1][sweep_off], timing[2])
    # The new places are judged against both sweeps whole: the two masks of the
    # ground differ at objects' feet, where a surface left in one sweep only would
    # read as new.
    whole = (first, second)
    objects = first.subset(off), second.subset(sweep_off)
    found = _clusters(*objects, egos, sigma, settings, cluster, rng, timing, whole)
    labels_off, estimator, rotations, translations, scales, sigmas, static, n_rounds, impossible = (
        found
    )
    if static < 0:  # the ground is the static world's first member
        ego = egos[0]
        static = len(rotations)
        rotations = np.concatenate([rotations, ego[0][None]])
        translations = np.concatenate([translations, ego[1][None]])
        scales = np.concatenate([scales, [np.nan]])
        sigmas = np.concatenate([sigmas, [np.nan]])
    labels = np.full(len(a), -1 if settings.ground == "drop" else static, dtype=labels_off.dtype)
    labels[off] = labels_off
    return labels, estimator, rotations, translations, scales, sigmas, static, n_rounds, impossible


def _clusters(first, second, egos, sigma, settings, cluster, rng, timing, whole=None):
    """The objects among the points of ``first`` and their motions.

    ``egos``: the ego motion reported (the static world's), and the one the islands are
    tested and the clusters started at (see
    :func:`~mmreg.sweeps._ego_motion.pair_ego_motion`); ``whole``: the states of both
    sweeps with their ground, when ``first`` and ``second`` are off it.
    """
    ego, probe = egos
    a = first.points
    target = second.target()
    islands, rotations, translations, moving = island_motions(
        first, second, probe, sigma, settings, rng
    )
    # Label 0: the ego motion, for the small islands and every static one (the
    # estimator starts from one static cluster, not one per static island).
    motions = (
        np.concatenate([probe[0][None], rotations]),
        np.concatenate([probe[1][None], translations]),
    )
    on_moving = np.zeros(len(a), dtype=bool)
    on_moving[islands >= 0] = moving[islands[islands >= 0]]
    labels = np.where(on_moving, islands + 1, 0)
    previous = None
    estimator = None
    for round_ in range(1, settings.max_rounds + 1):
        if cluster is None:  # the islands' clusters pass through, as they are
            labels, rotations, translations, static = _island_clusters(labels, motions)
        else:
            X = np.hstack([a, rigid_flow(a, labels, *motions) + a])
            estimator = cluster(X, labels)
            labels, rotations, translations, static, _ = clusters_of(estimator, X)
        # The static world keeps the ego motion: its ICP used the whole sweep, and
        # on real sweeps one fitted to the static cluster alone was worse (static EPE
        # 0.031 m against 0.020 m on icpflow_av2_demo).
        refine = np.ones(len(rotations), dtype=bool)
        if static >= 0:
            refine[static] = False
            rotations[static], translations[static] = ego
        # With capture times, two rounds of deskewing and ICP: the first deskews
        # with the estimator's motions, the second with the first's ICP motions.
        rotations, translations, scales = refine_clusters(
            a,
            labels,
            (rotations, translations),
            refine,
            target,
            static,
            settings,
            rng,
            timing,
            DESKEW_ROUNDS,
        )
        motions = (rotations, translations)
        n_rounds = round_
        if previous is not None and np.array_equal(previous, labels):
            break
        previous = labels
    sigmas = np.asarray(getattr(estimator, "sigmas_", np.full(len(rotations), np.nan)))
    impossible = []
    if static >= 0:
        labels, (rotations, translations, scales, sigmas), static = join_slides(
            a,
            labels,
            (rotations, translations, scales, sigmas),
            static,
            sigma,
            target,
            # Motions fitted to deskewed points put the raw ones near their view.
            None if timing is None else settings.max_distance,
            None if whole is None else (whole[0].target(), whole[1].target()),
            own_normals=first.normals,
        )
        # Motions no vehicle or person can make: taken apart (the static world where
        # its motion explains them, else outliers); mmreg.sweeps._motion_bounds.
        labels, (rotations, translations, scales, sigmas), static, impossible = bound_motions(
            a,
            labels,
            (rotations, translations, scales, sigmas),
            static,
            target if whole is None else whole[1].target(),
            sigma,
            scale=settings.tau,
            # "auto" stands for an unknown interval, searched twice as far.
            reach=settings.max_displacement * (2.0**WIDENINGS if settings.auto_reach else 1.0),
            interval=settings.interval,
            up=np.eye(3)[2] if (first if whole is None else whole[0]).is_z_up() else None,
        )
    return labels, estimator, rotations, translations, scales, sigmas, static, n_rounds, impossible
