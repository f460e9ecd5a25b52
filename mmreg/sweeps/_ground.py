"""The ground of a LiDAR sweep: which of its points lie on the road and the terrain.

A raw sweep holds the ground: a fifth of an Argoverse 2 sweep, rings of road on a KITTI
one. A planar patch constrains only the motion normal to its plane, so an ICP on a ring of
road slides along it with no penalty and the ring looks like a moving object. The ground
is therefore found first and given to the static world: it still holds the ego motion's
roll, pitch and height (the ego ICP uses every point), but it never proposes a motion of
its own.

The segmentation is Patchwork++ (Lee et al., "Patchwork++: Fast and Robust Ground
Segmentation Solving Partial Under-Segmentation Using 3D Point Cloud", IROS 2022), through
its Python binding ``pypatchworkpp``: concentric zones of polar bins, a plane fitted per
bin from its lowest points, accepted by its uprightness, elevation and flatness. Its
parameters are metres for a car-mounted sensor; mmreg's lengths are in the units of the
points, and its LiDAR defaults take ``tau = 5`` to mean metres, so the points are scaled by
``5 / tau`` before the segmentation and nothing here assumes metres.
"""

import contextlib
import os
import sys

import numpy as np

__all__ = ["ground_mask", "has_ground", "is_z_up_sweep"]

# The estimator's tau that stands for metres (MultiModelRegistration's LiDAR default).
METRE_TAU = 5.0
# A z-up sweep spreads far wider than it is tall: its 5-95 % height range is below this
# share of its widest horizontal range (Argoverse 2 and KITTI sweeps: 0.02-0.1; a camera
# frame, z forward: about 1).
_FLAT_SHARE = 0.25
# A sweep whose ground was removed before still has low points that Patchwork++ takes for
# patches of ground (2.3-2.6 % of the points of ground-removed Argoverse 2 sweeps, the
# bottoms of cars among them); a sweep with its ground holds several times more (13-15 %
# on Argoverse 2's two roof sensors, 30-50 % on KITTI's HDL-64). Between the two: the
# geometric mean of 2.5 % and 14 %.
_MIN_GROUND_SHARE = 0.06
# The ground surrounds the sensor: it lies in this share of the bearings (of _SECTORS)
# that hold points (1.0 on sweeps with their ground; 0.3 for the bottom faces of boxes in
# a scene without one).
_MIN_GROUND_COVER = 0.75
_SECTORS = 32
# The sensor's height above the ground is read from the lowest points this near to it
# (metres at tau = 5): the ring of road every car-mounted sensor sees.
_NEAR_RANGE = 20.0


@contextlib.contextmanager
def _quiet_stdout():
    """Silence what C++ code prints on standard output (Patchwork++ greets every start)."""
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except OSError:  # no standard output to silence
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def is_z_up_sweep(points):
    """Whether ``points`` look like a LiDAR sweep with z up (a ground can lie under them).

    Parameters
    ----------
    points : ndarray of shape (n, 3)

    Returns
    -------
    bool
        True when the 5-95 % range of z is below a quarter of the widest 5-95 % range of x
        and y: a sweep spreads along the ground far more than it rises; a camera frame
        (z forward into the scene) does not.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> street = rng.uniform([-50, -50, -2], [50, 50, 3], (1000, 3))
    >>> camera = rng.uniform([-10, -5, 5], [10, 5, 35], (1000, 3))
    >>> is_z_up_sweep(street), is_z_up_sweep(camera)
    (True, False)
    """
    low, high = np.percentile(points, [5, 95], axis=0)
    return flat_across(high - low, 2)


def flat_across(spread, axis):
    """Whether points of 5-95 % ``spread`` (per coordinate) lie flat across the other two
    axes: their range along ``axis`` is under a quarter of the widest of the others
    (:func:`is_z_up_sweep` with ``axis`` 2)."""
    others = [spread[k] for k in range(3) if k != axis]
    return bool(spread[axis] < _FLAT_SHARE * max(others))


