"""Two raw LiDAR sweeps of a street, as a spinning sensor on a car writes them.

A z-up sensor ``sensor_height`` above a flat road casts ``n_beams`` rings of rays (the
elevation angles of a 32-beam roof LiDAR) at ``n_azimuths`` bearings; every ray returns
its first hit among the road, the buildings along both kerbs, poles, parked cars and
moving cars (boxes). The road comes back as concentric rings, as on a real sweep, and the
first sweep's points are taken ``interval`` seconds before the second's: the sensor has
driven on and turned, the moving cars have driven their own way. Both sweeps are in their
own sensor frame (x forward, y left, z up), with the ground in.
"""

import numpy as np
from sklearn.utils import Bunch, check_random_state

__all__ = ["make_lidar_sweeps"]

# Elevation angles of the beams (degrees), as a VLP-32C's spread.
_ELEVATION = (-25.0, 15.0)


def _yaw(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _first_hits(origin, directions, boxes, max_range):
    """Distance along every ray to its first hit and what it hit (-1: road, -2: none).

    ``boxes`` is a list of ``(centre, yaw, half_size)``; the road is the plane z = 0.
    """
    n = len(directions)
    distance = np.full(n, np.inf)
    hit = np.full(n, -2)
    down = directions[:, 2] < 0
    road = np.full(n, np.inf)
    road[down] = -origin[2] / directions[down, 2]
    closer = road < distance
    distance[closer], hit[closer] = road[closer], -1
    for k, (centre, yaw, half) in enumerate(boxes):
        turn = _yaw(yaw)
        o = (origin - centre) @ turn  # the ray in the box's frame
        d = directions @ turn
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-half - o) / d
            t2 = (half - o) / d
        near = np.nanmax(np.minimum(t1, t2), axis=1)
        far = np.nanmin(np.maximum(t1, t2), axis=1)
        enter = (near <= far) & (far > 0) & (near > 0) & (near < distance)
        distance[enter], hit[enter] = near[enter], k
    hit[distance > max_range] = -2
    return distance, hit


