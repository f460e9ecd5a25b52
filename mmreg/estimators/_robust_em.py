"""The robust default: Algorithm 1 with an outlier model, merging and re-proposal around it.

The loop is the paper's (fit every cluster, drop the small ones, reassign each
correspondence to its most likely cluster within the gate); the named steps of
:mod:`mmreg.estimators._robust_steps` sit between its lines:

1. M-step on inliers (:func:`trimmed_fit`) instead of Horn on every member, each
   cluster with a robust noise scale of its own;
2. merging of adjacent clusters that share a motion (:func:`merge_adjacent`);
3. the static world (:func:`merge_static_world`): the dominant motion gathers every
   piece that moves with it, however far apart, into one cluster that the gate of eq. (7)
   admits everywhere;
4. dissolving layers of flow that bled along a boundary (:func:`boundary_layers`) and,
   in the sweep variant, clusters whose members lie scattered among other clusters'
   points (:func:`scattered_clusters`): neither has a body of its own (the static
   world and its slow pieces, which lie among its points, are never dissolved);
5. removal of small clusters (Algorithm 1, lines 10-13);
6. the E-step and classification of eq. (7) (:func:`assign_correspondences`), with each
   correspondence's noise scale ``sigma_j g_i`` growing with its range when the data say
   so (:func:`estimate_range_growth`);
7. the outlier component (:func:`reject_outliers`);
8. new clusters from what no cluster explains (:func:`propose_clusters`): this is also
   how a cluster holding two motions splits, since the trimmed M-step fits the majority
   and leaves the other motion's correspondences unexplained.

Each step but the E-step can be turned off (``skip_steps``, for ablations); with all of
them off the loop is Algorithm 1 with the static world's gate still in place.
"""

from dataclasses import dataclass, field
from itertools import compress

import numpy as np
from scipy.spatial import cKDTree
from scipy.stats import chi2
from sklearn.utils import check_random_state

