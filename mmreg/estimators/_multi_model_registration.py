"""Classification-EM multi-model registration: the robust default and the paper's Algorithm 1."""

import functools
from numbers import Integral, Real

import numpy as np
from scipy.spatial import cKDTree
from sklearn.base import _fit_context
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from mmreg._array.geometry import column_bounds, rotation_angle
from mmreg._array.neighbors import NeighbourTable
from mmreg._array.point_tree import PointTree
from mmreg._array.voxels import voxel_representatives, voxel_sample
from mmreg._validation import check_ego_motion, check_labels, check_paired, invalid_rows
from mmreg._warnings import warn
from mmreg.em._gate import ClusterGate
from mmreg.em._paper import multi_model_em
from mmreg.em._robust import (
    _FALSE_ALARMS,
    assign_to_pieces,
    joins_moving_pieces,
    propose_in_the_rest,
    reads_neighbours,
    refit_clusters,
    robust_multi_model_em,
)
from mmreg.em._steps import judge_correspondences, range_noise_scale
from mmreg.estimators._base import MIN_CORRESPONDENCES, BaseRegistration
from mmreg.init._resolve import INIT_CONSTRAINT, initial_labels, is_label_array
from mmreg.sweeps._sensor_frame import SensorFrameWarning, sensor_frame_problems

__all__ = ["MultiModelRegistration", "ScaleWarning"]

# Fitted attributes of the robust variants only.
_ROBUST_ATTRIBUTES = (
    "log_outlier_density_",
    "noise_growth_",
    "static_cluster_",
    "moving_",
)

# Points sampled to estimate the spacing of the a-points for the units check.
_SPACING_SAMPLE = 2000
# voxel_size="auto": inputs above this many correspondences are fitted on a sample of
# at most _AUTO_SAMPLE_VOXELS, one per voxel. The loop's cost grows with its rows; at
# this size an Argoverse 2 sweep's voxels are 0.3 m, small enough to keep a walking
# pedestrian's handful of rows (see benchmarks/results/real_default_vs_paper.md).
_AUTO_SAMPLE_ABOVE = 50_000
_AUTO_SAMPLE_VOXELS = 25_000
# A gate of fewer than this many nearest-neighbour distances lets a cluster grow by a
# point or two per iteration and merges nothing: the units of tau are probably wrong.
_MIN_GATE_SPACINGS = 4.0
# A gate longer than the diagonal of the a-points' bounding box joins any two points of
# the scene: it never separates anything, and objects that move alike merge however
# far apart they are. Beyond this many diagonals the units of tau are probably wrong.
_MAX_GATE_DIAMETERS = 1.0
# min_motion="auto": this fraction of tau, 5 cm at the street scenes' tau = 5 m (the
# gate of `mmreg run`, SweepRegistration and benchmarks/real.py), Argoverse 2's rule for
# dynamic points (0.5 m/s between sweeps 0.1 s apart). A length, so it scales with tau.
_MIN_MOTION_PER_TAU = 0.01
# The static world (the sensor's own motion) turns a few degrees between two frames;
# beyond this the flow and the points are probably in other units.
MAX_STATIC_TURN_DEGREES = 30.0
# Pieces of one static world turn alike (their motion is the sensor's).
_SAME_TURN_DEGREES = 10.0


class ScaleWarning(UserWarning):
    """``tau`` does not fit the scale of the points, or times their intervals (are they
    in other units?)."""


def median_spacing(points, random_state=0, neighbours=None):
    """Median distance from an a-point to its nearest neighbour (on a sample of them).

    ``neighbours``: a :class:`~mmreg._array.neighbors.NeighbourTable` of ``points``, read
    instead of a KD-tree query (the same distances).
    """
    points = np.asarray(points, dtype=float)
    if len(points) < 2:
        return 0.0
    rng = check_random_state(random_state)
    sample = np.arange(len(points))
    if len(points) > _SPACING_SAMPLE:
        sample = rng.choice(len(points), _SPACING_SAMPLE, replace=False)
    if neighbours is not None and neighbours.k >= 2:
        return float(np.median(neighbours.distance[sample, 1]))
    dist, _ = cKDTree(points).query(points[sample], k=2)
    return float(np.median(dist[:, 1]))


def tau_off_scale(points, tau, neighbours=None, spacing=None):
    """How a gate ``tau`` misses the scale of ``points`` (units other than the points'):
    ``("spacing", s)`` where it spans fewer than four of their median nearest-neighbour
    distances ``s`` (:func:`median_spacing`, or ``spacing`` where the caller measured
    it), ``("diameter", d)`` where it exceeds the diagonal ``d`` of their bounding box; a
    list of both, one or none.

    Examples
    --------
    A street in centimetres, sampled every 10 cm, judged with the 5 (metres) of LiDAR:

    >>> import numpy as np
    >>> from mmreg.estimators._multi_model_registration import tau_off_scale
    >>> g = np.arange(0.0, 5000.0, 10.0)
    >>> street = np.stack(np.meshgrid(g, g[:50], [0.0], indexing="ij"), -1).reshape(-1, 3)
    >>> [name for name, _ in tau_off_scale(street, 5.0)], tau_off_scale(street, 500.0)
    (['spacing'], [])
    """
    problems = []
    if spacing is None:
        spacing = median_spacing(points, neighbours=neighbours)
    if tau < _MIN_GATE_SPACINGS * spacing:
        problems.append(("spacing", spacing))
    # Coincident points (diameter 0) are another problem (a DegenerateInputWarning).
    low, high = column_bounds(points)
    diameter = float(np.linalg.norm(high - low))
    if 0 < _MAX_GATE_DIAMETERS * diameter < tau:
        problems.append(("diameter", diameter))
    return problems


def warn_if_tau_off_scale(points, tau, of, spacing=None):
    """A :class:`ScaleWarning` for each way ``tau`` misses the scale of raw sweeps'
    ``points`` (:func:`tau_off_scale`), which ``of`` names ("the first frame"): every
    length of their registration is a share of ``tau``, and in other units than the
    points' it finds nothing moving, however clear the motion."""
    for problem, length in tau_off_scale(points, tau, spacing=spacing):
        if problem == "spacing":
            found = (
                f"spans fewer than {_MIN_GATE_SPACINGS:g} times the median distance between "
                f"neighbouring points of {of} ({length:.3g})"
            )
        else:
            found = f"exceeds the diagonal of {of}'s bounding box ({length:.3g})"
        warn(
            f"tau={tau:g} {found}: every length of the registration is a share of tau, so "
            "no motion will be found as it is. tau is in the points' units: 5 for metres "
            "(500 for centimetres, 5000 for millimetres).",
            ScaleWarning,
        )


