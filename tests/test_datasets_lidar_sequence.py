"""make_lidar_sequence: a LiDAR log of a street with tracks, boxes and ego poses.

Every check is made against the geometry the log returns (the objects' boxes, the static
world's boxes, the poses), by hand: points on faces and inside boxes, distances between
box centres, not against the generator's own motion formulas.
"""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mmreg.datasets import _lidar, _lidar_sequence, lidar_sequence_pair, make_lidar_sequence

SMALL = {"n_beams": 16, "n_azimuths": 512}
TOL = 1e-9  # metres: rounding of the ray casting, with no range noise


def _to_world(log, f):
    pose = log.poses[f]
    return log.frames[f] @ pose[:3, :3].T + pose[:3, 3]


def _in_box_frame(points, x, y, z, yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    q = points - [x, y, z]
    return np.column_stack([c * q[:, 0] + s * q[:, 1], -s * q[:, 0] + c * q[:, 1], q[:, 2]])


def _face_gap(points, boxes):
    """Each point's distance from the nearest box's surface, measured inside or out along
    the axis that sticks out most (0 on a face)."""
    best = np.full(len(points), np.inf)
    for box in boxes.itertuples():
        q = _in_box_frame(points, box.x, box.y, box.z, box.yaw)
        half = np.array([box.length, box.width, box.height]) / 2
        best = np.minimum(best, np.abs((np.abs(q) - half).max(axis=1)))
    return best


@pytest.fixture(scope="module", params=[10.0, 2.0])
def log(request):
    return make_lidar_sequence(6, frame_rate=request.param, noise=0.0, random_state=3, **SMALL)


def test_shapes_dtypes_and_the_tables(log):
    n_objects = len(log.kinds) - 1
    assert len(log.frames) == len(log.labels) == len(log.moving) == len(log.ground) == 6
    assert log.poses.shape == (6, 4, 4)
    np.testing.assert_array_equal(log.times, np.arange(6) / log.frame_rate)
    for frame, labels, moving, ground in zip(
        log.frames, log.labels, log.moving, log.ground, strict=True
    ):
        assert frame.dtype == np.float64 and frame.shape == (len(labels), 3)
        assert labels.dtype.kind == "i" and moving.dtype == bool and ground.dtype == bool
        assert labels.min() >= 0 and labels.max() <= n_objects
        assert not (moving & (labels == 0)).any() and not (ground & (labels > 0)).any()
    assert len(log.objects) == 6 * n_objects
    assert sorted(set(log.objects["id"])) == list(range(1, n_objects + 1))
    assert (log.objects.groupby("id")["kind"].first().to_numpy() == log.kinds[1:]).all()
    counts = np.array([np.bincount(lab, minlength=n_objects + 1)[1:] for lab in log.labels])
    table = log.objects.pivot(index="frame", columns="id", values="n_points").to_numpy()
    np.testing.assert_array_equal(counts, table)
    # The poses are rigid, z up, the sensor 1.8 m above the road.
    rotations = log.poses[:, :3, :3]
    np.testing.assert_allclose(
        rotations @ rotations.transpose(0, 2, 1), np.tile(np.eye(3), (6, 1, 1)), atol=TOL
    )
    np.testing.assert_allclose(rotations[:, 2], [[0, 0, 1]] * 6)
    np.testing.assert_allclose(log.poses[:, 2, 3], 1.8)
    np.testing.assert_allclose(log.poses[:, 3], [[0, 0, 0, 1]] * 6)


def test_the_same_seed_gives_the_same_log_and_another_seed_another():
    first, again, other = (
        make_lidar_sequence(3, random_state=seed, n_beams=8, n_azimuths=128) for seed in (1, 1, 2)
    )
    for a, b in zip(first.frames, again.frames, strict=True):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(first.labels, again.labels, strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(first.poses, again.poses)
    assert first.objects.equals(again.objects)
    assert not np.array_equal(first.poses, other.poses)


def test_an_ids_points_lie_in_its_box_at_every_frame(log):
    seen = 0
    for f in range(len(log.frames)):
        world = _to_world(log, f)
        for box in log.objects[log.objects["frame"] == f].itertuples():
            mine = log.labels[f] == box.id
            q = _in_box_frame(world[mine], box.x, box.y, box.z, box.yaw)
            half = np.array([box.length, box.width, box.height]) / 2
            assert (np.abs(q) <= half + TOL).all(), (f, box.id)
            seen += mine.any()
    assert seen >= 2 * (len(log.kinds) - 1)  # the objects are seen, most of them often


def test_the_static_world_lies_on_its_boxes_and_the_road(log):
    for f in range(len(log.frames)):
        world = _to_world(log, f)
        static = log.labels[f] == 0
        assert np.abs(world[log.ground[f], 2]).max() < TOL
        others = static & ~log.ground[f]
        assert others.sum() > 100
        assert _face_gap(world[others], log.static_boxes).max() < TOL


def test_the_static_world_moved_by_the_relative_pose_lands_on_the_next_frames_surfaces(log):
    """Frame k's static points taken into frame k + 1 by the pair's transform, and from
    there into the world by frame k + 1's pose alone, lie on the static boxes and road."""
    for k in range(len(log.frames) - 1):
        pair = lidar_sequence_pair(log, k)
        static = (log.labels[k] == 0) & ~pair.ground
        moved = pair.a[static] + pair.flow[static]
        np.testing.assert_allclose(
            moved, pair.a[static] @ pair.transforms[0, :3, :3].T + pair.transforms[0, :3, 3]
        )
        pose = log.poses[k + 1]
        world = moved @ pose[:3, :3].T + pose[:3, 3]
        assert _face_gap(world, log.static_boxes).max() < TOL
        road = pair.a[pair.ground] + pair.flow[pair.ground]
        assert np.abs(road @ pose[2, :3] + pose[2, 3]).max() < TOL


def test_the_pair_moves_each_objects_points_into_its_box_at_the_next_frame(log):
    k = 2
    pair = lidar_sequence_pair(log, k)
    world = (pair.a + pair.flow) @ log.poses[k + 1, :3, :3].T + log.poses[k + 1, :3, 3]
    truth = log.labels[k]
    for box in log.objects[log.objects["frame"] == k + 1].itertuples():
        q = _in_box_frame(world[truth == box.id], box.x, box.y, box.z, box.yaw)
        assert (np.abs(q) <= np.array([box.length, box.width, box.height]) / 2 + TOL).all()
    moving = log.objects[log.objects["frame"].isin([k, k + 1])].groupby("id")["moving"].any()
    np.testing.assert_array_equal(pair.labels, np.where(np.r_[False, moving][truth], truth, 0))
    assert pair.sweep is log.frames[k + 1] and pair.interval == 1 / log.frame_rate


def test_moving_marks_the_points_of_objects_moving_at_that_frame(log):
    for f in range(len(log.frames)):
        rows = log.objects[log.objects["frame"] == f].set_index("id")
        labels = log.labels[f]
        expected = (labels > 0) & np.r_[False, rows["moving"].to_numpy()][labels]
        np.testing.assert_array_equal(log.moving[f], expected)
        np.testing.assert_array_equal(rows["moving"], rows["speed"] > 0.1)


@pytest.mark.parametrize("frame_rate", [10.0, 2.0])
def test_a_cruising_car_keeps_the_speed_asked_for(frame_rate):
    log = make_lidar_sequence(
        8, frame_rate=frame_rate, n_moving=3, car_speed=8.0, curvature=0.0, **_nothing_else()
    )
    cars = log.objects[log.objects["motion"] == "cruising"]
    assert len(cars) == 8 * 3
    for _, track in cars.groupby("id"):
        step = np.hypot(np.diff(track["x"]), np.diff(track["y"]))
        np.testing.assert_allclose(step * frame_rate, 8.0)  # from the boxes' centres
        np.testing.assert_allclose(track["speed"], 8.0)
        np.testing.assert_allclose(track["yaw_rate"], 0.0)
    # The sensor's car too: 10 m/s along a straight street.
    travel = np.linalg.norm(np.diff(log.poses[:, :3, 3], axis=0), axis=1)
    np.testing.assert_allclose(travel * frame_rate, 10.0)


def test_on_a_bending_street_a_cruising_car_turns_at_a_constant_rate():
    """Constant speed v and yaw rate w: the centre moves by the chord 2 v / w sin(w dt / 2)
    and turns by w dt at every frame."""
    log = make_lidar_sequence(
        10, frame_rate=2.0, n_moving=3, car_speed=8.0, curvature=1 / 100, **_nothing_else()
    )
    for _, track in log.objects[log.objects["motion"] == "cruising"].groupby("id"):
        rate = track["yaw_rate"].to_numpy()
        np.testing.assert_allclose(rate, rate[0])
        assert abs(rate[0]) > 0.05  # 8 m/s on a 100 m radius, give or take the lane
        chord = 2 * 8.0 / abs(rate[0]) * np.sin(abs(rate[0]) * 0.5 / 2)
        np.testing.assert_allclose(np.hypot(np.diff(track["x"]), np.diff(track["y"])), chord)
        turn = np.angle(np.exp(1j * np.diff(track["yaw"])))
        np.testing.assert_allclose(turn, rate[0] * 0.5)


def test_a_braking_car_stops_keeps_its_id_and_is_no_longer_moving():
    log = make_lidar_sequence(
        20, frame_rate=2.0, n_moving=0, curvature=0.0, **_nothing_else(n_braking=1)
    )
    track = log.objects[log.objects["motion"] == "braking"]
    speed = track["speed"].to_numpy()
    assert speed[0] > 1.0 and (np.diff(speed) <= 1e-12).all()
    stopped = speed == 0.0
    assert stopped[-7:].all() and not stopped[:6].any()  # the stop falls in the middle third
    np.testing.assert_array_equal(track["moving"], ~stopped)
    # At rest it stays where it stopped; its points keep its id and are not moving.
    rest = track[stopped]
    assert rest["x"].nunique() == 1 and rest["y"].nunique() == 1
    (car,) = set(track["id"])
    for f in np.flatnonzero(stopped):
        mine = log.labels[f] == car
        assert mine.any() and not log.moving[f][mine].any()
    assert log.moving[0][log.labels[0] == car].all()


def test_the_faster_car_of_a_pair_passes_the_slower():
    log = make_lidar_sequence(
        10, frame_rate=2.0, n_moving=0, curvature=0.0, **_nothing_else(n_overtaking=2)
    )
    pairs = log.objects[log.objects["motion"] == "overtaking"]
    ids = sorted(set(pairs["id"]))
    assert len(ids) == 4
    for slow, fast in zip(ids[::2], ids[1::2], strict=True):
        a = pairs[pairs["id"] == slow].reset_index()
        b = pairs[pairs["id"] == fast].reset_index()
        ahead = (b["x"] - a["x"]) * np.sign(a["vx"])  # along their way
        assert ahead.iloc[0] < -4.4 and ahead.iloc[-1] > 4.4  # a car's length behind, ahead
        assert (b["speed"] >= a["speed"] + 3.0).all()
        assert np.all(np.sign(a["vx"]) == np.sign(b["vx"]))
        assert abs(a["y"].iloc[0] - b["y"].iloc[0]) > 3.0  # in the next lane


def test_walkers_keep_to_the_sidewalks_or_cross_on_a_straight_line():
    log = make_lidar_sequence(
        20, frame_rate=2.0, n_moving=0, curvature=0.0, **_nothing_else(n_walkers=4)
    )
    walkers = log.objects[log.objects["kind"] == "walker"]
    assert list(walkers.groupby("id")["motion"].first()) == ["walking", "crossing"] * 2
    for _, track in walkers.groupby("id"):
        speed = track["speed"].to_numpy()
        assert (speed < 1.9).all() and (track["yaw_rate"] == 0).all()
        if track["motion"].iloc[0] == "walking":  # along the street, on a sidewalk
            assert (np.abs(track["y"]) > 10.5).all() and (np.abs(track["y"]) < 14).all()
            assert (track["vy"] == 0).all() and np.ptp(speed) == 0
        else:  # across, on one line, waiting on the sidewalks (|y| about 11.5) if at all
            xy = track[["x", "y"]].to_numpy()
            steps = np.diff(xy, axis=0)
            cross = steps[:, 0] * steps[0, 1] - steps[:, 1] * steps[0, 0]
            np.testing.assert_allclose(cross, 0.0, atol=1e-9)
            waiting = speed == 0
            assert (np.abs(track["y"][waiting]) > 11).all()
            assert (np.abs(track["y"][~waiting]) < 12).all()


def test_no_two_objects_and_no_object_and_the_sensors_car_overlap():
    log = make_lidar_sequence(
        12, frame_rate=2.0, n_walkers=4, n_cyclists=2, n_standing=3, random_state=5, **SMALL
    )
    grid = np.stack(np.meshgrid(np.linspace(-1, 1, 9), np.linspace(-1, 1, 9)), -1).reshape(-1, 2)
    for f, rows in log.objects.groupby("frame"):
        boxes = [(r.x, r.y, r.yaw, r.length / 2, r.width / 2) for r in rows.itertuples()]
        pose = log.poses[f]
        boxes.append((*pose[:2, 3], np.arctan2(pose[1, 0], pose[0, 0]), 2.3, 0.95))
        for i, (x, y, yaw, hl, hw) in enumerate(boxes):
            c, s = np.cos(yaw), np.sin(yaw)
            local = grid * [hl, hw]
            points = np.column_stack(
                [x + c * local[:, 0] - s * local[:, 1], y + s * local[:, 0] + c * local[:, 1]]
            )
            for j, (x2, y2, yaw2, hl2, hw2) in enumerate(boxes):
                if i != j:
                    q = _in_box_frame(np.c_[points, np.zeros(len(points))], x2, y2, 0.0, yaw2)
                    inside = (np.abs(q[:, 0]) < hl2) & (np.abs(q[:, 1]) < hw2)
                    assert not inside.any(), (f, i, j)


@pytest.mark.parametrize("frame_rate", [10.0, 2.0])
@pytest.mark.parametrize("n_hidden", [1, 2, 3])
def test_a_mover_hidden_for_m_frames_has_no_points_then_and_keeps_its_id(frame_rate, n_hidden):
    log = _lidar_sequence._hidden_mover_log(n_hidden, frame_rate=frame_rate, **SMALL)
    counts = np.array([(labels == log.mover).sum() for labels in log.labels])
    hidden = np.arange(2, 2 + n_hidden)
    np.testing.assert_array_equal(log.hidden, hidden)
    assert (counts[hidden] == 0).all()
    assert (np.delete(counts, hidden) > 0).all()  # seen before and after, under its id
    assert (log.kinds[log.mover], log.motions[log.mover]) == ("car", "cruising")


def test_the_mover_is_hidden_behind_the_van():
    """In the hidden frames the rays towards the mover's box end on the van (id 1)."""
    log = _lidar_sequence._hidden_mover_log(2, frame_rate=10.0, **SMALL)
    row = log.objects[(log.objects["frame"] == 2) & (log.objects["id"] == log.mover)].iloc[0]
    pose = log.poses[2]
    corner = np.array([row.x + row.length / 2, row.y - row.width / 2, row.z])  # towards us
    direction = (corner - pose[:3, 3]) / np.linalg.norm(corner - pose[:3, 3])
    van = log.objects[(log.objects["frame"] == 2) & (log.objects["id"] == 1)].iloc[0]
    box = (
        np.array([van.x, van.y, van.z]),
        van.yaw,
        np.array([van.length, van.width, van.height]) / 2,
    )
    distance, hit = _lidar._first_hits(pose[:3, 3], direction[None], [box], 60.0)
    assert hit[0] == 0 and distance[0] < np.linalg.norm(corner - pose[:3, 3])


@given(seed=st.integers(0, 2**16), frame=st.integers(0, 3))
def test_the_culled_casting_finds_what_every_ray_against_every_box_finds(seed, frame):
    """_cast tests each box against the rays that can reach it only; _first_hits of
    make_lidar_sweeps tests every ray against every box. Same hits, same distances."""
    rng = np.random.RandomState(seed)
    log = make_lidar_sequence(
        4, frame_rate=2.0, n_walkers=2, n_standing=2, random_state=seed, n_beams=8, n_azimuths=256
    )
    rows = log.objects[log.objects["frame"] == frame]
    statics = log.static_boxes
    boxes = [
        (np.array([b.x, b.y, b.z]), b.yaw, np.array([b.length, b.width, b.height]) / 2)
        for table in (statics, rows)
        for b in table.itertuples()
    ]
    position = log.poses[frame, :3, 3] + [rng.uniform(-3, 3), rng.uniform(-2, 2), 0.0]
    heading = rng.uniform(-np.pi, np.pi)
    elevations = np.radians(np.linspace(-25.0, 15.0, 8))
    azimuths = -np.pi + rng.uniform(0, 0.02) + 2 * np.pi / 256 * np.arange(256)
    arrays = tuple(np.array([box[i] for box in boxes]) for i in range(3))
    distance, hit = _lidar_sequence._cast(position, heading, arrays, elevations, azimuths, 60.0)
    el, az = np.meshgrid(elevations, azimuths + heading, indexing="ij")
    rays = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1)
    reference, reference_hit = _lidar._first_hits(position, rays.reshape(-1, 3), boxes, 60.0)
    np.testing.assert_array_equal(hit.ravel(), reference_hit)
    found = reference_hit > -2
    np.testing.assert_allclose(distance.ravel()[found], reference[found], rtol=0, atol=TOL)


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"n_frames": 1}, "n_frames"),
        ({"n_frames": 2.0}, "n_frames"),
        ({"frame_rate": 0.0}, "frame_rate"),
        ({"frame_rate": np.nan}, "frame_rate"),
        ({"n_walkers": -1}, "n_walkers"),
        ({"n_braking": True}, "n_braking"),
        ({"car_speed": (9.0, 5.0)}, "car_speed"),
        ({"car_speed": (1.0, 2.0, 3.0)}, "car_speed"),
        ({"car_speed": -2.0}, "car_speed"),
        ({"curvature": 0.5}, "curvature"),
        ({"ego_speed": -1.0}, "ego_speed"),
        ({"noise": -0.1}, "noise"),
        ({"n_azimuths": 4}, "n_azimuths"),
    ],
)
def test_bad_arguments_are_named(options, match):
    with pytest.raises(ValueError, match=match):
        make_lidar_sequence(**{"n_frames": 2, **options})


def test_too_many_objects_for_the_street_is_one_clear_error():
    with pytest.raises(ValueError, match="n_parked=300"):
        make_lidar_sequence(2, n_parked=300, random_state=0, n_beams=4, n_azimuths=64)


@pytest.mark.parametrize("k", [-1, 5, 1.0, True])
def test_a_pair_outside_the_log_is_refused(log, k):
    with pytest.raises(ValueError, match="k must be"):
        lidar_sequence_pair(log, k)


def _nothing_else(**asked):
    """No other objects than ``asked``, no range noise: the motions asked for alone."""
    return {
        "n_braking": 0,
        "n_overtaking": 0,
        "n_parked": 0,
        "n_walkers": 0,
        "n_cyclists": 0,
        "n_standing": 0,
        "noise": 0.0,
        "random_state": 0,
        **SMALL,
        **asked,
    }
