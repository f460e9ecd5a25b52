"""The robust default: Algorithm 1 with an outlier model, merging and re-proposal around it.

The loop is the paper's (fit every cluster, drop the small ones, reassign each
correspondence to its most likely cluster within the gate); the named steps of
:mod:`mmreg.em._steps` sit between its lines:

0. in the sweep variant, once the static world is known, a moving cluster that holds two
   touching objects whose flows jump between them split in two
   (:func:`~mmreg.em._mixed_clusters.split_mixed_clusters`, ``"moving_pieces"``);
1. M-step on inliers (:func:`trimmed_fit`) instead of Horn on every member, each
   cluster with a robust noise scale of its own (``"trimming"``; the first iteration
   also estimates the noise's growth with range, ``"range_noise"``);
2. merging of adjacent clusters that share a motion (:func:`merge_adjacent`,
   ``"merging"``);
3. the static world (:func:`merge_static_world`, ``"static_world"``): the dominant
   motion (or, without a majority, the cluster that spans the scene; or the clusters
   that move with a given ego motion) gathers every piece that moves with it, however
   far apart, into one cluster that the gate of eq. (7) admits everywhere;
4. in the sweep variant, touching moving pieces whose motions agree joined into one
   object (:func:`join_moving_pieces`, ``"moving_pieces"``);
5. dissolving layers of flow that bled along a boundary (:func:`boundary_layers`) and,
   in the sweep variant, clusters whose members lie scattered among other clusters'
   points (:func:`scattered_clusters`), ``"boundary_layers"``: neither has a body of
   its own (the static world and its slow pieces, which lie among its points, are never
   dissolved);
6. removal of small clusters (Algorithm 1, lines 10-13);
7. the E-step and classification of eq. (7) (:func:`assign_correspondences`), with each
   correspondence's noise scale ``sigma_j g_i`` growing with its range when the data say
   so (:func:`estimate_range_growth`, ``"range_noise"``);
8. the outlier component (:func:`reject_outliers`, ``"outliers"``);
9. new clusters from what no cluster explains (:func:`propose_clusters`,
   ``"proposals"``): this is also how a cluster holding two motions splits, since the
   trimmed M-step fits the majority and leaves the other motion's correspondences
   unexplained.

Each step but the E-step and the removal of small clusters can be turned off by its
name (``skip_steps``, for ablations); with all of them off the loop is Algorithm 1 with
the static world's gate still in place.

Each step is a small function of the fit's setting (:class:`_Setting`: the
correspondences and the options, never changed) and of the loop's state
(:class:`_LoopState`: the clusters, their models, the static world, the noise scale),
and turns itself off when ``skip_steps`` names it; :func:`robust_multi_model_em` is the
loop over them, one line a step. The final clean-up (:func:`_clean_up`) runs steps 1-6
once more, with the static world's slow pieces folded into it.
"""

from dataclasses import dataclass, field
from itertools import compress

import numpy as np
from scipy.spatial import cKDTree
from scipy.stats import chi2
from sklearn.utils import check_random_state

from mmreg._array.geometry import row_medians
from mmreg._array.moments import group_moments
from mmreg._array.neighbors import NeighbourTable, lookup_tree
from mmreg._array.relabelling import rows_moved
from mmreg.em._gate import ClusterGate
from mmreg.em._likelihood import morton_order, single_threaded_blas
from mmreg.em._mixed_clusters import split_mixed_clusters
from mmreg.em._paper import EMResult, _compact_initial, _size_rank, default_sigma_floor
from mmreg.em._static_world import StaticWorldRule, static_world_rule
from mmreg.em._steps import (
    _with,
    adjacent_pairs,
    assign_correspondences,
    boundary_layers,
    drop_small_clusters,
    estimate_range_growth,
    fit_clusters,
    join_moving_pieces,
    judge_correspondences,
    log_uniform_density,
    merge_adjacent,
    merge_static_world,
    motion_beyond_scatter,
    moves_slowly,
    propose_clusters,
    range_noise_scale,
    reject_outliers,
    scattered_clusters,
    squared_residuals,
    stray_members,
    trimmed_fit,
)

__all__ = [
    "ROBUST_STEPS",
    "Pieces",
    "RobustEMResult",
    "assign_to_pieces",
    "joins_moving_pieces",
    "propose_in_the_rest",
    "reads_neighbours",
    "refit_clusters",
    "robust_multi_model_em",
]

#: The steps around Algorithm 1 that ``skip_steps`` may turn off.
ROBUST_STEPS = (
    "trimming",
    "range_noise",
    "merging",
    "static_world",
    "moving_pieces",
    "boundary_layers",
    "outliers",
    "proposals",
)
# The outlier component's weight is the last iteration's outlier share, capped: when
# most correspondences are unexplained (initial clusters that mix several motions), an
# outlier prior above one half would make itself true.
_MAX_OUTLIER_WEIGHT = 0.5
# A moving object's noise scale is at most this fraction of its motion (the proposals'
# prior, see propose_clusters).
_MAX_NOISE_RATIO = 0.1
# Correspondences of a scene without outliers that the sweep variant may expect to call
# wrong (see reject_outliers).
_FALSE_ALARMS = 0.01


@dataclass
class RobustEMResult(EMResult):
    """:class:`EMResult` and what the robust steps did, iteration by iteration."""

    history: list = field(default_factory=list)
    log_outlier_density: float = 0.0
    """``log(pi_0 / V)``: the outlier component's log-density at the end."""
    noise_growth: float = 0.0
    """``c`` of the noise scale ``sigma_j (1 + c ||a||^2)``; 0 for equal noise."""
    static_cluster: int = -1
    """The static world's cluster, -1 if there is none (:func:`merge_static_world`)."""
    moving: np.ndarray = None
    """Per cluster: does it move relative to the static world?"""
    pieces: "Pieces" = None
    """The clusters of the final clean-up before they were joined into the ones
    reported (None without an iteration): what :func:`assign_to_pieces` judges
    further correspondences by."""


@dataclass
class Pieces:
    """The final clean-up's clusters, each with its own motion, and what each became.

    The static world's slow pieces keep a motion of their own here (a parked car whose
    flow carries a centimetre of jitter): judged by the static world's motion alone,
    their correspondences would look wrong.
    """

    points: np.ndarray
    """The a-points of the correspondences fitted."""
    labels: np.ndarray
    """Piece of each correspondence fitted (-1 for none)."""
    models: object
    """:class:`ClusterModels` of the pieces."""
    reported: np.ndarray
    """The reported cluster each piece became (-1: dissolved or dropped)."""
    static: int
    """The static world's piece (admitted everywhere by the gate), -1 if none."""


