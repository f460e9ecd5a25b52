"""The ego motion between two raw LiDAR sweeps: GICP from the identity, coarse to fine.

The engine is small_gicp's generalized ICP (Segal et al., RSS 2009; Koide, 2024): every
voxel-downsampled point carries the covariance of its neighbourhood, so a match counts
along the surface's normal only, on both sweeps at once. It was measured beside our own
point-to-plane ICP (``mmreg.sweeps._icp.multi_body_icp``) and KISS-ICP on real Argoverse 2 pairs
and on ray-cast street sweeps (``benchmarks/ego_motion.py``): it was the most accurate.

Every length is a multiple of the one length the caller gives, ``scale``: the points are
moved near the origin (:func:`layout_origin`) and divided by it before the engine sees
them (small_gicp's convergence test and its optimiser's damping are in absolute units), so
scaled inputs give the same motion, its translation scaled (to 1e-9 for scales from 1e-3
to 1e3: tests/test_ego_motion.py).

With ``robust=True`` a last stage reweights the fine voxels' matches by a kernel of
their Mahalanobis distances (small_gicp has none), so that moving objects lose their pull.

A displacement of up to ``max_displacement`` is found from the identity by halving the
correspondence distance from ``max_displacement`` down to the fine one, each stage on a
voxel grid a quarter of its reach, started from the last. The ground is kept: it holds
roll, pitch and height.
"""

import importlib.util
import numbers

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from mmreg._validation import check_ego_motion
from mmreg.sweeps._icp import SurfaceNormals, multi_body_icp, subsample_groups

__all__ = ["ego_motion", "fine_cloud", "has_small_gicp", "layout_origin", "pair_ego_motion"]

# Fine stage, in units of ``scale`` (5 m for LiDAR in metres: 0.25 m voxels, 1 m reach,
# small_gicp's own defaults for driving sweeps).
_FINE_VOXEL = 1 / 20
_FINE_REACH = 1 / 5
# A coarse stage's voxels are this share of its correspondence distance.
_VOXEL_PER_REACH = 1 / 4
# Neighbours of each fine point's covariance (15 beat small_gicp's 10 on all three
# real pairs, rotation and static EPE; benchmarks/results/ego_motion.md).
_NEIGHBOURS = 15
_COARSE_NEIGHBOURS = 10
# A stage has converged when a step turns by less than this (radians) and moves by less
# than this share of ``scale``: the coarse stages only bring the fine one within its reach.
_COARSE_TOL = 1e-3
_FINE_TOL = 1e-5
_MAD_TO_SIGMA = 1.4826
# The residual scale is measured on at most about this many of the first sweep's points
# (SweepRegistration's max_points), with multi_body_icp's normals and scan-line test.
_RESIDUAL_POINTS = 5000
_NORMAL_NEIGHBOURS = 10
_MIN_FLATNESS = 0.2
# GICP needs at least this many points on each side (a covariance needs 3, a motion 6).
_MIN_POINTS = 10
# The robust fine stage: a Geman-McClure kernel this many robust scales of the
# Mahalanobis distances wide, annealed from _START_WIDTH by this factor a step, with at
# least _MIN_ANNEAL steps and at most _ROBUST_ITER; a floor on the scale (distances of
# noiseless planes are 0) and the step length (radians, scales) that ends it.
_KERNEL = 3.0
_START_WIDTH = 10.0
_ANNEAL = 0.7
_MIN_ANNEAL = 10
_ROBUST_ITER = 100
_DISTANCE_FLOOR = 1e-3
_ROBUST_TOL = 1e-7
# small_gicp's voxel grid drops points more than 2**20 voxels from the origin.
_MAX_VOXELS = 2**20
# The grid (in fine voxels) that the voxels' layout origins are rounded to: 256 m at a
# scale of 5 m, so that a LiDAR sweep in its sensor's frame (its mean within 128 m of the
# sensor) is laid out about the sensor, and a sweep far from its frame's origin about a
# point within 128 m of its mean (GICP's turns are about that point: far off, a turn's
# error would weigh on its shift).
_LAYOUT = 1024
# ... and the layout's shift off it, in fine voxels: no whole fraction, so that surfaces
# at round coordinates (a generated scene's ground at z = 0) lie inside voxels, not on
# their faces, where rounding would put their points on either side.
_LAYOUT_SHIFT = np.array([0.381966, 0.618034, 0.236068])
# A pair's ego motion: GICP's motion is replaced by our ICP's when its robust residual
# scale is below this share of GICP's (see pair_ego_motion). Measured ratios: 0.89-1.02
# on real and ray-cast sweeps (GICP the more accurate), 0.47-0.52 on sparse resampled
# boxes of which 40 % move, 0.0005-0.002 on noiseless boxes and walker scenes.
_EXACT_SHARE = 0.75


