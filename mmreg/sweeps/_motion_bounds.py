"""Raw sweeps: motions no road user can make, relative to the static world.

A cluster's motion between the sweeps, relative to the static world's (``E^-1 M``), is
what a road user did in the interval. Vehicles and people are bounded:

* **speed**: its centroid moves at most :data:`MAX_SPEED` (50 m/s, 180 km/h) times the
  interval, when the interval is known; else at most ``reach`` (the estimator's
  ``max_displacement``, which stands for an unknown interval);
* **turn**: it turns (about any axis) at most :data:`VEHICLE_TURN_RATE` (90 deg/s: a
  car's tyres give about 1 g sideways, ``omega = sqrt(a / r)`` over the speeds at its
  smallest turning circle, 4-5 m: 1.4-1.6 rad/s) times the interval; a cluster no longer
  than a person (:data:`PERSON_LENGTH`, 1.2 m across, horizontally in a z-up sweep) may
  be one, who turns on the spot: :data:`PERSON_TURN_RATE` (360 deg/s). Only with the
  interval known;
* **shape**: no road user is a flat horizontal sheet (within 30 degrees of level) that
  slides along its own plane: such a cluster is a sliver of terrain or road that the
  ground left behind, whose point-to-plane fit cannot see any motion along it.

Every length is in the points' units; ``scale`` (the estimator's ``tau``, 5 for metres)
turns the physical constants into them: :data:`MAX_SPEED` and :data:`PERSON_LENGTH` are
multiplied by ``scale / 5``.

A free fit can break a bound on a real mover: the partial view of a car (an L of a few
dozen points) matches the car of the second sweep turned by 60-150 degrees about as well
as unturned, and its centroid then lands metres off. So a cluster that breaks the speed,
reach or turn bound in a z-up sweep is fitted once more as a road user moves: a level
shift (no turn; the static world's rotation and height) by a point-to-plane ICP started
where its motion takes its centroid along the ground (:func:`level_shift`). It keeps
that motion where the motion breaks no bound, most of its points show that it moved so
(the shift explains them on the second sweep and the static world's motion does not,
less twice those that only the static world's explains: a still patch's noise explains
a few either way), and the shift explains more of them than the broken motion did (the
free fit went astray; a cluster that really moves so is explained better by its own
fit). Else it has no admissible motion: each of its points rejoins the static world
where the static world's motion explains it (it lands on the second sweep,
:func:`mmreg.sweeps._explained.unexplained_mask`), and becomes an outlier where it does
not (no motion a road user can make explains it).
"""

import numpy as np

from mmreg._array.geometry import departures
from mmreg._array.moments import group_moments
from mmreg.sweeps._ambiguous_shapes import ACROSS, shapes
from mmreg.sweeps._explained import unexplained_mask
from mmreg.sweeps._level_icp import level_icp

__all__ = [
    "MAX_SPEED",
    "PERSON_LENGTH",
    "PERSON_TURN_RATE",
    "VEHICLE_TURN_RATE",
    "bound_motions",
    "impossible_motions",
    "level_shift",
    "max_travel",
    "object_motions",
]

#: Fastest road user relative to the static world, in units of ``tau / 5`` per second
#: (m/s for LiDAR in metres): 180 km/h.
MAX_SPEED = 50.0
#: Fastest turn of a vehicle, radians per second (90 deg/s).
VEHICLE_TURN_RATE = np.pi / 2
#: Fastest turn of a person (turning on the spot), radians per second (360 deg/s).
PERSON_TURN_RATE = 2 * np.pi
#: Longest a person is across (horizontally in a z-up sweep), in units of ``tau / 5``.
PERSON_LENGTH = 1.2
# The tau that stands for metres.
_METRE_TAU = 5.0


def max_travel(scale, interval):
    """The farthest a road user travels in ``interval`` seconds (:data:`MAX_SPEED`), in
    the points' units (``scale`` is the estimator's ``tau``; 5 stands for metres).

    Examples
    --------
    >>> from mmreg.sweeps._motion_bounds import max_travel
    >>> max_travel(5.0, 0.1), max_travel(0.5, 0.1)
    (5.0, 0.5)
    """
    return MAX_SPEED * (scale / _METRE_TAU) * interval