def _range_noise(a, b, labels, models, sigma_floor, robust):
    """The growth of the noise with range, and each correspondence's noise scale."""
    clustered = np.where(labels < len(models.sigmas), labels, -1)
    squared = squared_residuals(a, b, clustered, models.rotations, models.translations)
    growth = estimate_range_growth(
        a, squared, clustered, len(models.sigmas), sigma_floor, robust=robust
    )
    return growth, (range_noise_scale(a, growth) if growth > 0 else None)


def _sampling_spacing(points, k=6, neighbours=None, workers=1):
    """The local sampling spacing at each point: the median nearest-neighbour distance
    of its ``k`` nearest points (itself included).

    Smoothed so that a few points that happen to lie close together (random subsampling
    makes such clumps) are not read as a surface of their own, denser than the one
    around them. ``neighbours`` (a :class:`NeighbourTable` of at least ``k``) saves the
    query.
    """
    n = len(points)
    if n < 2:
        return np.zeros(n)
    if neighbours is not None and neighbours.k >= min(k, n):
        distance, index = neighbours.distance, neighbours.index[:, : min(k, n)]
    else:
        distance, index = cKDTree(points).query(points, k=min(k, n), workers=workers)
    return row_medians(distance[:, 1][index])


def reads_neighbours(skip_steps):
    """Whether the loop reads the a-points' neighbour table: its boundary layers do."""
    return "boundary_layers" not in skip_steps


def joins_moving_pieces(sweep, skip_steps, motion_tolerance):
    """Whether touching moving pieces whose motions agree are joined: with
    ``variant="sweep"``, its ``"moving_pieces"`` step and a tolerance above 0."""
    return sweep and "moving_pieces" not in skip_steps and motion_tolerance > 0


def _weights(counts, n):
    return np.asarray(counts, dtype=float) / max(n, 1)


def robust_multi_model_em(
    a,
    b,
    init_labels,
    *,
    tau=1.5,
    min_cluster_size=4,
    max_iter=10,
    sigma_floor=None,
    confidence=0.999,
    n_hypotheses=32,
    noise_model="range",
    static_share=0.5,
    min_motion=0.05,
    motion_tolerance=0.2,
    tol=1e-3,
    skip_steps=(),
    sweep=False,
    ego_motion=None,
    neighbours=None,
    random_state=None,
    verbose=0,
    workers=1,
):
    """Classification-EM with outliers, merging, a static world and re-proposal.

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
    init_labels : ndarray of shape (n,)
        Initial clusters; negative labels mark correspondences in no cluster.
    tau : float or None, default=1.5
        The gate of eq. (7); also the reach of merging and of proposals.
    min_cluster_size : int, default=4
    max_iter : int, default=10
    sigma_floor : float, default=None
    confidence : float, default=0.999
        Inlier quantile of the residual tests of the trimmed M-step and of proposals.
    n_hypotheses : int, default=32
        Minimal samples drawn in each group of unexplained correspondences.
    noise_model : {"range", "constant"}, default="range"
        ``"range"``: correspondence ``i`` of cluster ``j`` has noise ``sigma_j (1 + c
        ||a_i||^2)``, with ``c >= 0`` estimated by maximum likelihood every iteration (0
        when the noise does not grow with range); ``"constant"``: ``sigma_j``.
    static_share : float or None, default=0.5
        The dominant motion is the static world when it holds at least this share of the
        clustered correspondences; below it, the cluster that spans the scene
        (:func:`merge_static_world`); None: no static world (unless ``ego_motion``).
    min_motion : float, default=0.05
        A cluster moving less than this (RMS, in the units of the points) relative to the
        static world is part of it.
    motion_tolerance : float, default=0.2
        Touching moving clusters whose motions agree within this fraction of their motion
        are one object (:func:`join_moving_pieces`), unless their flows jump by more than
        ``min_motion`` where they touch; a moving cluster that holds two such objects is
        split (:func:`~mmreg.em._mixed_clusters.split_mixed_clusters`).
    tol : float, default=1e-3
        Converged when an iteration moves at most this fraction of the correspondences
        to another reported cluster (:func:`~mmreg._array.relabelling.rows_moved`: the
        clusters of two iterations matched by overlap, so that a merge moves the smaller
        part's members and a proposal its own; a move between pieces of the static
        world does not count, and a proposal that moves too slowly to leave it is
        reported with it; 0: none, as Algorithm 1).
    skip_steps : tuple of str, default=()
        Steps of :data:`ROBUST_STEPS` to leave out (ablations).
    sweep : bool, default=False
        The variant for real sweeps and scene-flow networks: a noise scale per cluster
        (robust, floored at the scene's), the static world, joined moving pieces,
        proposals that search the noise scale and also try local translations, slow
        movers sought in the static world's tail, and the outlier weight capped at one
        half. False: one shared noise scale and none of these (the robust default).
    ego_motion : tuple of (ndarray, ndarray) or None, default=None
        Sweep variant: the static world's motion ``(R, t)`` (``b = R a + t``), when the
        caller knows it; the static world is then the clusters that move with it
        (:func:`merge_static_world`), whatever their share.
    neighbours : NeighbourTable or None, default=None
        The a-points' 16 nearest neighbours, if the caller has listed them; None lists
        them here (when the boundary layers step runs, the only one that reads them).
    random_state : int, RandomState instance or None, default=None
        Seeds the proposals' samples.
    verbose : int, default=0
        Print one line per iteration.
    workers : int, default=1
        Threads of the larger KD-tree queries (``-1``: every core).

    Returns
    -------
    RobustEMResult
    """
    setting = _setting(
        a,
        b,
        tau=tau,
        min_cluster_size=min_cluster_size,
        sigma_floor=sigma_floor,
        confidence=confidence,
        n_hypotheses=n_hypotheses,
        noise_model=noise_model,
        static_share=static_share,
        min_motion=min_motion,
        motion_tolerance=motion_tolerance,
        tol=tol,
        skip_steps=skip_steps,
        sweep=sweep,
        ego_motion=ego_motion,
        neighbours=neighbours,
        random_state=random_state,
        verbose=verbose,
        workers=workers,
    )
    labels, n_clusters = _compact_initial(init_labels)
    state = _LoopState(labels, n_clusters, report=labels, own_scales=sweep)
    with single_threaded_blas():
        for _ in range(max_iter):
            if state.n_clusters == 0:
                state.converged = True  # nothing left to fit, merge or assign to
                break
            state.start_iteration()
            _split_mixed_clusters(setting, state)  # 0. (moving_pieces)
            _m_step(setting, state)  # 1. (trimming)
            if state.n_iter == 1:
                _first_estimates(setting, state)  # (range_noise)
            _merge_adjacent(setting, state)  # 2. (merging)
            _static_world(setting, state)  # 3. (static_world)
            _join_moving_pieces(setting, state)  # 4. (moving_pieces)
            _dissolve_layers(setting, state)  # 5. (boundary_layers)
            _drop_small_clusters(setting, state)  # 6.
            _e_step(setting, state)  # 7.
            _reject_outliers(setting, state)  # 8. (outliers)
            _hold_static_motion(setting, state)
            _propose_clusters(setting, state)  # 9. (proposals)
            _dissolve_proposed_layers(setting, state)  # (boundary_layers)
            _update_range_noise(setting, state)  # (range_noise)
            if _settle(setting, state):
                state.converged = True
                break
    return _result(setting, state, _clean_up(setting, state))