def has_small_gicp():
    """Whether small_gicp (the ego motion's GICP) is installed."""
    return importlib.util.find_spec("small_gicp") is not None


def layout_origin(points, scale):
    """Where :func:`fine_cloud` lays out the voxels of ``points``: their mean rounded to a
    multiple of ``_LAYOUT`` fine voxels, shifted by a fixed fraction of a voxel.

    A LiDAR sweep in its sensor's frame is laid out about that frame's origin, so the
    two sweeps of a pair share one voxel grid, however far the sensor moved: each
    sweep's voxels need no other sweep, and a log's sweep is laid out once for both
    pairs it is in. Far from the frame's origin (a map's coordinates) the rounding keeps
    the voxels' precision, and two sweeps that round apart are still laid out on one
    grid (``_LAYOUT`` is a whole number of fine voxels).
    """
    step = _LAYOUT * _FINE_VOXEL * scale
    return np.round(np.asarray(points).mean(axis=0) / step) * step + _LAYOUT_SHIFT * (
        _FINE_VOXEL * scale
    )


def fine_cloud(points, scale, workers=1):
    """small_gicp's fine cloud of ``points`` as :func:`ego_motion` makes it.

    The points moved to :func:`layout_origin` and divided by ``scale``, on voxels of
    ``1 / 20`` with the covariances of 15 neighbours: ``(PointCloud, KdTree, origin)``.

    Raises
    ------
    ValueError
        When the points reach farther from that origin than small_gicp's voxel grid
        holds (``scale`` out of proportion with them).
    """
    import small_gicp

    origin = layout_origin(points, scale)
    local = (points - origin) / scale
    extent = np.abs(local).max()
    if extent >= _MAX_VOXELS * _FINE_VOXEL:
        raise ValueError(
            f"the sweeps reach {extent:.3g} scales from their layout origin, more than "
            f"{_MAX_VOXELS * _FINE_VOXEL:.0f}; is scale={scale!r} in the points' units?"
        )
    cloud, tree = small_gicp.preprocess_points(
        local, _FINE_VOXEL, num_neighbors=_NEIGHBOURS, num_threads=workers
    )
    return cloud, tree, origin


def _check_points(points, name):
    array = np.asarray(points)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"{name} must be an array of shape (n, 3); got shape {array.shape}.")
    if not np.issubdtype(array.dtype, np.number) or np.iscomplexobj(array):
        raise ValueError(f"{name} must hold real numbers; got dtype {array.dtype}.")
    array = array.astype(np.float64, copy=False)
    if not np.isfinite(array).all():
        raise ValueError(f"{name} has NaN or infinite coordinates.")
    if len(array) < _MIN_POINTS:
        raise ValueError(f"{name} needs at least {_MIN_POINTS} points; got {len(array)}.")
    return array


def _check_length(value, name, *, allow_none=False):
    if value is None and allow_none:
        return None
    if (
        isinstance(value, bool)
        or not isinstance(value, numbers.Real)
        or not np.isfinite(value)
        or value <= 0
    ):
        raise ValueError(f"{name} must be a positive finite length; got {value!r}.")
    return float(value)


def _reaches(max_displacement):
    """Correspondence distances of the stages, in units of ``scale``: halving to the fine one."""
    reaches = []
    reach = max(max_displacement, _FINE_REACH)
    while reach > 2 * _FINE_REACH:
        reaches.append(reach)
        reach /= 2
    return reaches + [_FINE_REACH]


