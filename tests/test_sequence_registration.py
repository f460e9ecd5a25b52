"""SequenceRegistration: a LiDAR log in, tracks out.

Each behaviour here is one a pair-only method cannot show: a motion seen in one pair
only is dropped, an object keeps its id through an occlusion, a parked car is never
moving, a car's speed is measured in m/s; and online equals batch.
"""

import re
import warnings

import numpy as np
import pytest
from sklearn.base import BaseEstimator, clone

from mmreg import SequenceRegistration, SweepRegistration
from mmreg.datasets import make_lidar_sequence
from mmreg.datasets._lidar_sequence import _hidden_mover_log
from mmreg.estimators import ScaleWarning
from mmreg.estimators._sequence import _PairMaker
from mmreg.tracking import _log


def _in_box(points, box):
    """Which world points lie in a box row (x, y, z, length, width, height, yaw)."""
    c, s = np.cos(box.yaw), np.sin(box.yaw)
    d = points - [box.x, box.y, box.z]
    along, across = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    return (
        (np.abs(along) <= box.length / 2 + 0.05)
        & (np.abs(across) <= box.width / 2 + 0.05)
        & (np.abs(d[:, 2]) <= box.height / 2 + 0.05)
    )


def _world(log, k):
    return log.frames[k] @ log.poses[k][:3, :3].T + log.poses[k][:3, 3]


class _Ghosts(BaseEstimator):
    """SweepRegistration that also reports static points moving, in chosen pairs.

    ``ghosts`` maps the size of a pair's first sweep to ``(mask, shift)``: its points in
    ``mask`` become one more cluster, moving by ``shift`` relative to the static world.
    That is the kind of motion a pair alone finds on a static surface (a parked car at
    0.08 m a frame, a wall sliding along itself).
    """

    def __init__(self, ghosts=None, random_state=None):
        self.ghosts = ghosts
        self.random_state = random_state

    def fit(self, points, *, sweep, ego_motion=None):
        est = SweepRegistration(random_state=self.random_state)
        est = est.fit(points, sweep=sweep, ego_motion=ego_motion)
        for name, value in vars(est).items():
            if name.endswith("_") and not name.startswith("_"):
                setattr(self, name, value)
        if len(points) in (self.ghosts or {}):
            mask, shift = self.ghosts[len(points)]
            ghost = mask & (self.labels_ >= 0)
            k = self.n_clusters_
            R, t = self.ego_motion_
            self.labels_ = np.where(ghost, k, self.labels_)
            self.rotations_ = np.concatenate([self.rotations_, R[None]])
            self.translations_ = np.concatenate([self.translations_, (t + shift)[None]])
            self.moving_ = np.append(self.moving_, True)
            self.n_clusters_ = k + 1
            self.flow_ = self.flow_.copy()
            self.flow_[ghost] = points[ghost] @ R.T + t + shift - points[ghost]
        return self


def _inside(log, k, kind):
    world = _world(log, k)
    inside = np.zeros(len(world), bool)
    for box in log.static_boxes[log.static_boxes.kind == kind].itertuples():
        inside |= _in_box(world, box)
    return inside


@pytest.fixture(scope="module")
def street():
    """Six frames of a generated street at 10 Hz, with its fit."""
    log = make_lidar_sequence(6, frame_rate=10.0, n_azimuths=512, random_state=3)
    est = SequenceRegistration(random_state=0).fit(log.frames, times=log.times)
    return log, est


def test_tau_sets_the_units_of_the_log_and_of_its_pairs(street):
    # The same street in millimetres, told so by tau alone: the same tracks.
    log, metres = street
    scale = 1000.0
    frames = [frame * scale for frame in log.frames]
    with warnings.catch_warnings():
        warnings.simplefilter("error", ScaleWarning)  # tau is in the frames' units
        est = SequenceRegistration(tau=5.0 * scale, random_state=0).fit(frames, times=log.times)
    assert _PairMaker(est.pair_estimator, est.tau)(0).get_params()["tau"] == 5.0 * scale
    # (Pairs taken at tau 5 in any units found a tenth of the moving points here, and a
    # level ICP whose turn was weighed in square units 98-99 % of the labels.)
    for mm, m in zip(est.labels_, metres.labels_, strict=True):
        assert np.mean(mm == m) > 0.999
    assert est.n_tracks_ == metres.n_tracks_