def _result(setting, state, pieces):
    """:class:`RobustEMResult` of the cleaned-up state."""
    labels, n_clusters, static, models = state.labels, state.n_clusters, state.static, state.models
    moving = _moving(models, static, setting.min_motion)
    weights = _weights(np.bincount(labels[labels >= 0], minlength=n_clusters), setting.n)
    if setting.verbose and state.n_iter:
        # After the clean-up: the clusters of the result, not the loop's pieces.
        print(f"result: clusters {n_clusters}")
    log_outlier = np.log(max(np.mean(labels < 0), 1.0 / max(setting.n, 1)))
    return RobustEMResult(
        labels,
        models.rotations,
        models.translations,
        models.sigmas,
        weights,
        state.n_iter,
        state.converged,
        state.history,
        float(log_outlier + setting.log_volume_density),
        float(state.growth) if state.noise_scale is not None else 0.0,
        static,
        moving,
        pieces,
    )


@dataclass(frozen=True)
class _Setting:
    """What the loop reads and never changes: the correspondences, the options as the
    steps read them, and what is listed once (neighbours, spacing, Morton order)."""

    a: np.ndarray
    b: np.ndarray
    tau: object  # float or None
    min_cluster_size: int
    sigma_floor: float
    confidence: float
    """The inlier quantile of the proposals' tests and of the static world's tail."""
    trim_confidence: float
    """The trimmed M-step's inlier quantile (1: every member, ``trimming`` off)."""
    n_hypotheses: int
    share: object
    """The static world's least share of the clustered correspondences (None: none)."""
    min_motion: float
    motion_tolerance: object
    """Joins moving pieces whose motions agree within it (None: never joined)."""
    max_outlier_weight: float
    tol: float
    sweep: bool
    skip_steps: frozenset
    range_noise: bool
    """Whether the noise grows with range (``noise_model="range"``, ``range_noise``)."""
    neighbours: object
    spacing: object
    order: np.ndarray
    log_volume_density: float
    rng: object
    workers: int
    verbose: int

    @property
    def n(self):
        return len(self.a)

    @property
    def d(self):
        return self.a.shape[1]

    def runs(self, step):
        """Whether the step of :data:`ROBUST_STEPS` named ``step`` is on."""
        return step not in self.skip_steps


def _setting(
    a,
    b,
    *,
    tau,
    min_cluster_size,
    sigma_floor,
    confidence,
    n_hypotheses,
    noise_model,
    static_share,
    min_motion,
    motion_tolerance,
    tol,
    skip_steps,
    sweep,
    ego_motion,
    neighbours,
    random_state,
    verbose,
    workers,
):
    """:class:`_Setting` of :func:`robust_multi_model_em`'s arguments, checked."""
    unknown = set(skip_steps) - set(ROBUST_STEPS)
    if unknown:
        raise ValueError(f"Unknown steps {sorted(unknown)}; the steps are {ROBUST_STEPS}.")
    run = {step: step not in skip_steps for step in ROBUST_STEPS}
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    rng = check_random_state(random_state)
    if sigma_floor is None:
        sigma_floor = default_sigma_floor(b)
    share = (
        static_world_rule(static_share, ego_motion, a) if sweep and run["static_world"] else None
    )
    join_pieces = joins_moving_pieces(sweep, skip_steps, motion_tolerance)
    if not reads_neighbours(skip_steps):
        neighbours = None
    elif neighbours is None:
        neighbours = NeighbourTable(a, workers=workers)
    # The sweep variant reads the spacing off the table; the robust default keeps its own
    # k=6 query, whose ties among equidistant neighbours may order apart from the
    # table's, so that its labels stay as they were.
    spacing = (
        _sampling_spacing(a, neighbours=neighbours if sweep else None, workers=workers)
        if run["boundary_layers"]
        else None
    )
    return _Setting(
        a=a,
        b=b,
        tau=tau,
        min_cluster_size=min_cluster_size,
        sigma_floor=sigma_floor,
        confidence=confidence,
        trim_confidence=confidence if run["trimming"] else 1.0,
        n_hypotheses=n_hypotheses,
        share=share,
        min_motion=min_motion,
        motion_tolerance=motion_tolerance if join_pieces else None,
        max_outlier_weight=_MAX_OUTLIER_WEIGHT if sweep else 1.0,
        tol=tol,
        sweep=sweep,
        skip_steps=frozenset(skip_steps),
        range_noise=run["range_noise"] and noise_model == "range",
        neighbours=neighbours,
        spacing=spacing,
        order=morton_order(np.ascontiguousarray(a.T)),
        log_volume_density=log_uniform_density(a, b),
        rng=rng,
        workers=workers,
        verbose=verbose,
    )


# What the steps of one iteration count, for its line of the history.
_TALLIED = ("merges", "static_pieces", "joined", "bled", "dropped", "noise_growth")


