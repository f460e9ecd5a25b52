"""A whole LiDAR log of a street, frame after frame, with every object's track and box.

The street of :func:`make_lidar_sweeps` made long enough for a drive: two lanes each way,
parking lanes, sidewalks, poles and buildings with gaps, bending gently with a constant
curvature. The sensor's car drives along its lane; cars cruise, brake to a stop or pass
one another, walkers walk along the sidewalks or cross the road, cyclists ride by the
parked cars. Every object keeps one id for the whole log and moves by a known model (its
lane at a constant or braking speed, or a straight line), so that its box, velocity and
yaw rate are known at every frame. Each frame is ray cast from where the sensor is then,
the way :func:`make_lidar_sweeps` casts its two sweeps, and is given in its own sensor
frame (x forward, y left, z up) with the ground in.
"""

from collections.abc import Callable
from dataclasses import dataclass
from numbers import Integral, Real

import numpy as np
import pandas as pd
from sklearn.utils import Bunch, check_random_state

from mmreg.datasets._lidar import (
    _BIN,
    _CYCLIST,
    _CYCLIST_SPEED,
    _ELEVATION,
    _WALKER,
    _WALKER_SPEED,
)

__all__ = ["lidar_sequence_pair", "make_lidar_sequence"]

# The street across (lateral offsets d from the centre line, metres, left positive): our
# direction's lanes at d < 0, the oncoming ones at d > 0, then a parking lane, the kerb,
# the sidewalk and the buildings' fronts.
_LANES = (-1.75, -5.25, 1.75, 5.25)
_LANE_JITTER = 0.15  # a car's offset from its lane's centre, at most
_EGO_LANE = -1.75
_CYCLE_LANE = (7.0, 7.2)  # |d| of a cyclist's centre, between the lanes and the parked cars
_PARKING = 8.9  # the kerb is at 10
_POLE = 10.3
_SIDEWALK = (10.8, 13.6)  # |d| of a walker's or a standing thing's centre
_CROSSING = 11.5  # |d| where a crossing walker waits before and after crossing
_FRONT = 14.5  # the buildings' fronts are at least this far from the centre line
_CURVATURE = 1.0 / 200.0  # the most a drawn street bends (1/m)

# A car: a body box and a cabin box set back from its front, as in make_lidar_sweeps;
# rows are (offset of the part's centre in the car's frame, half sizes).
_CAR = np.array([[[0.0, 0.0, 0.75], [2.2, 0.9, 0.45]], [[-0.4, 0.0, 1.55], [1.2, 0.8, 0.35]]])
_EGO_FOOTPRINT = np.array([2.3, 0.95])  # the sensor's car, which no ray sees
_MOVING_SPEED = 0.1  # m/s: an object slower than this is at rest at that frame
_MAX_BRAKING = 8.0  # m/s^2
_CLEAR = 0.3  # metres between two footprints, at every moment of the log
_CLEAR_OF_EGO = 0.8
_CHECK_STEP = 0.1  # seconds between the moments the footprints are checked apart
_TRIES = 1000


@dataclass
class _Track:
    """One object of the log: what it is, its boxes and where it is at any time.

    ``parts`` is ``(p, 2, 3)``: each box's centre offset in the object's frame (x forward,
    z up from the road) and half sizes. ``state(t)`` gives the arrays ``x, y, yaw, vx, vy,
    yaw_rate`` of the object's frame (on the road) at the times ``t``.
    """

    kind: str
    motion: str
    parts: np.ndarray
    state: Callable

    def box(self):
        """Centre offset and half sizes of the box around all its parts."""
        low = (self.parts[:, 0] - self.parts[:, 1]).min(axis=0)
        high = (self.parts[:, 0] + self.parts[:, 1]).max(axis=0)
        return (low + high) / 2, (high - low) / 2


class _Road:
    """The street's centre line: a circular arc of curvature ``kappa`` along x at s = 0."""

    def __init__(self, kappa):
        self.kappa = float(kappa)

    def place(self, s, d):
        """World x, y and the road's heading at arc length ``s``, offset ``d`` to the left."""
        s = np.asarray(s, dtype=float)
        k = self.kappa
        # sin(ks)/k and (1 - cos(ks))/k, written to stay exact as k goes to 0.
        x = s * np.sinc(k * s / np.pi)
        y = k * s**2 / 2 * np.sinc(k * s / (2 * np.pi)) ** 2
        heading = k * s
        return x - d * np.sin(heading), y + d * np.cos(heading), heading


def _distance(times, speed, t_brake=np.inf, braking=0.0):
    """Distance driven and speed at ``times``: constant, then braking to a stop and resting."""
    t = np.asarray(times, dtype=float)
    cruise = np.minimum(t, t_brake)
    if braking <= 0:
        return speed * cruise, np.full(t.shape, float(speed))
    since = np.clip(t - t_brake, 0.0, speed / braking)
    return speed * cruise + speed * since - braking * since**2 / 2, speed - braking * since


def _lane_track(road, kind, motion, parts, lane, where, speed, brake=(np.inf, 0.0)):
    """An object in a lane: ``lane`` is ``(d, sign)``, its offset and +1 towards growing s
    (-1 against); ``where`` is ``(s, t)``, the arc length it is at at time t.

    It keeps ``speed`` (m/s along its lane) or, with ``brake = (t_brake, braking)``, brakes
    from ``t_brake`` at ``braking`` m/s^2 to a stop. Its yaw rate is the road's curvature
    times its speed along the centre line.
    """
    (d, sign), (s_at, at), (t_brake, braking) = lane, where, brake
    stretch = 1.0 - road.kappa * d  # lane length per centre-line length
    s0 = s_at - sign * _distance(at, speed, t_brake, braking)[0] / stretch

    def state(times):
        gone, now = _distance(times, speed, t_brake, braking)
        s = s0 + sign * gone / stretch
        x, y, heading = road.place(s, d)
        velocity = sign * now
        yaw = heading if sign > 0 else heading + np.pi
        return (
            x,
            y,
            np.arctan2(np.sin(yaw), np.cos(yaw)),
            velocity * np.cos(heading),
            velocity * np.sin(heading),
            road.kappa * velocity / stretch,
        )

    return _Track(kind, motion, parts, state)