@pytest.fixture(scope="module")
def two_frames():
    return make_lidar_sequence(2, frame_rate=10.0, n_azimuths=256, random_state=0)


def _scale_warnings(record):
    return [w for w in record if w.category is ScaleWarning]


def test_a_log_in_other_units_than_tau_warns_at_the_users_line(two_frames):
    # A street sampled every 3-7 cm, in centimetres: tau=5 spans a few spacings.
    frames = [frame * 100.0 for frame in two_frames.frames]
    message = "tau=5 spans fewer than 4 times the median distance between neighbouring"
    with pytest.warns(ScaleWarning, match=message) as record:
        SequenceRegistration(random_state=0).fit(frames, times=two_frames.times)
    (warning,) = _scale_warnings(record)
    assert warning.filename == __file__
    online = SequenceRegistration(random_state=0)
    with pytest.warns(ScaleWarning, match=message) as record:
        online.partial_fit(frames[0], time=0.0)
    assert len(_scale_warnings(record)) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error", ScaleWarning)  # once, at the log's first frame
        online.partial_fit(frames[1], time=0.1)
        online.finish()
    # In kilometres, tau=5 spans the street many times over.
    kilometres = two_frames.frames[0] * 1e-3
    with pytest.warns(ScaleWarning, match="tau=5 exceeds the diagonal of the first frame"):
        SequenceRegistration().partial_fit(kilometres, time=0.0)


@pytest.mark.parametrize(("unit", "shown"), [(1e3, "100 apart"), (1e9, "1e+08 apart")])
def test_times_in_milliseconds_or_nanoseconds_warn(two_frames, unit, shown):
    times = np.asarray(two_frames.times) * unit + 1.7e9 * unit  # a clock's epoch times
    with pytest.warns(ScaleWarning, match=f"times are {re.escape(shown)}.*milliseconds") as record:
        SequenceRegistration(random_state=0).fit(two_frames.frames, times=times)
    assert len(_scale_warnings(record)) == 1
    online = SequenceRegistration(random_state=0).partial_fit(two_frames.frames[0], time=times[0])
    with pytest.warns(ScaleWarning, match=re.escape(shown)):
        online.partial_fit(two_frames.frames[1], time=times[1])
    # In seconds, from the same epoch: no warning.
    with warnings.catch_warnings():
        warnings.simplefilter("error", ScaleWarning)
        SequenceRegistration(random_state=0).fit(two_frames.frames, times=times / unit)


def test_a_frame_period_given_as_the_frame_rate_warns(two_frames):
    # 0.05: the seconds between a 20 Hz sensor's frames, not its frames per second.
    with pytest.warns(ScaleWarning, match=r"frame_rate=0\.05 puts the frames 20 s apart"):
        SequenceRegistration(frame_rate=0.05, random_state=0).fit(two_frames.frames)
    with pytest.warns(ScaleWarning, match="frame_rate is frames per second"):
        SequenceRegistration(frame_rate=0.05).partial_fit(two_frames.frames[0])
    with warnings.catch_warnings():
        warnings.simplefilter("error", ScaleWarning)
        SequenceRegistration(frame_rate=20.0, random_state=0).fit(two_frames.frames)


def test_a_ghost_seen_in_one_pair_is_dropped(street):
    log, _ = street
    k = 2
    # A patch of the nearest building's face, in frame k's sensor frame, reported
    # moving 1 m along x in pair (k, k + 1).
    on = _inside(log, k, "building")
    points = log.frames[k]
    nearest = np.argmin(np.where(on, np.linalg.norm(points, axis=1), np.inf))
    low, high = points[nearest] - [3.0, 3.0, 1.0], points[nearest] + [3.0, 3.0, 3.0]
    patch = np.all((points >= low) & (points <= high), axis=1) & on
    assert patch.sum() > 50
    pair = _Ghosts({len(points): (patch, np.array([1.0, 0.0, 0.0]))}, random_state=0)
    alone = clone(pair).fit(points, sweep=log.frames[k + 1])
    assert alone.moving_[alone.labels_[patch]].all()  # the pair alone reports it moving
    est = SequenceRegistration(pair, random_state=0).fit(log.frames, times=log.times)
    assert not est.moving_[k][patch].any()
    assert np.all(est.labels_[k][patch] <= 0)


