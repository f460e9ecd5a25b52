"""Two sweeps in, objects and scene flow out: motions refined on the second sweep.

:class:`SweepRegistration` wraps a multi-model estimator. Given correspondences and the
second sweep as its own points, the estimator's clusters are kept and each cluster's
motion is refined by robust point-to-plane ICP on the second sweep (:mod:`mmreg.sweeps._icp`),
so a scene-flow network's bias (a systematic error that a rigid fit keeps) is removed.
Given the first sweep alone, putative correspondences are made first: the ego motion by
GICP from the identity, coarse to fine (:mod:`mmreg.sweeps._ego_motion`), then every spatial
island of the first sweep is aligned to the second from the ego motion and from the
peaks of a histogram of translations to nearby points of the second sweep (as ICP-Flow
does), and the estimator groups the islands' motions into the static world and the
moving objects. Given the points' capture times,
the moving clusters are deskewed in the ICP (:mod:`mmreg.sweeps._deskew`).
"""

import copy
import functools
import importlib.util
from numbers import Integral, Real
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree
from sklearn.base import BaseEstimator, ClusterMixin, _fit_context, clone
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import HasMethods, Interval, StrOptions
from sklearn.utils.validation import validate_data

from mmreg._array.flow import rigid_flow
from mmreg._array.geometry import climb, departures
from mmreg._array.grouping import group_bounds, group_centroids
from mmreg._array.motion import _group_median, moving_clusters, static_cluster
from mmreg._array.neighbors import query_workers
from mmreg._array.point_memo import PointMemo
from mmreg._validation import check_coordinate_range, check_ego_motion, invalid_rows
from mmreg.sweeps._ambiguous_shapes import ACROSS, is_line, slides_in_plane
from mmreg.sweeps._deskew import deskew, relative_motions
from mmreg.sweeps._ego_body import confirm_body, fixed_candidates
from mmreg.sweeps._ego_motion import _FINE_REACH as _EGO_FINE_REACH
from mmreg.sweeps._ego_motion import _RESIDUAL_POINTS as _EGO_RESIDUAL_POINTS
from mmreg.sweeps._ego_motion import _residual_scale, ego_motion
from mmreg.sweeps._explained import EXPLAINED_SPACINGS, spacing_ratio
from mmreg.sweeps._ground import METRE_TAU, ground_mask, has_ground, is_z_up_sweep
from mmreg.sweeps._icp import SurfaceNormals, multi_body_icp, subsample_groups
from mmreg.sweeps._island_motions import (
    choose_island_motions,
    driven_through,
    ego_fit,
    facing_away,
    translation_starts,
)
from mmreg.sweeps._islands import voxel_islands
from mmreg.sweeps._motion_bounds import bound_motions
from mmreg.sweeps._new_places import MIN_NEW_PLACE, new_place_shares
from mmreg.sweeps._slow_movers import beyond_spacing, slow_movers

__all__ = ["SweepRegistration"]

# Fewest points of the second sweep: the normals need neighbourhoods.
_MIN_SWEEP_POINTS = 10
# Raw mode: points per island in the ICP of its hypotheses, and the translation
# histogram's bins (in units of max_distance).
_HYPOTHESIS_POINTS = 128
# Raw mode: Gauss-Newton steps of the hypotheses' ICP (the chosen motions are refined
# again after the estimator, on up to max_points points).
_HYPOTHESIS_ITER = 15
# ICP has converged when no step moves a cluster by more than this share of max_distance.
_TOL = 1e-4
_BIN = 0.25
# The lengths of "auto" in units of the estimator's tau (LiDAR in metres: tau = 5).
_LENGTHS_PER_TAU = {"max_distance": 0.2, "island_radius": 0.1, "max_displacement": 0.6}
# Raw mode: a cluster whose motion moves its points off their own surfaces (relative to
# the static world) by fewer than this many of the ego ICP's robust residual scales only
# slides along them (see _join_slides).
_SLIDE_SCALES = 3.0
# Raw mode: a moving island is refused when the ego motion explains at least this share
# of a part of it and its own motion this share of the part's points fewer (a pole that
# a walker's motion takes along: 0.85 and 0.83-0.86 fewer; a sparse walker's rings, of
# fewer points than the parts asked for, 1.0 and 0.17-0.5 fewer).
_TORN_EXPLAINED = 0.5
_TORN_LOSS = 0.2
# Raw mode: the ego ICP's motion replaces GICP's when its robust residual scale is below
# this share of GICP's (see SweepRegistration._ego_motion). Measured ratios: 0.89-1.02
# on real and ray-cast sweeps (GICP the more accurate), 0.47-0.52 on sparse resampled
# boxes of which 40 % move, 0.0005-0.002 on noiseless boxes and walker scenes.
_EGO_EXACT_SHARE = 0.75
# Raw mode: "auto" max_displacement is at least this many times the ego motion's step.
_TRAFFIC_PER_EGO = 1.5
# Raw mode, "auto" max_displacement: how many times islands that nothing within the reach
# explains search again, each time twice as far.
_WIDENINGS = 1
# Raw mode, z-up LiDAR sweeps: the steepest climb (rise over run, relative to the static
# world) of an island's motion: roads climb 1 in 10 or less, very few over 1 in 5.
_MAX_GRADE = 0.25
# Raw mode: the searches on weaker evidence (slow movers, a motion of a spacing or two;
# the wider reach, eight times the volume to match by chance) take islands of this many
# times min_island_size (30 points at the default).
_WEAK_EVIDENCE_SIZES = 2.5
# Raw mode, the ego vehicle's body (mmreg.sweeps._ego_body), in units of tau: candidates lie
# within _BODY_REACH of the sensor (3 m at tau 5; nuScenes' body returns lie within
# 2.5 m) and match the other sweep within _BODY_MATCH (5 cm) at the same coordinates;
# fewer than _MIN_BODY_POINTS confirmed points are no body.
_BODY_REACH = 0.6
_BODY_MATCH = 0.01
_MIN_BODY_POINTS = 10
# With capture times: rounds of deskewing (with the last round's motions) and ICP.
_DESKEW_ROUNDS = 2


def _has_small_gicp():
    """Whether small_gicp (the ego motion's GICP) is installed."""
    return importlib.util.find_spec("small_gicp") is not None


def _group_sums_3(values, groups, n_groups):
    """Sums of the rows of ``values`` (n, 3) within each group."""
    return np.stack(
        [np.bincount(groups, weights=values[:, i], minlength=n_groups) for i in range(3)], axis=1
    )


def _in_boxes(points, low, high):
    """Whether each point lies in any of the axis-aligned boxes ``[low_k, high_k]``."""
    inside = (points[:, None, :] >= low) & (points[:, None, :] <= high)
    return inside.all(axis=2).any(axis=1)


def _check_times(times, n, name):
    """Capture times as a finite (n,) float array; a clear ValueError otherwise."""
    times = np.asarray(times)
    if times.dtype.kind not in "iuf":
        raise TypeError(f"{name} must hold numbers (seconds); got dtype {times.dtype}.")
    times = times.astype(np.float64)
    if times.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), one time per point; got {times.shape}.")
    if not np.all(np.isfinite(times)):
        raise ValueError(f"{name} contains NaN or infinity.")
    return times


def _check_interval(interval):
    """``interval`` as a finite float > 0 (seconds); a clear error otherwise."""
    if isinstance(interval, bool) or not isinstance(interval, (Real, np.number)):
        raise TypeError(f"interval must be a number of seconds; got {type(interval).__name__}.")
    interval = float(interval)
    if not np.isfinite(interval) or interval <= 0:
        raise ValueError(f"interval must be a finite number of seconds > 0; got {interval}.")
    return interval


def _check_timing(times, sweep_times, interval, n, m):
    """``(times, sweep_times, interval)`` checked, or None when no capture time is given
    (``interval`` alone bounds the motions, see :mod:`mmreg.sweeps._motion_bounds`)."""
    if times is None and sweep_times is None:
        if interval is not None:
            _check_interval(interval)
        return None
    if times is None or sweep_times is None or interval is None:
        raise ValueError(
            "times, sweep_times and interval go together: the capture time of every point "
            "of both sweeps (seconds from each sweep's reference time) and the seconds "
            "between the two reference times; got only "
            + ", ".join(
                k
                for k, v in (("times", times), ("sweep_times", sweep_times), ("interval", interval))
                if v is not None
            )
            + "."
        )
    interval = _check_interval(interval)
    return _check_times(times, n, "times"), _check_times(sweep_times, m, "sweep_times"), interval