@dataclass
class _LoopState:
    """What the loop's steps pass on: the clusters, their models, the static world and
    the noise scale."""

    labels: np.ndarray
    """Each correspondence's cluster when the iteration starts (-1: none)."""
    n_clusters: int
    report: np.ndarray
    """The clusters the last iteration reported, which convergence compares with."""
    own_scales: bool
    """Whether the M-step fits each cluster a noise scale of its own. A noise scale of
    its own is bounded by a cluster's motion relative to the static world (a network
    errs in proportion to it); without a static world nothing bounds it, and a few
    wrong correspondences near each other pass for an object with a large noise of its
    own: one shared scale then. The first iteration has not looked for a static world
    yet."""
    members: np.ndarray = None
    """Each correspondence's cluster through the steps of the iteration."""
    root: np.ndarray = None
    """What each of the ``n_clusters`` became through the steps (-1: dissolved)."""
    models: object = None
    inliers: np.ndarray = None
    counts: np.ndarray = None
    kept: np.ndarray = None
    """The clusters kept by :func:`_drop_small_clusters` (-1 for each proposal after)."""
    weights: np.ndarray = None
    before_e_step: np.ndarray = None
    """The members the E-step started from (did the static world hold its own?)."""
    static: int = -1
    """The static world's cluster (-1: none)."""
    slow: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.intp))
    """The static world's slow pieces: apart in the loop, reported with it."""
    reference: tuple = None
    """The static world's motion ``(R, t)``, once there is one."""
    noise_scale: np.ndarray = None
    """Each correspondence's relative noise scale ``g_i`` (None: all 1)."""
    growth: float = 0.0
    outlier_share: float = None
    log_outlier: float = None
    found: list = field(default_factory=list)
    n_iter: int = 0
    converged: bool = False
    history: list = field(default_factory=list)
    tally: dict = field(default_factory=dict)

    def start_iteration(self):
        self.n_iter += 1
        self.tally = dict.fromkeys(_TALLIED, 0)


def _through(mapping, labels):
    """``labels`` mapped cluster by cluster through ``mapping`` (-1 stays -1)."""
    return np.where(labels >= 0, mapping[np.maximum(labels, 0)], -1)


def _fit(setting, state, labels, n_clusters):
    """The trimmed M-step of ``labels``: each cluster's motion and noise scale fitted on
    its inliers."""
    return trimmed_fit(
        setting.a,
        setting.b,
        labels,
        n_clusters,
        setting.sigma_floor,
        state.noise_scale,
        confidence=setting.trim_confidence,
        per_cluster=state.own_scales,
        max_noise_ratio=_MAX_NOISE_RATIO if setting.sweep else None,
        reference=state.reference,
    )


def _m_step(setting, state):
    """1. The M-step on inliers (``trimming``: off, on every member)."""
    state.inliers, state.models = _fit(setting, state, state.labels, state.n_clusters)


def _first_estimates(setting, state):
    """The first iteration's noise growth with range (``range_noise``), from the initial
    clusters, and the M-step again with it; and the outlier share, the share of the
    correspondences the M-step trimmed."""
    if setting.range_noise:
        state.growth, state.noise_scale = _range_noise(
            setting.a, setting.b, state.inliers, state.models, setting.sigma_floor, setting.sweep
        )
        if state.noise_scale is not None:
            _m_step(setting, state)
    state.outlier_share = np.mean(state.inliers < 0)


def _merge_adjacent(setting, state):
    """2. Adjacent clusters that share a motion merged (``merging``)."""
    state.root = np.arange(state.n_clusters)
    if setting.runs("merging"):
        pairs = adjacent_pairs(setting.a, state.inliers, state.n_clusters, setting.tau)
        state.root, state.models, state.tally["merges"] = merge_adjacent(
            state.models, pairs, setting.d, setting.sigma_floor
        )


def _static_world(setting, state):
    """3. The static world (``static_world``, sweep variant): every piece that moves with
    it, however far."""
    state.static, state.models, state.root, state.tally["static_pieces"], state.slow = (
        _gather_static_world(
            state.models,
            state.root,
            setting.d,
            setting.sigma_floor,
            setting.share,
            setting.min_motion,
            state.labels,
        )
    )
    state.members = _through(state.root, state.labels)


def _split_mixed_clusters(setting, state):
    """0. A moving cluster that holds two touching objects whose flows jump between them
    split in two (``moving_pieces``, sweep variant): an initial cluster spans up to tau,
    more than an object. Only once the static world is known, and never the static world.
    """
    if setting.motion_tolerance is None or state.reference is None:
        return
    state.labels, state.n_clusters = split_mixed_clusters(
        setting.a,
        setting.b,
        state.labels,
        state.n_clusters,
        setting.sigma_floor,
        min_jump=setting.min_motion,
        min_size=setting.min_cluster_size,
        noise_scale=state.noise_scale,
        reference=state.reference,
    )


def _join_moving_pieces(setting, state):
    """4. Touching pieces of one moving object whose flow bends with the motion joined
    (``moving_pieces``, sweep variant)."""
    if setting.motion_tolerance is None:
        return
    joined, state.models, state.tally["joined"] = join_moving_pieces(
        setting.a,
        state.members,
        state.models,
        state.static,
        setting.d,
        setting.sigma_floor,
        tolerance=setting.motion_tolerance,
        neighbours=setting.neighbours,
        workers=setting.workers,
        targets=setting.b,
        min_jump=setting.min_motion,
    )
    state.members = _through(joined, state.members)
    state.root = joined[state.root]


def _layers(setting, labels, n_clusters, world):
    """The clusters of ``labels`` without a body of their own: layers of flow that bled
    along another cluster's boundary and, in the sweep variant, scattered clusters. The
    static world's clusters (``world``: it and its slow pieces, which are reported with it
    and lie among its points) are never layers."""
    layers = boundary_layers(
        setting.a,
        labels,
        n_clusters,
        setting.spacing,
        exempt=world,
        neighbours=setting.neighbours,
        ignore_strays=setting.sweep,
    )
    if not setting.sweep:
        return layers
    # With a noise scale of their own, a few scattered wrong flows can hold a motion.
    scattered = scattered_clusters(labels, n_clusters, setting.neighbours, exempt=world)
    return np.union1d(layers, scattered)