# A sheet is level within this angle (its normal within it of the vertical).
_LEVEL_DEG = 30.0
# The level shift's ICP (mmreg.sweeps._level_icp without the turn): its gate in units of
# tau (the estimator's default gate, a fifth of tau: 1 m) and its steps.
_SHIFT_GATE = 0.2
_SHIFT_STEPS = 30
# A re-fitted cluster's counter-evidence (points the static world explains and its shift
# does not) weighs this many times its evidence, as a track's does.
_AGAINST = 2


def object_motions(points, labels, motions, static):
    """Each cluster's own displacement and turn relative to the static world.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
    labels : ndarray of shape (n,)
        Cluster of every point, negative for none.
    motions : tuple of ndarray
        ``(rotations, translations)``, one per cluster (``b = R a + t``).
    static : int
        The static world's cluster (its motion is the reference); -1: the identity.

    Returns
    -------
    displacement : ndarray of shape (n_clusters, 3)
        Where the cluster's motion takes its centroid, less where the static world's
        does (NaN for a cluster without points).
    turn : ndarray of shape (n_clusters,)
        Angle of its rotation relative to the static world's, radians.

    Examples
    --------
    A cluster that moves 2 m along x while the sensor moves 1 m back (the static world
    moves by +1 m in the sensor's frame), turning 10 degrees:

    >>> import numpy as np
    >>> from scipy.spatial.transform import Rotation
    >>> from mmreg.sweeps._motion_bounds import object_motions
    >>> points = np.array([[10.0, 0, 0], [11, 0, 0], [20, 5, 0], [20, 6, 0]])
    >>> labels = np.array([0, 0, 1, 1])
    >>> turn = Rotation.from_euler("z", 10, degrees=True).as_matrix()
    >>> centre = np.array([20.0, 5.5, 0])
    >>> rotations = np.stack([np.eye(3), turn])
    >>> translations = np.array([[1.0, 0, 0], centre - turn @ centre + [3.0, 0, 0]])
    >>> d, angle = object_motions(points, labels, (rotations, translations), 0)
    >>> np.round(d[1], 6).tolist(), round(float(np.degrees(angle[1])), 6)
    ([2.0, 0.0, 0.0], 10.0)
    """
    rotations, translations = (np.asarray(m, dtype=float) for m in motions)
    n_clusters = len(rotations)
    labels = np.asarray(labels)
    clustered = labels >= 0
    counts = np.bincount(labels[clustered], minlength=n_clusters)
    sums = np.stack(
        [np.bincount(labels[clustered], points[clustered, i], n_clusters) for i in range(3)],
        axis=1,
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        centroids = sums / counts[:, None]
    ego = (rotations[static], translations[static]) if static >= 0 else (np.eye(3), np.zeros(3))
    displacement = departures(centroids, rotations, translations, ego)
    relative = np.einsum("ji,kjl->kil", ego[0], rotations)  # E^T M_k
    cosine = (np.trace(relative, axis1=1, axis2=2) - 1.0) / 2.0
    return displacement, np.arccos(np.clip(cosine, -1.0, 1.0))


def _lengths_across(moments, up):
    """How long each cluster is across: horizontally (``up`` given), else its middle
    principal length (a person's width, a car's height or width), as ``sqrt(12 var)``,
    the length of a uniform segment of that variance."""
    cov = moments.cross / np.maximum(moments.count, 1)[:, None, None]
    if up is not None:
        across = np.eye(3) - np.outer(up, up)  # the horizontal plane
        cov = across @ cov @ across
        spread = np.linalg.eigvalsh(cov)[:, 2]
    else:
        spread = np.linalg.eigvalsh(cov)[:, 1]
    return np.sqrt(12.0 * np.maximum(spread, 0.0))


def _level_slides(points, labels, moments, displacement, up):
    """Flat clusters, level within 30 degrees, whose displacement lies along their plane."""
    flat, _ = shapes(points, labels, len(moments.count))
    _, axes = np.linalg.eigh(moments.cross)
    normal = axes[:, :, 0]
    level = np.abs(normal @ up) >= np.cos(np.radians(_LEVEL_DEG))
    across = np.abs(np.einsum("ki,ki->k", np.nan_to_num(displacement), normal))
    length = np.linalg.norm(np.nan_to_num(displacement), axis=1)
    return flat & level & (across < ACROSS * length)


def impossible_motions(points, labels, motions, static, *, scale, reach, interval=None, up=None):
    """Which clusters move as no vehicle or person can, relative to the static world.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
        The first sweep.
    labels : ndarray of shape (n,)
        Cluster of every point, negative for none.
    motions : tuple of ndarray
        ``(rotations, translations)``, one per cluster.
    static : int
        The static world's cluster (never impossible); -1: none.
    scale : float
        The estimator's ``tau``: 5 stands for metres.
    reach : float
        The farthest a cluster's centroid may move when ``interval`` is None.
    interval : float or None
        Seconds between the sweeps: the speed and turn bounds.
    up : ndarray of shape (3,) or None
        The vertical of a z-up sweep: the shape bound, and lengths across measured
        horizontally.

    Returns
    -------
    impossible : ndarray of bool, shape (n_clusters,)
    reasons : list of str
        Per cluster, why (``""`` when possible): ``"speed"``, ``"reach"``, ``"turn"``,
        ``"sheet"``.

    Examples
    --------
    A car-sized box moving 29 m in 0.1 s, one moving 1 m in 0.1 s while turning
    110 degrees, one moving 1 m, and the static world:

    >>> import numpy as np
    >>> from scipy.spatial.transform import Rotation
    >>> from mmreg.sweeps._motion_bounds import impossible_motions
    >>> rng = np.random.default_rng(0)
    >>> box = rng.uniform([-2, -1, 0], [2, 1, 1.5], (60, 3))
    >>> points = np.vstack([box + [10, 0, 0], box + [0, 10, 0], box + [-10, 0, 0],
    ...                     rng.uniform(-30, 30, (200, 3)) * [1, 1, 0.1]])
    >>> labels = np.repeat([1, 2, 3, 0], [60, 60, 60, 200])
    >>> turn = Rotation.from_euler("z", 110, degrees=True).as_matrix()
    >>> centre = points[labels == 2].mean(axis=0)
    >>> rotations = np.stack([np.eye(3), np.eye(3), turn, np.eye(3)])
    >>> translations = np.array([[0, 0, 0], [29.0, 0, 0], centre - turn @ centre + [1, 0, 0],
    ...                          [1.0, 0, 0]])
    >>> bad, why = impossible_motions(points, labels, (rotations, translations), 0,
    ...                               scale=5.0, reach=3.0, interval=0.1, up=np.eye(3)[2])
    >>> bad.tolist(), why
    ([False, True, True, False], ['', 'speed', 'turn', ''])
    """
    labels = np.asarray(labels)
    n_clusters = len(motions[0])
    displacement, turn = object_motions(points, labels, motions, static)
    travel = np.linalg.norm(displacement, axis=1)
    metres = scale / _METRE_TAU
    moments = group_moments(points, points, labels, n_clusters)
    reasons = [""] * n_clusters
    rules = []
    if interval is None:
        rules.append(("reach", travel > reach))
    else:
        rules.append(("speed", travel > max_travel(scale, interval)))
        person = _lengths_across(moments, up) <= PERSON_LENGTH * metres
        rate = np.where(person, PERSON_TURN_RATE, VEHICLE_TURN_RATE)
        rules.append(("turn", turn > rate * interval))
    if up is not None:
        rules.append(("sheet", _level_slides(points, labels, moments, displacement, up)))
    impossible = np.zeros(n_clusters, dtype=bool)
    for name, broken in rules:
        for k in np.flatnonzero(broken & ~impossible):
            reasons[k] = name
        impossible |= broken
    if static >= 0:
        impossible[static] = False
        reasons[static] = ""
    empty = np.bincount(labels[labels >= 0], minlength=n_clusters) == 0
    impossible &= ~empty
    return impossible, [r if impossible[k] else "" for k, r in enumerate(reasons)]


def level_shift(points, start, static_motion, target, *, max_distance, up, max_iter=_SHIFT_STEPS):
    """A cluster's level shift by robust point-to-plane ICP: no turn, no climb.

    The points move by ``x + s`` (``s`` across ``up``, in the first sweep's frame), then
    by the static world's motion into the second sweep's frame, where the cost is read:
    the motion a road user makes at its simplest, driving on along the ground.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
        The cluster's points in the first sweep.
    start : ndarray of shape (3,)
        The shift to start from (its part along ``up`` is dropped).
    static_motion : tuple (R, t)
        The static world's motion, first sweep to second.
    target : tuple
        ``(sweep, tree, normals)`` of the second sweep.
    max_distance : float
        A point farther than this from the second sweep is not matched.
    up : ndarray of shape (3,)
        The vertical (unit) in the first sweep's frame.
    max_iter : int
        Largest number of Gauss-Newton steps.

    Returns
    -------
    shift : ndarray of shape (3,)
    scale : float
        The robust residual scale of the last step (NaN when too few points matched
        at the start).

    Examples
    --------
    A box seen again 1.5 m on along x, started 0.6 m beyond and 0.8 m up:

    >>> import numpy as np
    >>> from scipy.spatial import cKDTree
    >>> from mmreg.sweeps._icp import SurfaceNormals
    >>> from mmreg.sweeps._motion_bounds import level_shift
    >>> rng = np.random.default_rng(0)
    >>> def box(n):
    ...     p = rng.uniform(-1, 1, (n, 3)) * [2.0, 1.0, 0.7]
    ...     side = rng.integers(0, 3, n)
    ...     p[np.arange(n), side] = np.sign(rng.uniform(-1, 1, n)) * np.array([2.0, 1.0, 0.7])[side]
    ...     return p
    >>> sweep = box(20000) + [1.5, 0.0, 0.0]
    >>> tree = cKDTree(sweep)
    >>> target = (sweep, tree, SurfaceNormals(sweep, tree, 10))
    >>> shift, _ = level_shift(box(2000), np.array([2.1, 0.0, 0.8]), (np.eye(3), np.zeros(3)),
    ...                        target, max_distance=1.0, up=np.array([0.0, 0.0, 1.0]))
    >>> np.round(shift, 2) + 0.0
    array([1.5, 0. , 0. ])
    """
    rotation, translation = static_motion
    up = np.asarray(up, dtype=float)
    start_motion = np.eye(4)
    start_motion[:3, 3] = np.asarray(start, dtype=float) - up * (np.asarray(start) @ up)
    ego = np.eye(4)
    ego[:3, :3], ego[:3, 3] = rotation, translation
    fit = level_icp(
        points,
        start_motion,
        ego,
        target,
        max_distance=max_distance,
        max_iter=max_iter,
        up=up,
        turn=False,
    )
    # The shift: the level motion's translation (it does not turn).
    shift = rotation.T @ (fit.motion[:3, 3] - translation)
    return shift, fit.scale


def _explained(points, labels, clusters, motions, target, sigma):
    """Whether the second sweep explains each point of ``clusters`` (their rows in order,
    cluster by cluster) where the cluster's motion puts it (``motions``: rotations and
    translations, one row per cluster of ``clusters``)."""
    sweep, tree, normals = target
    rows = [np.flatnonzero(labels == k) for k in clusters]
    moved = np.vstack(
        [points[r] @ R.T + t for r, R, t in zip(rows, motions[0], motions[1], strict=True)]
    )
    unexplained, _ = unexplained_mask(moved, tree, sweep, normals, sigma)
    return ~unexplained


def _refit_level(points, labels, motions, static, target, sigma, impossible, reasons, bounds):
    """The clusters of ``impossible`` (but sheets) that a level shift explains instead.

    Returns the clusters re-fitted, their rotations, translations and robust scales.
    """
    up = bounds.get("up")
    clusters = [k for k in np.flatnonzero(impossible) if reasons[k] != "sheet"]
    if up is None or not clusters:
        return [], None, None, None
    rotations, translations = (np.asarray(m, dtype=float) for m in motions[:2])
    world = (rotations[static], translations[static])
    displacement, _ = object_motions(points, labels, (rotations, translations), static)
    gate = _SHIFT_GATE * bounds["scale"]
    shifts, scales = [], []
    for k in clusters:
        # Where its motion takes its centroid, in the first sweep's frame, along the ground.
        start = world[0].T @ displacement[k]
        shift, scale = level_shift(
            points[labels == k], start, world, target, max_distance=gate, up=up
        )
        shifts.append(shift)
        scales.append(scale)
    shifts = np.array(shifts)
    level = (
        np.broadcast_to(world[0], (len(clusters), 3, 3)),
        shifts @ world[0].T + world[1],
    )
    tried_r, tried_t = rotations.copy(), translations.copy()
    tried_r[clusters], tried_t[clusters] = level
    still, _ = impossible_motions(points, labels, (tried_r, tried_t), static, **bounds)
    counts = np.bincount(labels[labels >= 0], minlength=len(rotations))[clusters]
    owner = np.repeat(np.arange(len(clusters)), counts)
    broken = (rotations[clusters], translations[clusters])
    at_rest = (level[0], np.broadcast_to(world[1], (len(clusters), 3)))
    by_shift = _explained(points, labels, clusters, level, target, sigma)
    by_broken = _explained(points, labels, clusters, broken, target, sigma)
    by_static = _explained(points, labels, clusters, at_rest, target, sigma)
    # Most of its points show that it moved as a road user does: the shift explains them
    # and the static world does not, less twice those the static world explains and the
    # shift does not (as a track's evidence is counted, mmreg.tracking: a still patch's
    # noise explains a few points either way; a mover's evidence has no counterweight) ...
    moved = np.bincount(owner, weights=by_shift & ~by_static, minlength=len(clusters))
    against = np.bincount(owner, weights=by_static & ~by_shift, minlength=len(clusters))
    # ... and the shift explains more of them than its own fit did.
    better = np.bincount(owner, weights=by_shift.astype(float) - by_broken, minlength=len(clusters))
    keep = ~still[clusters] & (2 * (moved - _AGAINST * against) > counts) & (better > 0)
    chosen = np.flatnonzero(keep)
    return (
        [clusters[i] for i in chosen],
        level[0][chosen],
        level[1][chosen],
        np.asarray(scales)[chosen],
    )


def bound_motions(points, labels, motions, static, target, sigma, **bounds):
    """The clusters whose motion no road user can make, re-fitted or taken apart.

    A cluster that breaks the speed, reach or turn bound in a z-up sweep (``up`` given)
    keeps the level shift of :func:`level_shift` instead where that breaks no bound,
    explains most of its points where the static world's motion does not (less twice
    those that only the static world's explains), and explains
    more of them than its own motion did (a partial view fitted turned: a real mover);
    its robust scale (``motions``' third array) becomes the shift's. Every other cluster
    that breaks a bound is taken apart: each of its points rejoins the static world where
    the static world's motion explains it on the second sweep (``target``: the sweep, its
    cKDTree and its SurfaceNormals; ``sigma``: the ego ICP's robust residual scale; see
    :func:`mmreg.sweeps._explained.unexplained_mask`), and becomes an outlier (-1) where
    it does not. ``motions``: per-cluster arrays, rotations, translations and the ICP's
    robust scales first; ``bounds``: the keywords of :func:`impossible_motions`.

    Returns the labels, the arrays without the clusters taken apart, the static world's
    new index, and the reasons of those taken apart (a list, one per such cluster).
    """
    if static < 0:  # nothing to be relative to
        return labels, motions, static, []
    impossible, reasons = impossible_motions(points, labels, motions[:2], static, **bounds)
    if not impossible.any():
        return labels, motions, static, []
    labels = np.asarray(labels).copy()
    refitted, rotations, translations, scales = _refit_level(
        points, labels, motions, static, target, sigma, impossible, reasons, bounds
    )
    if refitted:
        motions = tuple(np.array(values, copy=True) for values in motions)
        motions[0][refitted], motions[1][refitted] = rotations, translations
        if len(motions) > 2:
            motions[2][refitted] = scales
        impossible[refitted] = False
        if not impossible.any():
            return labels, motions, static, []
    rows = np.flatnonzero((labels >= 0) & impossible[np.maximum(labels, 0)])
    rotation, translation = motions[0][static], motions[1][static]
    sweep, tree, normals = target
    unexplained, _ = unexplained_mask(
        points[rows] @ rotation.T + translation, tree, sweep, normals, sigma
    )
    labels[rows] = np.where(unexplained, -1, static)
    kept = ~impossible
    index = np.cumsum(kept) - 1
    labels = np.where(labels >= 0, index[np.maximum(labels, 0)], -1)
    removed = [reasons[k] for k in np.flatnonzero(impossible)]
    return labels, tuple(values[kept] for values in motions), int(index[static]), removed
