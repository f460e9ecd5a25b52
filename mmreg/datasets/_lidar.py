"""Two raw LiDAR sweeps of a street, as a spinning sensor on a car writes them.

A z-up sensor ``sensor_height`` above a flat road casts ``n_beams`` rings of rays (the
elevation angles of a 32-beam roof LiDAR) at ``n_azimuths`` bearings; every ray returns
its first hit among the road, the buildings along both kerbs, poles, parked cars, moving
cars and, when asked, pedestrians, cyclists and things standing on the sidewalks (boxes).
The road comes back as concentric rings, as on a real sweep, and the first sweep's points
are taken ``interval`` seconds before the second's: the sensor has driven on and turned,
the moving cars, walkers and cyclists have gone their own way. Both sweeps are in their
own sensor frame (x forward, y left, z up), with the ground in.
"""

from numbers import Integral

import numpy as np
from sklearn.utils import Bunch, check_random_state

__all__ = ["make_lidar_sweeps"]

# Elevation angles of the beams (degrees), as a VLP-32C's spread.
_ELEVATION = (-25.0, 15.0)

# Half extents (metres, along / across the heading, height) of the small things; each is
# scaled by 0.9-1.1 so that no two are alike.
_WALKER = np.array([0.25, 0.2, 0.85])
_CYCLIST = np.array([0.9, 0.3, 0.75])
_BIN = np.array([0.3, 0.3, 0.5])
_WALKER_SPEED = (1.0, 1.8)  # m/s
_CYCLIST_SPEED = (3.0, 7.0)
_CYCLIST_HEADING = np.radians(3.0)  # the most a cyclist's heading strays from the road's
_SIDEWALK = (7.3, 12.5)  # |y|: from the kerb (|y| = 7) to behind the buildings' fronts
_KERB_LANE = (4.3, 6.3)  # |y| of a cyclist's centre: between the lanes and the kerb
_SPREAD = (-35.0, 45.0)  # x: where the sensor sees them
_APART = 2.0  # metres between the centres of two small things
_CLEAR_OF_SENSOR = 4.0  # metres between a small thing and the sensor
_CLEAR_OF_BOXES = 0.3  # metres between a small thing's footprint and any other box's
_TRIES = 1000  # placements tried for one small thing before giving up


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


def _footprints_overlap(box, other, margin):
    """Whether two boxes' footprints (oriented rectangles on the road) come within ``margin``.

    The separating-axis test on the four edge directions of the two rectangles.
    """
    (c1, yaw1, half1), (c2, yaw2, half2) = box, other
    axes1, axes2 = _yaw(yaw1)[:2, :2].T, _yaw(yaw2)[:2, :2].T  # rows: the edge directions
    gap = c2[:2] - c1[:2]
    for axis in np.vstack([axes1, axes2]):
        reach1 = np.abs(axes1 @ axis) @ half1[:2]
        reach2 = np.abs(axes2 @ axis) @ half2[:2]
        if abs(gap @ axis) > reach1 + reach2 + margin:
            return False
    return True


def _small_things(rng, counts, obstacles, sensors, interval):
    """Place walkers, cyclists and standing things; a list of ``(kind, box, box2)``.

    ``counts`` is ``(n_walkers, n_cyclists, n_standing)``, ``obstacles`` the boxes at the
    first and at the second sweep (two lists), ``sensors`` the sensor's two positions. Each
    thing is drawn again until it keeps clear of the sensor, of every box and of the things
    already placed, at both sweeps; ``box2`` is where it is at the second sweep (the same
    box for a standing thing).
    """
    placed = []
    for kind, count in zip(("walker", "cyclist", "standing"), counts, strict=True):
        for _ in range(count):
            for _ in range(_TRIES):
                thing = _draw_small_thing(rng, kind, interval)
                if _keeps_clear(thing, placed, obstacles, sensors):
                    placed.append(thing)
                    break
            else:
                name = "n_standing" if kind == "standing" else f"n_{kind}s"
                raise ValueError(
                    f"Could not place {name}={count} {kind} objects {_APART} m apart on the "
                    f"street (placed {len(placed)} small things); ask for fewer."
                )
    return placed


def _draw_small_thing(rng, kind, interval):
    """One walker, cyclist or standing thing: ``(kind, box, box2)``, boxes on the road."""
    side = rng.choice([-1.0, 1.0])
    x = rng.uniform(*_SPREAD)
    if kind == "cyclist":  # near the kerb, riding with the traffic of its side
        y = side * rng.uniform(*_KERB_LANE)
        half = _CYCLIST * rng.uniform(0.9, 1.1)
        heading = (np.pi if side > 0 else 0.0) + rng.uniform(-1, 1) * _CYCLIST_HEADING
        speed = rng.uniform(*_CYCLIST_SPEED)
    else:  # on the sidewalk, walking any way or standing (a person or a bin)
        y = side * rng.uniform(*_SIDEWALK)
        person = kind == "walker" or rng.uniform() < 0.5
        half = (_WALKER if person else _BIN) * rng.uniform(0.9, 1.1)
        heading = rng.uniform(-np.pi, np.pi)
        speed = rng.uniform(*_WALKER_SPEED) if kind == "walker" else 0.0
    centre = np.array([x, y, half[2]])  # standing on the road plane
    step = speed * interval * np.array([np.cos(heading), np.sin(heading), 0.0])
    return kind, (centre, heading, half), (centre + step, heading, half)