def _dissolve_layers(setting, state):
    """5. Layers of flow that bled along another cluster's boundary dissolved
    (``boundary_layers``)."""
    if not setting.runs("boundary_layers"):
        return
    world = np.append(state.slow, state.static)
    bled = _layers(setting, state.members, state.n_clusters, world)
    state.members[np.isin(state.members, bled)] = -1
    state.root[np.isin(state.root, bled)] = -1
    state.tally["bled"] = len(bled)


def _drop_small_clusters(setting, state):
    """6. Clusters below m_min dropped (Algorithm 1, lines 10-13), the others numbered
    in order; merged-away clusters have no members."""
    state.counts = np.bincount(state.members[state.members >= 0], minlength=state.n_clusters)
    state.members, state.kept = drop_small_clusters(
        state.members, state.counts, setting.min_cluster_size
    )
    state.root = drop_small_clusters(state.root, state.counts, setting.min_cluster_size)[0]
    state.static = _position(state.kept, state.static)
    small = (state.counts > 0) & (state.counts < setting.min_cluster_size)
    state.tally["dropped"] = int(np.count_nonzero(small))


def _e_step(setting, state):
    """7. The E-step and classification of eq. (7) among the kept clusters, gated by tau
    but for the static world."""
    state.models = state.models.take(state.kept)
    state.weights = _weights(state.counts[state.kept], setting.n)
    gate = ClusterGate(
        setting.a,
        state.members,
        len(state.kept),
        setting.tau,
        ungated=[state.static] if state.static >= 0 else [],
        workers=setting.workers,
    )
    state.before_e_step = state.members
    state.members = assign_correspondences(
        setting.a,
        setting.b,
        state.models.rotations,
        state.models.translations,
        state.models.sigmas,
        state.weights,
        gate,
        state.members,
        setting.order,
        state.noise_scale,
    )


def _reject_outliers(setting, state):
    """8. The outlier component (``outliers``), of the last iteration's outlier share as
    its weight, capped."""
    outlier_weight = min(max(state.outlier_share, 1.0 / setting.n), setting.max_outlier_weight)
    state.log_outlier = np.log(outlier_weight) + setting.log_volume_density
    if setting.runs("outliers"):
        state.members = reject_outliers(
            setting.a,
            setting.b,
            state.members,
            state.models.rotations,
            state.models.translations,
            state.models.sigmas,
            state.weights,
            state.log_outlier,
            state.noise_scale,
        )
    state.outlier_share = np.mean(state.members < 0)


def _hold_static_motion(setting, state):
    """The static world's motion, kept for the steps that follow and the next M-step
    (it bounds the clusters' own noise scales and turns the proposals' hypotheses)."""
    if state.static >= 0:
        rotations, translations = state.models.rotations, state.models.translations
        state.reference = (rotations[state.static], translations[state.static])
    state.own_scales = setting.sweep and state.static >= 0


def _propose_clusters(setting, state):
    """9. New clusters from the unexplained correspondences (``proposals``)."""
    state.found = []
    if not setting.runs("proposals"):
        return
    # Their hypotheses turn like the static world, unless the E-step took most of its
    # members from it: then its motion was the mean of several (initial clusters that mix
    # motions, fitted by least squares) and would turn every hypothesis wrong.
    anchored = _holds_its_members(state.static, state.before_e_step, state.members)
    models = state.models
    smallest = float(np.min(models.sigmas)) if len(state.kept) else setting.sigma_floor
    state.found = propose_clusters(
        setting.a,
        setting.b,
        _unexplained(
            setting.a,
            setting.b,
            state.members,
            state.static,
            models,
            state.noise_scale,
            setting.confidence,
        ),
        setting.tau if setting.tau is not None else np.inf,
        smallest,
        state.log_outlier,
        setting.n,
        setting.rng,
        log_volume_density=setting.log_volume_density,
        models=models,
        min_cluster_size=setting.min_cluster_size,
        sigma_floor=setting.sigma_floor,
        noise_scale=state.noise_scale,
        n_hypotheses=setting.n_hypotheses,
        confidence=setting.confidence,
        reference=state.reference if anchored else None,
        per_cluster=setting.sweep,
        # Without scales of their own, the next M-step holds a proposal to the
        # clusters' shared scale: it may take no wider one.
        max_scale=None if state.own_scales else smallest,
    )
    for group in state.found:
        state.members[group] = len(state.kept)
        state.kept = np.append(state.kept, -1)


def _slow_positions(state):
    """The slow clusters' positions among the kept ones (proposals are not)."""
    return np.flatnonzero(np.isin(state.kept, state.slow))


def _dissolve_proposed_layers(setting, state):
    """A proposal along another cluster's boundary is bled flow too
    (``boundary_layers``)."""
    if not (setting.runs("boundary_layers") and state.found):
        return
    world = np.append(_slow_positions(state), state.static)
    layers = _layers(setting, state.members, len(state.kept), world)
    first_new = len(state.models.sigmas)
    state.found = [f for k, f in enumerate(state.found) if first_new + k not in layers]
    state.members[np.isin(state.members, layers[layers >= first_new])] = -1


def _update_range_noise(setting, state):
    """The noise's growth with range estimated again on this iteration's clusters, for
    the next M-step (``range_noise``)."""
    state.tally["noise_growth"] = float(state.growth) if state.noise_scale is not None else 0.0
    if setting.range_noise and len(state.models.sigmas):
        state.growth, state.noise_scale = _range_noise(
            setting.a,
            setting.b,
            state.members,
            state.models,
            setting.sigma_floor,
            setting.sweep,
        )


def _reported(setting, state):
    """The clusters as they would be reported: not their numbers (compacting renumbers
    them) and not the static world's pieces (slow pieces are reported with it, and a
    network's flow moves points between them for ever)."""
    static, found = state.static, state.found
    if static < 0:
        return state.members
    report = np.where(np.isin(state.members, _slow_positions(state)), static, state.members)
    if found:
        # A slow proposal will be reported with the static world, as a slow cluster;
        # reported apart now, it would count as moved twice.
        slowly = moves_slowly(
            setting.a,
            setting.b,
            found,
            state.reference,
            setting.sigma_floor,
            setting.min_motion,
            state.noise_scale,
        )
        if slowly.any():
            report = report.copy()
            report[np.concatenate(list(compress(found, slowly)))] = static
    return report


