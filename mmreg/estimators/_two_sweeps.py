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

The stages of two raw sweeps are :func:`mmreg.sweeps._pair.register_pair`'s, over the
sweeps' states (:class:`mmreg.sweeps._sweep_state.SweepState`); the estimator checks the
input, makes the states (or takes those a caller keeps) and stores the result.
"""

import warnings
from numbers import Integral, Real

import numpy as np
from sklearn.base import BaseEstimator, ClusterMixin, _fit_context, clone
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import HasMethods, Interval, StrOptions
from sklearn.utils.validation import validate_data

from mmreg._array.flow import rigid_flow
from mmreg._array.motion import moving_clusters
from mmreg._array.neighbors import query_workers
from mmreg._array.point_memo import PointMemo
from mmreg._validation import (
    check_coordinate_range,
    check_ego_motion,
    invalid_points,
    invalid_rows,
)
from mmreg.sweeps._cluster_icp import refine_clusters
from mmreg.sweeps._ground import METRE_TAU
from mmreg.sweeps._pair import DESKEW_ROUNDS, MIN_SWEEP_POINTS, clusters_of, register_pair
from mmreg.sweeps._sensor_frame import SensorFrameWarning, warn_if_not_sensor_frame
from mmreg.sweeps._settings import PairSettings
from mmreg.sweeps._sweep_state import SweepState

__all__ = ["SweepRegistration"]

# Fewest points of the second sweep: the normals need neighbourhoods.
_MIN_SWEEP_POINTS = MIN_SWEEP_POINTS
# The lengths of "auto" in units of the estimator's tau (LiDAR in metres: tau = 5).
_LENGTHS_PER_TAU = {"max_distance": 0.2, "island_radius": 0.1, "max_displacement": 0.6}
# Points of the first sweep whose spacing tells whether tau is in their units.
_SPACING_SAMPLE = 2000


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
    estimator : estimator, "passthrough" or None, default=None
        The multi-model estimator (fitted on clones). None:
        ``MultiModelRegistration(variant="sweep", tau=5.0)``, the variant for real LiDAR.
        ``"passthrough"`` (two raw sweeps only): no estimator; the clusters are the
        moving islands and their refined motions, the rest the static world. A log's
        tracks re-assign the points one by one, so ``SequenceRegistration`` pairs its
        sweeps this way (the same labels on the shared logs, in 11-14 % less time).
        Its ``n_jobs``, if it has one, also sets the threads of the ICPs' k-d tree
        queries (the same answers; None: one thread).
    tau : float or None, default=None
        The length scale, in the points' units (5 for metres): every ``"auto"`` length,
        the ground's and the ego motion's scales follow it. None: the estimator's
        ``tau`` (5 without one, or with ``"passthrough"``). The estimator keeps its own.
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
    widen_reach : bool, default=True
        Raw mode: whether an ``"auto"`` ``max_displacement`` is widened where the data
        ask (above). False: one search within the reach, what
        ``SequenceRegistration``'s pairs use: its tracks find such a mover from the
        places it leaves and reaches, and its logs take 5-29 % less time a frame.
    max_rounds : int, default=1
        Raw mode: most rounds of estimator and ICP (further rounds run while the labels
        change). One: a second round, fed by the refined motions, found the same
        objects on every real and generated pair we hold, and cost a sixth of the fit.
    raw_init : {"islands", "estimator"}, default="islands"
        Raw mode: the estimator's initial clusters. ``"islands"``: the moving islands
        and one cluster of all that keep the ego motion (the first round, slow movers
        included) or the last round's clusters, whose motions made
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
        EM iterations of the estimator (last round; 0 with ``"passthrough"``).
    converged_ : bool
        Whether the estimator settled (last round; True with ``"passthrough"``).
    icp_scales_ : ndarray of shape (n_clusters_,)
        Robust point-to-plane residual scale of each cluster on the second sweep (NaN for
        clusters not refined).
    estimator_ : estimator or None
        The fitted ``estimator`` (last round; None with ``"passthrough"``).
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
        "estimator": [HasMethods(["fit"]), StrOptions({"passthrough"}), None],
        "tau": [Interval(Real, 0, None, closed="neither"), None],
        "refine": [StrOptions({"moving", "all"})],
        "max_icp_iter": [Interval(Integral, 0, None, closed="left")],
        "max_distance": [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"})],
        "max_points": [Interval(Integral, 6, None, closed="left"), None],
        "island_radius": [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"})],
        "min_island_size": [Interval(Integral, 1, None, closed="left")],
        "max_displacement": [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"})],
        "widen_reach": ["boolean"],
        "max_rounds": [Interval(Integral, 1, None, closed="left")],
        "raw_init": [StrOptions({"islands", "estimator"})],
        "ground": [StrOptions({"auto", "keep", "drop"})],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        estimator=None,
        *,
        tau=None,
        refine="moving",
        max_icp_iter=30,
        max_distance="auto",
        max_points=5000,
        island_radius="auto",
        min_island_size=12,
        max_displacement="auto",
        widen_reach=True,
        max_rounds=1,
        raw_init="islands",
        ground="auto",
        random_state=None,
    ):
        self.estimator = estimator
        self.tau = tau
        self.refine = refine
        self.max_icp_iter = max_icp_iter
        self.max_distance = max_distance
        self.max_points = max_points
        self.island_radius = island_radius
        self.min_island_size = min_island_size
        self.max_displacement = max_displacement
        self.widen_reach = widen_reach
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
        states=None,
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
        states : tuple of two SweepState, or None
            Raw mode: the two sweeps' states, from :meth:`sweep_state` of ``X`` and of
            ``sweep``, kept by a caller that registers each sweep in more than one pair
            (a log: a sweep is the second of one pair and the first of the next). What
            the fit computes of one sweep alone (its ground, k-d trees, normals,
            islands) is then computed once and the states keep
            it; the result is the same as without them. None: made for this fit.

        Returns
        -------
        self : SweepRegistration

        Warns
        -----
        ScaleWarning
            Where ``tau`` does not fit the points (the multi-model estimator's check;
            with ``"passthrough"``, the first sweep's): other units than the points'.
        SensorFrameWarning
            Raw mode: where the first sweep does not look like a LiDAR sweep in its
            sensor's frame: the origin far outside it (a map's or world frame), or
            another axis than z up.
        """
        X = validate_data(
            self, X, dtype=np.float64, ensure_min_samples=3, ensure_all_finite="allow-nan"
        )
        if np.isinf(X).any():
            raise ValueError("X contains infinity.")
        if sweep is not None:
            _check_features(X)
        if X.shape[1] == 3:
            invalid = invalid_points(X)
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
                sweep_invalid = invalid_points(sweep)
                self.n_sweep_invalid_ = int(np.count_nonzero(sweep_invalid))
                if len(sweep) - self.n_sweep_invalid_ < _MIN_SWEEP_POINTS <= len(sweep):
                    raise ValueError(
                        f"sweep has {len(sweep) - self.n_sweep_invalid_} valid points (the "
                        f"other {self.n_sweep_invalid_} are NaN or at the origin); at least "
                        f"{_MIN_SWEEP_POINTS} are needed."
                    )
        if states is not None and (sweep is None or X.shape[1] != 3 or len(states) != 2):
            raise ValueError(
                "states go with two raw sweeps: fit(points1, sweep=points2, "
                "states=(est.sweep_state(points1), est.sweep_state(points2)))."
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
                states=states,
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
            states=states,
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
        body=None,
        states=None,
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
        if self.estimator == "passthrough" and (sweep is None or X.shape[1] != 3):
            raise ValueError(
                "estimator='passthrough' keeps the islands of two raw sweeps, "
                "fit(points1, sweep=points2); correspondences need a multi-model estimator "
                "(None: MultiModelRegistration)."
            )
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
            labels, rotations, translations, static, moving = clusters_of(estimator, X)
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
        settings = self._settings()
        if X.shape[1] == 3:
            return self._fit_raw(a, sweep, timing, (ground, sweep_ground), known, body, states)
        estimator = self._make_estimator(rng).fit(X)
        labels, rotations, translations, static, moving = clusters_of(estimator, X)
        refine = moving.copy() if self.refine == "moving" else np.ones(len(moving), bool)
        target = SweepState(sweep, workers=settings.workers).target()
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
        self.n_rounds_ = 1
        self.estimator_ = estimator
        self.icp_scales_ = scales
        self._copy_estimator_state(estimator)
        self._store(a, labels, rotations, translations, static)
        self.moving_ = self._moving(a, a + self.flow_, labels, rotations, translations, static)
        return self

    def _warn_if_tau_off_scale(self, state):
        """A ScaleWarning where ``tau`` does not fit the first sweep (``state``, its
        :class:`~mmreg.sweeps._sweep_state.SweepState`). The spacing is read off the
        sweep's own tree, on evenly spread points (kept: the pair reads them again)."""
        from mmreg.estimators._multi_model_registration import warn_if_tau_off_scale

        n = len(state.points)
        if n < 2:
            return
        rows = np.unique(np.linspace(0, n - 1, min(n, _SPACING_SAMPLE)).astype(np.intp))
        spacing = float(np.median(state.normals.spacing(rows)))
        warn_if_tau_off_scale(state.points, self._length_scale(), "the first sweep", spacing)

    def _fit_raw(self, a, sweep, timing, ground, known, body, states):
        """Two raw sweeps (valid rows): :func:`mmreg.sweeps._pair.register_pair` over
        their states, and its result stored."""
        rng = check_random_state(self.random_state)
        settings = self._settings()
        ground = self._given_ground(a, sweep, *ground)
        if states is None:
            states = (
                SweepState(a, workers=settings.workers),
                SweepState(sweep, workers=settings.workers),
            )
        else:
            _check_states(states, a, sweep)
        if self.estimator == "passthrough":  # no multi-model estimator to check tau
            self._warn_if_tau_off_scale(states[0])
        warn_if_not_sensor_frame(a, "the first sweep")
        result = register_pair(
            *states,
            settings,
            self._cluster(rng),
            rng,
            known=known,
            body=body,
            ground=ground,
            timing=timing,
        )
        self.ego_motion_ = result.ego
        self.ego_scale_ = result.ego_scale
        self.max_displacement_ = result.max_displacement
        self.impossible_motions_ = result.impossible
        if result.body is not None:
            keep, keep_sweep = ~result.body[0], ~result.body[1]
            a = a[keep]
            self.ego_body_mask_ = np.zeros(len(a), dtype=bool)
            self.sweep_ego_body_mask_ = np.zeros(int(keep_sweep.sum()), dtype=bool)
        if result.ground is not None:
            self.ground_mask_, self.sweep_ground_mask_ = result.ground
        labels, rotations, translations = result.labels, result.rotations, result.translations
        static = result.static
        self.estimator_ = result.estimator
        self.n_rounds_ = result.n_rounds
        self.icp_scales_ = result.scales
        if result.estimator is None:  # "passthrough": no estimator iterated
            self.n_iter_, self.converged_ = 0, True
        else:
            self._copy_estimator_state(result.estimator)
        self._store(a, labels, rotations, translations, static)
        # Clusters joined or added for the ground are not the estimator's.
        self.outlier_mask_ = labels < 0
        self.sigmas_ = result.sigmas
        if self.ground == "drop" and self.ground_mask_ is not None and static >= 0:
            dropped = a[self.ground_mask_]
            moved = dropped @ rotations[static].T + translations[static]
            self.flow_[self.ground_mask_] = moved - dropped
        self.moving_ = self._moving(a, a + self.flow_, labels, rotations, translations, static)
        if result.body is not None:
            self._restore_rows(keep, keep_sweep, 0.0)  # the body stays with the sensor
            self.n_ego_body_ = int(result.body[0].sum())
            self.ego_body_mask_, self.sweep_ego_body_mask_ = result.body
        return self

    def _given_ground(self, a, sweep, ground, sweep_ground):
        """The ground masks given to ``fit``, checked, or None."""
        if (ground is None) != (sweep_ground is None):
            raise ValueError(
                "ground and sweep_ground go together: the known ground points of both sweeps."
            )
        if ground is None:
            return None
        if self.ground == "keep":
            raise ValueError(
                "ground masks were given with ground='keep'; pass ground='auto' to use "
                "them, or leave them out."
            )
        return _check_mask(ground, len(a), "ground"), _check_mask(
            sweep_ground, len(sweep), "sweep_ground"
        )

    def _cluster(self, rng):
        """The estimator of the raw rounds: ``cluster(X, init)`` fits a clone (None with
        ``"passthrough"``: the islands' clusters are kept)."""
        if self.estimator == "passthrough":
            return None
        from mmreg.estimators._multi_model_registration import MultiModelRegistration

        memo = PointMemo()  # the rounds fit the same a-points: one sample, one table

        def cluster(X, init):
            estimator = self._make_estimator(rng, init=init)
            if isinstance(estimator, MultiModelRegistration):
                estimator._point_memo = memo
            with warnings.catch_warnings():
                # The first sweep's frame is checked once, by the pair (_fit_raw).
                warnings.simplefilter("ignore", SensorFrameWarning)
                return estimator.fit(X)

        return cluster

    def sweep_state(self, points):
        """One sweep's state, for :meth:`fit` ``(states=...)`` in every pair it is in.

        The state keeps what a raw fit computes of the sweep alone (its ground, k-d
        trees, surface normals, islands), keyed by the lengths
        it depends on: any ``SweepRegistration`` with the same ``tau`` and lengths can
        use it, and a sweep registered in two pairs computes each once.

        Parameters
        ----------
        points : array-like of shape (n, 3)
            The sweep, as it will be given to ``fit`` (as ``X`` or as ``sweep``): its
            invalid returns (NaN, failed returns at the origin) are left out as ``fit``
            leaves them out.

        Returns
        -------
        SweepState

        Examples
        --------
        Three sweeps of a street, each registered with the next; the middle one's
        state serves both pairs:

        >>> from mmreg import SweepRegistration
        >>> from mmreg.datasets import make_lidar_sequence
        >>> log = make_lidar_sequence(3, n_azimuths=256, random_state=0)
        >>> est = SweepRegistration(random_state=0)
        >>> states = [est.sweep_state(points) for points in log.frames]
        >>> for k in range(2):
        ...     pair = est.fit(log.frames[k], sweep=log.frames[k + 1],
        ...                    states=(states[k], states[k + 1]))
        >>> pair.labels_.shape == (len(log.frames[1]),)
        True
        """
        points = np.asarray(points)
        if points.dtype.kind not in "iuf" or points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(
                f"points must be an (n, 3) array of numbers; got {points.shape} of {points.dtype}."
            )
        points = points.astype(np.float64)
        if np.isinf(points).any():
            raise ValueError("points contain infinity.")
        valid = ~invalid_points(points)
        return SweepState(points[valid], workers=self._workers())

    def _settings(self):
        """The stages' settings (:class:`mmreg.sweeps._settings.PairSettings`)."""
        return PairSettings(
            tau=self._length_scale(),
            max_distance=self.max_distance_,
            island_radius=self.island_radius_,
            min_island_size=self.min_island_size,
            max_displacement=self.max_displacement_,
            auto_reach=self.max_displacement == "auto",
            widen=self.widen_reach,
            max_icp_iter=self.max_icp_iter,
            max_points=self.max_points,
            max_rounds=self.max_rounds,
            ground=self.ground,
            workers=self._workers(),
            interval=getattr(self, "interval_", None),
        )

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
    def _moving(a, b, labels, rotations, translations, static):
        if static < 0:
            return np.ones(len(rotations), dtype=bool)
        return moving_clusters(a, b, labels, rotations, translations, static)

    def _workers(self):
        """Threads of the ICPs' k-d tree queries: the estimator's ``n_jobs`` (None: one).

        The answers are the same with any number (each point's query is its own).
        """
        n_jobs = None
        if self._has_estimator():
            n_jobs = self.estimator.get_params(deep=False).get("n_jobs")
        return query_workers(n_jobs)

    def _resolve_lengths(self):
        """The lengths in use: as given, or ``"auto"`` from the estimator's ``tau``."""
        tau = self._length_scale()
        for name, share in _LENGTHS_PER_TAU.items():
            value = getattr(self, name)
            setattr(self, f"{name}_", share * tau if value == "auto" else float(value))

    def _has_estimator(self):
        """Whether an estimator was given (neither None nor ``"passthrough"``)."""
        return self.estimator is not None and not isinstance(self.estimator, str)

    def _length_scale(self):
        """``tau``, or the estimator's: the one length the user gives (5 stands for metres)."""
        tau = self.tau
        if tau is None and self._has_estimator():
            tau = self.estimator.get_params(deep=False).get("tau")
        return float(tau) if isinstance(tau, Real) and not isinstance(tau, bool) else METRE_TAU

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = False
        return tags


def _check_states(states, a, sweep):
    """``states`` as two SweepState of ``a`` and ``sweep``; a clear error otherwise."""
    for i, (state, points, name) in enumerate(zip(states, (a, sweep), ("X", "sweep"), strict=True)):
        if not isinstance(state, SweepState):
            raise TypeError(
                f"states[{i}] must be a SweepState from SweepRegistration.sweep_state; got "
                f"{type(state).__name__}."
            )
        if state.points.shape != points.shape or not np.array_equal(state.points, points):
            raise ValueError(
                f"states[{i}] holds other points than {name} ({len(state.points)} valid "
                f"points against {len(points)}): make it with sweep_state({name})."
            )