def _crossing_track(parts, start, direction, along_at, at, speed, reach):
    """A walker on a straight line ``start + e direction``, ``e`` clipped to ``[-reach, reach]``.

    At time ``at`` it is ``along_at`` along the line; it waits on the sidewalk before and
    after crossing (the clip), facing the way it walks.
    """
    yaw = float(np.arctan2(direction[1], direction[0]))

    def state(times):
        t = np.asarray(times, dtype=float)
        free = along_at + speed * (t - at)
        along = np.clip(free, -reach, reach)
        walking = np.abs(free) < reach
        v = np.where(walking, speed, 0.0)
        return (
            start[0] + along * direction[0],
            start[1] + along * direction[1],
            np.full(t.shape, yaw),
            v * direction[0],
            v * direction[1],
            np.zeros(t.shape),
        )

    return _Track("walker", "crossing", parts, state)


def _apart(centre1, yaw1, half1, centre2, yaw2, half2, margin):
    """Whether two footprints (oriented rectangles) are more than ``margin`` apart.

    The separating-axis test, broadcast over any leading shape: centres ``(..., 2)``,
    yaws, margins ``(...)``, half sizes ``(..., 2)``; made only where the circles around
    the two footprints come within the margin (a few pairs of a street's boxes).
    """
    gap = centre2 - centre1
    shape = np.broadcast_shapes(gap.shape[:-1], np.shape(yaw1), np.shape(yaw2))
    half1, half2 = np.broadcast_to(half1, (*shape, 2)), np.broadcast_to(half2, (*shape, 2))
    margin = np.broadcast_to(margin, shape)
    reach = np.hypot(*np.moveaxis(half1, -1, 0)) + np.hypot(*np.moveaxis(half2, -1, 0)) + margin
    gap = np.broadcast_to(gap, (*shape, 2))
    close = (gap**2).sum(-1) <= reach**2
    gap, half1, half2, margin = gap[close], half1[close], half2[close], margin[close]
    frames = []
    for yaw in (yaw1, yaw2):
        yaw = np.broadcast_to(yaw, shape)[close]
        c, s = np.cos(yaw), np.sin(yaw)
        frames.append((np.stack([c, s], axis=-1), np.stack([-s, c], axis=-1)))
    separated = np.zeros(len(gap), dtype=bool)
    for axis in (*frames[0], *frames[1]):
        reach = margin.copy()
        for (u, v), half in zip(frames, (half1, half2), strict=True):
            reach += (
                np.abs((u * axis).sum(-1)) * half[:, 0] + np.abs((v * axis).sum(-1)) * half[:, 1]
            )
        separated |= np.abs((gap * axis).sum(-1)) > reach
    apart = ~close
    apart[close] = separated
    return apart


class _Street:
    """The objects placed so far, and the test that a new one keeps clear of them all.

    Footprints are kept stacked: the static boxes' ``(n,)`` and the tracks' (the sensor's
    car first) ``(n_check_times, m)``, so that a candidate is tested against all at once.
    """

    def __init__(self, check_times, ego):
        self.check_times = check_times
        self.static = []  # (centre (3,), yaw, half (3,), kind)
        self.tracks = []
        self._static = (np.empty((0, 2)), np.empty(0), np.empty((0, 2)))
        x, y, yaw, *_ = ego.state(check_times)
        self._moving = (np.stack([x, y], -1)[:, None], yaw[:, None], _EGO_FOOTPRINT[None])
        self._margins = np.array([_CLEAR_OF_EGO])

    def _footprint(self, item):
        """Centre ``(t, 2)``, yaw ``(t,)`` and half sizes ``(2,)`` of a track or a box."""
        if not isinstance(item, _Track):
            return item[0][None, :2], np.array([float(item[1])]), item[2][:2]
        offset, half = item.box()
        x, y, yaw, *_ = item.state(self.check_times)
        c, s = np.cos(yaw), np.sin(yaw)
        centre = np.stack(
            [x + c * offset[0] - s * offset[1], y + s * offset[0] + c * offset[1]], -1
        )
        return centre, yaw, half[:2]

    def clear(self, item):
        """Whether a track or a static box ``(centre, yaw, half, kind)`` keeps clear."""
        centre, yaw, half = self._footprint(item)
        centre, yaw = centre[:, None], yaw[:, None]
        centres, yaws, halves = self._static
        if not _apart(centre, yaw, half, centres, yaws, halves, _CLEAR).all():
            return False
        centres, yaws, halves = self._moving
        return bool(_apart(centre, yaw, half, centres, yaws, halves, self._margins).all())

    def add(self, item):
        centre, yaw, half = self._footprint(item)
        if isinstance(item, _Track):
            self.tracks.append(item)
            centres, yaws, halves = self._moving
            self._moving = (
                np.concatenate([centres, centre[:, None]], axis=1),
                np.concatenate([yaws, yaw[:, None]], axis=1),
                np.concatenate([halves, half[None]]),
            )
            self._margins = np.r_[self._margins, _CLEAR]
        else:
            self.static.append(item)
            centres, yaws, halves = self._static
            self._static = (np.r_[centres, centre], np.r_[yaws, yaw], np.r_[halves, half[None]])

    def place(self, draw, name, count):
        """Draw ``count`` objects, the i-th with ``draw(i)`` (a list of tracks or static boxes)
        until it keeps clear; raise if one cannot."""
        for i in range(count):
            for _ in range(_TRIES):
                items = draw(i)
                if all(self.clear(item) for item in items):
                    for item in items:
                        self.add(item)
                    break
            else:
                raise ValueError(
                    f"Could not place {name}={count} on the street clear of everything else "
                    f"(placed {i}, then {_TRIES} tries for one more); ask for fewer."
                )