def _settle(setting, state):
    """The iteration's line of the history, and the labels compacted for the next one.

    Returns whether the loop converged: at most ``tol`` of the correspondences moved to
    another reported cluster (merges, proposals and joined pieces count by the
    correspondences they move).
    """
    report = _reported(setting, state)
    n_changed = rows_moved(state.report, report)
    state.report = report
    tally = state.tally
    step = {
        "iteration": state.n_iter,
        # Clusters as reported, and the pieces the loop keeps apart (slow pieces of the
        # static world, pieces the clean-up may join).
        "clusters": int(np.count_nonzero(np.bincount(report[report >= 0]))),
        "pieces": int(len(state.kept)),
        "merges": int(tally["merges"]),
        "static_pieces": int(tally["static_pieces"]),
        "joined": int(tally["joined"]),
        "bled": tally["bled"],
        "dropped": tally["dropped"],
        "outliers": int(np.count_nonzero(state.members < 0)),
        "proposed": len(state.found),
        "noise_growth": tally["noise_growth"],
        "changed": n_changed,
    }
    state.history.append(step)
    if setting.verbose:
        print(", ".join(f"{key} {value:g}" for key, value in step.items()))
    state.labels, state.n_clusters = _compact_initial(state.members)
    return n_changed <= setting.tol * setting.n


def _clean_up(setting, state):
    """The final clean-up: the loop's steps 1-6 once more, with the static world's slow
    pieces folded into it, then the clusters numbered by size and fitted.

    With ``max_iter=0`` the initial clusters are returned as given (the paper's
    contract), but for those below m_min.

    Returns
    -------
    Pieces or None
        The clusters before the slow pieces were folded and the moving pieces joined
        (None without an iteration).
    """
    pieces = None
    if state.n_iter and state.n_clusters:
        _m_step(setting, state)
        _merge_adjacent(setting, state)
        _static_world(setting, state)
        pieces = _fold_slow_pieces(setting, state)
        _join_moving_pieces(setting, state)
        _dissolve_layers(setting, state)
    else:
        state.members, state.root = state.labels, np.arange(state.n_clusters)
    _drop_small_clusters(setting, state)
    rank = _size_rank(state.members, len(state.kept))
    state.labels, state.n_clusters = rank[state.members], len(state.kept)
    if pieces is not None:
        pieces.reported = rank[state.root]
    state.static = int(rank[state.static]) if state.static >= 0 else -1
    _, state.models = _fit(setting, state, state.labels, state.n_clusters)
    if setting.sweep and state.n_iter and state.n_clusters and setting.runs("outliers"):
        state.labels = _readmit_outliers(
            setting.a,
            setting.b,
            state.labels,
            state.models,
            state.static,
            setting.tau,
            state.noise_scale,
            state.outlier_share,
            setting.log_volume_density,
            setting.workers,
        )
    return pieces


def _fold_slow_pieces(setting, state):
    """The clean-up's pieces (:class:`Pieces`, what :func:`assign_to_pieces` judges
    further correspondences by); then the static world's slow pieces folded into it,
    as they are reported."""
    pieces = Pieces(
        setting.a,
        state.members,
        state.models.take(np.arange(state.n_clusters)),
        None,
        state.static,
    )
    state.root[np.isin(state.root, state.slow)] = state.static
    state.members = _through(state.root, state.labels)
    state.slow = np.empty(0, dtype=np.intp)
    return pieces


def assign_to_pieces(
    a, b, pieces, *, tau, log_outlier, noise_scale=None, false_alarms=None, workers=1
):
    """Correspondences that the loop did not fit, judged by the final clean-up's pieces.

    Each goes to its most likely piece among those whose fitted a-points lie within
    ``tau`` (the static world's everywhere), or -1 where the outlier component
    (``log_outlier``, :func:`reject_outliers`) explains it better, and is reported as
    the cluster its piece became.

    Returns
    -------
    labels : ndarray of shape (len(a),)
    """
    if pieces is None or not len(a):
        return np.full(len(a), -1, dtype=np.intp)
    n_pieces = len(pieces.models.sigmas)
    fitted = pieces.labels
    gate = ClusterGate(
        pieces.points,
        fitted,
        n_pieces,
        tau,
        ungated=[pieces.static] if pieces.static >= 0 else [],
        workers=workers,
    )
    judged = judge_correspondences(
        a,
        b,
        pieces.models.rotations,
        pieces.models.translations,
        pieces.models.sigmas,
        _weights(np.bincount(fitted[fitted >= 0], minlength=n_pieces), len(fitted)),
        gate,
        log_outlier,
        noise_scale,
        false_alarms=false_alarms,
    )
    return np.where(judged >= 0, np.append(pieces.reported, -1)[judged], -1)