def _join_slides(a, labels, motions, static, sigma, target, reach, whole=None):
    """The static world takes back every cluster that only slides along its own surfaces.

    A planar patch (a wall, a kerb, a strip of road) constrains only motion along its
    normals: an ICP slides it along itself at no cost, and the slide reads as motion.
    What shows that a cluster moved is how far its motion carries its points off their
    own surfaces relative to the static world's motion: the RMS, over its points, of the
    displacement ``M_k a - E a`` along each point's normal (PCA of its 10 nearest
    points of the first sweep). Below 3 robust residual scales of the ego-motion ICP
    (``sigma``, the same point-to-plane residual) the data cannot tell the cluster from
    the static world: it joins it, with the static world's motion. So does a cluster
    whose motion moves its points (median) by less than half the second sweep's sampling
    spacing where they land (``target``: the second sweep, its cKDTree and its
    SurfaceNormals): no sweep can show such a motion, whatever the noise. And so does
    a cluster that its motion shows at a new place with fewer than a tenth of its
    points (:mod:`mmreg.sweeps._new_places`) while moving along its own surfaces
    (normal component under half the displacement): a wall slid up or down along itself
    lands on surfaces the first sweep held already. And so does a line of points (a
    pole, a ring of road), whatever it shows.

    ``motions`` is ``(rotations, translations, ...)``, per-cluster arrays; ``reach``:
    the ICP's gate with capture times, else None; ``whole``:
    both sweeps with their ground, for the new places (see
    :func:`mmreg.sweeps._new_places.new_place_shares`); returns the labels, the same
    arrays without the joined clusters, and the static world's new index.
    """
    rotations, translations = motions[:2]
    others = np.flatnonzero((labels >= 0) & (labels != static))
    if not len(others):
        return labels, motions, static
    tree = cKDTree(a)
    normals, _, _ = SurfaceNormals(a, tree, 10)(others)
    group = labels[others]
    points = a[others]
    moved = np.einsum("nij,nj->ni", rotations[group], points) + translations[group]
    displacement = moved - (points @ rotations[static].T + translations[static])
    along = np.einsum("ni,ni->n", np.nan_to_num(normals), displacement)
    n_clusters = len(rotations)
    counts = np.maximum(np.bincount(group, minlength=n_clusters), 1)
    evidence = np.sqrt(np.bincount(group, weights=along**2, minlength=n_clusters) / counts)
    sweep, tree, sweep_normals = target
    _, _, spacing = spacing_ratio(moved, tree, sweep, sweep_normals)
    departure = _group_median(np.linalg.norm(displacement, axis=1), group, n_clusters)
    unseen = departure < 0.5 * _group_median(spacing, group, n_clusters)
    # A cluster whose motion shows none of it at a new place slid onto static surfaces.
    shares = new_place_shares(
        a, labels, motions[:2], static, sigma, target, reach=reach, whole=whole
    )
    # Only where its surfaces' normals lie across the motion (a wall, a building's
    # corner slid along itself): a car seen from behind that drives on by less than its
    # length lands within its old footprint too (its rear face among its old roof and
    # sides), but moves across its rear face.
    squared = np.einsum("ni,ni->n", displacement, displacement)
    length = np.sqrt(np.bincount(group, weights=squared, minlength=n_clusters) / counts)
    nowhere = (shares < MIN_NEW_PLACE) & (evidence < ACROSS * length)
    # A line of points (a pole, a ring of road) slides along itself and onto any other.
    line = is_line(points, group, n_clusters)
    slides = np.bincount(group, minlength=n_clusters) > 0
    # Sliding along itself shows nothing where the slide lands on places the first sweep
    # held already; a walker crossing the view slides its face along itself too, but
    # arrives where the first sweep saw through.
    slid = (evidence < _SLIDE_SCALES * sigma) & (shares < MIN_NEW_PLACE)
    slides &= slid | unseen | nowhere | line
    if not slides.any():
        return labels, motions, static
    kept = ~slides
    index = np.cumsum(kept) - 1
    labels = np.where(labels >= 0, labels, -1)
    labels = np.where(slides[np.maximum(labels, 0)] & (labels >= 0), static, labels)
    labels = np.where(labels >= 0, index[np.maximum(labels, 0)], -1)
    return labels, tuple(values[kept] for values in motions), int(index[static])


class _IslandSearch(NamedTuple):
    """What every search for the islands' motions shares (see ``_island_hypotheses``)."""

    a: np.ndarray  # the first sweep
    sweep: np.ndarray  # the second sweep
    islands2: np.ndarray  # the second sweep's islands
    n_islands2: int
    context: tuple  # (sweep, its tree, its SurfaceNormals, random state, capture times)
    ego: tuple  # (R, t) at which the islands are tested
    sigma: float  # the ego ICP's robust residual scale
    at_rest: np.ndarray  # the first sweep where the ego motion puts it
    resting: cKDTree  # of at_rest[inside]
    inside: np.ndarray  # the first sweep's points that lie on an island
    rest_normals: SurfaceNormals | None  # of at_rest[inside]; None unless z-up sweeps


def _torn_islands(a, islands, n_islands, moving, motions, at_rest, target, cell, min_size):
    """Moving islands that hold a part their motion explains clearly worse than the ego
    motion does.

    A part is an island of voxels of side ``cell`` of at least ``min_size`` points
    within a moving island; ``at_rest``: ``a`` moved by the ego motion. A point is
    explained within 2 of the second sweep's sampling spacings of a point of it (the
    slow movers' rule). Torn: the ego motion
    explains at least half of a part's points, and the island's motion a fifth of the
    part's points fewer. A point-to-plane cost, which chose the motion, cannot see it:
    a thin pole moved half a metre keeps points near some plane.
    """
    rows = np.flatnonzero((islands >= 0) & moving[np.maximum(islands, 0)])
    torn = np.zeros(n_islands, dtype=bool)
    parts, n_parts = voxel_islands(a[rows], cell, 1)
    if n_parts < 2:
        return torn
    owner = islands[rows]
    sweep, tree, normals = target
    rotations, translations = motions
    own = np.einsum("nij,nj->ni", rotations[owner], a[rows]) + translations[owner]
    sizes = np.bincount(parts, minlength=n_parts)
    shares = [
        np.bincount(
            parts,
            weights=spacing_ratio(moved, tree, sweep, normals)[0] <= EXPLAINED_SPACINGS,
            minlength=n_parts,
        )
        / np.maximum(sizes, 1)
        for moved in (at_rest[rows], own)
    ]
    worse = (
        (sizes >= min_size) & (shares[0] >= _TORN_EXPLAINED) & (shares[1] < shares[0] - _TORN_LOSS)
    )
    part_owner = np.zeros(n_parts, dtype=np.intp)
    part_owner[parts] = owner
    torn[part_owner[worse]] = True
    return torn


def _check_features(X):
    """X as (n, 6) correspondences or (n, 3) points; a clear ValueError otherwise."""
    if X.shape[1] not in (3, 6):
        raise ValueError(
            "X must be (n, 6) correspondences [a | b] or (n, 3) points of the first "
            f"sweep; got X with n_features = {X.shape[1]}."
        )


def _check_mask(mask, n, name):
    """A boolean mask of n points; a clear ValueError otherwise."""
    mask = np.asarray(mask)
    if mask.dtype != bool:
        raise TypeError(f"{name} must be a boolean mask (one bool per point); got {mask.dtype}.")
    if mask.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), one bool per point; got {mask.shape}.")
    return mask


def _check_sweep(sweep, d):
    """The second sweep as a finite (m, d) float array; a clear ValueError otherwise."""
    if sweep is None:
        raise ValueError(
            "sweep is required with (n, 3) points: pass the second sweep's points, "
            "fit(X, sweep=points2)."
        )
    sweep = np.asarray(sweep)
    if sweep.dtype.kind not in "iuf":
        raise TypeError(f"sweep must hold numbers; got dtype {sweep.dtype}.")
    sweep = sweep.astype(np.float64)
    if sweep.ndim != 2 or sweep.shape[1] != d:
        raise ValueError(f"sweep must have shape (m, {d}); got {sweep.shape}.")
    if len(sweep) < _MIN_SWEEP_POINTS:
        raise ValueError(
            f"sweep has {len(sweep)} points; at least {_MIN_SWEEP_POINTS} are needed "
            "(the normals of its surface need neighbourhoods)."
        )
    if not np.all(np.isfinite(sweep)):
        raise ValueError("sweep contains NaN or infinity.")
    check_coordinate_range(sweep, name="sweep")
    return sweep