def _cast(position, heading, boxes, elevations, azimuths, max_range):
    """Distance and hit (box index, -1 the road, -2 nothing) of every ray of a sweep.

    The rays of ``elevations`` (ascending, radians) by ``azimuths`` (radians in the
    sensor's frame, evenly spaced) from ``position`` with the sensor's ``heading`` (yaw);
    ``boxes`` are arrays ``centres (b, 3), yaws (b,), halves (b, 3)``. The slab test of
    ``_first_hits`` in :mod:`mmreg.datasets._lidar`, made on the rays that can reach each
    box only: those in the bearings of the circle around its footprint and the elevations
    between its bottom and its top, which keeps a frame of 100 boxes fast.
    """
    centres, yaws, halves = boxes
    n_beams, n_azimuths = len(elevations), len(azimuths)
    step = azimuths[1] - azimuths[0]
    cos_el, sin_el = np.cos(elevations)[:, None], np.sin(elevations)[:, None]
    with np.errstate(divide="ignore"):
        road = np.where(sin_el < 0, -position[2] / sin_el, np.inf)
    distance = np.broadcast_to(road, (n_beams, n_azimuths)).copy()
    hit = np.where(np.isfinite(distance), -1, -2)
    world_azimuths = azimuths + heading
    # Which rays each box can take: its bearings and its elevations from the sensor.
    rel = centres[:, :2] - position[:2]
    rho = np.hypot(rel[:, 0], rel[:, 1])
    radius = np.hypot(halves[:, 0], halves[:, 1])
    near, far = np.maximum(rho - radius, 0.0), rho + radius
    low = centres[:, 2] - halves[:, 2] - position[2]
    high = centres[:, 2] + halves[:, 2] - position[2]
    top = np.where(high >= 0, np.arctan2(high, near), np.arctan2(high, far))
    bottom = np.where(low <= 0, np.arctan2(low, near), np.arctan2(low, far))
    first_row = np.searchsorted(elevations, bottom - 1e-9, side="left")
    end_row = np.searchsorted(elevations, top + 1e-9, side="right")
    around = rho <= radius + 1e-9  # the sensor above the footprint's circle: every bearing
    with np.errstate(invalid="ignore", divide="ignore"):
        spread = np.arcsin(np.minimum(radius / rho, 1.0))
    bearing = np.arctan2(rel[:, 1], rel[:, 0]) - heading
    first_col = np.floor((bearing - spread - azimuths[0]) / step).astype(int) - 1
    last_col = np.ceil((bearing + spread - azimuths[0]) / step).astype(int) + 1
    reach = (near <= max_range) & (first_row < end_row)
    for k in np.flatnonzero(reach):
        rows = slice(first_row[k], end_row[k])
        if around[k] or last_col[k] - first_col[k] + 1 >= n_azimuths:
            cols = np.arange(n_azimuths)
        else:
            cols = np.arange(first_col[k], last_col[k] + 1) % n_azimuths
        c, s = np.cos(yaws[k]), np.sin(yaws[k])
        u = position - centres[k]
        origin = (u[0] * c + u[1] * s, -u[0] * s + u[1] * c, u[2])  # in the box's frame
        turn = world_azimuths[cols] - yaws[k]
        directions = (
            cos_el[rows] * np.cos(turn),
            cos_el[rows] * np.sin(turn),
            sin_el[rows],
        )
        enter, leave = -np.inf, np.inf
        with np.errstate(divide="ignore", invalid="ignore"):
            for o, d, h in zip(origin, directions, halves[k], strict=True):
                t1, t2 = (-h - o) / d, (h - o) / d
                enter = np.fmax(enter, np.fmin(t1, t2))
                leave = np.fmin(leave, np.fmax(t1, t2))
        block = np.ix_(np.arange(rows.start, rows.stop), cols)
        now = distance[block]
        closer = (enter <= leave) & (leave > 0) & (enter > 0) & (enter < now)
        distance[block] = np.where(closer, enter, now)
        hit[block] = np.where(closer, k, hit[block])
    hit[distance > max_range] = -2
    return distance, hit


def _parts_at(track, x, y, yaw):
    """World centres, yaws and half sizes of a track's boxes at one pose."""
    c, s = np.cos(yaw), np.sin(yaw)
    offsets, halves = track.parts[:, 0], track.parts[:, 1]
    centres = np.column_stack(
        [x + c * offsets[:, 0] - s * offsets[:, 1], y + s * offsets[:, 0] + c * offsets[:, 1]]
    )
    return np.column_stack([centres, offsets[:, 2]]), np.full(len(offsets), yaw), halves