def propose_in_the_rest(
    a,
    b,
    labels,
    pieces,
    reference,
    *,
    tau,
    log_outlier,
    noise_scale=None,
    min_cluster_size=4,
    sigma_floor=None,
    n_hypotheses=32,
    confidence=0.999,
    min_motion=0.05,
    moving,
    static=-1,
    motion_tolerance=None,
    sweep=True,
    random_state=None,
    max_rounds=4,
):
    """New clusters among the correspondences that a fit on a sample left unexplained.

    A fit on one correspondence per voxel sees a small object as a handful of rows, too
    few to outweigh the objects beside it in the proposals' groups; every row of it, once
    judged by the pieces (:func:`assign_to_pieces`), is an outlier. Here the proposals
    (:func:`propose_clusters`, the loop's step 9, with their a-contrario and BIC tests)
    look at all the outliers, round after round while they find something, each round
    holding the motions found before it to the test that a proposal brings a new one.
    A proposal is kept only with a body of its own (:func:`scattered_clusters`' rule,
    read against the nearest of all the a-points) and, with a static world
    (``reference``, its motion), moving ``min_motion`` beyond its scatter. One that
    touches a moving cluster is kept only where :func:`join_moving_pieces` gives it to
    one (with ``motion_tolerance``): a dense object that the sample thinned to a few
    rows, the loop's cluster holding those, and the rest of it here.

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
    labels : ndarray of shape (n,)
        The reported clusters, ``-1`` for outliers.
    pieces : Pieces
        The fit's pieces: a proposal must have a motion that none of them has.
    reference : tuple of (ndarray, ndarray) or None
        The static world's motion ``(R, t)``.
    moving : ndarray of bool of shape (n_clusters,)
        Which reported clusters move; a proposal that touches one of them is kept only
        where it is joined to one (``motion_tolerance``). New clusters are numbered from
        ``n_clusters`` on.
    static : int, default=-1
        The static world's reported cluster (-1: none).
    motion_tolerance : float or None, default=None
        A new cluster that touches a moving cluster whose motion agrees with its own
        within this fraction (:func:`join_moving_pieces`) is given to it; None: never.
    sweep : bool, default=True
        The proposals of the sweep variant (a noise scale of their own), or the robust
        default's (the smallest of the pieces').
    random_state : int, RandomState instance or None, default=None
        Seeds the proposals' samples.
    max_rounds : int, default=4

    Returns
    -------
    labels : ndarray of shape (n,)
        The new clusters numbered after the others, in the order found.
    n_new : int
    """
    n, d = a.shape
    unexplained = labels < 0
    if pieces is None or np.count_nonzero(unexplained) < min_cluster_size:
        return labels, 0
    if sigma_floor is None:
        sigma_floor = default_sigma_floor(b)
    rng = check_random_state(random_state)
    models = pieces.models
    scale = float(np.min(models.sigmas))
    log_volume_density = log_uniform_density(a, b)
    tree = None  # of all the a-points, once a proposal is to be judged
    moves = np.asarray(moving, dtype=bool)
    next_label = len(moves)
    labels = labels.copy()
    n_new = 0
    held = []  # bodies that touch a moving cluster: kept only where joined to one
    for _ in range(max_rounds):
        found = propose_clusters(
            a,
            b,
            unexplained,
            tau if tau is not None else np.inf,
            scale,
            log_outlier,
            n,
            rng,
            log_volume_density=log_volume_density,
            models=models,
            min_cluster_size=min_cluster_size,
            sigma_floor=sigma_floor,
            noise_scale=noise_scale,
            n_hypotheses=n_hypotheses,
            confidence=confidence,
            reference=reference,
            per_cluster=sweep,
        )
        if not found:
            break
        for group in found:
            unexplained[group] = False
        if reference is not None:
            slowly = moves_slowly(a, b, found, reference, sigma_floor, min_motion, noise_scale)
            found = list(compress(found, ~slowly))
        tree = lookup_tree(a) if tree is None else tree
        judged = [_has_a_body(tree, labels, moves, group) for group in found]
        bodies = [
            (group, touches) for group, (body, touches) in zip(found, judged, strict=True) if body
        ]
        if motion_tolerance:
            held += [group for group, touches in bodies if touches]
        found = [group for group, touches in bodies if not touches]
        if not found:
            continue
        rows = np.concatenate(found)
        own = np.repeat(np.arange(len(found)), [len(group) for group in found])
        fitted = fit_clusters(
            a[rows],
            b[rows],
            own,
            len(found),
            sigma_floor,
            None if noise_scale is None else noise_scale[rows],
        )
        models = _with(models, fitted)
        moves = np.append(moves, np.ones(len(found), dtype=bool))
        labels[rows] = next_label + own
        next_label += len(found)
        n_new += len(found)
    if held:
        labels = _join_held(a, b, labels, held, static, sigma_floor, motion_tolerance)
    if n_new and motion_tolerance:
        labels, n_new = _join_new_pieces(
            a, b, labels, next_label - n_new, static, sigma_floor, motion_tolerance
        )
    return labels, n_new


def _join_held(a, b, labels, held, static, sigma_floor, tolerance):
    """The held proposals (a body that touches a moving cluster) given to the cluster
    that :func:`join_moving_pieces` joins each to: the rest of an object that the
    sample saw as a handful of rows (a dense object thinned to a few voxels). One that
    joins none, or only other held ones, is flow bled from the object beside it, and
    stays unexplained."""
    n_clusters = int(labels.max()) + 1
    trial = labels.copy()
    for offset, group in enumerate(held):
        trial[group] = n_clusters + offset
    root, _ = _joined_roots(a, b, trial, static, sigma_floor, tolerance)
    labels = labels.copy()
    for offset, group in enumerate(held):
        target = root[n_clusters + offset]
        if target < n_clusters:
            labels[group] = target
    return labels


def _join_new_pieces(a, b, labels, first_new, static, sigma_floor, tolerance):
    """The new clusters that :func:`join_moving_pieces` joins to another cluster given
    to it (a part of a car whose flow bends, left out by the sample's fit); the
    clusters found before are left as they were."""
    n_clusters = int(labels.max()) + 1
    root, n_joined = _joined_roots(a, b, labels, static, sigma_floor, tolerance)
    if not n_joined:
        return labels, n_clusters - first_new
    target = np.arange(n_clusters)
    target[first_new:] = root[first_new:]
    kept = np.unique(target)
    renumber = np.full(n_clusters + 1, -1, dtype=np.intp)
    renumber[kept] = np.arange(len(kept))
    labels = np.where(labels >= 0, renumber[target[np.maximum(labels, 0)]], -1)
    return labels, len(kept) - first_new


def _joined_roots(a, b, labels, static, sigma_floor, tolerance):
    """:func:`join_moving_pieces` on the clusters of ``labels`` (numbered from 0, with
    none empty), fitted afresh: each cluster's root and the number of joins."""
    models = fit_clusters(a, b, labels, int(labels.max()) + 1, sigma_floor)
    root, _, n_joined = join_moving_pieces(
        a, labels, models, static, a.shape[1], sigma_floor, tolerance=tolerance
    )
    return root, n_joined


def _has_a_body(tree, labels, moves, group, k=16, thickness=3.0):
    """Whether ``group`` is a body of its own among all the points, and whether it
    touches a moving cluster, read off each member's ``k`` nearest points.

    A body is not scattered (more than half of its members strays,
    :func:`stray_members`) and not a layer along another cluster (more than half of its
    members with a point of a cluster in ``labels`` within ``thickness`` times the
    group's median spacing, :func:`boundary_layers`). Touching a moving cluster
    (``moves``, per cluster), whose sample the fit saw, it is either flow that bled
    from that object or the rest of it (:func:`_join_held` tells which).

    Returns
    -------
    body, touches : bool
    """
    k = min(k, tree.n)
    distance, nearest = tree.query(tree.data[group], k=k)
    inside = np.zeros(tree.n, dtype=bool)
    inside[group] = True
    listed = inside[nearest[:, 1:]].astype(np.intp)
    depth = np.full(len(group), min(k - 1, len(group) - 1))
    stray = stray_members(np.ones(len(group), dtype=np.intp), listed, depth)
    limit = thickness * np.median(distance[:, 1])
    around = (labels[nearest] >= 0) & ~inside[nearest] & (distance <= limit)
    near = np.count_nonzero(around.any(axis=1))
    touches = np.any(around & np.append(moves, False)[labels[nearest]])
    needed = (len(group) - 1) // 2 + 1
    return 2 * np.count_nonzero(stray) <= len(group) and near < needed, bool(touches)