def test_a_mover_hidden_for_two_frames_keeps_its_id():
    log = _hidden_mover_log(
        2, frame_rate=2.0, n_before=3, n_after=3, ego_speed=4.0, mover_speed=6.0
    )
    est = SequenceRegistration(random_state=0).fit(log.frames, times=log.times)
    ids = set()
    for k in range(len(log.frames)):
        mover = log.labels[k] == log.mover
        if not mover.any():
            assert k in log.hidden
            continue
        values, counts = np.unique(est.labels_[k][mover], return_counts=True)
        if values[np.argmax(counts)] > 0:
            ids.add(int(values[np.argmax(counts)]))
            assert est.moving_[k][mover].mean() > 0.5 or k == 1
    before = {int(np.bincount(est.labels_[0][log.labels[0] == log.mover].clip(0)).argmax())}
    after = {int(np.bincount(est.labels_[-2][log.labels[-2] == log.mover].clip(0)).argmax())}
    assert before == after == ids
    assert ids.pop() > 0


def test_parked_cars_stay_static(street):
    log, est = street
    for k in range(len(log.frames)):
        inside = _inside(log, k, "parked car")
        assert inside.sum() > 100
        assert not est.moving_[k][inside].any()


def test_a_parked_car_that_two_pairs_call_moving_stays_static(street):
    log, _ = street
    # The nearest parked car, reported moving by 8 cm in two pairs running (another
    # way each time: what a pair finds on a car seen from two sides).
    ghosts, cars = {}, {}
    for k, shift in ((1, [0.08, 0.0, 0.0]), (2, [0.0, 0.08, 0.0])):
        inside = _inside(log, k, "parked car")
        points = log.frames[k]
        nearest = np.argmin(np.where(inside, np.linalg.norm(points, axis=1), np.inf))
        low, high = points[nearest] - 2.5, points[nearest] + 2.5
        cars[k] = np.all((points >= low) & (points <= high), axis=1) & inside
        ghosts[len(points)] = (cars[k], np.array(shift))
    pair = _Ghosts(ghosts, random_state=0)
    for k, car in cars.items():  # each pair alone calls the car moving
        alone = clone(pair).fit(log.frames[k], sweep=log.frames[k + 1])
        assert car.sum() > 50 and alone.moving_[alone.labels_[car]].all()
    est = SequenceRegistration(pair, random_state=0).fit(log.frames, times=log.times)
    for k, car in cars.items():
        assert not est.moving_[k][car].any()


def _cruising_cars(n_moving):
    """Six 10 Hz frames of ``n_moving`` cars cruising at 8 m/s, parked cars, nothing else."""
    return make_lidar_sequence(
        6,
        frame_rate=10.0,
        n_moving=n_moving,
        n_braking=0,
        n_overtaking=0,
        n_walkers=0,
        n_cyclists=0,
        n_standing=0,
        car_speed=8.0,
        n_azimuths=512,
        random_state=1,
    )


def test_a_constant_velocity_cars_speed_is_measured_within_five_percent():
    log = _cruising_cars(1)
    est = SequenceRegistration(random_state=0).fit(log.frames, times=log.times)
    car = next(i for i, kind in enumerate(log.kinds) if kind == "car")
    # The track that holds most of the car's points.
    held = np.concatenate([est.labels_[k][log.labels[k] == car] for k in range(6)])
    track = np.bincount(held[held > 0]).argmax()
    speeds = est.tracks_.loc[est.tracks_.track == track, "speed"]
    assert len(speeds) >= 3
    assert abs(np.median(speeds) - 8.0) < 0.05 * 8.0