def _patchwork():
    try:
        import pypatchworkpp
    except ImportError as error:  # pragma: no cover - platforms without a wheel
        raise ImportError(
            "finding the ground of a sweep needs pypatchworkpp (pip install pypatchworkpp); "
            "or pass ground='keep' to register the ground as ordinary points, or give the "
            "ground masks to fit."
        ) from error
    return pypatchworkpp


def ground_mask(points, tau=METRE_TAU):
    """Which points of a z-up LiDAR sweep lie on the ground (Patchwork++).

    Parameters
    ----------
    points : ndarray of shape (n, 3)
        One sweep in the sensor's or the vehicle's frame, z up, the sensor near the
        origin (any units).
    tau : float, default=5.0
        The registration's length scale in the units of the points; 5 stands for metres
        (the sweep is scaled by ``5 / tau`` before the segmentation).

    Returns
    -------
    ndarray of shape (n,), bool
        True for ground points.

    Examples
    --------
    A flat road 1.7 m under the sensor with a box standing on it:

    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> road = np.c_[rng.uniform(-30, 30, (20000, 2)), np.full(20000, -1.7)]
    >>> box = rng.uniform([8, -1, -1.7], [12, 1, 0], (2000, 3))
    >>> mask = ground_mask(np.vstack([road, box]))
    >>> road_share, box_share = mask[:20000].mean(), mask[20000:].mean()
    >>> bool(road_share > 0.8), bool(box_share < 0.2)
    (True, True)
    """
    points = np.asarray(points, dtype=np.float64)
    if len(points) == 0:
        return np.zeros(0, dtype=bool)
    pypatchworkpp = _patchwork()
    metres = points * (METRE_TAU / tau)
    near = np.hypot(metres[:, 0], metres[:, 1]) < _NEAR_RANGE
    heights = metres[near, 2] if near.sum() >= 10 else metres[:, 2]
    params = pypatchworkpp.Parameters()
    params.verbose = False
    params.enable_RNR = False  # reflected-noise removal needs intensities
    # The ground lies at the lowest dense layer near the sensor.
    params.sensor_height = float(-np.percentile(heights, 5))
    with _quiet_stdout():
        segmenter = pypatchworkpp.patchworkpp(params)
    segmenter.estimateGround(np.ascontiguousarray(metres))
    mask = np.zeros(len(points), dtype=bool)
    mask[np.asarray(segmenter.getGroundIndices(), dtype=np.intp)] = True
    return mask


def has_ground(points, mask):
    """Whether a sweep's ground mask found a ground, not the low remnants of a removed one.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
        The sweep, the sensor near the origin.
    mask : ndarray of shape (n,), bool
        :func:`ground_mask` of the sweep.

    Returns
    -------
    bool
        True when the ground holds at least 6 % of the points and lies around the
        sensor: in at least three quarters of the 32 bearings (seen from the origin)
        that hold any point. A sweep whose ground was removed keeps 2-3 % of low points
        that look like ground (car bottoms, kerbs); one with its ground holds 13-50 %,
        in every bearing; the bottom faces of objects in a scene without a ground lie
        in a few bearings.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> points = rng.uniform(-20, 20, (1000, 3))
    >>> near_road = np.hypot(points[:, 0], points[:, 1]) < 15
    >>> one_side = points[:, 0] > 15
    >>> has_ground(points, near_road), has_ground(points, one_side)
    (True, False)
    """
    if not len(mask) or np.mean(mask) < _MIN_GROUND_SHARE:
        return False
    bearing = np.arctan2(points[:, 1], points[:, 0])
    sector = np.minimum((bearing + np.pi) * (_SECTORS / (2 * np.pi)), _SECTORS - 1).astype(int)
    occupied = np.bincount(sector, minlength=_SECTORS) > 0
    grounded = np.bincount(sector[mask], minlength=_SECTORS) > 0
    return bool(grounded.sum() >= _MIN_GROUND_COVER * occupied.sum())