def refit_clusters(
    a,
    b,
    labels,
    n_clusters,
    static,
    reference,
    *,
    sigma_floor=None,
    noise_scale=None,
    confidence=0.999,
    sweep=True,
    min_motion=0.05,
):
    """The trimmed M-step of the final clusters on correspondences labelled after the
    loop (:func:`assign_to_pieces`), and which of the clusters move.

    ``reference``: the static world's motion ``(R, t)`` (None without one), which bounds
    a moving cluster's noise scale as in the loop.

    Returns
    -------
    models : ClusterModels
    moving : ndarray of bool of shape (n_clusters,)
    """
    if sigma_floor is None:
        sigma_floor = default_sigma_floor(b)
    own_scales = sweep and static >= 0
    _, models = trimmed_fit(
        a,
        b,
        labels,
        n_clusters,
        sigma_floor,
        noise_scale,
        confidence=confidence,
        per_cluster=own_scales,
        max_noise_ratio=_MAX_NOISE_RATIO if sweep else None,
        reference=reference if own_scales else None,
    )
    return models, _moving(models, static, min_motion)


def _moving(models, static, min_motion):
    """Per cluster: does it move relative to the static world, beyond its own scatter
    (all of them when there is no static world)?"""
    n_clusters = len(models.sigmas)
    moving = np.ones(n_clusters, dtype=bool)
    if static >= 0:
        moving = motion_beyond_scatter(models, static, np.arange(n_clusters)) >= min_motion
        moving[static] = False
    return moving


def _readmit_outliers(
    a, b, labels, models, static, tau, noise_scale, outlier_share, log_volume_density, workers
):
    """The outliers that the final clusters explain, given back to them.

    The loop stops when few labels change, with its outliers judged by the last
    iteration's motions and noise; judged again by the final ones (the E-step of eq. (7)
    and the outlier test, as :meth:`predict` judges new correspondences), the tail of a
    cluster's noise that an early, smaller scale rejected comes back.
    """
    rows = np.flatnonzero(labels < 0)
    if not len(rows):
        return labels
    n_clusters = len(models.sigmas)
    weights = _weights(np.bincount(labels[labels >= 0], minlength=n_clusters), len(labels))
    gate = ClusterGate(
        a, labels, n_clusters, tau, ungated=[static] if static >= 0 else [], workers=workers
    )
    outlier_weight = min(max(outlier_share, 1.0 / len(labels)), _MAX_OUTLIER_WEIGHT)
    judged = judge_correspondences(
        a[rows],
        b[rows],
        models.rotations,
        models.translations,
        models.sigmas,
        weights,
        gate,
        np.log(outlier_weight) + log_volume_density,
        None if noise_scale is None else noise_scale[rows],
        false_alarms=_FALSE_ALARMS * len(rows) / len(labels),
    )
    labels = labels.copy()
    labels[rows] = judged
    return labels


def _gather_static_world(models, root, d, sigma_floor, share, min_motion, labels=None):
    """:func:`merge_static_world` on the clusters left by ``root``; composes the roots.

    ``share``: the static world's rule (:class:`StaticWorldRule`, or the majority share
    alone), None for no static world; ``labels``: each correspondence's cluster before
    ``root``, for the clusters' spread on the rule's points.

    Returns the static world's cluster (-1 if none), the models, the composed roots, the
    number of merges and the slow clusters (see :func:`merge_static_world`).
    """
    none = (-1, models, root, 0, np.empty(0, dtype=np.intp))
    if share is None:
        return none
    rule = share if isinstance(share, StaticWorldRule) else StaticWorldRule(share)
    survivors = np.flatnonzero(root == np.arange(len(root)))
    geometry = None
    if rule.points is not None and labels is not None:
        rows = np.flatnonzero(labels >= 0)
        points = rule.points[rows]
        geometry = group_moments(points, points, root[labels[rows]], len(root)).take(survivors)
    static, sub_root, sub_models, n_merges, slow = merge_static_world(
        models.take(survivors),
        d,
        sigma_floor,
        share=rule.share,
        min_motion=min_motion,
        ego_motion=rule.ego_motion,
        geometry=geometry,
    )
    if static < 0:
        return none
    models = models.take(np.arange(len(root)))
    models.put(survivors, sub_models)
    remap = np.arange(len(root))
    remap[survivors] = survivors[sub_root]
    return int(survivors[static]), models, remap[root], n_merges, survivors[slow]


def _unexplained(a, b, labels, static, models, noise_scale, confidence):
    """Outliers, and the static world's members beyond its inlier quantile.

    An object that moves slowly (a pedestrian, 0.1 m between sweeps) hides in the static
    world when its noise is a few centimetres: unlikely under the static motion, yet
    likelier than an outlier. Offered to the proposals, such members form a cluster of
    their own only if they share a motion that pays for itself.
    """
    unexplained = labels < 0
    if static < 0:
        return unexplained
    rows = np.flatnonzero(labels == static)
    sq = squared_residuals(
        a[rows],
        b[rows],
        np.zeros(len(rows), dtype=np.intp),
        models.rotations[static][None],
        models.translations[static][None],
    )
    if noise_scale is not None:
        sq /= noise_scale[rows] ** 2
    limit = chi2.ppf(confidence, a.shape[1]) * models.sigmas[static] ** 2
    unexplained[rows[sq > limit]] = True
    return unexplained


def _holds_its_members(cluster, before, after):
    """Whether ``cluster`` (-1: none) keeps at least half of its members from the labels
    ``before`` to ``after``."""
    if cluster < 0:
        return False
    return 2 * np.count_nonzero(after == cluster) >= np.count_nonzero(before == cluster)


def _position(kept, cluster):
    """Where ``cluster`` landed among the ``kept`` clusters (-1 if dropped or -1)."""
    if cluster < 0:
        return -1
    where = np.flatnonzero(kept == cluster)
    return int(where[0]) if len(where) else -1