def test_tracks_move_level_on_level_ground():
    # A far car's few points fit a free motion that tilts it. A confirmed track that
    # took a pair's motion as it came predicted the car sinking into the road at
    # 1.8 m/s, lost it, and the car was found again as a new track.
    log = make_lidar_sequence(10, frame_rate=10.0, n_azimuths=512, random_state=0)
    tracks = SequenceRegistration(random_state=0).fit(log.frames, times=log.times).tracks_
    assert len(tracks) >= 10
    assert np.all(tracks.vz.abs() <= 0.05 * np.maximum(tracks.speed, 1.0))


def test_online_times_given_for_some_frames_only_are_one_clear_error(two_frames):
    frames, times = two_frames.frames, two_frames.times
    online = SequenceRegistration(random_state=0)
    online.partial_fit(frames[0], time=times[0])
    with pytest.raises(ValueError, match="frame 1 has no time and frame 0 had one"):
        online.partial_fit(frames[1])
    untimed = SequenceRegistration(random_state=0)
    untimed.partial_fit(frames[0])
    with pytest.raises(ValueError, match="frame 1 has a time and frame 0 had none"):
        untimed.partial_fit(frames[1], time=times[1])


def test_online_equals_batch(street):
    log, batch = street
    online = SequenceRegistration(random_state=0)
    results = []
    for points, time in zip(log.frames, log.times, strict=True):
        results += online.partial_fit(points, time=time).finished_
        # Frame k is final once frame k + lookahead + 1 is in.
        assert all(r.index <= results[-1].index for r in results)
    results += online.finish().finished_
    assert [r.index for r in results] == list(range(len(log.frames)))
    for k, result in enumerate(results):
        np.testing.assert_array_equal(result.labels, batch.labels_[k])
        np.testing.assert_array_equal(result.moving, batch.moving_[k])
        np.testing.assert_allclose(result.pose, batch.ego_poses_[k])


def test_invalid_returns_are_labelled_minus_one_and_change_nothing_else(street):
    log, batch = street
    frames = []
    for k, points in enumerate(log.frames):
        # A NaN row, and the origin twice (a driver's failed returns).
        rows = np.insert(points, [0, 10, 10], [[np.nan] * 3, [0.0] * 3, [0.0] * 3], axis=0)
        frames.append(rows if k % 2 else points)
    est = SequenceRegistration(random_state=0).fit(frames, times=log.times)
    for k in range(len(frames)):
        labels = est.labels_[k]
        if k % 2:
            assert np.all(labels[[0, 11, 12]] == -1)
            assert np.isnan(est.flows_[k][[0, 11, 12]]).all()
            labels = np.delete(labels, [0, 11, 12])
        np.testing.assert_array_equal(labels, batch.labels_[k])


def test_the_fitted_log(street):
    log, est = street
    assert est.n_frames_ == len(log.frames)
    assert [len(labels) for labels in est.labels_] == [len(f) for f in log.frames]
    np.testing.assert_allclose(est.ego_poses_[0], np.eye(4))
    # The odometry: each relative pose within 5 cm of the truth.
    for k in range(len(log.frames) - 1):
        truth = np.linalg.inv(log.poses[k + 1]) @ log.poses[k]
        found = np.linalg.inv(est.ego_poses_[k + 1]) @ est.ego_poses_[k]
        assert np.linalg.norm(truth[:3, 3] - found[:3, 3]) < 0.05
    assert list(est.tracks_.columns)[:3] == ["track", "frame", "time"]
    assert est.n_tracks_ == est.tracks_.track.nunique()
    labels = np.concatenate(est.labels_)
    assert labels.min() >= -1 and np.mean(labels == 0) > 0.5
    assert set(np.unique(labels[labels > 0])) <= set(est.tracks_.track)