def _keeps_clear(thing, placed, obstacles, sensors):
    _, box, box2 = thing
    apart = all(  # the cheap tests first: most draws that fail, fail here
        np.linalg.norm(box[0][:2] - other[0][:2]) >= _APART
        and np.linalg.norm(box2[0][:2] - other2[0][:2]) >= _APART
        for _, other, other2 in placed
    )
    if not apart or any(
        np.linalg.norm(ours[0][:2] - sensor[:2]) < _CLEAR_OF_SENSOR
        for ours, sensor in zip((box, box2), sensors, strict=True)
    ):
        return False
    return not any(
        _footprints_overlap(ours, other, _CLEAR_OF_BOXES)
        for ours, others in zip((box, box2), obstacles, strict=True)
        for other in others
    )


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
    n_walkers=0,
    n_cyclists=0,
    n_standing=0,
):
    """Two raw LiDAR sweeps of a street with moving cars, the ground in.

    Pedestrians, cyclists and things standing on the sidewalks (people standing, bins)
    are small: a 32-beam sensor sees them with tens of points, and the standing ones must
    not be taken for moving ones.

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
    n_walkers : int, default=0
        Pedestrians (boxes of about 0.5 x 0.4 x 1.7 m) on the sidewalks, between the kerb
        (``|y|`` = 7 m) and the buildings, walking at 1.0-1.8 m/s in a uniformly random
        heading.
    n_cyclists : int, default=0
        Cyclists (boxes of about 1.8 x 0.6 x 1.5 m) near the kerb, riding at 3-7 m/s along
        the road with the traffic of their side, their heading within 3 degrees of it.
    n_standing : int, default=0
        Things of a pedestrian's size that do not move, on the sidewalks: people standing
        and bins (about 0.6 x 0.6 x 1.0 m). They are the static world's (label 0).

    Returns
    -------
    scene : sklearn.utils.Bunch
        ``a`` (n, 3) and ``sweep`` (m, 3): the two sweeps in their own sensor frames;
        ``labels`` (n,): 0 for the static world (road, buildings, poles, parked cars), k
        for the k-th moving object (an object hidden behind another has no point): the
        cars ``1..n_moving``, then the walkers, then the cyclists; ``kinds``
        (n_objects + 1,): what each label is, ``"static"``, ``"car"``, ``"walker"`` or
        ``"cyclist"``; ``standing`` (n,): returns from the standing things (label 0);
        ``ground`` (n,) and ``sweep_ground`` (m,): returns from the road; ``transforms``
        (n_objects + 1, 4, 4), ``n_objects = n_moving + n_walkers + n_cyclists``:
        ``transforms[k]`` maps a point of ``a`` with label k to where it is in the second
        sweep's frame (label 0: the inverse of the ego motion); ``flow`` (n, 3): each
        point's motion into that frame; ``interval``.

    Notes
    -----
    The walkers, cyclists and standing things keep 2 m apart, 4 m from the sensor and
    0.3 m from every other box, at both sweeps. They are drawn after everything else, so
    asking for them leaves the buildings, the cars and the ego motion as they are without
    them (the range noise, drawn after them, changes); with the three counts at 0 the
    scene is the one drawn before they existed.

    Examples
    --------
    >>> from mmreg.datasets import make_lidar_sweeps
    >>> scene = make_lidar_sweeps(random_state=0)
    >>> scene.a.shape[1], scene.transforms.shape  # the static world and 3 cars
    (3, (4, 4, 4))
    >>> bool(0.2 < scene.ground.mean() < 0.8)
    True

    Two cars, three walkers, a cyclist and four standing things, 0.5 s apart:

    >>> scene = make_lidar_sweeps(
    ...     2, n_walkers=3, n_cyclists=1, n_standing=4, interval=0.5, n_azimuths=512, random_state=0
    ... )
    >>> scene.kinds.tolist()
    ['static', 'car', 'car', 'walker', 'walker', 'walker', 'cyclist']
    >>> bool(scene.labels[scene.standing].max() == 0)
    True
    """
    counts = {"n_walkers": n_walkers, "n_cyclists": n_cyclists, "n_standing": n_standing}
    for name, count in counts.items():
        if isinstance(count, bool) or not isinstance(count, Integral) or count < 0:
            raise ValueError(f"{name} must be a non-negative integer; got {count!r}.")
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
    # The small things, drawn only when asked and after every other object: without them
    # the street's draws are what they were before they existed, with them only the range
    # noise's change.
    things = []
    if any(counts.values()):
        things = _small_things(
            rng, tuple(counts.values()), (boxes, boxes2), (pose1[1], pose2[1]), interval
        )
    first_thing = len(boxes)
    for kind, box, box2 in things:
        boxes.append(box)
        boxes2.append(box2)
        if kind != "standing":
            motions.append((np.eye(3), box2[0] - box[0]))
    elevations = np.linspace(*_ELEVATION, n_beams)
    azimuths = np.linspace(-np.pi, np.pi, n_azimuths, endpoint=False)
    world1, hit1 = _sweep(pose1, boxes, elevations, azimuths, max_range, noise, rng)
    world2, hit2 = _sweep(
        pose2, boxes2, elevations, azimuths + np.pi / n_azimuths, max_range, noise, rng
    )
    labels = np.zeros(len(world1), dtype=np.intp)
    for k, (index, _, _) in enumerate(moving, start=1):
        labels[(hit1 == index) | (hit1 == index + 1)] = k
    movers = [i for i, (kind, _, _) in enumerate(things, start=first_thing) if kind != "standing"]
    for k, index in enumerate(movers, start=len(moving) + 1):
        labels[hit1 == index] = k
    standing_boxes = [
        i for i, thing in enumerate(things, start=first_thing) if thing[0] == "standing"
    ]
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
        kinds=np.array(
            ["static"]
            + ["car"] * len(moving)
            + [kind for kind, _, _ in things if kind != "standing"]
        ),
        standing=np.isin(hit1, standing_boxes),
        ground=hit1 == -1,
        sweep_ground=hit2 == -1,
        transforms=transforms,
        flow=moved - a,
        interval=float(interval),
    )