class MultiModelRegistration(BaseRegistration):
    """Multi-model registration by Classification-EM (Jin et al., ICRA 2024).

    Given putative correspondences ``(a_i, b_i)`` between two point clouds of a scene in
    which several objects move rigidly, finds the objects (clusters of correspondences),
    the motion ``b = R_j a + t_j`` of each, and the outliers. Starting from an initial
    over-segmentation, every iteration fits a pose, weight ``pi_j = |H_j| / n`` and noise
    scale ``sigma_j`` per cluster, drops clusters smaller than ``min_cluster_size``, and
    moves each correspondence to the cluster of largest weighted likelihood among those
    whose a-points come within ``tau`` of its own a-point (eq. 7).

    The default, ``variant="sweep"``, is made for real LiDAR sweeps and scene-flow
    networks and is also the default on generated and matched correspondences: wrong
    correspondences are labelled -1 by a uniform outlier component and kept out of the
    motion fits; every cluster keeps a robust noise scale of its own (a network errs by
    millimetres on the static world and by centimetres on a moving car); the dominant
    motion, when it holds half of the scene (else the cluster that spans the scene, or
    the clusters that move with a known ``ego_motion`` given to :meth:`fit`), is one
    static world however far apart its pieces lie, flagged in ``static_cluster_``;
    adjacent clusters whose motions agree are merged, touching moving pieces that move
    alike are one object, and correspondences no cluster explains are searched for new
    motions, each accepted only if it pays for itself. ``variant="robust"`` is the
    earlier default (one noise scale shared by all clusters, no static world) and
    ``variant="paper"`` the paper's Algorithm 1, exactly.

    Parameters
    ----------
    tau : float or None, default=1.5
        Distance gate of eq. (7), in the units of the points: a correspondence may join
        cluster ``H_j`` only if ``min_{a' in H_j} ||a' - a_i|| <= tau`` (eq. 7 writes ``<``;
        ``<=`` matches the paper's tau-connectedness, so Theorem 1 holds also for gaps of
        exactly ``tau``). Two objects farther apart than ``tau`` stay apart even when they
        move alike; the robust variant merges only clusters within ``tau`` of each other.
        None turns the gate off (the paper's "Ours (Vanilla)").
    min_cluster_size : int, default=4
        ``m_min``: clusters with fewer correspondences are removed before each M-step;
        the robust variant also removes them from the result.
    max_iter : int, default=10
        ``T``, the largest number of EM iterations; iteration stops as soon as one leaves
        every assignment unchanged (and, robust variant, merged and proposed nothing).
        ``max_iter=0`` returns the initial clusters with their fitted motions (the
        paper's "Naive" baseline).
    init : {"euclidean", "dbscan"}, clusterer or array-like of shape (n,), \
            default="euclidean"
        Initial clusters. ``"euclidean"``: :class:`~mmreg.init.EuclideanClustering` with
        100 clusters, as in the paper, its radius capped at ``tau`` so that every initial
        cluster is ``tau``-connected (Definition 2; objects farther apart than ``tau``
        then start in clusters of their own however many there are); ``"dbscan"``:
        :class:`~mmreg.init.DBSCANClustering`.
        An mmreg initialiser is fitted on ``X``; any other object with ``fit_predict``
        (every scikit-learn clusterer) is fitted on the a-points ``X[:, :d]``. An array
        gives precomputed labels (e.g. from SAM masks), negative for none.
    variant : {"sweep", "robust", "paper"}, default="sweep"
        ``"sweep"``: the robust loop (see Notes) for real LiDAR sweeps and scene-flow
        networks, the default: every cluster keeps a robust noise scale of its own while
        there is a static world to measure its motion against (one shared scale when there
        is none, as on Table I's objects), the dominant
        motion is one static world however far apart its pieces lie (``static_share``,
        ``min_motion``), touching moving pieces whose motions agree within
        ``motion_tolerance`` of their motion are one object, proposals search the noise
        scale (as MAGSAC marginalises it) and try local translations, slow movers are
        sought in the static world's tail, a cluster whose members lie scattered among
        other clusters' points (a few wrong flows that agree by chance, with a noise
        scale of their own) is dissolved, and the outliers are judged once more by the
        final clusters. ``"robust"``: the robust loop with one noise scale shared by all
        clusters and none of these (the earlier default). ``"paper"``: Algorithm 1
        exactly as published (bit for bit the results of
        :func:`~mmreg.estimators.multi_model_em`).
    confidence : float in (0, 1), default=0.999
        Robust variant: the quantile of the ``sigma^2 chi2_d`` residual distribution
        within which a correspondence counts as an inlier of its cluster when the
        motions are fitted and when new motions are proposed.
    n_hypotheses : int, default=32
        Robust variant: minimal samples drawn in each group of unexplained
        correspondences to propose a new motion; 0 proposes none.
    noise_model : {"range", "constant"}, default="range"
        Robust variant. ``"range"``: correspondence ``i`` of cluster ``j`` has noise
        ``sigma_j g_i`` with ``g_i = 1 + c ||a_i||^2``, the sensor at the origin of the
        a-points' frame (stereo depth errs by the square of the range); ``c >= 0`` is
        estimated by maximum likelihood every iteration and is 0 when the noise does not
        grow with range. ``"constant"``: ``sigma_j`` for every member.
    static_share : float in (0, 1] or None, default=0.5
        ``variant="sweep"``: the dominant motion is the *static world* (the ego motion of a
        sensor on a vehicle) when the clusters that share it hold at least this share of
        the clustered correspondences. Its pieces then form one cluster however far apart
        they lie (ground removed, a LiDAR sweep is islands of buildings, poles and parked
        cars), the gate of eq. (7) admits it everywhere, and ``static_cluster_`` names it.
        When no motion holds this share (a crowded scene: FlyingThings3D frames whose
        background holds 3-47 % of the points), the static world is the cluster that
        *spans the scene*: the RMS distance of its a-points from their centroid is at
        least half that of all the clustered a-points (a background reaches across the
        view, an object is a thing of a few metres; measured: 0.54-1.0 for the
        backgrounds of real frames, at most 0.36 for objects); if none does, there is no
        static world. Other motions keep the gate: two far-apart objects that move alike
        stay two objects. None: no static world (unless :meth:`fit` is given
        ``ego_motion``).
    min_motion : float or "auto", default="auto"
        ``variant="sweep"``: a cluster whose motion carries its points less than this far
        (RMS, in the units of the points) from where the static world's motion carries
        them, beyond the cluster's own scatter (the RMS of its residuals), is part of the
        static world, and a cluster is ``moving_`` only beyond it. ``"auto"``:
        ``tau / 100``, so that it scales with the units of ``tau``: 5 cm at the street
        scenes' ``tau = 5`` m, Argoverse 2's rule for dynamic points (0.5 m/s between
        sweeps 0.1 s apart), which also absorbs the annotation jitter of parked cars
        (give it explicitly with another ``tau``); with ``tau=None``, the median distance
        between neighbouring a-points. The scatter keeps a patch of a network's flow
        that errs coherently (ZeroFlow: a wall 36 m away shifted by 6 cm, scattered by
        2 cm) in the static world. ``min_motion_`` holds the value used.
    motion_tolerance : float, default=0.2
        ``variant="sweep"``: two touching moving clusters are one object when each one's
        motion carries the other's points within this fraction of their motion relative
        to the static world (RMS). A scene-flow network's error on a moving object grows
        with its motion and bends the flow across it (ZeroFlow: 10-30 cm over a car 1.1 m
        into its motion), so the object's parts fit different rigid motions. Objects
        that do not touch are never joined this way, nor are touching ones whose flows
        jump where they touch by more than ``min_motion`` (a bent flow meets itself
        there; two boxes moving 1 m, one of them 10 cm further, do not). A moving
        cluster that holds two such objects (an initial cluster spans up to ``tau``) is
        split in two. 0 turns joining and splitting off.
    tol : float in [0, 1) or None, default=None
        Robust variants: the iterations have converged when one moves at most this
        fraction of the correspondences to another reported cluster, the clusters of
        two iterations matched by their overlap whatever their numbers (a merge moves
        the smaller part's correspondences, a proposal its members, a move to or from
        the outliers counts; a move between pieces of the static world does not). None:
        1e-3, and 1e-2 with ``variant="sweep"``, where a network's flow moves a few
        tenths of a percent of the correspondences between an object and the outliers
        every iteration without changing the answer (ZeroFlow's flow on an Argoverse 2
        sweep: 7 iterations at 5e-3, 3 at 1e-2, the same objects found).
    skip_steps : tuple of str, default=()
        Robust variant: steps of the loop to leave out, for ablations; any of
        ``"trimming"``, ``"range_noise"``, ``"merging"``, ``"static_world"``,
        ``"moving_pieces"``, ``"boundary_layers"``, ``"outliers"``, ``"proposals"`` (see Notes).
    voxel_size : float, "auto" or None, default="auto"
        Robust variants: fit on one correspondence per occupied cubic voxel of this side
        (the first of each, in the units of the points; Open3D's ``voxel_down_sample``
        grid), then judge every other correspondence by the fitted clusters as
        :meth:`predict` does, but with the static world's slow pieces keeping their own
        motions, look for new clusters among those that no cluster explains (a small
        object that the sample saw as a handful of rows), and refit every cluster on
        all its members. A LiDAR sweep is thinned near the sensor and kept whole far
        from it. ``"auto"``: inputs of more than 50,000 correspondences are fitted on
        a sample of 21,250-25,000, the side found by a search on the a-points (at 0.3 m
        on an 82k-point Argoverse 2 sweep: three times faster); smaller inputs are
        fitted whole. None fits every correspondence. The paper variant always does
        (``"auto"`` is None there).
    sigma_floor : float or None, default=None
        Smallest noise scale ``sigma_j``. None uses ``1e-6`` times the RMS spread of the
        b-points, which keeps noiseless data well posed (see Notes).
    random_state : int, RandomState instance or None, default=None
        Seeds the proposals' samples, and a clusterer ``init`` whose own
        ``random_state`` is None.
    n_jobs : int or None, default=None
        Threads of the k-d tree queries (the gate's, and the initial clustering's when
        ``init`` is a shortcut or a clusterer whose own ``n_jobs`` is None). None means
        1, -1 every core, ``-k`` all but ``k - 1`` of them. The results do not depend
        on it.
    verbose : int, default=0
        Print one line per iteration: the clusters, those dropped below
        ``min_cluster_size``, the outliers (paper variant: the correspondences in no
        cluster) and the changed labels; the robust variants also the merges and
        proposals.

    Attributes
    ----------
    labels_ : ndarray of shape (n_samples,)
        Cluster of each correspondence in ``0..n_clusters_-1``, numbered by decreasing
        size; ``-1`` for outliers (and, paper variant, for correspondences that the gate
        keeps out of every cluster).
    rotations_ : ndarray of shape (n_clusters_, d, d)
        Proper rotation of each cluster (determinant ``+1``).
    translations_ : ndarray of shape (n_clusters_, d)
        Translation of each cluster: ``b ~ rotations_[j] @ a + translations_[j]``.
    sigmas_ : ndarray of shape (n_clusters_,)
        Isotropic noise scale of each cluster's residuals.
    weights_ : ndarray of shape (n_clusters_,)
        ``pi_j``: the fraction of all correspondences in each cluster.
    n_clusters_ : int
        Number of clusters found.
    outlier_mask_ : ndarray of shape (n_samples,)
        True for the correspondences labelled -1 (the invalid rows among them).
    n_invalid_ : int
        Rows that hold no measurement and were left out of the fit, labelled -1 (flow
        NaN): rows with NaN (padding) and rows whose a- or b-point lies exactly at the
        origin together with another row's (a LiDAR driver's failed returns; see Notes).
    min_motion_ : float
        The ``min_motion`` used (``"auto"`` resolved).
    flow_ : ndarray of shape (n_samples, d)
        The rigid scene flow of every correspondence, ``R_j a_i + t_j - a_i`` for
        cluster ``j``. An outlier is a wrong ``b_i``, not a wrong ``a_i``: its a-point
        moves with the cluster of its nearest clustered a-point (NaN if no cluster).
    init_labels_ : ndarray of shape (n_samples,)
        The initial clusters as given by ``init`` (-1 for the correspondences that
        ``voxel_size`` left out of the fit).
    voxel_size_ : float or None
        The voxel side of the sample fitted, None if every correspondence was.
    n_iter_ : int
        Number of EM iterations run.
    converged_ : bool
        Whether the last iteration left everything unchanged.
    history_ : list of dict
        Robust variant: per iteration, the number of clusters (as reported: the slow
        pieces of the static world counted with it), of the pieces the loop keeps apart
        (``pieces``, which the final clean-up may still join), merges, clusters dropped
        below ``min_cluster_size``, outliers and proposed clusters. Empty for the paper
        variant.
    log_outlier_density_ : float
        Robust variant: ``log(pi_0 / V)``, the fitted outlier component, which
        :meth:`predict` compares each correspondence's likelihood with.
    static_cluster_ : int
        Robust variants: the cluster of the static world, -1 if there is none (see
        ``static_share`` and :meth:`fit`'s ``ego_motion``).
    moving_ : ndarray of shape (n_clusters_,)
        Robust variants: whether each cluster moves, relative to the static world, by at
        least ``min_motion`` beyond its own scatter; all True when there is no static
        world.
    noise_growth_ : float
        Robust variant: ``c`` of the noise scale ``sigma_j (1 + c ||a||^2)``; ``sigmas_``
        are then the scales at the origin.
    n_features_in_ : int
        Number of columns of ``X`` (``2 * d``).

    See Also
    --------
    mmreg.init.EuclideanClustering : The default initial clustering.
    mmreg.estimators.multi_model_em : Algorithm 1 on arrays.

    Notes
    -----
    **The robust variant.** Each iteration of Algorithm 1 becomes:

    1. *M-step on inliers*: each cluster's motion is fitted, its noise scale estimated
       robustly (``median(r^2) / median(chi2_d)``, unharmed by up to half of the cluster
       being wrong), members beyond the ``confidence`` quantile are set aside, and the
       motion refitted without them.
    2. *Merging*: for every two clusters with points in a common cell of side
       ``tau / sqrt(d)`` (hence within ``tau``), the joint motion is fitted with each
       cluster keeping its own noise scale, and ``Lambda = sum_k (RSS_k(joint) -
       RSS_k(own)) / sigma_k^2`` (``chi2`` with ``d(d+1)/2`` degrees of freedom if the
       motions agree) is compared with the BIC price of a second motion,
       ``d(d+1)/2 * log(n_i + n_j)``. Mutual best pairs below it merge, round after
       round within the iteration, from sufficient statistics (no pass over the points),
       so a large over-segmented surface merges at once. Keeping each cluster's own
       noise scale in the test is what keeps a background whose noise grows with depth
       in one piece.
    3. Clusters below ``min_cluster_size`` are removed (Algorithm 1, lines 10-13).
    4. The E-step and classification of eq. (7), with the noise scale of each
       correspondence (``noise_model``): a background whose depth errors grow with range
       does not split into depth layers, nor swallow the near objects in front of it.
    5. *Outliers*: a correspondence stays in its cluster ``j`` only if
       ``pi_j N(r; 0, sigma_j^2 I) >= pi_0 / V``, a uniform component over the bounding
       box (volume ``V``) of the displacements ``b - a`` (a wrong match or flow moves its
       point by something in the range the scene shows) whose weight ``pi_0`` is the
       share of outliers of the previous iteration (at least ``1 / n``): a residual test
       at about 4-7 ``sigma_j``. The parameter-free uniform component of CPD (Myronenko
       and Song, 2010), over displacements rather than positions.
    6. *Proposals*: the correspondences labelled -1 are split into ``tau``-connected
       groups; in each, ``n_hypotheses`` local minimal samples are fitted and the one
       with most inliers becomes a new cluster if its inliers' likelihood beats the
       outlier component's by more than the BIC price of a motion and a noise scale.
       A car in the same initial cluster as the road under it becomes its own cluster;
       scattered wrong correspondences, agreeing on no motion, never do.

    Initial clusters should be spatial pieces (Euclidean, DBSCAN, SAM masks, k-means on
    the a-points, voxels): that every initial cluster mixes two motions in equal parts
    (random labels) is the one case where the paper variant does better, since its
    clusters compete until one motion wins each, while the robust variant merges such
    clusters first (their average motions agree).

    **When to use the paper variant**: to reproduce the paper, or on clean data whose
    initial clusters already satisfy Definition 2, where both give the same objects
    (Theorem 1 holds for both) and the paper variant is faster.

    Choices the paper leaves open (both variants):

    * **Ties** in the M-step keep a correspondence in its current cluster; among other
      clusters the lowest index wins.
    * **sigma** is ``sqrt(tr(cov(E_j)) / d)`` with the sample covariance (``ddof=1``),
      never below ``sigma_floor``; one-point clusters get ``sigma_floor``. Without a floor
      the sigmas of exact fits are rounding noise and would decide assignments at random.
      (The robust variant divides by the degrees of freedom ``d n - d(d+1)/2``.)
    * **Points no cluster may take** (their own cluster was removed and no other is
      within ``tau``) are labelled ``-1``. They are not in any cluster, so they do not
      move the poses, but every M-step offers them to the clusters again.
    * **Initial labels below 0** mark correspondences in no cluster, handled as above.
    * The returned poses, sigmas and weights are refitted on the final clusters (robust
      variant: on their inliers).

    **Inputs that are not what they claim.** Rows with NaN, and rows whose a- or
    b-point lies exactly at the origin ``(0, ..., 0)`` together with another row's
    (LiDAR drivers write failed returns there; one point at the origin is kept), are
    dropped before the fit and labelled -1 (``n_invalid_``); :meth:`predict` labels them
    -1 and :meth:`score_samples` gives them NaN. Infinity is refused. ``X`` whose rows
    pair points across the scene (two point clouds sampled independently, stacked row by
    row) is refused with a ValueError pointing to :class:`SweepRegistration`: the flows
    ``b - a`` of nearest a-points differ by a median of more than ``tau``, four times
    the a-points' median spacing and half their median distance from their median
    (generated and real flows: at most 0.27 of it, with half of the correspondences
    wrong; two sweeps sampled independently: 1.24 to 1.85;
    :func:`~mmreg._validation.check_paired`). The robust variants fit each distinct row
    once (a copy of a row is no second measurement): duplicated rows take their
    original's label and do not change the others'.

    Warnings: a :class:`~sklearn.exceptions.ConvergenceWarning` when ``max_iter`` ends
    the iterations before they settle, and a :class:`ScaleWarning` when ``tau`` is less
    than four times the median nearest-neighbour distance of the a-points, or more than
    the diagonal of their bounding box (the gate then never separates anything); the
    points are probably in other units than ``tau``. A :class:`ScaleWarning` also when
    the static world of ``variant="sweep"`` (``static_cluster_``, or clusters that turn
    alike and hold more than ``static_share`` of the correspondences) turns by more than 30
    degrees: a sensor
    turns a few degrees between two frames, so the flow ``b - a`` is probably in other
    units than the points (points in metres, flow in millimetres: 83 degrees on an
    Argoverse 2 sweep).

    :meth:`score` is the mean log-likelihood of correspondences under the fitted
    mixture, the gate of eq. (7) applied as the E-step applies it (the static world of
    ``variant="sweep"`` admitted everywhere); the robust variants' outlier component
    is ``log_outlier_density_``, the paper variant's the same uniform density with the
    weight of its unclustered correspondences (see :meth:`score_samples`).

    Each iteration costs one batched SVD for the poses of the clusters that changed and
    scores each spatial block of correspondences only against the clusters whose
    bounding ball, grown by ``tau``, reaches it and which could beat the block's own
    clusters; the gate itself is tested with KD-trees only for correspondences whose
    best cluster is not their own. Memory stays linear in ``n``; time is about linear
    in ``n`` and sub-linear in the number of initial clusters (see ``benchmarks/``).

    References
    ----------
    D. Jin, S. Karmalkar, H. Zhang and L. Carlone, "Multi-Model 3D Registration: Finding
    Multiple Moving Objects in Cluttered Point Clouds", ICRA 2024.

    A. Myronenko and X. Song, "Point Set Registration: Coherent Point Drift", TPAMI 2010.

    H. Isack and Y. Boykov, "Energy-based Geometric Multi-Model Fitting", IJCV 2012.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg import MultiModelRegistration
    >>> rng = np.random.default_rng(0)
    >>> a = np.vstack([rng.uniform(0, 1, (50, 3)), rng.uniform(5, 6, (50, 3))])
    >>> b = a + rng.normal(scale=0.01, size=a.shape)
    >>> b[:50] += [1.0, 0.0, 0.0]                 # the first object moves, the second not
    >>> b[::10] += rng.uniform(1, 3, (10, 3))    # every tenth correspondence is wrong
    >>> X = np.hstack([a, b])
    >>> init = np.repeat([0, 1, 2, 3], [30, 20, 30, 20])  # two clusters per object
    >>> est = MultiModelRegistration(init=init).fit(X)
    >>> est.n_clusters_, int(est.outlier_mask_.sum())
    (2, 10)
    >>> np.round(est.translations_[est.labels_[1]], 1) + 0.0
    array([1., 0., 0.])
    >>> MultiModelRegistration(init=init, variant="paper").fit(X).n_clusters_
    4
    >>> one_motion = MultiModelRegistration(init=np.zeros(100, dtype=int), variant="paper")
    >>> bool(est.score(X) > one_motion.fit(X).score(X))  # mean log-likelihood
    True
    """

    _no_cluster_hint = "Lower min_cluster_size, raise tau, or use a coarser initial clustering."

    _parameter_constraints: dict = {
        **BaseRegistration._parameter_constraints,
        "tau": [Interval(Real, 0, None, closed="neither"), None],
        "min_cluster_size": [Interval(Integral, 1, None, closed="left")],
        "max_iter": [Interval(Integral, 0, None, closed="left")],
        "init": INIT_CONSTRAINT,
        "variant": [StrOptions({"robust", "sweep", "paper"})],
        "confidence": [Interval(Real, 0, 1, closed="neither")],
        "n_hypotheses": [Interval(Integral, 0, None, closed="left")],
        "noise_model": [StrOptions({"range", "constant"})],
        "static_share": [Interval(Real, 0, 1, closed="right"), None],
        "min_motion": [Interval(Real, 0, None, closed="left"), StrOptions({"auto"})],
        "motion_tolerance": [Interval(Real, 0, None, closed="left")],
        "skip_steps": [tuple, list],
        "tol": [Interval(Real, 0, 1, closed="left"), None],
        "voxel_size": [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"}), None],
        "random_state": ["random_state"],
        "n_jobs": [Integral, None],
        "verbose": ["verbose"],
    }

    def __init__(
        self,
        *,
        tau=1.5,
        min_cluster_size=4,
        max_iter=10,
        init="euclidean",
        variant="sweep",
        confidence=0.999,
        n_hypotheses=32,
        noise_model="range",
        static_share=0.5,
        min_motion="auto",
        motion_tolerance=0.2,
        tol=None,
        skip_steps=(),
        voxel_size="auto",
        sigma_floor=None,
        random_state=None,
        n_jobs=None,
        verbose=0,
    ):
        self.tau = tau
        self.min_cluster_size = min_cluster_size
        self.max_iter = max_iter
        self.init = init
        self.variant = variant
        self.confidence = confidence
        self.n_hypotheses = n_hypotheses
        self.noise_model = noise_model
        self.static_share = static_share
        self.min_motion = min_motion
        self.motion_tolerance = motion_tolerance
        self.tol = tol
        self.skip_steps = skip_steps
        self.voxel_size = voxel_size
        self.sigma_floor = sigma_floor
        self.random_state = random_state
        self.n_jobs = n_jobs
        self.verbose = verbose

    @_fit_context(prefer_skip_nested_validation=False)
    def fit(self, X, y=None, ego_motion=None):
        """Find the moving objects, their motions and the outliers.

        Parameters
        ----------
        X : array-like of shape (n_samples, 2 * d)
            Stacked correspondences ``[a | b]``; ``d = 3`` for point clouds.
        y : Ignored
            Not used, present for API consistency.
        ego_motion : tuple of (ndarray, ndarray), ndarray or None, default=None
            ``variant="sweep"``: the static world's motion from the a-points' frame to the
            b-points', ``b = R a + t`` for a static point, as ``(R, t)`` (shapes
            ``(d, d)`` and ``(d,)``) or a homogeneous ``(d + 1, d + 1)`` matrix, when the
            sensor's motion is known (odometry; Argoverse 2's
            ``inv(city_SE3_ego[t+1]) @ city_SE3_ego[t]``; ``SweepRegistration``'s
            ``ego_motion_``). The static world is then every cluster whose motion carries
            its points within ``min_motion`` (beyond its own scatter) of where this one
            carries them, whatever their share of the scene, and none if no cluster
            does; ``static_share`` is not consulted. None: the static world is found
            from the data (``static_share``).

        Returns
        -------
        self : MultiModelRegistration
            The fitted estimator.
        """
        X, a, b = self._validate_correspondences(X, reset=True, allow_nan=True)
        if ego_motion is not None and self.variant != "sweep":
            raise ValueError(
                f"ego_motion names the static world of variant='sweep'; variant="
                f"{self.variant!r} has none. Use variant='sweep' or leave ego_motion out."
            )
        ego_motion = check_ego_motion(ego_motion, a.shape[1])
        vars(self).pop("_cluster_labels", None)  # a previous fit's
        invalid = invalid_rows(X)
        self.n_invalid_ = int(np.count_nonzero(invalid))
        if self.n_invalid_ > len(X) - MIN_CORRESPONDENCES:
            raise ValueError(
                f"X holds {len(X) - self.n_invalid_} valid correspondences of {len(X)} "
                f"(at least {MIN_CORRESPONDENCES} are needed): the others hold NaN or "
                "points at the origin (0, 0, 0), a LiDAR driver's failed returns."
            )
        kept, source = self._rows_to_fit(X, invalid)
        init = self.init
        if kept is not None:
            if is_label_array(init):
                init = check_labels(init, len(X), name="init labels")[kept]
            X, a, b = X[kept], a[kept], b[kept]
        self._warn_if_sensor_away(a)
        self._fit_valid(X, a, b, init, ego_motion)
        if kept is not None:
            self._restore_rows(source)
        self._warn_if_static_world_turns()
        if self.max_iter > 0 and not self.converged_:
            warn(
                f"The EM did not settle within max_iter={self.max_iter} iterations; raise "
                "max_iter (or, with the paper variant, use a coarser initial clustering).",
                ConvergenceWarning,
            )
        return self

    def _fit_valid(self, X, a, b, init, ego_motion=None):
        """:meth:`fit` on the valid rows."""
        workers = self._workers()
        all_a, all_b, n = a, b, len(X)
        # SweepRegistration's rounds fit the same a-points: their sample and neighbour
        # table are computed once (a PointMemo it hands over; None: computed here).
        memo = vars(self).pop("_point_memo", None)
        rows = self._fitted_rows(a, memo)
        if rows is not None:
            X, a, b = X[rows], a[rows], b[rows]
        # The robust variants' neighbour table, listed once for the initial clusters too.
        neighbours = None
        if self.variant != "paper" and reads_neighbours(self.skip_steps):
            # SweepRegistration's rounds (a memo) list a sweep's points: on small_gicp's
            # tree, in half the time. Other inputs keep scipy's exact distances.
            tree = cKDTree if memo is None else PointTree
            table = functools.partial(NeighbourTable, a, workers=workers, tree=tree)
            neighbours = table() if memo is None else memo.get(("table", workers), a, table)
        # Before any warning about tau: two sweeps stacked row by row are no input at all.
        known = neighbours is not None and neighbours.k > 1
        check_paired(
            a,
            b,
            self.tau,
            nearest=neighbours.index[:, 1] if known else None,
            spacing=neighbours.distance[:, 1] if known else None,
        )
        self._warn_if_tau_off_scale(a, neighbours)
        self.min_motion_ = self._resolve_min_motion(a, neighbours)
        if rows is not None and is_label_array(init):
            init = check_labels(init, n, name="init labels")[rows]
        self.init_labels_ = initial = initial_labels(
            init,
            X,
            random_state=self.random_state,
            n_jobs=self.n_jobs,
            tau=self.tau,
            neighbours=neighbours,
        )
        # A refit with another variant must not keep the robust variants' attributes.
        for name in _ROBUST_ATTRIBUTES:
            vars(self).pop(name, None)
        if self.variant == "paper":
            result = multi_model_em(
                a,
                b,
                self.init_labels_,
                tau=self.tau,
                min_cluster_size=self.min_cluster_size,
                max_iter=self.max_iter,
                sigma_floor=self.sigma_floor,
                workers=workers,
                verbose=self.verbose,
            )
            self.history_ = []
        else:
            result = robust_multi_model_em(
                a,
                b,
                self.init_labels_,
                tau=self.tau,
                min_cluster_size=self.min_cluster_size,
                max_iter=self.max_iter,
                sigma_floor=self.sigma_floor,
                confidence=self.confidence,
                n_hypotheses=self.n_hypotheses,
                noise_model=self.noise_model,
                static_share=self.static_share,
                min_motion=self.min_motion_,
                motion_tolerance=self.motion_tolerance,
                tol=(1e-2 if self.variant == "sweep" else 1e-3) if self.tol is None else self.tol,
                skip_steps=tuple(self.skip_steps),
                sweep=self.variant == "sweep",
                ego_motion=ego_motion,
                neighbours=neighbours,
                random_state=self.random_state,
                verbose=self.verbose,
                workers=workers,
            )
            self.history_ = result.history
            self.log_outlier_density_ = result.log_outlier_density
            self.noise_growth_ = result.noise_growth
            self.static_cluster_ = result.static_cluster
            self.moving_ = result.moving
        labels, rotations, translations, sigmas = (
            result.labels,
            result.rotations,
            result.translations,
            result.sigmas,
        )
        weights = result.weights
        if rows is not None:
            a, b = all_a, all_b
            noise_scale = self._noise_scale(a)
            labels = self._judge_the_rest(a, b, rows, result, noise_scale, workers)
            labels, n_new = self._propose_in_the_rest(a, b, labels, result, noise_scale)
            rotations, translations, sigmas = self._refit_on_all(
                a, b, labels, result, noise_scale, len(result.sigmas) + n_new
            )
            weights = np.bincount(labels[labels >= 0], minlength=len(sigmas)) / n
            self.init_labels_ = np.full(n, -1, dtype=np.intp)
            self.init_labels_[rows] = initial
        self._store_clusters(a, b, labels, rotations, translations, sigmas, weights)
        self.outlier_mask_ = self.labels_ < 0
        self.n_iter_ = result.n_iter
        self.converged_ = result.converged

    def _resolve_min_motion(self, a, neighbours=None):
        """``min_motion`` as a length: ``"auto"`` is ``tau / 100``, or the median spacing
        of the a-points when there is no ``tau``."""
        if self.min_motion != "auto":
            return float(self.min_motion)
        if self.tau is None:
            return median_spacing(a, neighbours=neighbours)
        return float(self.tau * _MIN_MOTION_PER_TAU)

    def _rows_to_fit(self, X, invalid):
        """The rows fitted, ``(kept, source)``: the valid ones and, robust variants, each
        distinct row once (a copy of a row is no second measurement, and must not change
        the answer); ``source[i]`` is the fitted row that row ``i`` takes its results
        from, -1 if invalid. ``(None, None)`` when every row is fitted."""
        valid = np.flatnonzero(~invalid)
        first_of = np.arange(len(valid))
        if self.variant != "paper":
            first_of = _first_copies(X[valid])
        is_first = first_of == np.arange(len(valid))
        if np.count_nonzero(is_first) < MIN_CORRESPONDENCES:
            first_of, is_first = np.arange(len(valid)), np.ones(len(valid), dtype=bool)
        kept = valid[is_first]
        source = np.full(len(X), -1, dtype=np.intp)
        source[valid] = (np.cumsum(is_first) - 1)[first_of]
        if len(kept) == len(X):
            return None, None
        return kept, source

    def _restore_rows(self, source):
        """Give the fitted per-row attributes a row for every input row: a duplicate its
        original's, an invalid one -1 (flow NaN). ``predict`` and ``score`` keep the
        fitted rows'."""
        self._cluster_labels = self.labels_
        fitted = source >= 0
        n = len(source)
        labels = np.full(n, -1, dtype=np.intp)
        labels[fitted] = self.labels_[source[fitted]]
        init = np.full(n, -1, dtype=np.intp)
        init[fitted] = self.init_labels_[source[fitted]]
        flow = np.full((n, self.flow_.shape[1]), np.nan)
        flow[fitted] = self.flow_[source[fitted]]
        self.labels_, self.init_labels_, self.flow_ = labels, init, flow
        self.outlier_mask_ = labels < 0

    def _warn_if_static_world_turns(self):
        """A static world that turns by more than MAX_STATIC_TURN_DEGREES: other units.

        The static world is ``static_cluster_`` or, when the sweep variant found none
        (a flow in other units breaks it into pieces: Argoverse 2's ground truth times
        1000 gives 54 clusters turning 79-82 degrees), the clusters that turn within
        ``_SAME_TURN_DEGREES`` of the largest one, if they hold more than ``static_share``
        of the correspondences.
        """
        if self.variant != "sweep" or self.static_share is None or not self.n_clusters_:
            return
        if self.rotations_.shape[-1] not in (2, 3):
            return
        static = getattr(self, "static_cluster_", -1)
        reference = static if static >= 0 else int(np.argmax(self.weights_))
        alike = rotation_angle(self.rotations_, self.rotations_[reference]) <= _SAME_TURN_DEGREES
        if static >= 0:
            alike = np.arange(self.n_clusters_) == static
        share = float(np.sum(self.weights_[alike]))
        angle = float(rotation_angle(self.rotations_[reference]))
        if share > self.static_share and angle > MAX_STATIC_TURN_DEGREES:
            warn(
                f"The static world ({share:.0%} of the correspondences) turns {angle:.0f} "
                "degrees between a and b; a sensor turns a few degrees between two frames. "
                "Are the flow b - a and the points in the same units (e.g. points in "
                "metres and flow in millimetres)?",
                ScaleWarning,
            )

    def _fitted_rows(self, a, memo=None):
        """The rows the loop fits: one per voxel of ``voxel_size``, None for all; sets
        ``voxel_size_``."""
        side, rows = self.voxel_size, None
        if side == "auto":
            if self.variant != "paper" and len(a) > _AUTO_SAMPLE_ABOVE:
                sample = functools.partial(voxel_sample, a, _AUTO_SAMPLE_VOXELS)
                side, rows = sample() if memo is None else memo.get("sample", a, sample)
            else:
                side = None
        elif side is not None:
            if self.variant == "paper":
                raise ValueError(
                    "voxel_size needs a robust variant (variant='sweep' or 'robust'); the "
                    "paper variant fits every correspondence, as Algorithm 1 does."
                )
            rows = voxel_representatives(a, side)
        if rows is None or len(rows) == len(a):
            self.voxel_size_ = None
            return None
        self.voxel_size_ = float(side)
        return rows

    def _judge_the_rest(self, a, b, rows, result, noise_scale, workers):
        """Labels of every correspondence, those left out of the fit judged by its
        pieces (:func:`assign_to_pieces`)."""
        n = len(a)
        labels = np.full(n, -1, dtype=np.intp)
        labels[rows] = result.labels
        rest = np.ones(n, dtype=bool)
        rest[rows] = False
        rest = np.flatnonzero(rest)
        labels[rest] = assign_to_pieces(
            a[rest],
            b[rest],
            result.pieces,
            tau=self.tau,
            log_outlier=result.log_outlier_density,
            noise_scale=None if noise_scale is None else noise_scale[rest],
            false_alarms=_FALSE_ALARMS * len(rest) / n if self.variant == "sweep" else None,
            workers=workers,
        )
        return labels

    def _propose_in_the_rest(self, a, b, labels, result, noise_scale):
        """New clusters among the correspondences that no piece explains
        (:func:`propose_in_the_rest`): small objects that the sample saw as a handful."""
        if "proposals" in self.skip_steps:
            return labels, 0
        return propose_in_the_rest(
            a,
            b,
            labels,
            result.pieces,
            _static_motion(result),
            tau=self.tau,
            log_outlier=result.log_outlier_density,
            noise_scale=noise_scale,
            min_cluster_size=self.min_cluster_size,
            sigma_floor=self.sigma_floor,
            n_hypotheses=self.n_hypotheses,
            confidence=self.confidence,
            min_motion=self.min_motion_,
            static=result.static_cluster,
            moving=result.moving,
            motion_tolerance=(
                self.motion_tolerance
                if joins_moving_pieces(
                    self.variant == "sweep", self.skip_steps, self.motion_tolerance
                )
                else None
            ),
            sweep=self.variant == "sweep",
            random_state=self.random_state,
        )

    def _refit_on_all(self, a, b, labels, result, noise_scale, n_clusters):
        """The clusters' motions and noise scales refitted on all their members, and
        which of them move (``moving_``)."""
        static = result.static_cluster
        models, self.moving_ = refit_clusters(
            a,
            b,
            labels,
            n_clusters,
            static,
            _static_motion(result),
            sigma_floor=self.sigma_floor,
            noise_scale=noise_scale,
            confidence=self.confidence if "trimming" not in self.skip_steps else 1.0,
            sweep=self.variant == "sweep",
            min_motion=self.min_motion_,
        )
        return models.rotations, models.translations, models.sigmas

    def _warn_if_sensor_away(self, a):
        """A SensorFrameWarning where the a-points lie farther from the origin than they
        extend (a map's or world frame): the robust variants read the origin as the
        sensor (the noise grows with range from it; the static world is the cluster
        behind the others, seen from it). A 1 km offset changed 4 % of a street's labels
        (gross errors 10 % -> 14 %); the paper's variant does not read it."""
        if self.variant == "paper" or a.shape[1] != 3:
            return
        for problem in sensor_frame_problems(a):
            if problem[0] == "away":
                _, gap, extent = problem
                warn(
                    f"the a-points lie {gap:.3g} from the origin, farther than they extend "
                    f"({extent:.3g}): variant={self.variant!r} reads the origin as the "
                    "sensor (noise grows with the range from it, and the static world lies "
                    "behind the objects, seen from it). Give the correspondences in the "
                    "first sensor's frame (subtract its position).",
                    SensorFrameWarning,
                )

    def _warn_if_tau_off_scale(self, a, neighbours=None):
        if self.tau is None:
            return
        for problem, length in tau_off_scale(a, self.tau, neighbours):
            if problem == "spacing":
                message = (
                    f"tau={self.tau:g} spans fewer than {_MIN_GATE_SPACINGS:g} times the median "
                    f"distance between neighbouring a-points ({length:.3g}): clusters can grow "
                    "by a point or two per iteration and hardly merge. Are tau and the points "
                    "in the same units?"
                )
            else:
                message = (
                    f"tau={self.tau:g} exceeds the diagonal of the a-points' bounding box "
                    f"({length:.3g}): the gate of eq. (7) joins any two points of the scene, "
                    "so objects that move alike merge however far apart they are. Are tau "
                    "and the points in the same units? (tau=None turns the gate off on "
                    "purpose.)"
                )
            warn(message, ScaleWarning)

    def predict(self, X):
        """Assign correspondences to the fitted motions.

        Each row goes to the cluster of largest weighted likelihood
        ``pi_j phi_j(b | a)`` (eq. 7) among the clusters whose fitted a-points lie within
        ``tau`` of its a-point (and, ``variant="sweep"``, the static world, which the
        E-step admits everywhere); ``-1`` if there is none or, with the robust variants,
        if the fitted outlier component explains it better.

        Parameters
        ----------
        X : array-like of shape (n_samples, 2 * d)
            Stacked correspondences ``[a | b]``.

        Returns
        -------
        labels : ndarray of shape (n_samples,)
        """
        if self.variant == "paper":
            return super().predict(X)
        check_is_fitted(self, "labels_")
        X, a, b = self._validate_correspondences(X, reset=False, allow_nan=True)
        return self._per_valid_row(X, a, b, self._judge, fill=-1)

    def _judge(self, a, b):
        """The robust variants' :meth:`predict` on valid rows."""
        return judge_correspondences(
            a,
            b,
            self.rotations_,
            self.translations_,
            self.sigmas_,
            self.weights_,
            self._fitted_gate(),
            self.log_outlier_density_,
            self._noise_scale(a),
            false_alarms=_FALSE_ALARMS if self.variant == "sweep" else None,
        )

    def _noise_scale(self, a):
        """Each correspondence's relative noise scale ``g_i`` (None: all 1)."""
        growth = getattr(self, "noise_growth_", 0.0)
        return range_noise_scale(a, growth) if growth > 0 else None

    def _fitted_gate(self):
        """The gate of eq. (7) as the E-step applies it: the static world admitted everywhere."""
        static = getattr(self, "static_cluster_", -1)
        return ClusterGate(
            self._cluster_points,
            self._fitted_labels(),
            self.n_clusters_,
            self.tau,
            ungated=[static] if static >= 0 else [],
            workers=self._workers(),
        )

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        # Rows with NaN are padding: left out of the fit and labelled -1 (n_invalid_).
        tags.input_tags.allow_nan = True
        return tags

    def _log_outlier_density(self):
        """The robust variants' fitted outlier component; the paper's: the base class's."""
        fitted = getattr(self, "log_outlier_density_", None)
        return super()._log_outlier_density() if fitted is None else fitted


def _first_copies(X):
    """For each row of ``X``, the first row equal to it (itself if none is).

    Rows are compared through one linear combination of their columns (equal rows give
    equal values), and exactly only where two values agree: a sort instead of a sort of
    every row's bytes (30 ms against 120 ms on an Argoverse 2 sweep).
    """
    first_of = np.arange(len(X))
    weights = np.sqrt(np.arange(2, X.shape[1] + 2, dtype=float))  # rationally independent
    key = X @ weights
    order = np.argsort(key, kind="stable")
    tie = key[order[1:]] == key[order[:-1]]
    if not tie.any():
        return first_of
    candidates = np.sort(order[np.concatenate([tie, [False]]) | np.concatenate([[False], tie])])
    rows = np.ascontiguousarray(X[candidates]).view(np.dtype((np.void, 8 * X.shape[1])))
    _, firsts, inverse = np.unique(rows.ravel(), return_index=True, return_inverse=True)
    first_of[candidates] = candidates[firsts][inverse.ravel()]
    return first_of


def _static_motion(result):
    """The static world's motion ``(R, t)`` of a robust fit, None without one."""
    static = result.static_cluster
    return (result.rotations[static], result.translations[static]) if static >= 0 else None
