"""Which frame a point cloud is in: a z-up LiDAR sweep or a camera's frame, from its geometry.

The sign of z alone cannot tell them apart: a LiDAR frame whose origin is on the ground has
z > 0 everywhere, and a camera in OpenGL's convention (FlyingThings3D as HPLFlowNet writes
it) looks down -z. What does tell them apart is where the points lie around the origin:

* a camera sees a cone: every point in front of it (z of one sign) and within its field of
  view of the z axis, so that the points' distance from the z axis stays within a few
  times their depth;
* a LiDAR (x forward, y left, z up: ROS REP 103, Argoverse 2, KITTI's Velodyne) sees a flat
  disc: the points spread far more across x and y than along z, and the sensor sits among
  them (near the origin), not off to one side.
"""

import numpy as np

__all__ = ["FRAMES", "detect_frame", "looks_down_minus_z"]

FRAMES = ("camera", "lidar")
# A camera's half field of view, at most (a 140-degree fisheye's diagonal): points further
# from the z axis than tan(70 deg) times their depth are outside every camera's view.
_MAX_HALF_FOV = np.deg2rad(70.0)
# Shares of points that may break a rule (a few wrong returns, a stray far point).
_IN_FRONT = 0.99
_IN_VIEW = 0.95
# A LiDAR sweep is a disc: its height spread at most this share of its horizontal spread.
_FLATNESS = 0.5
# The sensor is among its points: the origin no further outside their horizontal box than
# this share of the box's size.
_ORIGIN_MARGIN = 0.1
_MIN_POINTS = 10


def _spread(values):
    """Robust extent: from the 1st to the 99th percentile (a stray return does not count)."""
    low, high = np.percentile(values, [1.0, 99.0], axis=0)
    return low, high


def detect_frame(points):
    """Whether points are in a camera's frame, a z-up LiDAR frame, or neither that shows.

    Parameters
    ----------
    points : array-like of shape (n, 3)
        The points, in the frame of the sensor that took them.

    Returns
    -------
    frame : {"camera", "lidar"} or None
        ``"camera"``: z along the viewing direction (forward or backward), every point in
        front and within a field of view of at most 140 degrees; ``"lidar"``: z up, the
        points spread at least twice as far across x and y as along z, with the origin
        among them; None: neither (an object scanned from all around, a map frame far from
        the origin, fewer than 10 finite points).

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.frames import detect_frame
    >>> rng = np.random.default_rng(0)
    >>> azimuth, distance = rng.uniform(-np.pi, np.pi, 500), rng.uniform(3, 40, 500)
    >>> sweep = np.c_[distance * np.cos(azimuth), distance * np.sin(azimuth),
    ...               rng.uniform(0.0, 3.0, 500)]  # z > 0 everywhere, yet a LiDAR
    >>> detect_frame(sweep)
    'lidar'
    >>> depth = rng.uniform(2, 30, 500)
    >>> camera = np.c_[rng.uniform(-0.8, 0.8, 500) * depth, rng.uniform(-0.3, 0.5, 500) * depth,
    ...                depth]
    >>> detect_frame(camera), detect_frame(camera * [1, -1, -1])  # OpenCV, OpenGL
    ('camera', 'camera')
    """
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3); got {points.shape}.")
    points = points[np.isfinite(points).all(axis=1)]
    if len(points) < _MIN_POINTS:
        return None
    x, y, z = points.T
    side = np.sign(np.median(z))
    in_front = side != 0 and np.mean(np.sign(z) == side) >= _IN_FRONT
    off_axis = np.hypot(x, y)
    in_view = np.mean(off_axis <= np.tan(_MAX_HALF_FOV) * np.abs(z)) >= _IN_VIEW
    if in_front and in_view:
        return "camera"
    low, high = _spread(points)
    horizontal = float(np.max(high[:2] - low[:2]))
    flat = high[2] - low[2] <= _FLATNESS * horizontal
    margin = _ORIGIN_MARGIN * horizontal
    among = np.all((low[:2] - margin <= 0.0) & (high[:2] + margin >= 0.0))
    if horizontal > 0 and flat and among:
        return "lidar"
    return None


def looks_down_minus_z(points):
    """Whether a camera frame's points lie at z < 0 (OpenGL's convention, y up).

    Parameters
    ----------
    points : array-like of shape (n, 3)
        Points in a camera frame.

    Returns
    -------
    bool
        True when most points have z < 0: turn the frame by 180 degrees about x,
        ``(x, y, z) -> (x, -y, -z)``, to draw it in OpenCV's (x right, y down, z forward).

    Examples
    --------
    >>> from mmreg._array.frames import looks_down_minus_z
    >>> looks_down_minus_z([[0.0, 1.0, -5.0], [1.0, 0.0, -9.0]])
    True
    """
    z = np.asarray(points, dtype=float)[:, 2]
    return bool(np.median(z[np.isfinite(z)]) < 0) if np.isfinite(z).any() else False