def _residual_scale(points, sweep, rotation, translation, reach, normals):
    """Robust scale (1.4826 MAD) of the point-to-plane residuals of ``points`` on ``sweep``.

    Measured as ``multi_body_icp`` measures a cluster's (the raw sweep's PCA normals of 10
    neighbours, matches within ``reach``, none on a scan line), so that the ego motion's
    scale and the islands' stay comparable. ``normals``: the sweep's SurfaceNormals or None.
    """
    if normals is None:
        normals = SurfaceNormals(sweep, cKDTree(sweep), _NORMAL_NEIGHBOURS)
    moved = points @ rotation.T + translation
    distance, nearest = normals.tree.query(moved, distance_upper_bound=reach)
    matched = np.flatnonzero(distance <= reach)
    normal, _, flatness = normals(nearest[matched])
    flat = flatness >= _MIN_FLATNESS
    if not flat.any():
        return float("nan")
    matched = matched[flat]
    residual = np.einsum("ni,ni->n", normal[flat], moved[matched] - sweep[nearest[matched]])
    return _MAD_TO_SIGMA * float(np.median(np.abs(residual)))


def _skew(vectors):
    """Cross-product matrices ``[v]x`` of ``(n, 3)`` vectors."""
    out = np.zeros((len(vectors), 3, 3))
    out[:, 0, 1], out[:, 0, 2], out[:, 1, 2] = -vectors[:, 2], vectors[:, 1], -vectors[:, 0]
    return out - out.transpose(0, 2, 1)


def _robust_gicp(source, source_covs, target, target_covs, motion, reach):
    """GICP with a Geman-McClure kernel on the Mahalanobis distances, from a close start.

    The kernel is ``_KERNEL`` robust scales (1.4826 MAD of the distances) wide, annealed
    down from ``_START_WIDTH``, so that the voxels off the static world's surfaces (moving
    objects) lose their pull instead of dragging the motion (small_gicp has no kernel).
    Works in units of ``scale``; returns the 4 x 4 motion.
    """
    tree = cKDTree(target)
    rotation, translation = motion[:3, :3].copy(), motion[:3, 3].copy()
    identity = np.broadcast_to(np.eye(3), (len(source), 3, 3))
    for iteration in range(_ROBUST_ITER):
        moved = source @ rotation.T + translation
        distance, nearest = tree.query(moved, distance_upper_bound=reach)
        matched = np.flatnonzero(distance <= reach)
        if len(matched) < _MIN_POINTS:
            break
        q, j = moved[matched], nearest[matched]
        residual = target[j] - q
        information = np.linalg.inv(target_covs[j] + rotation @ source_covs[matched] @ rotation.T)
        weighted = np.einsum("nij,nj->ni", information, residual)
        mahalanobis = np.sqrt(np.maximum(np.einsum("ni,ni->n", residual, weighted), 0.0))
        sigma = max(_MAD_TO_SIGMA * float(np.median(mahalanobis)), _DISTANCE_FLOOR)
        width = max(_KERNEL * sigma, _ANNEAL**iteration * _START_WIDTH)
        weight = 1.0 / (1.0 + (mahalanobis / width) ** 2) ** 2
        # residual = y - (R x + t); a left step (omega, v) changes it by [q]x omega - v.
        jacobian = np.concatenate([_skew(q), -identity[: len(q)]], axis=2)
        jt_info = np.einsum("nji,njk->nik", jacobian, information) * weight[:, None, None]
        hessian = np.einsum("nik,nkl->il", jt_info, jacobian)
        gradient = np.einsum("nik,nk->i", jt_info, residual)
        step = -np.linalg.solve(hessian + 1e-12 * np.trace(hessian) * np.eye(6), gradient)
        turn = Rotation.from_rotvec(step[:3]).as_matrix()
        rotation, translation = turn @ rotation, turn @ translation + step[3:]
        if iteration >= _MIN_ANNEAL and np.linalg.norm(step) < _ROBUST_TOL:
            break
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rotation, translation
    return out