def _render(static, tracks, ego, times, sensor, rng):
    """Cast every frame of the log and gather the truth: the Bunch of make_lidar_sequence.

    ``sensor`` holds ``frame_rate, height, n_beams, n_azimuths, max_range, noise``.
    """
    static_centres = np.array([box[0] for box in static]).reshape(-1, 3)
    static_yaws = np.array([box[1] for box in static], dtype=float)
    static_halves = np.array([box[2] for box in static]).reshape(-1, 3)
    static_kinds = np.array([str(box[3]) for box in static])
    # What each box is: 0 the static world, k the k-th track; and which are standing things.
    owner = np.repeat(
        np.arange(len(tracks) + 1), [len(static)] + [len(track.parts) for track in tracks]
    )
    standing = np.r_[static_kinds == "standing", np.zeros(len(owner) - len(static), bool)]
    states = np.array([np.stack(track.state(times), axis=1) for track in tracks])
    states = states.reshape(len(tracks), len(times), 6)  # x, y, yaw, vx, vy, yaw rate
    speeds = np.r_[np.zeros((1, len(times))), np.hypot(states[..., 3], states[..., 4])]
    ex, ey, eyaw, *_ = ego.state(times)
    n_azimuths = sensor["n_azimuths"]
    elevations = np.radians(np.linspace(*_ELEVATION, sensor["n_beams"]))
    step = 2 * np.pi / n_azimuths
    phases = rng.uniform(0.0, step, len(times))  # a spinning sensor fires anew each turn
    log = Bunch(frames=[], labels=[], moving=[], ground=[], standing=[])
    poses = np.tile(np.eye(4), (len(times), 1, 1))
    for f in range(len(times)):
        parts = [_parts_at(track, *states[k, f, :3]) for k, track in enumerate(tracks)]
        boxes = (
            np.concatenate([static_centres, *(p[0] for p in parts)]),
            np.concatenate([static_yaws, *(p[1] for p in parts)]),
            np.concatenate([static_halves, *(p[2] for p in parts)]),
        )
        position = np.array([ex[f], ey[f], sensor["height"]])
        azimuths = -np.pi + phases[f] + step * np.arange(n_azimuths)
        distance, hit = _cast(position, eyaw[f], boxes, elevations, azimuths, sensor["max_range"])
        seen = hit > -2
        rows, cols = np.nonzero(seen)
        ranges = distance[seen] + sensor["noise"] * rng.standard_normal(len(rows))
        el, az = elevations[rows], azimuths[cols]
        local = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        log.frames.append(local * ranges[:, None])
        hits = hit[seen]
        label = np.where(hits >= 0, owner[np.maximum(hits, 0)], 0)
        log.labels.append(label)
        log.moving.append(speeds[label, f] > _MOVING_SPEED)
        log.ground.append(hits == -1)
        log.standing.append((hits >= 0) & standing[np.maximum(hits, 0)])
        c, s = np.cos(eyaw[f]), np.sin(eyaw[f])
        poses[f, :2, :2] = [[c, -s], [s, c]]
        poses[f, :3, 3] = position
    counts = np.array([np.bincount(label, minlength=len(owner)) for label in log.labels])
    log.update(
        poses=poses,
        times=np.asarray(times, dtype=float),
        objects=_objects_table(tracks, states, times, counts[:, 1 : len(tracks) + 1]),
        kinds=np.array(["static"] + [track.kind for track in tracks]),
        motions=np.array(["static"] + [track.motion for track in tracks]),
        static_boxes=pd.DataFrame(
            {
                "kind": static_kinds,
                "x": static_centres[:, 0],
                "y": static_centres[:, 1],
                "z": static_centres[:, 2],
                "length": 2 * static_halves[:, 0],
                "width": 2 * static_halves[:, 1],
                "height": 2 * static_halves[:, 2],
                "yaw": static_yaws,
            }
        ),
        frame_rate=float(sensor["frame_rate"]),
    )
    return log


def _objects_table(tracks, states, times, counts):
    """A row per object and frame: its box, velocity, yaw rate and returns (``counts``)."""
    tables = []
    for k, (track, state) in enumerate(zip(tracks, states, strict=True), start=1):
        offset, half = track.box()
        x, y, yaw, vx, vy, yaw_rate = state.T
        c, s = np.cos(yaw), np.sin(yaw)
        speed = np.hypot(vx, vy)
        columns = {
            "frame": np.arange(len(times)),
            "time": times,
            "id": k,
            "kind": track.kind,
            "motion": track.motion,
            "x": x + c * offset[0] - s * offset[1],
            "y": y + s * offset[0] + c * offset[1],
            "z": offset[2],
            "length": 2 * half[0],
            "width": 2 * half[1],
            "height": 2 * half[2],
            "yaw": yaw,
            "vx": vx,
            "vy": vy,
            "speed": speed,
            "yaw_rate": yaw_rate,
            "moving": speed > _MOVING_SPEED,
            "n_points": counts[:, k - 1],
        }
        tables.append(pd.DataFrame(columns))
    if not tables:
        return pd.DataFrame(columns=_OBJECT_COLUMNS)
    table = pd.concat(tables, ignore_index=True)
    return table.sort_values(["frame", "id"], ignore_index=True)[_OBJECT_COLUMNS]


_OBJECT_COLUMNS = [
    "frame",
    "time",
    "id",
    "kind",
    "motion",
    "x",
    "y",
    "z",
    "length",
    "width",
    "height",
    "yaw",
    "vx",
    "vy",
    "speed",
    "yaw_rate",
    "moving",
    "n_points",
]


def _check_count(name, value, low=0):
    if isinstance(value, bool) or not isinstance(value, Integral) or value < low:
        kind = "a non-negative" if low == 0 else f"an integer >= {low}, not a"
        raise ValueError(f"{name} must be {kind} integer; got {value!r}.")


def _check_real(name, value, low=None, *, strict=True):
    if isinstance(value, bool) or not isinstance(value, Real) or not np.isfinite(value):
        raise ValueError(f"{name} must be a finite number; got {value!r}.")
    if low is not None and (value <= low if strict else value < low):
        raise ValueError(f"{name} must be {'>' if strict else '>='} {low}; got {value!r}.")
    return float(value)


def _speed_range(car_speed):
    try:
        low, high = (car_speed, car_speed) if np.ndim(car_speed) == 0 else car_speed
    except (TypeError, ValueError):
        raise ValueError(
            f"car_speed must be a number or a (low, high) pair; got {car_speed!r}."
        ) from None
    low, high = _check_real("car_speed", low, 0.0), _check_real("car_speed", high, 0.0)
    if low > high:
        raise ValueError(f"car_speed must be (low, high) with low <= high; got {car_speed!r}.")
    return low, high


def _person(rng, size):
    half = size * rng.uniform(0.9, 1.1)
    return np.array([[[0.0, 0.0, half[2]], half]])