from mmreg._gate import ClusterGate
from mmreg._geometry import row_medians
from mmreg._likelihood import morton_order, single_threaded_blas
from mmreg._neighbors import NeighbourTable, lookup_tree
from mmreg._relabelling import rows_moved
from mmreg.estimators._em import EMResult, _compact_initial, _size_rank, default_sigma_floor
from mmreg.estimators._mixed_clusters import split_mixed_clusters
from mmreg.estimators._robust_steps import (
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
    """The static world's cluster, -1 if no motion holds the majority."""
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
        clustered correspondences (:func:`merge_static_world`); None: no static world.
    min_motion : float, default=0.05
        A cluster moving less than this (RMS, in the units of the points) relative to the
        static world is part of it.
    motion_tolerance : float, default=0.2
        Touching moving clusters whose motions agree within this fraction of their motion
        are one object (:func:`join_moving_pieces`), unless their flows jump by more than
        ``min_motion`` where they touch; a moving cluster that holds two such objects is
        split (:func:`~mmreg.estimators._mixed_clusters.split_mixed_clusters`).
    tol : float, default=1e-3
        Converged when an iteration moves at most this fraction of the correspondences
        to another reported cluster (:func:`~mmreg._relabelling.rows_moved`: the
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
    unknown = set(skip_steps) - set(ROBUST_STEPS)
    if unknown:
        raise ValueError(f"Unknown steps {sorted(unknown)}; the steps are {ROBUST_STEPS}.")
    run = {step: step not in skip_steps for step in ROBUST_STEPS}
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    n, d = a.shape
    rng = check_random_state(random_state)
    if sigma_floor is None:
        sigma_floor = default_sigma_floor(b)
    confidence_trim = confidence if run["trimming"] else 1.0
    share = static_share if sweep and run["static_world"] else None
    join_pieces = joins_moving_pieces(sweep, skip_steps, motion_tolerance)
    max_outlier_weight = _MAX_OUTLIER_WEIGHT if sweep else 1.0
    labels, n_clusters = _compact_initial(init_labels)
    report_before = labels
    log_volume_density = log_uniform_density(a, b)
    order = morton_order(np.ascontiguousarray(a.T))
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
    history = []
    converged = False
    n_iter = 0
    outlier_share = None
    noise_scale = None
    growth = 0.0
    static = -1
    reference = None  # the static world's motion, once there is one
    # A noise scale of its own is bounded by a cluster's motion relative to the static
    # world (a network errs in proportion to it); without a static world nothing bounds
    # it, and a few wrong correspondences near each other pass for an object with a
    # large noise of its own: one shared scale then. The first iteration has not looked
    # for a static world yet.
    own_scales = sweep

    def layers_of(labels, n_clusters, world):
        # The static world's clusters (it and its slow pieces, which are reported with
        # it and lie among its points) are never layers.
        layers = boundary_layers(
            a,
            labels,
            n_clusters,
            spacing,
            exempt=world,
            neighbours=neighbours,
            ignore_strays=sweep,
        )
        if not sweep:
            return layers
        # With a noise scale of their own, a few scattered wrong flows can hold a motion.
        scattered = scattered_clusters(labels, n_clusters, neighbours, exempt=world)
        return np.union1d(layers, scattered)

    def fit(labels, n_clusters):
        return trimmed_fit(
            a,
            b,
            labels,
            n_clusters,
            sigma_floor,
            noise_scale,
            confidence=confidence_trim,
            per_cluster=own_scales,
            max_noise_ratio=_MAX_NOISE_RATIO if sweep else None,
            reference=reference,
        )

    with single_threaded_blas():
        for _ in range(max_iter):
            if n_clusters == 0:
                # Nothing left to fit, merge or assign to.
                converged = True
                break
            n_iter += 1
            # 0. Moving clusters that hold two touching objects whose flows jump between
            # them (an initial cluster spans up to tau, more than an object), once the
            # static world is known and left whole.
            if join_pieces and reference is not None:
                labels, n_clusters = split_mixed_clusters(
                    a,
                    b,
                    labels,
                    n_clusters,
                    sigma_floor,
                    min_jump=min_motion,
                    min_size=min_cluster_size,
                    noise_scale=noise_scale,
                    reference=reference,
                )
            # 1. M-step on inliers. The noise's growth with range comes from the last
            # iteration's clusters; the first estimates it from the initial ones.
            inliers, models = fit(labels, n_clusters)
            if run["range_noise"] and noise_model == "range" and n_iter == 1:
                growth, noise_scale = _range_noise(a, b, inliers, models, sigma_floor, sweep)
                if noise_scale is not None:
                    inliers, models = fit(labels, n_clusters)
            if outlier_share is None:
                outlier_share = np.mean(inliers < 0)
            # 2. Merge adjacent clusters that share a motion.
            root, n_merges = np.arange(n_clusters), 0
            if run["merging"]:
                pairs = adjacent_pairs(a, inliers, n_clusters, tau)
                root, models, n_merges = merge_adjacent(models, pairs, d, sigma_floor)
            # 3. The static world: every piece that moves with it, however far.
            static, models, root, n_static, slow = _gather_static_world(
                models, root, d, sigma_floor, share, min_motion
            )
            members = np.where(labels >= 0, root[np.maximum(labels, 0)], -1)
            # 4. Pieces of one moving object whose flow bends with the motion.
            n_joined = 0
            if join_pieces:
                joined, models, n_joined = join_moving_pieces(
                    a,
                    members,
                    models,
                    static,
                    d,
                    sigma_floor,
                    tolerance=motion_tolerance,
                    neighbours=neighbours,
                    workers=workers,
                    targets=b,
                    min_jump=min_motion,
                )
                members = np.where(members >= 0, joined[np.maximum(members, 0)], -1)
            # 5. Dissolve layers of flow that bled along another cluster's boundary.
            bled = []
            if run["boundary_layers"]:
                bled = layers_of(members, n_clusters, np.append(slow, static))
                members[np.isin(members, bled)] = -1
            # 6. Drop clusters below m_min (lines 10-13); merged-away ones have no members.
            counts = np.bincount(members[members >= 0], minlength=n_clusters)
            own, kept = drop_small_clusters(members, counts, min_cluster_size)
            static = _position(kept, static)
            models = models.take(kept)
            weights = _weights(counts[kept], n)
            # 7. E-step and classification of eq. (7), gated by tau but for the static world.
            gate = ClusterGate(
                a, own, len(kept), tau, ungated=[static] if static >= 0 else [], workers=workers
            )
            new = assign_correspondences(
                a,
                b,
                models.rotations,
                models.translations,
                models.sigmas,
                weights,
                gate,
                own,
                order,
                noise_scale,
            )
            # 8. The outlier component.
            outlier_weight = min(max(outlier_share, 1.0 / n), max_outlier_weight)
            log_outlier = np.log(outlier_weight) + log_volume_density
            if run["outliers"]:
                new = reject_outliers(
                    a,
                    b,
                    new,
                    models.rotations,
                    models.translations,
                    models.sigmas,
                    weights,
                    log_outlier,
                    noise_scale,
                )
            outlier_share = np.mean(new < 0)
            if static >= 0:
                reference = (models.rotations[static], models.translations[static])
            own_scales = sweep and static >= 0
            # 9. New clusters from the unexplained correspondences. Their hypotheses turn
            # like the static world, unless the E-step took most of its members from
            # it: then its motion was the mean of several (initial clusters that mix
            # motions, fitted by least squares) and would turn every hypothesis wrong.
            anchored = _holds_its_members(static, own, new)
            found = []
            if run["proposals"]:
                smallest = float(np.min(models.sigmas)) if len(kept) else sigma_floor
                found = propose_clusters(
                    a,
                    b,
                    _unexplained(a, b, new, static, models, noise_scale, confidence),
                    tau if tau is not None else np.inf,
                    smallest,
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
                    reference=reference if anchored else None,
                    per_cluster=sweep,
                    # Without scales of their own, the next M-step holds a proposal to
                    # the clusters' shared scale: it may take no wider one.
                    max_scale=None if own_scales else smallest,
                )
            for group in found:
                new[group] = len(kept)
                kept = np.append(kept, -1)
            # The slow clusters' positions among the kept ones (proposals are not).
            slow_kept = np.flatnonzero(np.isin(kept, slow))
            if run["boundary_layers"] and found:
                # A proposal along another cluster's boundary is bled flow too.
                layers = layers_of(new, len(kept), np.append(slow_kept, static))
                first_new = len(models.sigmas)
                found = [f for k, f in enumerate(found) if first_new + k not in layers]
                new[np.isin(new, layers[layers >= first_new])] = -1
            step = {
                "iteration": n_iter,
                # Clusters as reported (set below), and the pieces the loop keeps apart
                # (slow pieces of the static world, pieces the clean-up may join).
                "clusters": 0,
                "pieces": int(len(kept)),
                "merges": int(n_merges),
                "static_pieces": int(n_static),
                "joined": int(n_joined),
                "bled": len(bled),
                "dropped": int(np.count_nonzero((counts > 0) & (counts < min_cluster_size))),
                "outliers": int(np.count_nonzero(new < 0)),
                "proposed": len(found),
                "noise_growth": float(growth) if noise_scale is not None else 0.0,
            }
            history.append(step)
            if run["range_noise"] and noise_model == "range" and len(models.sigmas):
                growth, noise_scale = _range_noise(a, b, new, models, sigma_floor, sweep)
            # A change of the clusters reported, not of their numbers (compacting
            # renumbers them) nor inside the static world (slow pieces are reported
            # with it, and a network's flow moves points between them for ever).
            # Slow clusters are reported with the static world they belong to.
            report = np.where(np.isin(new, slow_kept), static, new) if static >= 0 else new
            if static >= 0 and found:
                # A slow proposal will be reported with the static world, as a slow
                # cluster; reported apart now, it would count as moved twice.
                slowly = moves_slowly(a, b, found, reference, sigma_floor, min_motion, noise_scale)
                if slowly.any():
                    report = report.copy()
                    report[np.concatenate(list(compress(found, slowly)))] = static
            step["clusters"] = int(np.count_nonzero(np.bincount(report[report >= 0])))
            n_changed = rows_moved(report_before, report)
            report_before = report
            new, n_clusters = _compact_initial(new)
            step["changed"] = n_changed
            if verbose:
                print(", ".join(f"{key} {value:g}" for key, value in step.items()))
            labels = new
            # Merges, proposals and joined pieces count by the correspondences they move.
            if n_changed <= tol * n:
                converged = True
                break
    # Final clean-up: one more merge, the static world gathered, no boundary layer and
    # no cluster below m_min; numbered by size. With max_iter=0 the initial clusters are
    # returned as given (the paper's contract).
    pieces = None
    if n_iter and n_clusters:
        inliers, models = fit(labels, n_clusters)
        root = np.arange(n_clusters)
        if run["merging"]:
            pairs = adjacent_pairs(a, inliers, n_clusters, tau)
            root, models, _ = merge_adjacent(models, pairs, d, sigma_floor)
        static, models, root, _, slow = _gather_static_world(
            models, root, d, sigma_floor, share, min_motion
        )
        pieces = Pieces(
            a,
            np.where(labels >= 0, root[np.maximum(labels, 0)], -1),
            models.take(np.arange(n_clusters)),
            None,
            static,
        )
        # Slow clusters are reported as the static world they belong to.
        root[np.isin(root, slow)] = static
        labels = np.where(labels >= 0, root[np.maximum(labels, 0)], -1)
        became = root.copy()  # what each piece became, through the steps below
        if join_pieces:
            joined, models, _ = join_moving_pieces(
                a,
                labels,
                models,
                static,
                d,
                sigma_floor,
                tolerance=motion_tolerance,
                neighbours=neighbours,
                workers=workers,
                targets=b,
                min_jump=min_motion,
            )
            labels = np.where(labels >= 0, joined[np.maximum(labels, 0)], -1)
            became = joined[became]
        if run["boundary_layers"]:
            bled = layers_of(labels, n_clusters, [static])
            labels = np.where(np.isin(labels, bled), -1, labels)
            became[np.isin(became, bled)] = -1
    counts = np.bincount(labels[labels >= 0], minlength=n_clusters)
    labels, kept = drop_small_clusters(labels, counts, min_cluster_size)
    static = _position(kept, static) if n_iter else -1
    rank = _size_rank(labels, len(kept))
    labels = rank[labels]
    if pieces is not None:
        pieces.reported = rank[drop_small_clusters(became, counts, min_cluster_size)[0]]
    n_clusters = len(kept)
    static = int(rank[static]) if static >= 0 else -1
    _, models = fit(labels, n_clusters)
    if sweep and n_iter and n_clusters and run["outliers"]:
        labels = _readmit_outliers(
            a,
            b,
            labels,
            models,
            static,
            tau,
            noise_scale,
            outlier_share,
            log_volume_density,
            workers,
        )
    moving = _moving(models, static, min_motion)
    weights = _weights(np.bincount(labels[labels >= 0], minlength=n_clusters), n)
    if verbose and n_iter:
        # After the clean-up: the clusters of the result, not the loop's pieces.
        print(f"result: clusters {n_clusters}")
    return RobustEMResult(
        labels,
        models.rotations,
        models.translations,
        models.sigmas,
        weights,
        n_iter,
        converged,
        history,
        float(np.log(max(np.mean(labels < 0), 1.0 / max(n, 1))) + log_volume_density),
        float(growth) if noise_scale is not None else 0.0,
        static,
        moving,
        pieces,
    )


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


def _gather_static_world(models, root, d, sigma_floor, share, min_motion):
    """:func:`merge_static_world` on the clusters left by ``root``; composes the roots.

    Returns the static world's cluster (-1 if none), the models, the composed roots, the
    number of merges and the slow clusters (see :func:`merge_static_world`).
    """
    none = (-1, models, root, 0, np.empty(0, dtype=np.intp))
    if share is None:
        return none
    survivors = np.flatnonzero(root == np.arange(len(root)))
    static, sub_root, sub_models, n_merges, slow = merge_static_world(
        models.take(survivors), d, sigma_floor, share=share, min_motion=min_motion
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