@pytest.mark.parametrize(
    ("frames", "kwargs", "message"),
    [
        ([np.zeros((5, 3))], {}, "at least 2 frames"),
        ([np.ones((5, 3))] * 2, {"times": [1.0, 1.0]}, "times must increase"),
        (
            [np.ones((5, 3))] * 2,  # epoch seconds 0.1 apart, in float32 (128 s steps)
            {"times": np.array([1.7e9, 1.7e9 + 0.1], dtype=np.float32)},
            r"float32, which holds times of 1\.7e\+09 only to 128 s",
        ),
        ([np.ones((5, 3))] * 2, {"times": [1.0]}, "one per frame"),
        ([np.ones((5, 3))] * 2, {"poses": np.eye(4)}, r"poses must have shape \(2, 4, 4\)"),
        (
            [np.ones((5, 3))] * 2,  # a scaled pose (a map's units, a similarity)
            {"poses": np.stack([np.eye(4), np.diag([2.0, 2.0, 2.0, 1.0])])},
            r"poses\[1\] is not a rigid motion",
        ),
        ([np.ones(5)] * 2, {}, r"shape \(n, 3\)"),
    ],
)
def test_bad_input_gets_one_clear_error(frames, kwargs, message):
    with pytest.raises(ValueError, match=message):
        SequenceRegistration().fit(frames, **kwargs)


def test_online_memory_is_bounded():
    """Only the tracks, lookahead + 2 frames and the frames of the last half second (the
    long span's) are kept, however long the log."""
    import gc

    from mmreg.tracking._log import LogFrame
    from mmreg.tracking._long_span import LONG_SPAN

    log = make_lidar_sequence(12, frame_rate=10.0, n_azimuths=256, random_state=0)
    est = SequenceRegistration(random_state=0, lookahead=1)

    def frames_alive():
        gc.collect()
        return sum(isinstance(o, LogFrame) for o in gc.get_objects())

    before = frames_alive()  # other tests' estimators hold none once fitted
    held = []
    for points, time in zip(log.frames, log.times, strict=True):
        est.partial_fit(points, time=time)
        held.append(frames_alive() - before)
    span = round(LONG_SPAN * 10.0)  # frames
    assert max(held) <= est.lookahead + 2 + span
    assert held[-1] == held[span + 3]  # flat, not growing with the log
    est.finish()
    assert frames_alive() == before


class _Recording(BaseEstimator):
    """SweepRegistration that records what each pair's fit was given."""

    calls = []

    def __init__(self, random_state=None):
        self.random_state = random_state

    def fit(self, points, *, sweep, **kwargs):
        type(self).calls.append(kwargs)
        est = SweepRegistration(random_state=self.random_state).fit(points, sweep=sweep, **kwargs)
        for name, value in vars(est).items():
            if name.endswith("_") and not name.startswith("_"):
                setattr(self, name, value)
        return self


def test_each_pair_gets_the_log_s_times_ego_start_and_body(street):
    log, _ = street
    offsets = [np.linspace(0.0, 0.1, len(f)) for f in log.frames]
    _Recording.calls = []
    est = SequenceRegistration(_Recording(random_state=0), random_state=0)
    est.fit(log.frames, times=log.times, point_times=offsets)
    calls = _Recording.calls
    assert len(calls) == len(log.frames) - 1
    for k, kwargs in enumerate(calls):
        assert kwargs["interval"] == pytest.approx(log.times[k + 1] - log.times[k])
        np.testing.assert_array_equal(kwargs["times"], offsets[k])
        np.testing.assert_array_equal(kwargs["sweep_times"], offsets[k + 1])
    assert "ego_motion" not in calls[0] and all("ego_motion" in c for c in calls[1:])
    with pytest.raises(ValueError, match="point_times goes with times"):
        SequenceRegistration().fit(log.frames, point_times=offsets)