def make_lidar_sequence(
    n_frames=20,
    *,
    frame_rate=10.0,
    n_moving=3,
    n_braking=1,
    n_overtaking=1,
    n_parked=6,
    n_walkers=2,
    n_cyclists=1,
    n_standing=2,
    ego_speed=10.0,
    car_speed=(5.0, 12.0),
    curvature=None,
    n_beams=32,
    n_azimuths=1024,
    sensor_height=1.8,
    max_range=60.0,
    noise=0.01,
    random_state=None,
):
    """A LiDAR log of a street: frames in their sensor frames, tracks, boxes and ego poses.

    A street with two lanes each way, parking lanes, sidewalks, poles and buildings with
    gaps, bending gently with a constant curvature, is ray cast ``n_frames`` times by a
    spinning z-up sensor on a car driving along it, as :func:`make_lidar_sweeps` casts its
    two sweeps. Every object keeps its id in every frame and moves by a known model, so its
    box, velocity and yaw rate are known at every frame.

    Parameters
    ----------
    n_frames : int, default=20
        Frames of the log (at least 2).
    frame_rate : float, default=10.0
        Frames per second: 10 for a 10 Hz sensor, 2 for nuScenes' keyframes.
    n_moving : int, default=3
        Cars cruising in the lanes (either direction, the same lane as the sensor's car
        too) at a constant speed drawn from ``car_speed``; following the bending lane, they
        turn at a constant yaw rate (constant velocity and turn rate).
    n_braking : int, default=1
        Cars that cruise, then brake (at most 8 m/s^2) to a stop in the middle third of the
        log and stay: their id stays, ``moving`` turns False.
    n_overtaking : int, default=1
        Pairs of cars, one passing the other in the inner lane of the same direction; they
        are alongside in the middle third of the log. The passing car is faster by at least
        3 m/s, and by enough to be 6 m behind at the first frame and 6 m ahead at the last.
    n_parked : int, default=6
        Cars parked along both kerbs, around the sensor's drive (the static world).
    n_walkers : int, default=2
        Pedestrians (boxes of about 0.5 x 0.4 x 1.7 m) at 1.0-1.8 m/s: the first, third...
        walk along a sidewalk, the second, fourth... cross the road (waiting on the
        sidewalks before and after).
    n_cyclists : int, default=1
        Cyclists riding at 3-7 m/s between the lanes and the parked cars, with the traffic.
    n_standing : int, default=2
        People standing and bins on the sidewalks (the static world, label 0).
    ego_speed : float, default=10.0
        The sensor's car drives its lane (the inner one of its direction) at this many
        metres per second (0: it waits).
    car_speed : float or (float, float), default=(5.0, 12.0)
        Speed of the cruising and braking cars and of the slower car of each pair (m/s),
        drawn uniformly in the range, or this speed.
    curvature : float or None, default=None
        The street's curvature (1/m, positive bends left): the sensor and the cars turn at
        ``curvature`` times their speed. None draws it within 1/200 either way; 0 is a
        straight street.
    n_beams, n_azimuths : int, default=32, 1024
        Rings of the sensor and returns per ring; each frame's bearings start at a random
        fraction of their spacing, as a spinning sensor's do.
    sensor_height : float, default=1.8
        Height of the sensor above the road (metres).
    max_range : float, default=60.0
        Returns beyond this range are lost.
    noise : float, default=0.01
        Standard deviation of the range noise (metres).
    random_state : int, RandomState instance or None, default=None

    Returns
    -------
    log : sklearn.utils.Bunch
        ``frames``: list of ``n_frames`` arrays (n_k, 3), each in its own sensor frame (x
        forward, y left, z up, the road ``sensor_height`` below); ``labels``: list of (n_k,)
        int, 0 the static world (road, buildings, poles, parked cars, standing things) and
        k >= 1 the object with id k, the same in every frame; ``moving``: list of (n_k,)
        bool, the point's object moves faster than 0.1 m/s at that frame; ``ground`` and
        ``standing``: list of (n_k,) bool, returns from the road and from the standing
        things; ``poses`` (n_frames, 4, 4): the sensor in the world, ``x_world = pose @
        x_frame``; ``times`` (n_frames,) seconds from the first frame; ``objects``: a
        DataFrame with a row per object and frame (``frame, time, id, kind, motion``, the
        box ``x, y, z`` (centre, world), ``length, width, height, yaw``, the velocity ``vx,
        vy`` (world, m/s), ``speed``, ``yaw_rate`` (rad/s), ``moving`` and ``n_points``,
        the returns it gave); ``kinds`` and ``motions`` (n_objects + 1,): what each id is
        (``"static"``, ``"car"``, ``"walker"``, ``"cyclist"``) and how it moves
        (``"cruising"``, ``"braking"``, ``"overtaking"``, ``"walking"``, ``"crossing"``,
        ``"riding"``); ``static_boxes``: a DataFrame of the static world's boxes (``kind,
        x, y, z, length, width, height, yaw``); ``frame_rate``.

    See Also
    --------
    lidar_sequence_pair : two consecutive frames in the layout of make_lidar_sweeps.

    Notes
    -----
    The ids run through the cruising cars, the braking cars, the pairs (the slower car
    first), the walkers and the cyclists. Each moving object is drawn near the sensor's car
    at some moment of the log and kept 0.3 m clear of every other box (0.8 m of the
    sensor's car) at every frame and every tenth of a second, so that no two objects
    overlap; an
    object may still be out of range, or hidden behind another, in some frames (no
    points). The world frame is the street's: the sensor starts at x = 0 in its lane,
    heading along x.

    Examples
    --------
    >>> from mmreg.datasets import make_lidar_sequence
    >>> log = make_lidar_sequence(5, n_azimuths=256, random_state=0)
    >>> len(log.frames), log.poses.shape, log.times.tolist()
    (5, (5, 4, 4), [0.0, 0.1, 0.2, 0.3, 0.4])
    >>> log.kinds.tolist()
    ['static', 'car', 'car', 'car', 'car', 'car', 'car', 'walker', 'walker', 'cyclist']
    >>> log.motions[1:7].tolist()
    ['cruising', 'cruising', 'cruising', 'braking', 'overtaking', 'overtaking']
    >>> log.objects.shape[0] == 5 * (len(log.kinds) - 1)
    True

    A frame's road returns, taken into the world by its pose, lie on the plane z = 0 (to
    the 1 cm range noise):

    >>> import numpy as np
    >>> world = log.frames[3] @ log.poses[3, :3, :3].T + log.poses[3, :3, 3]
    >>> bool(np.abs(world[log.ground[3], 2]).max() < 0.1)
    True
    """
    _check_count("n_frames", n_frames, 2)
    for name, value in {
        "n_moving": n_moving,
        "n_braking": n_braking,
        "n_overtaking": n_overtaking,
        "n_parked": n_parked,
        "n_walkers": n_walkers,
        "n_cyclists": n_cyclists,
        "n_standing": n_standing,
    }.items():
        _check_count(name, value)
    _check_count("n_beams", n_beams, 2)
    _check_count("n_azimuths", n_azimuths, 8)
    frame_rate = _check_real("frame_rate", frame_rate, 0.0)
    ego_speed = _check_real("ego_speed", ego_speed, 0.0, strict=False)
    sensor_height = _check_real("sensor_height", sensor_height, 0.0)
    max_range = _check_real("max_range", max_range, 0.0)
    noise = _check_real("noise", noise, 0.0, strict=False)
    speeds = _speed_range(car_speed)
    if curvature is not None:
        curvature = _check_real("curvature", curvature)
        if abs(curvature) > 1 / 50:
            raise ValueError(
                f"curvature must be within 1/50 either way (a radius of 50 m or more); "
                f"got {curvature!r}."
            )
    rng = check_random_state(random_state)
    road = _Road(rng.uniform(-_CURVATURE, _CURVATURE) if curvature is None else curvature)
    times = np.arange(n_frames) / frame_rate
    ego = _lane_track(road, "ego", "ego", _CAR, (_EGO_LANE, 1), (0.0, 0.0), ego_speed)
    street = _Street(np.unique(np.r_[times, np.arange(0.0, times[-1], _CHECK_STEP)]), ego)
    end = ego_speed * times[-1]  # the sensor's drive along the centre line, from 0
    _static_world(rng, road, street, -max_range - 30.0, end + max_range + 30.0)
    counts = {
        "n_parked": n_parked,
        "n_moving": n_moving,
        "n_braking": n_braking,
        "n_overtaking": n_overtaking,
        "n_walkers": n_walkers,
        "n_cyclists": n_cyclists,
        "n_standing": n_standing,
    }
    _populate(rng, road, street, counts, speeds, ego_speed, times[-1])
    sensor = {
        "frame_rate": frame_rate,
        "height": sensor_height,
        "n_beams": n_beams,
        "n_azimuths": n_azimuths,
        "max_range": max_range,
        "noise": noise,
    }
    return _render(street.static, street.tracks, ego, times, sensor, rng)