def _sweep(pose, boxes, elevations, azimuths, max_range, noise, rng):
    """World points, hit index and the ray of every return of a sensor at ``pose``."""
    rotation, position = pose
    el, az = np.meshgrid(np.radians(elevations), azimuths, indexing="ij")
    local = np.stack(
        [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1
    ).reshape(-1, 3)
    directions = local @ rotation.T
    distance, hit = _first_hits(position, directions, boxes, max_range)
    seen = hit > -2
    distance = distance[seen] + noise * rng.standard_normal(seen.sum())
    return position + directions[seen] * distance[:, None], hit[seen]


def make_lidar_sweeps(
    n_moving=3,
    n_parked=4,
    *,
    interval=0.1,
    ego_speed=10.0,
    n_beams=32,
    n_azimuths=2048,
    sensor_height=1.8,
    max_range=60.0,
    noise=0.01,
    random_state=None,
):
    """Two raw LiDAR sweeps of a street with moving cars, the ground in.

    Parameters
    ----------
    n_moving : int, default=3
        Cars driving in the lanes at 5-12 m/s (one oncoming), each with a motion of its
        own.
    n_parked : int, default=4
        Cars parked along the kerbs (the static world).
    interval : float, default=0.1
        Seconds between the sweeps (0.1: a 10 Hz sensor; 0.5: 2 Hz keyframes).
    ego_speed : float, default=10.0
        The sensor's car drives this many metres per second along its lane and turns
        by up to 5 degrees per second.
    n_beams, n_azimuths : int, default=32, 2048
        Rings of the sensor and returns per ring.
    sensor_height : float, default=1.8
        Height of the sensor above the road (metres).
    max_range : float, default=60.0
        Returns beyond this range are lost.
    noise : float, default=0.01
        Standard deviation of the range noise (metres).
    random_state : int, RandomState instance or None, default=None

    Returns
    -------
    scene : sklearn.utils.Bunch
        ``a`` (n, 3) and ``sweep`` (m, 3): the two sweeps in their own sensor frames;
        ``labels`` (n,): 0 for the static world (road, buildings, poles, parked cars), k
        for the k-th moving car (a car hidden behind another has no point); ``ground``
        (n,) and ``sweep_ground`` (m,): returns from the road; ``transforms``
        (n_moving + 1, 4, 4): ``transforms[k]`` maps a point of ``a`` with label k to
        where it is in the second sweep's frame (label 0: the inverse of the ego
        motion); ``flow`` (n, 3): each point's motion into that frame; ``interval``.

    Examples
    --------
    >>> from mmreg.datasets import make_lidar_sweeps
    >>> scene = make_lidar_sweeps(random_state=0)
    >>> scene.a.shape[1], scene.transforms.shape  # the static world and 3 cars
    (3, (4, 4, 4))
    >>> bool(0.2 < scene.ground.mean() < 0.8)
    True
    """
    rng = check_random_state(random_state)
    # The world: the road along x, the sensor's car in the right lane at y = -1.75.
    boxes, moving = [], []
    for side in (-1.0, 1.0):  # buildings behind sidewalks, with gaps between them
        x = -80.0
        while x < 120.0:
            length = rng.uniform(12.0, 30.0)
            depth, height = rng.uniform(8.0, 14.0), rng.uniform(6.0, 15.0)
            y = side * (9.0 + rng.uniform(0.0, 4.0) + depth / 2)  # set back unevenly
            boxes.append(
                (
                    np.array([x + length / 2, y, height / 2]),
                    rng.uniform(-0.3, 0.3),  # not one long corridor: x must be held
                    np.array([length / 2, depth / 2, height / 2]),
                )
            )
            x += length + rng.uniform(2.0, 8.0)
        for x in rng.uniform(-60.0, 100.0, 10):  # poles and trunks by the kerb
            boxes.append((np.array([x, side * 7.5, 2.5]), 0.0, np.array([0.1, 0.1, 2.5])))
    # A car: a body box and a cabin box set back from its front, one rigid body.
    body, cabin = np.array([2.2, 0.9, 0.45]), np.array([1.2, 0.8, 0.35])

    def car(centre, yaw):
        offset = _yaw(yaw) @ np.array([-0.4, 0.0, 0.8])
        return [(centre, yaw, body), (centre + offset, yaw, cabin)]

    for _ in range(n_parked):
        x, side = rng.uniform(-30.0, 40.0), rng.choice([-1.0, 1.0])
        boxes += car(np.array([x, side * 6.0, 0.75]), rng.uniform(-0.05, 0.05))
    lanes = np.array([-1.75, 1.75, -1.75])  # beside and ahead in our lane, one oncoming
    for k in range(n_moving):
        lane = lanes[k % 3]
        x = rng.uniform(6.0, 20.0) * (1 if k % 2 == 0 else -1) + (k // 3) * 12.0
        speed = rng.uniform(5.0, 12.0) * (-1 if lane > 0 else 1)
        yaw_rate = np.radians(rng.uniform(-5.0, 5.0))
        centre = np.array([x, lane + rng.uniform(-0.3, 0.3), 0.75])
        moving.append((len(boxes), speed, yaw_rate))
        boxes += car(centre, 0.0 if speed > 0 else np.pi)
    # The two sensor poses (world from sensor) and the cars' poses at the second sweep.
    yaw1 = np.radians(rng.uniform(-5.0, 5.0)) * interval
    pose1 = (np.eye(3), np.array([0.0, -1.75, sensor_height]))
    pose2 = (_yaw(yaw1), pose1[1] + [ego_speed * interval, 0.0, 0.0])
    boxes2 = list(boxes)
    motions = []  # world motion of each moving car: x -> R x + t
    for index, speed, yaw_rate in moving:
        centre = boxes[index][0]
        turn = _yaw(yaw_rate * interval)
        new_centre = centre + [speed * interval, 0.0, 0.0]  # along the road, signed
        translation = new_centre - turn @ centre
        for part in (index, index + 1):  # body and cabin
            part_centre, yaw, half = boxes[part]
            boxes2[part] = (turn @ part_centre + translation, yaw + yaw_rate * interval, half)
        motions.append((turn, translation))
    elevations = np.linspace(*_ELEVATION, n_beams)
    azimuths = np.linspace(-np.pi, np.pi, n_azimuths, endpoint=False)
    world1, hit1 = _sweep(pose1, boxes, elevations, azimuths, max_range, noise, rng)
    world2, hit2 = _sweep(
        pose2, boxes2, elevations, azimuths + np.pi / n_azimuths, max_range, noise, rng
    )
    labels = np.zeros(len(world1), dtype=np.intp)
    for k, (index, _, _) in enumerate(moving, start=1):
        labels[(hit1 == index) | (hit1 == index + 1)] = k
    # Sensor frames: a = R1^T (w - c1); the second sweep's frame likewise with pose 2.
    (R1, c1), (R2, c2) = pose1, pose2

    def to_second(rotation, translation):
        # a -> world (R1 a + c1) -> moved (rotation w + translation) -> second frame.
        transform = np.eye(4)
        transform[:3, :3] = R2.T @ rotation @ R1
        transform[:3, 3] = R2.T @ (rotation @ c1 + translation - c2)
        return transform

    transforms = np.stack(
        [to_second(np.eye(3), np.zeros(3))] + [to_second(*motion) for motion in motions]
    )
    a = (world1 - c1) @ R1
    sweep = (world2 - c2) @ R2
    moved = np.einsum("nij,nj->ni", transforms[labels, :3, :3], a) + transforms[labels, :3, 3]
    return Bunch(
        a=a,
        sweep=sweep,
        labels=labels,
        ground=hit1 == -1,
        sweep_ground=hit2 == -1,
        transforms=transforms,
        flow=moved - a,
        interval=float(interval),
    )