def test_each_frame_s_state_is_computed_once(monkeypatch):
    """Every frame is the second sweep of one pair and the first of the next: its ground
    (Patchwork++), islands and k-d tree are made once for both, and the tracks use the
    same tree."""
    import mmreg.sweeps._sweep_state as sweep_state
    import mmreg.tracking._log as sequence

    calls = {}
    for module, name in (
        (sweep_state, "ground_mask"),
        (sweep_state, "voxel_islands"),
        (sweep_state, "PointTree"),
        (sequence, "cKDTree"),
    ):
        original = getattr(module, name)

        def counted(points, *args, _original=original, _name=name, **kwargs):
            key = (_name, np.ascontiguousarray(points).tobytes(), args)
            calls[key] = calls.get(key, 0) + 1
            return _original(points, *args, **kwargs)

        monkeypatch.setattr(module, name, counted)
    log = make_lidar_sequence(4, frame_rate=10.0, n_azimuths=256, random_state=0)
    whole = {f.tobytes() for f in log.frames}
    SequenceRegistration(random_state=0).fit(log.frames, times=log.times)
    # Nothing of a sweep's state is made twice from the same points.
    trees = ("PointTree", "cKDTree")
    state = {key: n for key, n in calls.items() if key[0] not in trees or key[1] in whole}
    assert state and max(state.values()) == 1
    for name in ("ground_mask", "voxel_islands"):
        made = [key for key in calls if key[0] == name]
        assert len(made) >= len(log.frames)
    made = [key for key in calls if key[0] in trees and key[1] in whole]
    # One tree of every frame that is some pair's second sweep, which the tracks share;
    # the first frame's too where a claim reads its surface normals.
    assert len(log.frames) - 1 <= len(made) <= len(log.frames)


def test_thinned_to_voxels_every_point_takes_its_voxel_s_labels(street):
    log, full = street
    est = SequenceRegistration(random_state=0, voxel_size=0.1).fit(log.frames, times=log.times)
    for k, points in enumerate(log.frames):
        keys = np.floor(points / 0.1).astype(np.int64)
        _, group = np.unique(keys, axis=0, return_inverse=True)
        group = group.ravel()
        labels = est.labels_[k]
        # One label per voxel.
        first = np.zeros(group.max() + 1, dtype=np.intp)
        first[group[::-1]] = labels[::-1]
        np.testing.assert_array_equal(labels, first[group])
        assert est.flows_[k].shape == points.shape
    # It finds what the full sweeps find firmly: every object of 500 points or more of
    # which the full fit calls nine tenths moving, it calls most of moving (the car
    # tracked from the second frame on: 0.87-1.0 of it). The oncoming car at 40 m/s is
    # left out: whether its track is born on its first sighting or a frame later
    # changes with the random state, thinned or not, and so do its shares. And it calls
    # nothing moving that is static.
    for k, truth in enumerate(log.moving):
        objects = np.where(truth, log.labels[k], 0)
        for i in np.unique(objects[objects > 0]):
            rows = objects == i
            if rows.sum() >= 500 and np.mean(full.moving_[k][rows]) >= 0.9:
                assert np.mean(est.moving_[k][rows]) > 0.5, (k, i)
        assert not np.any(est.moving_[k] & ~truth)


def test_a_frame_too_sparse_to_register_is_a_gap_with_a_warning(street):
    log, _ = street
    frames = list(log.frames)
    frames[3] = frames[3][:5]  # an almost empty message
    # Without a look ahead, frame k is final once frame k + 1 is in: frames 0 and 1 are
    # final before the gap arrives (a look ahead lets a later pair revise them).
    batch = SequenceRegistration(random_state=0, lookahead=0).fit(log.frames, times=log.times)
    with pytest.warns(UserWarning, match="frame 3: fewer than 10 valid points"):
        est = SequenceRegistration(random_state=0, lookahead=0).fit(frames, times=log.times)
    assert [len(labels) for labels in est.labels_] == [len(f) for f in frames]
    # The frames before the gap are as without it; the odometry goes on across it.
    for k in (0, 1):
        np.testing.assert_array_equal(est.labels_[k], batch.labels_[k])
    truth = np.linalg.inv(log.poses[5]) @ log.poses[4]
    found = np.linalg.inv(est.ego_poses_[5]) @ est.ego_poses_[4]
    assert np.linalg.norm(truth[:3, 3] - found[:3, 3]) < 0.05


