"""Two raw LiDAR sweeps of a generated street, ray cast from two sensor poses.

mmreg's street scenes (``mmreg.datasets.make_street``) are seen by a camera; this helper
casts the rays of a spinning LiDAR (32 beams, -25 to +10 degrees, 0.2 degree steps, 80 m)
on the same meshes (road, sidewalks, buildings, poles, trees, parked cars) plus cars
that drive on between the sweeps. Both sweeps are in their own sensor frame (the street's:
x right, y down, z forward); the true ego motion carries the first sweep's static points
onto the second sweep's surfaces.
"""

import numpy as np
from sklearn.utils import Bunch, check_random_state

from mmreg.datasets._camera import box_mesh, transform_mesh
from mmreg.datasets._street import _CAMERA_HEIGHT, _car, _street_side, _yaw

_ELEVATIONS = np.deg2rad(np.linspace(-25.0, 10.0, 32))
_AZIMUTH_STEP = np.deg2rad(0.2)
_MAX_RANGE = 80.0
_ROAD_HALF_WIDTH = 7.0


def _ray_directions():
    """Unit directions of one revolution, in the sensor frame (y down)."""
    azimuth = np.arange(0.0, 2 * np.pi, _AZIMUTH_STEP)
    elevation, azimuth = np.meshgrid(_ELEVATIONS, azimuth, indexing="ij")
    return np.stack(
        [
            np.cos(elevation) * np.sin(azimuth),
            -np.sin(elevation),
            np.cos(elevation) * np.cos(azimuth),
        ],
        axis=-1,
    ).reshape(-1, 3)


def _cast(meshes, rotation, translation, noise, rng):
    """Points (sensor frame) and mesh index of every ray of a sensor at ``(R, t)``."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    for vertices, triangles in meshes:
        scene.add_triangles(
            o3d.core.Tensor(np.asarray(vertices, np.float32)),
            o3d.core.Tensor(np.asarray(triangles, np.uint32)),
        )
    local = _ray_directions()
    rays = np.hstack([np.broadcast_to(translation, local.shape), local @ rotation.T])
    hits = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))
    distance = hits["t_hit"].numpy().astype(np.float64)
    mesh = hits["geometry_ids"].numpy().astype(np.int64)
    keep = np.isfinite(distance) & (distance <= _MAX_RANGE)
    distance = distance[keep] + noise * rng.standard_normal(keep.sum())
    return local[keep] * distance[:, None], mesh[keep]


def street_sweeps(dt=0.1, speed=10.0, yaw_rate=8.0, *, n_moving=2, noise=0.0, random_state=0):
    """Two sweeps ``dt`` seconds apart of a sensor driving at ``speed`` m/s, turning.

    Parameters
    ----------
    dt : float
        Seconds between the sweeps.
    speed : float
        Forward speed of the sensor (m/s); it moves ``speed * dt`` metres.
    yaw_rate : float
        Degrees per second of turn.
    n_moving : int
        Cars driving in the lanes at 5-12 m/s (their points are not the static world).
    noise : float
        Standard deviation of the range noise (m).
    random_state : int or None

    Returns
    -------
    Bunch with ``a`` (n, 3), ``sweep`` (m, 3), ``static`` (n,) bool, ``rotation``,
    ``translation`` (the true ego motion: ``a[static] @ R.T + t`` lies on the second
    sweep's static surfaces).
    """
    rng = check_random_state(random_state)
    road = box_mesh((2 * _ROAD_HALF_WIDTH + 0.2, 0.5, 120.0), (0.0, _CAMERA_HEIGHT + 0.25, 35.0))
    static = [road]
    static += [mesh for _, mesh in _street_side(_ROAD_HALF_WIDTH, 1, rng)]
    static += [mesh for _, mesh in _street_side(-_ROAD_HALF_WIDTH, -1, rng)]
    for z in rng.uniform(-8.0, 40.0, size=6):  # parked cars along both kerbs
        side = rng.choice([-1, 1])
        car = _car(4.4, 1.8, 1.5, rng)
        static.append(
            transform_mesh(car, _yaw(rng.uniform(-3, 3)), (side * 5.9, _CAMERA_HEIGHT, z))
        )
    first, second = list(static), list(static)
    for lane in range(n_moving):  # cars in the lanes, moving on between the sweeps
        car = _car(4.4, 1.8, 1.5, rng)
        x = (-1.75, 1.75)[lane % 2] + 3.5 * (lane // 2 % 2)
        centre = np.array([x, _CAMERA_HEIGHT, rng.uniform(10.0, 30.0)])
        first.append(transform_mesh(car, translation=centre))
        step = np.array([0.0, 0.0, rng.uniform(5.0, 12.0) * dt * (1 if x > 0 else -1)])
        second.append(transform_mesh(car, translation=centre + step))
    yaw = yaw_rate * dt
    ego_rotation = _yaw(yaw)
    ego_translation = _yaw(yaw / 2) @ [0.0, 0.0, speed * dt]
    a, mesh = _cast(first, np.eye(3), np.zeros(3), noise, rng)
    sweep, _ = _cast(second, ego_rotation, ego_translation, noise, rng)
    return Bunch(
        a=a,
        sweep=sweep,
        static=mesh < len(static),
        rotation=ego_rotation.T,
        translation=-ego_rotation.T @ ego_translation,
    )