def ego_motion(
    points,
    sweep,
    *,
    scale,
    max_displacement=None,
    max_iter=30,
    workers=1,
    sweep_normals=None,
    robust=False,
    init=None,
    clouds=None,
):
    """The rigid motion that carries one raw sweep onto the next, found from the identity.

    Parameters
    ----------
    points : array-like of shape (n, 3)
        The first sweep, in its sensor's frame.
    sweep : array-like of shape (m, 3)
        The second sweep, in its own sensor's frame; any size, any order.
    scale : float
        The caller's length (the estimator's ``tau``; 5 for LiDAR in metres). The fine
        stage works on voxels of ``scale / 20`` with correspondences up to ``scale / 5``.
    max_displacement : float or None, default=None
        The largest distance the sensor moves between the sweeps; None: ``scale``. The
        first stage matches points this far apart and the next ones halve the reach down
        to the fine one. (With the default, Argoverse 2 sweeps moved on by up to 6 m and
        turned by up to 10 degrees were registered from the identity.)
    max_iter : int, default=30
        Largest number of Gauss-Newton steps of each stage.
    workers : int, default=1
        Threads of small_gicp.
    sweep_normals : SurfaceNormals or None, default=None
        ``mmreg.sweeps._icp.SurfaceNormals(sweep, cKDTree(sweep), 10)`` where the caller keeps
        one (``SweepRegistration`` does): the residual scale then reuses its KD-tree and
        normals. None: built here.
    robust : bool, default=False
        End with a robust GICP stage on the fine voxels (a Geman-McClure kernel three
        robust scales of the Mahalanobis distances wide, annealed from far wider), so
        that moving objects do not drag the motion. On boxes of which a third drive off
        it recovers the ego motion to 0.4 mm where GICP alone is 9 cm off; on the real
        Argoverse 2 pairs its rotation is 0.04-0.06 degrees off against GICP's
        0.01-0.04 (``benchmarks/results/ego_motion.md``).
    init : tuple (rotation, translation) or None, default=None
        The start (e.g. a known ego motion from odometry), ``(3, 3)`` and ``(3,)`` in
        the points' units; None: the identity. The coarse stages start from it, so
        ``max_displacement`` then bounds how far off it may be.
    clouds : tuple or None, default=None
        The fine clouds of ``sweep`` and ``points``, in that order, where the caller
        keeps them: :func:`fine_cloud` of each with this ``scale`` and ``workers``. None:
        made here.

    Returns
    -------
    rotation : ndarray of shape (3, 3)
    translation : ndarray of shape (3,)
        ``points @ rotation.T + translation`` lies on ``sweep`` where the world is static.
    residual_scale : float
        Robust scale (1.4826 times the median absolute value) of the point-to-plane
        residuals of the first sweep's points (up to about 5,000 of them, evenly
        strided) on the second sweep (its PCA normals of 10 neighbours), those within
        ``scale / 5`` and not on a scan line, as ``multi_body_icp`` measures a cluster's;
        in the points' units.

    Raises
    ------
    ValueError
        When a point set is not ``(n, 3)`` real and finite with at least 10 points (and
        10 voxels of ``scale / 20``), a length is not positive and finite, or ``scale``
        is out of proportion with the points (some 52,428 scales or more from their
        :func:`layout_origin`).
    ImportError
        When small_gicp is not installed.

    Notes
    -----
    Cost: the fine voxel grid, covariances and KD-tree of both sweeps, a coarser grid of
    those per coarse stage, GICP on the voxel centres, then one KD-tree of the second
    sweep for the residual scale. On two 100,000-point Argoverse 2 sweeps, one thread:
    about twice ``small_gicp.align`` with its defaults and a third of the point-to-plane
    ICP it replaces (``benchmarks/results/ego_motion.md``).

    Examples
    --------
    A floor and two walls sampled twice, the second time seen from a sensor turned by 3
    degrees and moved on by 1.2 m:

    >>> import numpy as np
    >>> from mmreg.sweeps._ego_motion import ego_motion
    >>> rng = np.random.default_rng(0)
    >>> def corner(n):
    ...     p = rng.uniform(0, 30, (n, 3))
    ...     p[np.arange(n), rng.integers(0, 3, n)] = 0.0  # on one of three planes
    ...     return p
    >>> c, s = np.cos(np.deg2rad(3)), np.sin(np.deg2rad(3))
    >>> R, t = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]), np.array([-1.2, 0.4, 0.1])
    >>> a, sweep = corner(20000), corner(20000) @ R.T + t
    >>> rotation, translation, sigma = ego_motion(a, sweep, scale=5.0)
    >>> bool(np.allclose(rotation, R, atol=1e-3)), bool(np.allclose(translation, t, atol=1e-2))
    (True, True)
    """
    try:
        import small_gicp
    except ImportError as error:  # pragma: no cover - a core dependency
        raise ImportError("mmreg's ego motion needs small_gicp: pip install small_gicp") from error
    points = _check_points(points, "points")
    sweep = _check_points(sweep, "sweep")
    scale = _check_length(scale, "scale")
    max_displacement = _check_length(max_displacement, "max_displacement", allow_none=True)
    if sweep_normals is not None and (
        not isinstance(sweep_normals, SurfaceNormals) or sweep_normals.points.shape != sweep.shape
    ):
        raise ValueError(
            "sweep_normals must be None or the SurfaceNormals of sweep (same shape); got "
            f"{type(sweep_normals).__name__}."
        )
    for name, value in (("max_iter", max_iter), ("workers", workers)):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
            raise ValueError(f"{name} must be a positive integer; got {value!r}.")
    reach = (scale if max_displacement is None else max_displacement) / scale
    # Work in units of ``scale``, each sweep about its layout origin, so that every
    # length and tolerance inside the engine is relative (and far sweeps keep their
    # precision). The fine clouds first; the coarse stages' voxel grids are drawn from
    # them (a few times fewer points than the sweeps).
    if clouds is None:
        clouds = [fine_cloud(cloud, scale, workers) for cloud in (sweep, points)]
    fine = [(cloud, tree) for cloud, tree, _ in clouds]
    sweep_origin, origin = clouds[0][2], clouds[1][2]
    if min(cloud.size() for cloud, _ in fine) < _MIN_POINTS:
        raise ValueError(
            f"points and sweep need at least {_MIN_POINTS} voxels of scale / 20 each; got "
            f"{fine[1][0].size()} and {fine[0][0].size()} (is scale in the points' units?)."
        )
    fine_points = [np.asarray(cloud.points())[:, :3] for cloud, _ in fine]
    rotation, translation = (np.eye(3), np.zeros(3)) if init is None else check_ego_motion(init)
    # The start between the two layouts: (y - o2) / s = R (x - o) / s + t'.
    motion = np.eye(4)
    motion[:3, :3] = rotation
    motion[:3, 3] = (rotation @ origin + translation - sweep_origin) / scale
    for stage_reach in _reaches(reach):
        last = stage_reach == _FINE_REACH
        if last:
            (target, tree), (source, _) = fine
        else:
            voxel = stage_reach * _VOXEL_PER_REACH
            (target, tree), (source, _) = (
                small_gicp.preprocess_points(
                    cloud, voxel, num_neighbors=_COARSE_NEIGHBOURS, num_threads=workers
                )
                for cloud in fine_points
            )
            if min(target.size(), source.size()) < _MIN_POINTS:
                continue  # too coarse for this sweep's extent: the next stage starts
        tolerance = _FINE_TOL if last else _COARSE_TOL
        result = small_gicp.align(
            target,
            source,
            tree,
            init_T_target_source=motion,
            registration_type="GICP",
            max_correspondence_distance=stage_reach,
            num_threads=workers,
            max_iterations=max_iter,
            rotation_epsilon=tolerance,
            translation_epsilon=tolerance,
        )
        motion = np.asarray(result.T_target_source)
    if robust:
        (target, _), (source, _) = fine
        motion = _robust_gicp(
            fine_points[1],
            np.asarray(source.covs())[:, :3, :3],
            fine_points[0],
            np.asarray(target.covs())[:, :3, :3],
            motion,
            _FINE_REACH,
        )
    rotation = motion[:3, :3].copy()
    # Back from the scaled layouts: (y - o2) / s = R (x - o) / s + t'.
    translation = scale * motion[:3, 3] + sweep_origin - rotation @ origin
    # The residuals of the raw points (a voxel's centre averages their noise away), every
    # k-th one for a bounded cost.
    stride = -(-len(points) // _RESIDUAL_POINTS)
    sigma = _residual_scale(
        points[::stride], sweep, rotation, translation, _FINE_REACH * scale, sweep_normals
    )
    return rotation, translation, sigma


def pair_ego_motion(first, second, settings, rng, *, known=None, gicp=True):
    """A pair's dominant motion: GICP from the identity (or ``known``), then our ICP.

    GICP (:func:`ego_motion`, coarse to fine on voxels) finds motions up to
    ``max(tau, max_displacement)`` from the identity and is the more accurate on real
    sweeps (static EPE 12-17 mm against 18-34 mm on the Argoverse 2 pairs), but where
    moving objects make much of a scene, or the sweeps are noiseless, its voxels'
    covariances pull it centimetres off. Our raw-point ICP (Tukey's kernel) is then run
    from GICP's motion and kept only when its robust point-to-plane residual scale is
    under three quarters of GICP's: it is when GICP is off by more than the sampling
    noise (0.002-0.5 of it on box and walker scenes), never on real or ray-cast sweeps
    (0.89-1.02 of it; ``benchmarks/results/ego_motion.md``).

    Without small_gicp (``gicp`` False; Intel macOS has no wheel), our ICP alone, from
    the identity (or ``known``) with a reach of twice then once ``max_distance``.

    ``first`` and ``second`` are the sweeps'
    :class:`~mmreg.sweeps._sweep_state.SweepState`; ``settings`` a
    :class:`~mmreg.sweeps._settings.PairSettings`. Returns the motion, the ICP's motion
    (where the islands are tested) and its robust point-to-plane residual scale.
    """
    a = first.points
    sweep, tree, normals = second.target()
    labels = np.zeros(len(a), dtype=np.intp)
    keep = subsample_groups(labels, settings.max_points, rng)
    mask = np.full(len(a), -1, dtype=np.intp)
    mask[keep] = 0
    icp = {
        "tree": tree,
        "normals": normals,
        "max_iter": settings.max_icp_iter,
        "tol": settings.tol,
        "workers": settings.workers,
    }
    if not gicp:
        rotation, translation = (np.eye(3), np.zeros(3)) if known is None else known
        rotation, translation = rotation[None], translation[None]
        for reach in (2.0, 1.0):
            result = multi_body_icp(
                a,
                mask,
                rotation,
                translation,
                sweep,
                max_distance=reach * settings.max_distance,
                **icp,
            )
            rotation, translation = result.rotations, result.translations
        ego = (rotation[0], translation[0])
        return ego, ego, float(result.scales[0])
    tau = settings.tau
    reach = max(tau, settings.max_displacement)
    if known is not None:  # a start within the fine stage's reach: no coarse stage
        reach = _FINE_REACH * tau
    rotation, translation, sigma = ego_motion(
        a,
        sweep,
        scale=tau,
        max_displacement=reach,
        sweep_normals=normals,
        init=known,
        clouds=(second.ego_cloud(tau), first.ego_cloud(tau)),
    )
    gicp_motion = (rotation, translation)
    result = multi_body_icp(
        a,
        mask,
        rotation[None],
        translation[None],
        sweep,
        max_distance=settings.max_distance,
        **icp,
    )
    icp_motion = (result.rotations[0], result.translations[0])
    stride = -(-len(a) // _RESIDUAL_POINTS)
    icp_sigma = _residual_scale(a[::stride], sweep, *icp_motion, _FINE_REACH * tau, normals)
    # The islands' tests (their motions, the slow movers) weigh point-to-plane
    # residuals on the raw points: they read them at the ICP's motion, the minimum
    # of that cost, in the ICP's own scale (annealed, floored). At GICP's motion a
    # static wall keeps a residual of a few millimetres that reads as a slow mover.
    chosen = icp_motion if icp_sigma < _EXACT_SHARE * sigma else gicp_motion
    return chosen, icp_motion, float(result.scales[0])