def _populate(rng, road, street, counts, speeds, ego_speed, duration):
    """Draw the parked cars, the movers and the standing things of ``counts`` onto the
    street, each clear of all before it; the movers near the sensor at some moment."""
    end = ego_speed * duration

    def near(at, behind=30.0, ahead=45.0):  # arc length a little behind or ahead of us
        return ego_speed * at + rng.uniform(-behind, ahead)

    def lane(centre=None):
        centre = rng.choice(_LANES) if centre is None else centre
        return centre + rng.uniform(-_LANE_JITTER, _LANE_JITTER), (-1 if centre > 0 else 1)

    def parked(_):
        side = rng.choice([-1.0, 1.0])
        x, y, heading = road.place(rng.uniform(-30.0, end + 45.0), side * _PARKING)
        yaw = heading + (np.pi if side > 0 else 0.0) + rng.uniform(-0.03, 0.03)
        return [(c, yaw, half, "parked car") for c, half in _parts_at_rest(_CAR, x, y, yaw)]

    def cruising(_):
        at = rng.uniform(0.0, duration)
        where, speed = (near(at), at), rng.uniform(*speeds)
        return [_lane_track(road, "car", "cruising", _CAR, lane(), where, speed)]

    def braking(_):
        road_lane = lane()
        stop = rng.uniform(duration / 3, 2 * duration / 3)
        t_brake = rng.uniform(0.0, 0.5) * stop
        speed = min(rng.uniform(*speeds), _MAX_BRAKING * (stop - t_brake))
        where, brake = (near(stop, 25.0, 40.0), stop), (t_brake, speed / (stop - t_brake))
        return [_lane_track(road, "car", "braking", _CAR, road_lane, where, speed, brake)]

    def overtaking(_):
        side = rng.choice([-1.0, 1.0])
        alongside = rng.uniform(duration / 3, 2 * duration / 3)
        slow = rng.uniform(*speeds)
        fast = slow + max(3.0, 6.0 / min(alongside, duration - alongside))
        where = (near(alongside, 20.0, 40.0), alongside)
        return [  # the slower in the outer lane, the faster passing it in the inner one
            _lane_track(road, "car", "overtaking", _CAR, lane(side * abs(centre)), where, speed)
            for centre, speed in ((_LANES[1], slow), (_LANES[0], fast))
        ]

    def walker(rank):
        return [_walker(rng, road, near, duration, crossing=rank % 2 == 1)]

    def cyclist(_):
        side, at = rng.choice([-1.0, 1.0]), rng.uniform(0.0, duration)
        parts, lane = _person(rng, _CYCLIST), (side * rng.uniform(*_CYCLE_LANE), -int(side))
        where, speed = (near(at, 25.0, 40.0), at), rng.uniform(*_CYCLIST_SPEED)
        return [_lane_track(road, "cyclist", "riding", parts, lane, where, speed)]

    def standing(_):
        side = rng.choice([-1.0, 1.0])
        x, y, _ = road.place(rng.uniform(-30.0, end + 45.0), side * rng.uniform(*_SIDEWALK))
        half = _person(rng, _WALKER if rng.uniform() < 0.5 else _BIN)[0, 1]
        return [(np.array([x, y, half[2]]), rng.uniform(-np.pi, np.pi), half, "standing")]

    draws = {
        "n_parked": parked,
        "n_moving": cruising,
        "n_braking": braking,
        "n_overtaking": overtaking,
        "n_walkers": walker,
        "n_cyclists": cyclist,
        "n_standing": standing,
    }
    for name, draw in draws.items():  # in this order: the ids follow it
        street.place(draw, name, counts[name])