# One static thing at (9, 7) beside which a walker passes (the tests and
# benchmarks/beside_static.py): centre, yaw, half sizes, and the unit direction from the
# thing to the walker.
_BESIDE = {
    "pole": ((9.0, 7.0, 2.5), 0.0, (0.08, 0.08, 2.5), (-np.cos(0.8), np.sin(0.8))),
    "bin": ((9.0, 7.0, 0.5), 0.3, (0.3, 0.3, 0.5), (-np.cos(0.8), np.sin(0.8))),
    "parked car": ((9.0, 7.0, 0.75), 0.0, (2.2, 0.9, 0.45), (0.0, -1.0)),
    "wall": ((9.0, 7.6, 1.5), 0.0, (4.0, 0.1, 1.5), (0.0, -1.0)),
}


def _walker_beside(thing, heading, gap, seed=0):
    """Two 64-beam sweeps 0.5 s apart (the sensor at 7 m/s), a walker beside a thing.

    Buildings on both sides, the road in, 1 cm range noise; one static ``thing`` of
    :data:`_BESIDE` and a walker ``gap`` metres from it (from a pole's or a bin's axis,
    from a car's or a wall's side), walking 1.4 m/s towards ``heading`` (radians).
    Returns the two sweeps (sensor frames), and the walker's and the static world's
    masks of the first.
    """
    rng = np.random.RandomState(seed)
    boxes = [
        (np.array([x, side * 16.0, 5.0]), 0.05 * side, np.array([12.0, 4.0, 5.0]))
        for side in (-1.0, 1.0)
        for x in (-40.0, -12.0, 16.0, 44.0)
    ]
    centre, yaw, half, away = (np.asarray(value) for value in _BESIDE[thing])
    boxes.append((centre, float(yaw), half))
    edge = half[1] if thing in ("parked car", "wall") else 0.0
    walker = np.r_[centre[:2] + away * (edge + gap), _WALKER[2]]
    step = 0.7 * np.array([np.cos(heading), np.sin(heading), 0.0])
    elevations = np.linspace(*_ELEVATION, 64)
    azimuths = np.linspace(-np.pi, np.pi, 2048, endpoint=False)
    first = (np.eye(3), np.array([0.0, 0.0, 1.8]))
    second = (_yaw(0.01), np.array([3.5, 0.0, 1.8]))
    world1, hit1 = _sweep(
        first, [*boxes, (walker, heading, _WALKER)], elevations, azimuths, 70.0, 0.01, rng
    )
    world2, _ = _sweep(
        second,
        [*boxes, (walker + step, heading, _WALKER)],
        elevations,
        azimuths + np.pi / 2048,
        70.0,
        0.01,
        rng,
    )
    a = (world1 - first[1]) @ first[0]
    sweep = (world2 - second[1]) @ second[0]
    return a, sweep, hit1 == len(boxes), hit1 < len(boxes)