class SweepRegistration(ClusterMixin, BaseEstimator):
    """Multi-model registration of two sweeps: motions refined on the second sweep.

    Two ways in, one way out:

    * **refinement** -- ``X`` of shape ``(n, 6)``: correspondences ``[a | b]`` (e.g. the
      first sweep and a scene-flow network's ``a + flow``) and ``sweep``, the second sweep
      as its own points (any size, any order). ``estimator`` finds the clusters; the
      motion of each is then refined by aligning its a-points to ``sweep`` with robust
      point-to-plane ICP (Tukey's biweight, the cluster's own residual scale), all
      clusters at once, starting from the cluster's motion.
    * **raw** -- ``X`` of shape ``(n, 3)``: the first sweep alone. The ego motion is found
      from the identity (or the ``ego_motion`` given to ``fit``) by GICP, coarse to fine
      (:mod:`mmreg.sweeps._ego_motion`, any step up to ``max(tau, max_displacement)``), and
      polished by ICP on the raw points where that clearly fits better. Both sweeps are
      cut into islands (voxels of side ``island_radius`` that touch,
      :mod:`mmreg.sweeps._islands`); every island of the first is aligned to ``sweep`` from
      the ego motion, from the offsets of its centroid to those of nearby islands of the
      second, and from the peaks of a histogram of translations towards the second
      sweep's points within ``max_displacement`` (as ICP-Flow does).
      An island keeps the ego motion unless its best alternative wins by a clear margin
      (robust point-to-plane likelihood gain over a BIC price, a tenth more of its points
      explained and more than its six parameters, and mmreg's moving rule;
      :mod:`mmreg.sweeps._island_motions`). Faces the second sensor cannot see where
      the ego motion puts them (it drove past their plane, not through them) are no
      sign of motion, nor is a climb steeper than 1 in 4 (a sparse sensor's rings slid
      onto each other); z-up sweeps are taken as a sensor writes them, each sensor at
      its sweep's origin. Small objects
      that move a few sampling spacings (a pedestrian beside a wall) stay within that
      margin; they are found point by point among the islands that keep the ego
      motion (the points the ego motion leaves far from the second sweep or off its
      surfaces, aligned by ICP; kept when they land where the first sweep explains
      nothing;
      :mod:`mmreg.sweeps._slow_movers`) and become islands of their own. The islands'
      motions become putative correspondences for ``estimator``; the static world keeps
      the ego motion and the other clusters are refined as above (with ``max_rounds``
      above 1, this repeats while the labels change: a multi-body ICP around the EM).
      A cluster that only slides along its own surfaces, or that its motion shows at a
      new place with under a tenth of its points (:mod:`mmreg.sweeps._new_places`),
      then rejoins the static world. A cluster whose motion relative to the static world
      no vehicle or person can make (:mod:`mmreg.sweeps._motion_bounds`: faster than
      50 m/s or turning faster than 90 deg/s, 360 for one of a person's size, when
      ``interval`` is known, else farther than ``max_displacement``; a level sheet
      sliding along itself) is taken apart: its points rejoin
      the static world where its motion explains them, and are outliers elsewhere.

    Parameters
    ----------
    estimator : estimator or None, default=None
        The multi-model estimator (fitted on clones). None:
        ``MultiModelRegistration(variant="sweep", tau=5.0)``, the variant for real LiDAR.
        Its ``n_jobs``, if it has one, also sets the threads of the ICPs' k-d tree
        queries (the same answers; None: one thread).
    refine : {"moving", "all"}, default="moving"
        Which clusters' motions are refined in refinement mode. ``"moving"`` keeps the
        static world's motion from the correspondences: a network's flow on the static
        world is as good as the ego pose it was computed with, and on real sweeps ICP
        moves it by 1-2 cm (different scan lines, occlusions). Raw mode refines all.
    max_icp_iter : int, default=30
        Gauss-Newton steps of every ICP.
    max_distance : float or "auto", default="auto"
        A point is matched to the second sweep only within this distance (units of the
        points). ``"auto"``: a fifth of the estimator's ``tau`` (1 m for LiDAR in metres
        with ``tau=5``). Like every length here, it scales with ``tau``: nothing assumes
        metres.
    max_points : int or None, default=5000
        Points per cluster used by the ICP (chosen at random); None: all.
    island_radius : float or "auto", default="auto"
        Raw mode: side of the voxels whose touching sets are the sweeps' islands (points
        within this distance always share an island). ``"auto"``: a tenth of ``tau``.
    min_island_size : int, default=12
        Raw mode: smaller islands take the ego motion. 12 is the fewest matched points
        with which the ICP moves a cluster (6 unknowns and a margin): a pedestrian 20 m
        from a 32-beam sensor returns 15-30 points.
    max_displacement : float or "auto", default="auto"
        Raw mode: largest motion of an object relative to the static world, between the
        sweeps. ``"auto"``: ``0.6 tau`` (3 m with ``tau=5``: 30 m/s at 10 Hz), or 1.5
        times the length of the ego motion's translation where that is more (other
        traffic moves about as fast as the sensor: 7.5 m for 2 Hz keyframes at 36 km/h).
        Being a guess, ``"auto"`` is widened where the data ask: islands that neither
        the ego motion nor any motion within it explains search again twice as far
        (a slow ego car 0.5 s apart from a car 5 m on). A number is a bound.
    max_rounds : int, default=1
        Raw mode: most rounds of estimator and ICP (further rounds run while the labels
        change). One: a second round, fed by the refined motions, found the same
        objects on every real and generated pair we hold, and cost a sixth of the fit.
    raw_init : {"islands", "estimator"}, default="islands"
        Raw mode: the estimator's initial clusters. ``"islands"``: the islands (the first
        round, slow movers included) or the last round's clusters, whose motions made
        its correspondences (set as the ``init`` of the estimator's clone, when it has
        one); the same clusters as a Euclidean clustering on the shared Argoverse 2
        pairs in half the time, and the only way for the slow movers, which share
        islands with the static world, to start apart. ``"estimator"``: its own ``init``.
    ground : {"auto", "keep", "drop"}, default="auto"
        Raw mode: what to do with the ground of the sweeps. ``"auto"``: when the first
        sweep is z-up (it spreads far wider than it is tall, see
        :func:`mmreg.sweeps._ground.is_z_up_sweep`), the ground of both sweeps is found
        (Patchwork++, in the units of the estimator's ``tau``; or the masks given to
        ``fit``) and given to the static world: the ego-motion ICP uses it (it holds roll,
        pitch and height), the islands, hypotheses and object ICPs leave it out (a patch
        of road slides along itself and would look like a moving object), and its points
        take the static world's label and motion. A sweep whose ground was removed
        before, or a scene without one, is registered as it is (the ground found must
        hold 6 % of the points and surround the sensor, see
        :func:`mmreg.sweeps._ground.has_ground`). ``"drop"``: found the same way, the ground
        is left out: its points are labelled -1 and take the static world's flow.
        ``"keep"``: the ground is registered like every other point.
    random_state : int, RandomState instance or None, default=None
        Seeds the subsampling and an ``estimator`` whose ``random_state`` is None.

    Attributes
    ----------
    labels_ : ndarray of shape (n_samples,)
        Cluster of every point of the first sweep, ``-1`` for outliers.
    rotations_ : ndarray of shape (n_clusters_, 3, 3)
    translations_ : ndarray of shape (n_clusters_, 3)
        Motion of every cluster: the first sweep's point ``a`` of cluster ``j`` lies at
        ``rotations_[j] @ a + translations_[j]`` in the second.
    n_clusters_ : int
    static_cluster_ : int
        The static world's cluster, -1 if none.
    moving_ : ndarray of shape (n_clusters_,)
        Whether each cluster moves relative to the static world.
    flow_ : ndarray of shape (n_samples, 3)
        Scene flow of every point of the first sweep; an outlier moves with the cluster
        of its nearest clustered point.
    sigmas_ : ndarray of shape (n_clusters_,)
        The estimator's noise scale of each cluster's correspondences.
    outlier_mask_ : ndarray of shape (n_samples,)
        True where ``labels_`` is -1.
    n_iter_ : int
        EM iterations of the estimator (last round).
    converged_ : bool
        Whether the estimator settled (last round).
    icp_scales_ : ndarray of shape (n_clusters_,)
        Robust point-to-plane residual scale of each cluster on the second sweep (NaN for
        clusters not refined).
    estimator_ : estimator
        The fitted ``estimator`` (last round).
    ego_motion_ : tuple of ndarray
        Raw mode: ``(R, t)`` of the ego-motion ICP.
    max_distance_, island_radius_, max_displacement_ : float
        The lengths used: the parameters, or what ``"auto"`` made of them.
    n_invalid_, n_sweep_invalid_ : int
        Rows of ``X`` and points of ``sweep`` that hold no measurement (NaN, or the
        origin where a LiDAR driver writes its failed returns, when more than one point
        lies there): left out of the fit; in ``X`` they are labelled -1 with a NaN flow.
    n_ego_body_ : int
        Raw mode: points of the first sweep taken for returns from the ego vehicle's own
        body (near the sensor and fixed in its frame while the ego motion carries the
        world away; :mod:`mmreg.sweeps._ego_body`): left out of the fit, labelled -1, with a
        zero flow (they stay where they were in the sensor's frame). Always 0 without
        small_gicp, whose ego motion tells them apart.
    ego_body_mask_ : ndarray of shape (n_samples,), bool
        Which points those are.
    sweep_ego_body_mask_ : ndarray of shape (m,), bool
        Raw mode: the same for the points of ``sweep`` (empty without ``sweep``).
    ego_scale_ : float
        Raw mode: the robust point-to-plane residual scale of the ego-motion ICP (the
        noise the islands' tests read residuals in); NaN otherwise.
    interval_ : float or None
        The ``interval`` given to ``fit`` (seconds between the sweeps), or None.
    impossible_motions_ : list of str
        Raw mode: the clusters taken apart because no road user moves so, one reason
        each: ``"speed"``, ``"turn"`` (with ``interval_``), ``"reach"`` (without) or
        ``"sheet"`` (see :mod:`mmreg.sweeps._motion_bounds`).
    ground_mask_ : ndarray of shape (n_samples,) or None
        Raw mode: which points of the first sweep were taken for the ground (all in the
        static world); None when the ground was kept.
    sweep_ground_mask_ : ndarray of shape (m,) or None
        The same for the second sweep.
    n_rounds_ : int
        Rounds of estimator and ICP run (1 in refinement mode).
    n_features_in_ : int
        6 (refinement) or 3 (raw).

    See Also
    --------
    mmreg.MultiModelRegistration : The estimator used by default.

    Notes
    -----
    The refined motion of a cluster minimises ``sum_i rho(n_i . (R a_i + t - q_i) / s)``
    over its points ``a_i``, ``q_i`` the nearest point of the second sweep and ``n_i`` its
    normal (PCA of its 10 nearest neighbours; points whose neighbourhood is one scan
    line are left out). One KD-tree over the second sweep serves every cluster and
    iteration, and the 6x6 normal equations of all clusters are solved as one stack.
    Clusters keep their labels: the refinement changes motions, not membership.

    **Capture times** (``times``, ``sweep_times``, ``interval``). A spinning LiDAR takes a
    sweep's points over its whole period (Argoverse 2: two heads, 0-106 ms, each object
    seen by them about 50 ms apart). Sweeps come compensated for the ego motion, so the
    static world is where it was at the sweep's reference time, but a moving object is
    where it was when each point was taken: a car moving 8 m/s relative to the world is
    two copies 0.4 m apart within one sweep, and no single rigid motion aligns both
    copies with the other sweep's. With the times, the ICP of every cluster but the
    static world runs in rounds: the cluster's motion relative to the static world
    (``E^-1 M_k``, or ``M_k`` when no cluster is static) gives its velocity over
    ``interval``; its a-points, and the second sweep's points nearer to its moved points
    than to any other cluster's, are moved back to their sweep's reference time by
    ``tau / interval`` of that displacement (``tau`` each point's capture time); the ICP
    aligns the deskewed sets, starting from the last motion. Two rounds in refinement
    mode; in raw mode one per round of estimator and ICP, which deskews with the last
    round's motions (a second one per round changed the moving EPE of
    ``av2_api_7fab2350`` by 2 mm and took 0.3 s). The static world
    is not deskewed, and is refined (``refine="all"``) or kept as without times.

    The deskewing follows the cluster's centroid and does not turn the points: over one
    sweep, vehicles turn by a fraction of a degree (0.12-0.13 deg relative to the world
    for the four moving objects found in the Argoverse 2 pair ``av2_api_7fab2350``),
    while the rotation fitted to a partial view of a car is off by 0.4-5 deg, and turning
    the deskewed copies by a share of it fed that error back (on that pair, with two
    deskewing rounds per round and three seeds: moving EPE 0.093-0.097 m with the turn,
    0.087-0.088 m without).

    The motions found are those between the two reference times, and ``flow_`` is ``R_k
    a + t_k - a`` for every point ``a`` as captured, the convention of the Argoverse 2
    ground truth (each point moved by its cuboid's motion between the two sweeps'
    timestamps, whatever its capture time). For a body moving at constant velocity it is
    also where the surface point is one ``interval`` after it was captured.

    Examples
    --------
    A box moved by (0.3, 0.1, 0) and sampled again; the correspondences carry a 10% bias.

    >>> import numpy as np
    >>> from mmreg import MultiModelRegistration, SweepRegistration
    >>> rng = np.random.default_rng(0)
    >>> def box(n):
    ...     p = rng.uniform(-1, 1, (n, 3))
    ...     p[np.arange(n), rng.integers(0, 3, n)] = rng.choice([-1.0, 1.0], n)
    ...     return p
    >>> a, sweep = box(2000), box(8000) + [0.3, 0.1, 0.0]
    >>> X = np.hstack([a, a + [0.27, 0.09, 0.0]])
    >>> em = MultiModelRegistration(tau=1.0)  # a gate for a 2 m box, not a street
    >>> est = SweepRegistration(em, refine="all", max_distance=0.5, random_state=0)
    >>> est = est.fit(X, sweep=sweep)
    >>> est.n_clusters_, np.round(est.translations_[0], 3) + 0.0
    (1, array([0.3, 0.1, 0. ]))
    """

    _parameter_constraints: dict = {
        "estimator": [HasMethods(["fit"]), None],
        "refine": [StrOptions({"moving", "all"})],
        "max_icp_iter": [Interval(Integral, 0, None, closed="left")],
        "max_distance": [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"})],
        "max_points": [Interval(Integral, 6, None, closed="left"), None],
        "island_radius": [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"})],
        "min_island_size": [Interval(Integral, 1, None, closed="left")],
        "max_displacement": [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"})],
        "max_rounds": [Interval(Integral, 1, None, closed="left")],
        "raw_init": [StrOptions({"islands", "estimator"})],
        "ground": [StrOptions({"auto", "keep", "drop"})],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        estimator=None,
        *,
        refine="moving",
        max_icp_iter=30,
        max_distance="auto",
        max_points=5000,
        island_radius="auto",
        min_island_size=12,
        max_displacement="auto",
        max_rounds=1,
        raw_init="islands",
        ground="auto",
        random_state=None,
    ):
        self.estimator = estimator
        self.refine = refine
        self.max_icp_iter = max_icp_iter
        self.max_distance = max_distance
        self.max_points = max_points
        self.island_radius = island_radius
        self.min_island_size = min_island_size
        self.max_displacement = max_displacement
        self.max_rounds = max_rounds
        self.raw_init = raw_init
        self.ground = ground
        self.random_state = random_state

    def _make_estimator(self, random_state, init=None):
        if self.estimator is None:
            from mmreg.estimators._multi_model_registration import MultiModelRegistration

            estimator = MultiModelRegistration(variant="sweep", tau=5.0)
        else:
            estimator = clone(self.estimator)
        params = estimator.get_params(deep=False)
        if init is not None and self.raw_init == "islands" and "init" in params:
            estimator.set_params(init=init)
        if "random_state" in params and params["random_state"] is None:
            estimator.set_params(random_state=random_state.randint(2**31 - 1))
        return estimator

    @_fit_context(prefer_skip_nested_validation=False)
    def fit(
        self,
        X,
        y=None,
        *,
        sweep=None,
        times=None,
        sweep_times=None,
        interval=None,
        ground=None,
        sweep_ground=None,
        ego_motion=None,
        ego_body=None,
    ):
        """Find the objects and their motions, refined on the second sweep.

        Parameters
        ----------
        X : array-like of shape (n_samples, 6) or (n_samples, 3)
            Correspondences ``[a | b]`` (refinement), or the first sweep alone (raw).
            Without ``sweep``, correspondences of any even number of columns ``2 d``
            give the estimator's result, unrefined.
        y : Ignored
            Not used, present for API consistency.
        sweep : array-like of shape (m, 3) or None
            The second sweep, any size and order; required with ``(n, 3)`` points.
        times : array-like of shape (n_samples,) or None
            Capture time of every point of the first sweep, in seconds from that sweep's
            reference time (Argoverse 2: ``offset_ns * 1e-9``, from the sweep's
            timestamp). With ``sweep_times`` and ``interval``, the moving clusters are
            deskewed in the ICP (see Notes); None (all three): no deskewing.
        sweep_times : array-like of shape (m,) or None
            The same for the points of ``sweep``, from its own reference time.
        interval : float or None
            Seconds between the two sweeps' reference times (Argoverse 2: the difference
            of the two timestamps, about 0.1 s). Alone (without ``times`` and
            ``sweep_times``) it only bounds the objects' motions in raw mode: a speed and
            a turn rate no road user exceeds (see :mod:`mmreg.sweeps._motion_bounds`);
            without it, ``max_displacement`` bounds them.
        ground, sweep_ground : array-like of shape (n_samples,) and (m,), bool, or None
            Raw mode: the known ground points of each sweep (e.g. from a map: Argoverse 2
            takes points within 0.3 m of its ground height raster). Given together, they
            replace the segmentation of ``ground="auto"``; see ``ground``.
        ego_motion : tuple (rotation, translation) or None
            Raw mode: a known ego motion (odometry, a previous pair's), ``(3, 3)`` and
            ``(3,)``, taking the first sweep's points into the second sweep's frame. The
            ego step starts from it instead of searching from the identity, and refines
            it on the sweeps (so it should be within ``tau / 5`` of the truth). None: the
            ego motion is found from the identity, up to ``max(tau, max_displacement)``
            away (5 m with ``tau=5``: 2 Hz keyframes at 36 km/h).
        ego_body : tuple of two array-like of bool, or None
            Raw mode: the ego vehicle's body in each sweep, known (a log's, carried from
            the last pair: it is fixed in the sensor's frame), ``(n_samples,)`` and
            ``(m,)``. Its points are left out as found ones are, and the search for them
            is skipped. None: found from the sweeps.

        Returns
        -------
        self : SweepRegistration
        """
        X = validate_data(
            self, X, dtype=np.float64, ensure_min_samples=3, ensure_all_finite="allow-nan"
        )
        if np.isinf(X).any():
            raise ValueError("X contains infinity.")
        if sweep is not None:
            _check_features(X)
        if X.shape[1] == 3:
            invalid = invalid_rows(np.hstack([X, X]))
        elif X.shape[1] % 2 == 0:
            invalid = invalid_rows(X)
        else:  # refused with its shape below
            invalid = np.zeros(len(X), dtype=bool)
        self.n_invalid_ = int(np.count_nonzero(invalid))
        self.n_sweep_invalid_ = 0
        sweep_invalid = None
        if sweep is not None:
            sweep = np.asarray(sweep)
            if sweep.dtype.kind in "iuf" and sweep.ndim == 2 and sweep.shape[1] == 3:
                sweep = sweep.astype(np.float64)
                if np.isinf(sweep).any():
                    raise ValueError("sweep contains infinity.")
                sweep_invalid = invalid_rows(np.hstack([sweep, sweep]))
                self.n_sweep_invalid_ = int(np.count_nonzero(sweep_invalid))
                if len(sweep) - self.n_sweep_invalid_ < _MIN_SWEEP_POINTS <= len(sweep):
                    raise ValueError(
                        f"sweep has {len(sweep) - self.n_sweep_invalid_} valid points (the "
                        f"other {self.n_sweep_invalid_} are NaN or at the origin); at least "
                        f"{_MIN_SWEEP_POINTS} are needed."
                    )
        if ego_body is not None:
            if sweep is None or X.shape[1] != 3 or len(ego_body) != 2:
                raise ValueError(
                    "ego_body goes with two raw sweeps: fit(points1, sweep=points2, "
                    "ego_body=(mask1, mask2))."
                )
            ego_body = (
                _check_mask(ego_body[0], len(X), "ego_body[0]"),
                _check_mask(ego_body[1], len(sweep), "ego_body[1]"),
            )
        if not self.n_invalid_ and not self.n_sweep_invalid_:
            return self._fit(
                X,
                sweep,
                times,
                sweep_times,
                interval,
                ground,
                sweep_ground,
                ego_motion,
                body=ego_body,
            )
        # Invalid returns (NaN padding, a driver's failed returns at the origin) are no
        # measurement: the fit leaves them out and they come back as outliers.
        if invalid.all():
            raise ValueError(f"every row of X is invalid (NaN, or at the origin); got {len(X)}.")
        keep = ~invalid
        keep_sweep = np.ones(0 if sweep is None else len(sweep), dtype=bool)
        if sweep_invalid is not None:
            keep_sweep = ~sweep_invalid

        def rows(values, mask, name):
            if values is None:
                return None
            values = np.asarray(values)
            if values.shape[:1] != mask.shape:
                raise ValueError(
                    f"{name} must have one entry per point ({len(mask)}); got {values.shape}."
                )
            return values[mask]

        self._fit(
            X[keep],
            None if sweep is None else sweep[keep_sweep],
            rows(times, keep, "times"),
            rows(sweep_times, keep_sweep, "sweep_times"),
            interval,
            rows(ground, keep, "ground"),
            rows(sweep_ground, keep_sweep, "sweep_ground"),
            ego_motion,
            body=None if ego_body is None else (ego_body[0][keep], ego_body[1][keep_sweep]),
        )
        # Invalid returns: no flow (NaN), in no cluster.
        self._restore_rows(keep, keep_sweep, np.nan)
        return self

    def _restore_rows(self, keep, keep_sweep, flow_value):
        """The fitted per-point attributes back on every row: the rows left out (``keep``
        False) get label -1, flow ``flow_value``, and no ground or body."""
        labels = np.full(len(keep), -1, dtype=self.labels_.dtype)
        labels[keep] = self.labels_
        flow = np.full((len(keep), self.flow_.shape[1]), flow_value)
        flow[keep] = self.flow_
        self.labels_, self.flow_, self.outlier_mask_ = labels, flow, labels < 0
        body = np.zeros(len(keep), dtype=bool)
        body[keep] = self.ego_body_mask_
        self.ego_body_mask_ = body
        if len(keep_sweep):
            sweep_body = np.zeros(len(keep_sweep), dtype=bool)
            sweep_body[keep_sweep] = self.sweep_ego_body_mask_
            self.sweep_ego_body_mask_ = sweep_body
        if self.ground_mask_ is not None:
            ground_mask = np.zeros(len(keep), dtype=bool)
            ground_mask[keep] = self.ground_mask_
            sweep_ground_mask = np.zeros(len(keep_sweep), dtype=bool)
            sweep_ground_mask[keep_sweep] = self.sweep_ground_mask_
            self.ground_mask_, self.sweep_ground_mask_ = ground_mask, sweep_ground_mask

    def _fit(
        self,
        X,
        sweep,
        times,
        sweep_times,
        interval,
        ground,
        sweep_ground,
        known=None,
        find_body=True,
        body=None,
    ):
        """``fit`` on valid rows: ``X`` validated, invalid returns of both sweeps left out."""
        self.n_ego_body_ = 0
        self.ego_body_mask_ = np.zeros(len(X), dtype=bool)
        self.sweep_ego_body_mask_ = np.zeros(0 if sweep is None else len(sweep), dtype=bool)
        self.ego_scale_ = np.nan
        self.impossible_motions_ = []
        self.interval_ = None
        check_coordinate_range(X)
        rng = check_random_state(self.random_state)
        self._resolve_lengths()
        if sweep is None and any(v is not None for v in (times, sweep_times, interval)):
            raise ValueError(
                "times, sweep_times and interval deskew the ICP on the second sweep: pass "
                "the second sweep too, fit(X, sweep=points2, times=..., sweep_times=..., "
                "interval=...)."
            )
        if known is not None and (sweep is None or X.shape[1] != 3):
            raise ValueError(
                "ego_motion goes with two raw sweeps: fit(points1, sweep=points2, "
                "ego_motion=(R, t)); with correspondences their static world holds it."
            )
        if known is not None:
            known = check_ego_motion(known)
        if sweep is None and (ground is not None or sweep_ground is not None):
            raise ValueError("ground and sweep_ground go with two raw sweeps: pass sweep too.")
        if sweep is None and X.shape[1] % 2 == 0:
            # Without a second sweep there is nothing to refine on: the estimator's result.
            estimator = self._make_estimator(rng).fit(X)
            d = X.shape[1] // 2
            labels, rotations, translations, static, moving = self._clusters(estimator, X)
            self.estimator_, self.n_rounds_ = estimator, 1
            self._store(X[:, :d], labels, rotations, translations, static)
            self.icp_scales_ = np.full(len(rotations), np.nan)
            self._copy_estimator_state(estimator)
            self.moving_ = moving
            self.ground_mask_ = self.sweep_ground_mask_ = None
            return self
        _check_features(X)
        sweep = _check_sweep(sweep, 3)
        timing = _check_timing(times, sweep_times, interval, len(X), len(sweep))
        self.interval_ = None if interval is None else float(interval)
        if X.shape[1] == 6 and (ground is not None or sweep_ground is not None):
            raise ValueError(
                "ground and sweep_ground are for two raw sweeps (X of shape (n, 3)); with "
                "correspondences the estimator's static world holds the ground."
            )
        self.ground_mask_ = self.sweep_ground_mask_ = None
        a = X[:, :3]
        tree = cKDTree(sweep)
        normals = SurfaceNormals(sweep, tree, 10, self._workers())
        context = (sweep, tree, normals, rng, timing)
        if X.shape[1] == 6:
            estimator = self._make_estimator(rng).fit(X)
            labels, rotations, translations, static, moving = self._clusters(estimator, X)
            refine = moving.copy() if self.refine == "moving" else np.ones(len(moving), bool)
            rotations, translations, scales = self._refine(
                a, labels, rotations, translations, refine, context, static, _DESKEW_ROUNDS
            )
            self.n_rounds_ = 1
        else:
            masks = self._ground_masks(a, sweep, ground, sweep_ground)
            if body is not None:  # known (a log's): no search
                body = (*body, known) if body[0].any() or body[1].any() else None
            elif find_body:
                body = self._ego_body(a, sweep, masks, known)
            if body is not None:
                return self._fit_without_body(X, sweep, (times, sweep_times, interval), masks, body)
            labels, estimator, rotations, translations, scales, sigmas, static = (
                self._raw_with_ground(a, context, masks, known)
            )
        self.estimator_ = estimator
        self.icp_scales_ = scales
        self._copy_estimator_state(estimator)
        self._store(a, labels, rotations, translations, static)
        if X.shape[1] == 3:  # clusters joined or added for the ground are not the estimator's
            self.outlier_mask_ = labels < 0
            self.sigmas_ = sigmas
            if self.ground == "drop" and self.ground_mask_ is not None and static >= 0:
                dropped = a[self.ground_mask_]
                moved = dropped @ rotations[static].T + translations[static]
                self.flow_[self.ground_mask_] = moved - dropped
        self.moving_ = self._moving(a, a + self.flow_, labels, rotations, translations, static)
        return self

    def _ego_body(self, a, sweep, masks, known):
        """Returns of the ego vehicle's body (:mod:`mmreg.sweeps._ego_body`), or None if none.

        Candidates: points within ``_BODY_REACH tau`` of the sensor, off the ground,
        that the other sweep holds within ``_BODY_MATCH tau`` at the same sensor
        coordinates. The ego motion is found without them (from ``known`` if given) and
        confirms those it carries off the second sweep. Returns ``(body, sweep_body,
        ego)``, the ego motion to start the registration of the rest from.
        """
        if not _has_small_gicp():  # the body is told apart by GICP's ego motion
            return None
        tau = self._length_scale()
        match = _BODY_MATCH * tau
        exclude = (None, None) if masks is None else masks
        candidates, sweep_candidates = fixed_candidates(
            a,
            sweep,
            reach=_BODY_REACH * tau,
            match=match,
            exclude=exclude[0],
            sweep_exclude=exclude[1],
        )
        if candidates.sum() < _MIN_BODY_POINTS or sweep_candidates.sum() < _MIN_BODY_POINTS:
            return None
        rest, sweep_rest = a[~candidates], sweep[~sweep_candidates]
        if len(rest) < _MIN_SWEEP_POINTS or len(sweep_rest) < _MIN_SWEEP_POINTS:
            return None
        reach = _EGO_FINE_REACH * tau if known is not None else max(tau, self.max_displacement_)
        rotation, translation, _ = ego_motion(
            rest, sweep_rest, scale=tau, max_displacement=reach, init=known
        )
        ego = (rotation, translation)
        body, sweep_body = confirm_body(
            a,
            sweep,
            candidates,
            sweep_candidates,
            ego,
            match=match,
            cell=self.island_radius_,
            near=(np.linalg.norm(a, axis=1) < _BODY_REACH * tau)
            & (True if masks is None else ~masks[0]),
        )
        if body.sum() < _MIN_BODY_POINTS:
            return None
        return body, sweep_body, ego

    def _fit_without_body(self, X, sweep, timing, masks, body):
        """``_fit`` on the points off the ego vehicle's body; those are labelled -1.

        They move with the sensor: their flow is zero (they stay at the same sensor
        coordinates) and they join no cluster.
        """
        body, sweep_body, ego = body
        keep, keep_sweep = ~body, ~sweep_body
        times, sweep_times, interval = timing
        ground, sweep_ground = (None, None) if masks is None else masks
        self._fit(
            X[keep],
            sweep[keep_sweep],
            None if times is None else np.asarray(times)[keep],
            None if sweep_times is None else np.asarray(sweep_times)[keep_sweep],
            interval,
            None if ground is None else ground[keep],
            None if sweep_ground is None else sweep_ground[keep_sweep],
            known=ego,
            find_body=False,
        )
        self._restore_rows(keep, keep_sweep, 0.0)  # the body stays with the sensor
        self.n_ego_body_ = int(body.sum())
        self.ego_body_mask_ = body
        self.sweep_ego_body_mask_ = sweep_body
        return self

    def _copy_estimator_state(self, estimator):
        n_clusters = len(estimator.rotations_)
        self.sigmas_ = np.asarray(getattr(estimator, "sigmas_", np.full(n_clusters, np.nan)))
        self.outlier_mask_ = np.asarray(estimator.labels_) < 0
        self.n_iter_ = getattr(estimator, "n_iter_", 0)
        self.converged_ = getattr(estimator, "converged_", True)

    def _store(self, a, labels, rotations, translations, static):
        self.labels_ = labels
        self.rotations_ = rotations
        self.translations_ = translations
        self.n_clusters_ = len(rotations)
        self.static_cluster_ = static
        self.flow_ = rigid_flow(a, labels, rotations, translations)

    @staticmethod
    def _clusters(estimator, X):
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

    @staticmethod
    def _moving(a, b, labels, rotations, translations, static):
        if static < 0:
            return np.ones(len(rotations), dtype=bool)
        return moving_clusters(a, b, labels, rotations, translations, static)

    def _refine(self, a, labels, rotations, translations, refine, context, static, rounds):
        """ICP of the clusters flagged ``refine`` on the sweep; the others keep their motion.

        With capture times, ``rounds`` of deskewing and ICP.
        """
        sweep, tree, normals, rng, timing = context
        rotations, translations = rotations.copy(), translations.copy()
        scales = np.full(len(rotations), np.nan)
        chosen = np.flatnonzero(refine)
        if not len(chosen) or self.max_icp_iter == 0:
            return rotations, translations, scales
        index = -np.ones(len(rotations) + 1, dtype=np.intp)
        index[chosen] = np.arange(len(chosen))
        sub = np.where(labels >= 0, index[labels], -1)
        keep = subsample_groups(sub, self.max_points, rng)
        mask = np.full(len(a), -1, dtype=np.intp)
        mask[keep] = sub[keep]
        # With capture times the static world is refined as without (it needs no
        # deskewing: the sweeps are compensated for the ego motion), then the others.
        parts = [chosen] if timing is None else [chosen[chosen == static], chosen[chosen != static]]
        for part in parts:
            if not len(part):
                continue
            index[:] = -1
            index[part] = np.arange(len(part))
            group = np.where(mask >= 0, index[chosen[np.maximum(mask, 0)]], -1)
            if part is chosen or part[0] == static:
                result = self._icp(
                    a, group, rotations[part], translations[part], sweep, tree, normals
                )
            else:
                result = self._deskewed_icp(
                    a, labels, group, part, rotations, translations, static, sweep, timing, rounds
                )
            rotations[part] = result.rotations
            translations[part] = result.translations
            scales[part] = result.scales
        return rotations, translations, scales

    def _icp(self, a, group, rotations, translations, sweep, tree, normals):
        return multi_body_icp(
            a,
            group,
            rotations,
            translations,
            sweep,
            tree=tree,
            normals=normals,
            max_distance=self.max_distance_,
            max_iter=self.max_icp_iter,
            tol=_TOL * self.max_distance_,
            workers=self._workers(),
        )

    def _workers(self):
        """Threads of the ICPs' k-d tree queries: the estimator's ``n_jobs`` (None: one).

        The answers are the same with any number (each point's query is its own).
        """
        n_jobs = None
        if self.estimator is not None:
            n_jobs = self.estimator.get_params(deep=False).get("n_jobs")
        return query_workers(n_jobs)

    def _deskewed_icp(
        self, a, labels, group, part, rotations, translations, static, sweep, timing, rounds
    ):
        """Rounds of deskewing (with the last motions) and ICP of the clusters ``part``.

        The a-points of every cluster of ``part``, and the points of the second sweep
        nearer to that cluster's moved points than to any other cluster's, are moved to
        their sweep's reference time along the cluster's motion relative to the static
        world (:mod:`mmreg.sweeps._deskew`); the ICP aligns the deskewed sets. ``group`` numbers
        the ICP's points by their cluster's place in ``part``.
        """
        times, sweep_times, interval = timing
        if static >= 0:
            world = rotations[static], translations[static]
        else:
            world = np.eye(3), np.zeros(3)
        member = np.flatnonzero(group >= 0)
        g = group[member]
        n_part = len(part)
        counts = np.maximum(np.bincount(g, minlength=n_part), 1)
        centres = _group_sums_3(a[member], g, n_part) / counts[:, None]
        R, t = rotations[part], translations[part]
        # Only the second sweep's points near the clusters can be matched or deskewed:
        # those in the clusters' moved bounding boxes grown by twice the ICP's reach
        # (the rounds move them far less).
        moved = np.einsum("nij,nj->ni", R[g], a[member]) + t[g]
        margin = 2 * self.max_distance_
        low, high = group_bounds(moved, g, n_part)
        local = np.flatnonzero(_in_boxes(sweep, low - margin, high + margin))
        if not len(local):  # nothing to match: the ICP leaves the motions as they are
            return multi_body_icp(
                a, group, R, t, sweep, max_distance=self.max_distance_, max_iter=0
            )
        # A point nearer to another cluster (the static world's points all take part)
        # stays as it is.
        rest = np.flatnonzero((labels >= 0) & ~np.isin(labels, part))
        others = np.einsum("nij,nj->ni", rotations[labels[rest]], a[rest])
        others += translations[labels[rest]]
        others = others[_in_boxes(others, low - 2 * margin, high + 2 * margin)]
        other = np.full(len(local), np.inf)
        if len(others) and len(local):
            other, _ = cKDTree(others).query(sweep[local])
        fractions = sweep_times[local] / interval
        fractions1 = times[member] / interval
        result = None
        for _ in range(rounds):
            first, second = relative_motions(R, t, world)
            points = a.copy()
            points[member] = deskew(a[member], g, fractions1, *first, centres, turn=False)
            moved = np.einsum("nij,nj->ni", R[g], points[member]) + t[g]
            # Each of these sweep points belongs to the cluster of its nearest moved point.
            distance, nearest = cKDTree(moved).query(sweep[local])
            owner = np.where(distance < other, g[nearest], -1)
            # The second sweep's centres: where the clusters' centroids moved.
            centres2 = np.einsum("kij,kj->ki", R, centres) + t
            target = deskew(sweep[local], owner, fractions, *second, centres2, turn=False)
            target_tree = cKDTree(target)
            normals = SurfaceNormals(target, target_tree, 10, self._workers())
            result = self._icp(points, group, R, t, target, target_tree, normals)
            R, t = result.rotations, result.translations
        return result

    def _ego_motion(self, a, context, known=None):
        """The dominant motion: GICP from the identity (or ``known``), then our ICP.

        GICP (:func:`mmreg.sweeps._ego_motion.ego_motion`, coarse to fine on voxels) finds
        motions up to ``max(tau, max_displacement_)`` from the identity and is the more
        accurate on real sweeps (static EPE 12-17 mm against 18-34 mm on the Argoverse 2
        pairs), but where moving objects make much of a scene, or the sweeps are
        noiseless, its voxels' covariances pull it centimetres off. Our raw-point ICP
        (Tukey's kernel) is then run from GICP's motion and kept only when its robust
        point-to-plane residual scale is under three quarters of GICP's: it is when GICP
        is off by more than the sampling noise (0.002-0.5 of it on box and walker
        scenes), never on real or ray-cast sweeps (0.89-1.02 of it;
        ``benchmarks/results/ego_motion.md``).

        Without small_gicp (Intel macOS has no wheel), our ICP alone, from the identity
        (or ``known``) with a reach of twice then once ``max_distance_``.

        Returns the motion, the ICP's motion (where the islands are tested) and its
        robust point-to-plane residual scale.
        """
        sweep, tree, normals, rng, _ = context
        labels = np.zeros(len(a), dtype=np.intp)
        keep = subsample_groups(labels, self.max_points, rng)
        mask = np.full(len(a), -1, dtype=np.intp)
        mask[keep] = 0
        if not _has_small_gicp():
            rotation, translation = (np.eye(3), np.zeros(3)) if known is None else known
            rotation, translation = rotation[None], translation[None]
            for reach in (2.0, 1.0):
                result = multi_body_icp(
                    a,
                    mask,
                    rotation,
                    translation,
                    sweep,
                    tree=tree,
                    normals=normals,
                    max_distance=reach * self.max_distance_,
                    max_iter=self.max_icp_iter,
                    tol=_TOL * self.max_distance_,
                    workers=self._workers(),
                )
                rotation, translation = result.rotations, result.translations
            ego = (rotation[0], translation[0])
            return ego, ego, float(result.scales[0])
        tau = self._length_scale()
        reach = max(tau, self.max_displacement_)
        if known is not None:  # a start within the fine stage's reach: no coarse stage
            reach = _EGO_FINE_REACH * tau
        rotation, translation, sigma = ego_motion(
            a,
            sweep,
            scale=tau,
            max_displacement=reach,
            sweep_normals=normals,
            init=known,
        )
        gicp = (rotation, translation)
        result = multi_body_icp(
            a,
            mask,
            rotation[None],
            translation[None],
            sweep,
            tree=tree,
            normals=normals,
            max_distance=self.max_distance_,
            max_iter=self.max_icp_iter,
            tol=_TOL * self.max_distance_,
            workers=self._workers(),
        )
        icp = (result.rotations[0], result.translations[0])
        stride = -(-len(a) // _EGO_RESIDUAL_POINTS)
        icp_sigma = _residual_scale(a[::stride], sweep, *icp, _EGO_FINE_REACH * tau, normals)
        # The islands' tests (their motions, the slow movers) weigh point-to-plane
        # residuals on the raw points: they read them at the ICP's motion, the minimum
        # of that cost, in the ICP's own scale (annealed, floored). At GICP's motion a
        # static wall keeps a residual of a few millimetres that reads as a slow mover.
        chosen = icp if icp_sigma < _EGO_EXACT_SHARE * sigma else gicp
        return chosen, icp, float(result.scales[0])

    def _island_motions(self, a, context, ego, sigma):
        """Every island's motion: the ego motion unless another one clearly explains it.

        ``ego`` and ``sigma`` are the ego motion and its residual scale. Returns the
        islands of the first sweep, their rotations and translations, and whether each
        moves relative to the ego motion.
        """
        sweep, tree, normals, rng, _ = context
        islands, n_islands = voxel_islands(a, self.island_radius_, self.min_island_size)
        islands2, n_islands2 = voxel_islands(sweep, self.island_radius_, self.min_island_size)
        at_rest = a @ ego[0].T + ego[1]  # the first sweep where the ego motion puts it
        inside = np.flatnonzero(islands >= 0)
        resting = cKDTree(at_rest[inside])
        # The islands' surfaces where the ego motion puts them (their normals on demand).
        rest_normals = None
        if is_z_up_sweep(a):
            rest_normals = SurfaceNormals(at_rest[inside], resting, 10, self._workers())
        search = _IslandSearch(
            a,
            sweep,
            islands2,
            n_islands2,
            context,
            ego,
            sigma,
            at_rest,
            resting,
            inside,
            rest_normals,
        )
        reach = self.max_displacement_
        moving, rotations, translations, unexplained, explained = self._island_hypotheses(
            islands, n_islands, search, reach, rng
        )
        if self.max_displacement == "auto":
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
            large = sizes >= _WEAK_EVIDENCE_SIZES * self.min_island_size
            for _ in range(_WIDENINGS):
                lost = unexplained & (~moving | (explained < 0.5)) & large
                if not lost.any():
                    break
                reach *= 2.0
                number = np.cumsum(lost) - 1
                subset = np.where(islands >= 0, np.where(lost, number, -1)[islands], -1)
                found, sub_r, sub_t, sub_unexplained, sub_explained = self._island_hypotheses(
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
            torn = _torn_islands(
                a,
                islands,
                n_islands,
                moving,
                (rotations, translations),
                at_rest,
                (sweep, tree, normals),
                0.5 * self.island_radius_,
                int(np.ceil(_WEAK_EVIDENCE_SIZES * self.min_island_size)),
            )
            moving &= ~torn
            rotations[torn], translations[torn] = ego
        # Objects that move by a few sampling spacings stay within the ego motion's
        # band and often share an island with a static structure: found point by point
        # among the points no moving island holds, they become islands of their own.
        slow, slow_rotations, slow_translations = slow_movers(
            a,
            (islands < 0) | ~moving[np.maximum(islands, 0)],
            ego,
            sigma,
            (sweep, tree, normals),
            resting,
            cell=0.5 * self.island_radius_,
            min_size=int(np.ceil(_WEAK_EVIDENCE_SIZES * self.min_island_size)),
            max_points=2 * _HYPOTHESIS_POINTS,
            max_distance=self.max_distance_,
            max_iter=min(self.max_icp_iter, _HYPOTHESIS_ITER),
            tol=_TOL * self.max_distance_,
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
                max_displacement=self.max_displacement_,
                bin_size=_BIN * self.max_distance_,
                random_state=copy.deepcopy(rng),
                moved=at_rest,
            ),
            reach=self.max_displacement_,
            max_grade=None if rest_normals is None else _MAX_GRADE,
            rest_normals=rest_normals,
        )
        if len(slow_rotations):
            islands = np.where(slow >= 0, n_islands + slow, islands)
            rotations = np.concatenate([rotations, slow_rotations])
            translations = np.concatenate([translations, slow_translations])
            moving = np.concatenate([moving, np.ones(len(slow_rotations), dtype=bool)])
        return islands, rotations, translations, moving

    def _island_hypotheses(self, islands, n_islands, search, reach, rng, last=False):
        """Each island's motion hypotheses within ``reach``, and the one it keeps.

        The ICPs start within ``reach`` and, but in the ``last`` search, end there.

        ``search`` holds what every search shares (:class:`_IslandSearch`). Returns
        whether each island moves, its rotation and translation (the ego motion's where
        it does not), whether the ego motion leaves most of its points unexplained, and
        the share of its points that its motion explains (where it moves).
        """
        a, sweep, ego, sigma = search.a, search.sweep, search.ego, search.sigma
        at_rest, inside, rest_normals = search.at_rest, search.inside, search.rest_normals
        _, tree, normals, _, _ = search.context
        starts = translation_starts(
            a,
            islands,
            n_islands,
            sweep,
            search.islands2,
            search.n_islands2,
            ego,
            max_displacement=reach,
            bin_size=_BIN * self.max_distance_,
            random_state=rng,
            moved=at_rest,
        )
        n_starts = starts.shape[1]
        # Every (island, start) pair is one cluster of one multi-body ICP.
        chosen = subsample_groups(islands, _HYPOTHESIS_POINTS, rng)
        rows = np.repeat(chosen, n_starts)
        pair = islands[rows] * n_starts + np.tile(np.arange(n_starts), len(chosen))
        valid = np.isfinite(starts).all(axis=2).ravel()
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
            max_distance=self.max_distance_,
        )
        # Faces the second sensor cannot see, where the ego motion puts them, are no
        # sign of motion (a building's end wall driven past, 2 Hz keyframes), unless
        # the sensor drove through them (the rear of the car ahead): asked of the
        # islands the ego motion does not already explain, in LiDAR sweeps as a sensor
        # writes them (z up, each sensor at its sweep's origin).
        open_ = np.flatnonzero(~fit.hopeless()[islands[chosen]])
        # The noise of a climb: the ego's residual, or the islands' own sampling spacing.
        rise_noise = np.full(n_islands, _SLIDE_SCALES * sigma)
        if len(open_) and rest_normals is not None:
            rest = at_rest[chosen[open_]]
            position = np.searchsorted(inside, chosen[open_])
            normal, _, _ = rest_normals(position)
            spacing = _group_median(
                rest_normals.spacing(position), islands[chosen[open_]], n_islands
            )
            rise_noise = np.fmax(rise_noise, spacing)
            hidden = np.zeros(len(chosen), dtype=bool)
            hidden[open_] = facing_away(rest, normal, ego[1], np.zeros(3))
            through = driven_through(
                rest, islands[chosen[open_]], n_islands, ego[1], np.zeros(3), self.island_radius_
            )
            hidden[open_] &= ~through[islands[chosen[open_]]]
            fit = fit.with_hidden(islands[chosen], hidden)
        hopeless = fit.hopeless()
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
            max_distance=self.max_distance_,
            max_iter=min(self.max_icp_iter, _HYPOTHESIS_ITER),
            tol=_TOL * self.max_distance_,
            measure=False,
            workers=self._workers(),
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
            (search.resting, islands[inside], 0.5 * self.island_radius_),
            max_distance=self.max_distance_,
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

    def _resolve_lengths(self):
        """The lengths in use: as given, or ``"auto"`` from the estimator's ``tau``."""
        tau = self._length_scale()
        for name, share in _LENGTHS_PER_TAU.items():
            value = getattr(self, name)
            setattr(self, f"{name}_", share * tau if value == "auto" else float(value))

    def _length_scale(self):
        """The estimator's ``tau``, the one length the user gives (5 stands for metres)."""
        tau = None
        if self.estimator is not None:
            tau = self.estimator.get_params(deep=False).get("tau")
        return float(tau) if isinstance(tau, Real) and not isinstance(tau, bool) else METRE_TAU

    def _ground_masks(self, a, sweep, ground, sweep_ground):
        """The ground of both sweeps: the masks given, found, or None (kept)."""
        if (ground is None) != (sweep_ground is None):
            raise ValueError(
                "ground and sweep_ground go together: the known ground points of both sweeps."
            )
        if ground is not None:
            if self.ground == "keep":
                raise ValueError(
                    "ground masks were given with ground='keep'; pass ground='auto' to use "
                    "them, or leave them out."
                )
            return _check_mask(ground, len(a), "ground"), _check_mask(
                sweep_ground, len(sweep), "sweep_ground"
            )
        if self.ground == "keep" or not is_z_up_sweep(a):
            return None
        tau = self._length_scale()
        ground = ground_mask(a, tau)
        if not has_ground(a, ground):  # removed before: its remnants are objects' bottoms
            return None
        return ground, ground_mask(sweep, tau)

    def _raw_with_ground(self, a, context, masks, known=None):
        """Two raw sweeps: the ego motion on everything, the objects off the ground.

        The ego-motion ICP aligns the whole sweeps (the ground holds roll, pitch and
        height); the islands, their hypotheses, the estimator and the object ICPs see the
        points off the ground of both sweeps; the ground joins the static world.
        """
        ego, probe, sigma = self._ego_motion(a, context, known)
        self.ego_motion_ = ego
        self.ego_scale_ = sigma
        if self.max_displacement == "auto":
            # Other traffic moves about as fast as the sensor: sweeps far apart (2 Hz
            # keyframes) need a reach that grows with the ego motion's step.
            step = _TRAFFIC_PER_EGO * float(np.linalg.norm(ego[1]))
            self.max_displacement_ = max(self.max_displacement_, step)
        if masks is None:
            return self._raw(a, context, (ego, probe), sigma)
        ground, sweep_ground = masks
        self.ground_mask_, self.sweep_ground_mask_ = ground, sweep_ground
        sweep, whole_tree, whole_normals, rng, timing = context
        off, sweep_off = ~ground, ~sweep_ground
        if off.sum() < 3 or sweep_off.sum() < _MIN_SWEEP_POINTS:
            raise ValueError(
                f"{ground.sum()} of {len(a)} points of the first sweep and "
                f"{sweep_ground.sum()} of {len(sweep)} of the second were taken for the "
                "ground, leaving too few to register; pass ground='keep'."
            )
        sweep_off_points = sweep[sweep_off]
        tree = cKDTree(sweep_off_points)
        if timing is not None:
            timing = (timing[0][off], timing[1][sweep_off], timing[2])
        context = (
            sweep_off_points,
            tree,
            SurfaceNormals(sweep_off_points, tree, 10, self._workers()),
            rng,
            timing,
        )
        # The new places are judged against both sweeps whole: the two masks of the
        # ground differ at objects' feet, where a surface left in one sweep only would
        # read as new.
        whole = (a, (sweep, whole_tree, whole_normals))
        labels_off, estimator, rotations, translations, scales, sigmas, static = self._raw(
            a[off], context, (ego, probe), sigma, whole
        )
        if static < 0:  # the ground is the static world's first member
            static = len(rotations)
            rotations = np.concatenate([rotations, ego[0][None]])
            translations = np.concatenate([translations, ego[1][None]])
            scales = np.concatenate([scales, [np.nan]])
            sigmas = np.concatenate([sigmas, [np.nan]])
        labels = np.full(len(a), -1 if self.ground == "drop" else static, dtype=labels_off.dtype)
        labels[off] = labels_off
        return labels, estimator, rotations, translations, scales, sigmas, static

    def _raw(self, a, context, egos, sigma, whole=None):
        # ``egos``: the ego motion reported (the static world's), and the one the islands
        # are tested and the clusters started at (see _ego_motion).
        ego, probe = egos
        sweep, tree, normals, rng, _ = context
        islands, rotations, translations, _ = self._island_motions(a, context, probe, sigma)
        # Label 0: the ego motion, for the small islands and every static one.
        motions = (
            np.concatenate([probe[0][None], rotations]),
            np.concatenate([probe[1][None], translations]),
        )
        labels = islands + 1
        previous = None
        from mmreg.estimators._multi_model_registration import MultiModelRegistration

        memo = PointMemo()  # the rounds fit the same a-points: one sample, one table
        for round_ in range(1, self.max_rounds + 1):
            X = np.hstack([a, rigid_flow(a, labels, *motions) + a])
            estimator = self._make_estimator(rng, init=labels)
            if isinstance(estimator, MultiModelRegistration):
                estimator._point_memo = memo
            estimator = estimator.fit(X)
            labels, rotations, translations, static, _ = self._clusters(estimator, X)
            # The static world keeps the ego motion: its ICP used the whole sweep, and
            # on real sweeps one fitted to the static cluster alone was worse (static EPE
            # 0.031 m against 0.020 m on icpflow_av2_demo).
            refine = np.ones(len(rotations), dtype=bool)
            if static >= 0:
                refine[static] = False
                rotations[static], translations[static] = ego
            # With capture times, two rounds of deskewing and ICP: the first deskews
            # with the estimator's motions, the second with the first's ICP motions.
            rotations, translations, scales = self._refine(
                a, labels, rotations, translations, refine, context, static, _DESKEW_ROUNDS
            )
            motions = (rotations, translations)
            self.n_rounds_ = round_
            if previous is not None and np.array_equal(previous, labels):
                break
            previous = labels
        sigmas = np.asarray(getattr(estimator, "sigmas_", np.full(len(rotations), np.nan)))
        if static >= 0:
            labels, (rotations, translations, scales, sigmas), static = _join_slides(
                a,
                labels,
                (rotations, translations, scales, sigmas),
                static,
                sigma,
                (sweep, tree, normals),
                # Motions fitted to deskewed points put the raw ones near their view.
                None if context[4] is None else self.max_distance_,
                whole,
            )
            # Motions no vehicle or person can make: taken apart (the static world where
            # its motion explains them, else outliers); mmreg.sweeps._motion_bounds.
            labels, (rotations, translations, scales, sigmas), static, self.impossible_motions_ = (
                bound_motions(
                    a,
                    labels,
                    (rotations, translations, scales, sigmas),
                    static,
                    (sweep, tree, normals) if whole is None else whole[1],
                    sigma,
                    scale=self._length_scale(),
                    # "auto" stands for an unknown interval, searched twice as far.
                    reach=self.max_displacement_
                    * (2.0**_WIDENINGS if self.max_displacement == "auto" else 1.0),
                    interval=getattr(self, "interval_", None),
                    up=np.eye(3)[2] if is_z_up_sweep(a if whole is None else whole[0]) else None,
                )
            )
        return labels, estimator, rotations, translations, scales, sigmas, static

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = False
        return tags