def _parts_at_rest(parts, x, y, yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    for offset, half in parts:
        centre = [x + c * offset[0] - s * offset[1], y + s * offset[0] + c * offset[1], offset[2]]
        yield np.array(centre), half


def _walker(rng, road, near, duration, crossing):
    """A walker along a sidewalk, or across the road and waiting on both sidewalks."""
    parts = _person(rng, _WALKER)
    speed = rng.uniform(*_WALKER_SPEED)
    at = rng.uniform(0.0, duration)
    if not crossing:
        side = rng.choice([-1.0, 1.0])
        lane = (side * rng.uniform(*_SIDEWALK), rng.choice([-1, 1]))
        return _lane_track(
            road, "walker", "walking", parts, lane, (near(at, 25.0, 40.0), at), speed
        )
    x, y, heading = road.place(near(at, 10.0, 40.0), 0.0)
    stray = rng.uniform(-0.2, 0.2)
    across = heading + np.pi / 2 + stray + (np.pi if rng.uniform() < 0.5 else 0.0)
    reach = _CROSSING / np.cos(stray)
    return _crossing_track(
        parts, (x, y), (np.cos(across), np.sin(across)), rng.uniform(-8.0, 8.0), at, speed, reach
    )


def _static_world(rng, road, street, first, last):
    """Buildings with gaps along both sides between arc lengths ``first`` and ``last``, and
    poles by the kerbs."""
    k = abs(road.kappa)
    for side in (-1.0, 1.0):
        s = first
        while s < last:
            length, depth = rng.uniform(12.0, 30.0), rng.uniform(8.0, 14.0)
            height, turn = rng.uniform(6.0, 15.0), rng.uniform(-0.1, 0.1)
            # Set back so that neither its turn nor the bend brings a corner to the sidewalk.
            back = _FRONT + rng.uniform(0.0, 3.0) + depth / 2
            back += length / 2 * abs(np.sin(turn)) + k * length**2 / 8
            x, y, heading = road.place(s + length / 2, side * back)
            half = np.array([length / 2, depth / 2, height / 2])
            street.add((np.array([x, y, height / 2]), heading + turn, half, "building"))
            s += length + rng.uniform(2.0, 8.0)
        for s in rng.uniform(first, last, int((last - first) / 16.0)):
            x, y, heading = road.place(s, side * _POLE)
            street.add((np.array([x, y, 2.5]), heading, np.array([0.1, 0.1, 2.5]), "pole"))


def lidar_sequence_pair(log, k):
    """Frames ``k`` and ``k + 1`` of a log in the layout of :func:`make_lidar_sweeps`.

    Parameters
    ----------
    log : sklearn.utils.Bunch
        A log from :func:`make_lidar_sequence`.
    k : int
        The first frame of the pair, ``0 <= k < n_frames - 1``.

    Returns
    -------
    scene : sklearn.utils.Bunch
        ``a`` and ``sweep``: frames ``k`` and ``k + 1``; ``labels``: the log's ids of
        frame ``k``, 0 where the object moves at neither frame (a car stopped, a walker
        waiting); ``kinds``: the log's; ``transforms`` (n_objects + 1, 4, 4):
        ``transforms[i]`` maps a point of object ``i`` in ``a`` to where it is in the
        frame of ``sweep`` (0: the static world, the inverse of the ego motion); ``flow``
        (n, 3): each point's motion into that frame (its own object's, labelled or not);
        ``ground``, ``sweep_ground``, ``standing``; ``interval``: seconds between them.

    Examples
    --------
    >>> from mmreg.datasets import lidar_sequence_pair, make_lidar_sequence
    >>> log = make_lidar_sequence(3, frame_rate=2.0, n_azimuths=256, random_state=0)
    >>> pair = lidar_sequence_pair(log, 1)
    >>> pair.a.shape == log.frames[1].shape, pair.interval
    (True, 0.5)

    The static world moves by the inverse of the ego motion between the frames:

    >>> import numpy as np
    >>> ego_motion = np.linalg.inv(log.poses[1]) @ log.poses[2]
    >>> bool(np.allclose(pair.transforms[0] @ ego_motion, np.eye(4)))
    True
    """
    n_frames = len(log.frames)
    if isinstance(k, bool) or not isinstance(k, Integral) or not 0 <= k < n_frames - 1:
        raise ValueError(f"k must be an integer in [0, {n_frames - 1}); got {k!r}.")
    poses = [np.asarray(log.poses[f], dtype=float) for f in (k, k + 1)]
    transforms = np.tile(np.linalg.solve(poses[1], poses[0]), (len(log.kinds), 1, 1))
    moved = np.zeros(len(log.kinds), dtype=bool)
    table = log.objects.set_index(["frame", "id"])
    for j in range(1, len(log.kinds)):
        now, then = table.loc[(k, j)], table.loc[(k + 1, j)]
        # World pose of the object's box at both frames; the box moves rigidly with it.
        there = [_pose(row["x"], row["y"], row["z"], row["yaw"]) for row in (now, then)]
        transforms[j] = np.linalg.solve(poses[1], there[1] @ np.linalg.solve(there[0], poses[0]))
        moved[j] = now["moving"] or then["moving"]
    labels = log.labels[k]
    a = log.frames[k]
    flow = np.einsum("nij,nj->ni", transforms[labels, :3, :3], a) + transforms[labels, :3, 3] - a
    return Bunch(
        a=a,
        sweep=log.frames[k + 1],
        labels=np.where(moved[labels], labels, 0),
        kinds=log.kinds,
        standing=log.standing[k],
        ground=log.ground[k],
        sweep_ground=log.ground[k + 1],
        transforms=transforms,
        flow=flow,
        interval=1.0 / log.frame_rate,
    )


def _pose(x, y, z, yaw):
    pose = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    pose[:2, :2] = [[c, -s], [s, c]]
    pose[:3, 3] = x, y, z
    return pose


def _hidden_mover_log(
    n_hidden=2,
    *,
    frame_rate=10.0,
    n_before=2,
    n_after=2,
    ego_speed=8.0,
    mover_speed=10.0,
    n_beams=32,
    n_azimuths=1024,
    noise=0.0,
    random_state=0,
):
    """A scripted log in which a car is hidden for exactly ``n_hidden`` frames.

    A straight street with buildings (drawn from ``random_state``) and nothing else but
    the sensor's car in the outer lane, a van (id 1) driving beside it in the inner lane at
    its speed, and an oncoming car (id 2) in the nearer oncoming lane that passes behind
    the van. The van's length is chosen so that the oncoming car is wholly in its shadow
    in frames ``n_before .. n_before + n_hidden - 1``, with half a frame's travel to spare
    at both ends, and partly out of it in every other frame. Returns the Bunch of
    :func:`make_lidar_sequence` with ``hidden`` (the hidden frames) and ``mover`` (2).
    """
    _check_count("n_hidden", n_hidden, 1)
    road = _Road(0.0)
    n_frames = n_before + n_hidden + n_after
    times = np.arange(n_frames) / frame_rate
    step = 1.0 / frame_rate
    ego_lane, van_lane, mover_lane = _LANES[1], _LANES[0], _LANES[2]
    van_half = np.array([0.0, 1.1, 1.5])
    car_half = _CAR[0, 1]
    # The van's shadow, seen from the sensor beside its middle, is |x| <= L y / near at
    # the lateral distance y; the oncoming car is wholly in it while its centre is within
    # L far / near - its half length, far being the distance to its nearer side.
    near = van_lane - van_half[1] - ego_lane
    far = mover_lane - car_half[1] - ego_lane
    window = n_hidden * step * (ego_speed + mover_speed) / 2
    van_half[0] = (window + car_half[0]) * near / far
    ego = _lane_track(road, "ego", "ego", _CAR, (ego_lane, 1), (0.0, 0.0), ego_speed)
    middle = (n_before + (n_hidden - 1) / 2) * step
    passing = (ego_speed * middle, middle)  # the car passes the sensor's x then
    van = np.array([[[0.0, 0.0, van_half[2]], van_half]])
    tracks = [
        _lane_track(road, "van", "cruising", van, (van_lane, 1), (0.0, 0.0), ego_speed),
        _lane_track(road, "car", "cruising", _CAR, (mover_lane, -1), passing, mover_speed),
    ]
    sensor = {"frame_rate": frame_rate, "n_beams": n_beams, "n_azimuths": n_azimuths}
    log = _scripted_street(road, tracks, ego, times, sensor | {"noise": noise}, random_state)
    hidden = np.arange(n_before, n_before + n_hidden)
    seen = log.objects.loc[log.objects["id"] == 2, "n_points"].to_numpy()
    if (seen[hidden] > 0).any() or (np.delete(seen, hidden) == 0).any():
        raise ValueError(
            f"The oncoming car's returns per frame are {seen.tolist()}: with {n_beams} beams "
            f"and {n_azimuths} azimuths it is not hidden in frames {hidden.tolist()} only."
        )
    log.hidden = hidden
    log.mover = 2
    return log


def _convoy_log(
    n_frames=6,
    *,
    frame_rate=2.0,
    ego_speed=8.0,
    mover_speed=8.0,
    n_beams=32,
    n_azimuths=1024,
    noise=0.0,
    random_state=0,
):
    """A scripted log of two oncoming cars in a line, one frame's travel apart.

    A straight street with buildings (drawn from ``random_state``), the sensor's car in
    its lane and two cars alike (ids 1, the leader, and 2) in the nearer oncoming lane at
    ``mover_speed``, the second ``(ego_speed + mover_speed) / frame_rate`` metres behind
    the first: in each frame the second car stands, in the sensor's frame, where the first
    stood in the frame before. A pair alone cannot tell the leader's motion from staying
    put in the sensor's frame (moving with the sensor's car); the leader passes the
    sensor in the middle of the log. Returns the Bunch of :func:`make_lidar_sequence`.
    """
    _check_count("n_frames", n_frames, 2)
    road = _Road(0.0)
    times = np.arange(n_frames) / frame_rate
    gap = (ego_speed + mover_speed) / frame_rate
    ego = _lane_track(road, "ego", "ego", _CAR, (_EGO_LANE, 1), (0.0, 0.0), ego_speed)
    middle = times[-1] / 2
    passing = ego_speed * middle  # where the leader passes the sensor
    tracks = [
        _lane_track(road, "car", "cruising", _CAR, (-_EGO_LANE, -1), (s, middle), mover_speed)
        for s in (passing, passing + gap)
    ]
    sensor = {"frame_rate": frame_rate, "n_beams": n_beams, "n_azimuths": n_azimuths}
    return _scripted_street(road, tracks, ego, times, sensor | {"noise": noise}, random_state)


def _scripted_street(road, tracks, ego, times, sensor, random_state):
    """A scripted log: ``tracks`` and the sensor's car ``ego`` on ``road``, between buildings
    drawn from ``random_state`` 100 m beyond the drive either way, ray cast at ``times`` by
    a sensor 1.8 m up that sees 60 m (``sensor``: frame_rate, n_beams, n_azimuths, noise)."""
    rng = check_random_state(random_state)
    street = _Street(times, ego)
    x, *_ = ego.state(times)
    _static_world(rng, road, street, x[0] - 100.0, x[-1] + 100.0)
    sensor = {"height": 1.8, "max_range": 60.0} | sensor
    return _render(street.static, tracks, ego, times, sensor, rng)