class _Blind(BaseEstimator):
    """SweepRegistration that calls every cluster static: a pair that sees no motion."""

    def __init__(self, random_state=None):
        self.random_state = random_state

    def fit(self, points, *, sweep, ego_motion=None):
        est = SweepRegistration(random_state=self.random_state)
        est = est.fit(points, sweep=sweep, ego_motion=ego_motion)
        for name, value in vars(est).items():
            if name.endswith("_") and not name.startswith("_"):
                setattr(self, name, value)
        self.moving_ = np.zeros_like(np.asarray(est.moving_, dtype=bool))
        return self


def test_movers_no_pair_detects_are_found_from_the_places_they_leave_and_reach(monkeypatch):
    log = _cruising_cars(2)
    cars = [i for i, kind in enumerate(log.kinds) if kind == "car"]
    est = SequenceRegistration(_Blind(random_state=0), random_state=0)
    est.fit(log.frames, times=log.times)
    checked = 0
    for car in cars:
        held = [est.labels_[k][log.labels[k] == car] for k in range(1, 5)]
        held = [h for h in held if len(h) >= 100]  # a far car of a few rings: no body
        # One id holds most of the car's points in the middle frames.
        ids = {int(np.bincount(h.clip(0)).argmax()) for h in held}
        if held:
            assert len(ids) == 1 and ids.pop() > 0
            checked += 1
    assert checked >= 1
    for k in range(len(log.frames)):
        assert not est.moving_[k][~log.moving[k]].any()
    # Without the places, the blind pairs leave every car static.
    monkeypatch.setattr("mmreg.tracking._log.LogTracker._moved_places", lambda self, *args: [])
    est = SequenceRegistration(_Blind(random_state=0), random_state=0)
    est.fit(log.frames, times=log.times)
    assert not any(m.any() for m in est.moving_)


def test_a_track_s_few_points_where_it_ends_are_static():
    from mmreg.tracking._log import LogFrame, LogTracker

    tracker = LogTracker(
        None, tau=5.0, lookahead=2, max_misses=3, frame_rate=None, min_points=12,
        rng=np.random.RandomState(0),
    )  # fmt: skip
    frame = LogFrame(5, np.zeros((40, 3)), np.ones(40, bool), 5.0)
    # Track 1: 6 points, last seen here; track 2: 20 points, last seen here; track 3:
    # 6 points, seen two frames later; track 4 joined track 3 (its key names track 3).
    keys = np.r_[np.full(6, 1), np.full(20, 2), np.full(6, 3), np.full(4, 4), [-1] * 4]
    tracker._state.last_seen.update({1: 5, 2: 5, 3: 7, 4: 4})
    tracker._state.alias[4] = 3
    kept, gone = tracker._without_remnants(keys, frame, ending=True)
    assert gone == {1}
    np.testing.assert_array_equal(kept, np.where(keys == 1, -1, keys))
    # The log's last frame has no pair after it: nothing is a remnant there.
    kept, gone = tracker._without_remnants(keys, frame, ending=False)
    assert gone == set() and kept is keys


def test_what_a_track_keeps_does_not_reseed_the_pairs(monkeypatch):
    # The pairs' seeds come from a stream of their own: tracks that keep fewer points
    # (other draws of the track samples) leave every pair's seed as it was.
    log = make_lidar_sequence(5, frame_rate=10.0, n_azimuths=512, random_state=3)

    def seeds_of_a_fit():
        seeds = []
        make = _PairMaker.__call__

        def recording(self, seed):
            seeds.append(seed)
            return make(self, seed)

        with monkeypatch.context() as patch:
            patch.setattr(_PairMaker, "__call__", recording)
            est = SequenceRegistration(random_state=0).fit(log.frames, times=log.times)
        return seeds, est

    seeds, est = seeds_of_a_fit()
    assert est.n_tracks_ >= 1  # tracks there are, and they draw samples
    monkeypatch.setattr(_log, "_TRACK_POINTS", 20)
    fewer, _ = seeds_of_a_fit()
    assert len(seeds) == len(log.frames) - 1
    assert fewer == seeds
