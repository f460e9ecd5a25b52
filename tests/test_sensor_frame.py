"""Raw points that are not a LiDAR sweep in its sensor's frame are told so.

A map's coordinates (the sensor far from the origin) or another axis up are valid
numbers that every raw stage misreads (the ground, what the sensor could see, the level
motions): the pair and the log warn, once, at the user's line. Sweeps in their sensor's
frame, any scanner, any units, and camera frames, warn nothing.
"""

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.exceptions import ConvergenceWarning

from mmreg import SequenceRegistration, SweepRegistration
from mmreg.datasets import make_lidar_sequence
from mmreg.estimators import SensorFrameWarning
from mmreg.sweeps._sensor_frame import sensor_frame_problems


@pytest.fixture(scope="module")
def log():
    return make_lidar_sequence(3, frame_rate=10.0, n_azimuths=256, random_state=0)


def _turned(points, axis):
    """``points`` turned by 90 degrees about ``axis`` (0: x, 1: y): z becomes y or x."""
    turn = np.eye(3)
    others = [a for a in range(3) if a != axis]
    turn[np.ix_(others, others)] = [[0.0, -1.0], [1.0, 0.0]]
    return points @ turn.T


def _kinds(points):
    return [problem[0] for problem in sensor_frame_problems(points)]


@settings(max_examples=25, deadline=None)
@given(
    direction=st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda d: np.linalg.norm(d) > 0.1),
    scale=st.sampled_from([0.01, 1.0, 1000.0]),
)
def test_where_the_sensor_is_does_not_depend_on_units(log, direction, scale):
    sweep = log.frames[0] * scale
    low, high = np.percentile(sweep, [5, 95], axis=0)
    extent = np.linalg.norm(high - low)
    unit = np.asarray(direction) / np.linalg.norm(direction)
    assert _kinds(sweep) == []
    assert _kinds(sweep + 0.1 * extent * unit) == []  # a sensor off its sweep's centre
    assert _kinds(sweep + 20 * extent * unit) == ["away"]  # a map's coordinates


@pytest.mark.parametrize("axis, up", [(0, "y"), (1, "x")])
def test_a_sweep_with_another_axis_up_is_told(log, axis, up):
    assert sensor_frame_problems(_turned(log.frames[0], axis)) == [("up", up)]


def test_scanners_that_look_one_way_and_camera_frames_are_sensor_frames(log):
    sweep = log.frames[0]
    ahead = sweep[(sweep[:, 0] > 1.0) & (np.abs(sweep[:, 1]) < 0.7 * sweep[:, 0])]  # 70 deg
    assert _kinds(ahead) == []
    rng = np.random.default_rng(0)
    camera = rng.uniform([-10, -5, 5], [10, 5, 35], (3000, 3))  # z into the scene
    assert _kinds(camera) == []
    assert _kinds(sweep[:9] + 1e6) == []  # too few to tell


def test_a_pair_not_in_its_sensor_frame_warns_at_the_users_line(log):
    a, b = log.frames[0], log.frames[1]
    far = np.array([5e5, 4e6, 30.0])  # UTM
    with pytest.warns(SensorFrameWarning, match="not in their sensor's frame") as record:
        SweepRegistration(random_state=0).fit(a + far, sweep=b + far, interval=0.1)
    (warning,) = [w for w in record if w.category is SensorFrameWarning]
    assert warning.filename == __file__
    with pytest.warns(SensorFrameWarning, match="with y vertical"):
        SweepRegistration(random_state=0).fit(_turned(a, 0), sweep=_turned(b, 0), interval=0.1)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SensorFrameWarning)
        SweepRegistration(random_state=0).fit(a, sweep=b, interval=0.1)


def test_a_log_in_a_world_frame_warns_once_where_it_leaves_the_origin(log):
    # The sensor drives off along x: frames in the first frame's (world) frame.
    frames = [frame + [60.0 * k, 0.0, 0.0] for k, frame in enumerate(log.frames)]
    for k, off in [(1, False), (2, True)]:  # the origin's gap to the bulk, against its extent
        low, high = np.percentile(log.frames[k], [5, 95], axis=0)
        assert low[1] < 0 < high[1] and low[2] < 0 < high[2]
        assert (60.0 * k + low[0] > 1.3 * np.linalg.norm(high - low)) == off
        assert (60.0 * k + low[0] < 0.8 * np.linalg.norm(high - low)) != off
    with pytest.warns(SensorFrameWarning, match="origin lies .* from frame 2") as record:
        SequenceRegistration(random_state=0).fit(frames, times=log.times)
    assert len([w for w in record if w.category is SensorFrameWarning]) == 1
    assert {w.filename for w in record if w.category is SensorFrameWarning} == {__file__}
    online = SequenceRegistration(random_state=0)
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        for frame, time in zip(frames, log.times, strict=True):
            online.partial_fit(frame, time=time)
        online.finish()
    said = [str(w.message) for w in record if w.category is SensorFrameWarning]
    assert len(said) == 1 and "from frame 2" in said[0]


def test_a_log_with_y_up_warns_once_and_one_in_its_sensor_frame_does_not(log):
    turned = [_turned(frame, 0) for frame in log.frames]
    with pytest.warns(SensorFrameWarning, match="frame 0 lies flat .* with y vertical") as record:
        SequenceRegistration(random_state=0).fit(turned, times=log.times)
    assert len([w for w in record if w.category is SensorFrameWarning]) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error", SensorFrameWarning)
        SequenceRegistration(random_state=0).fit(log.frames, times=log.times)


def test_correspondences_far_from_their_sensor_warn_but_not_for_the_paper_variant():
    from mmreg import MultiModelRegistration
    from mmreg.datasets import make_street

    scene = make_street(random_state=0)
    X = np.hstack([scene.a, scene.a + scene.flow])
    with pytest.warns(SensorFrameWarning, match="reads the origin as the sensor") as record:
        MultiModelRegistration(tau=5.0, random_state=0).fit(X + 1000.0)
    assert {w.filename for w in record if w.category is SensorFrameWarning} == {__file__}
    with warnings.catch_warnings():
        warnings.simplefilter("error", SensorFrameWarning)
        warnings.simplefilter("ignore", ConvergenceWarning)  # the paper's EM, 10 steps
        MultiModelRegistration(tau=5.0, random_state=0).fit(X)
        MultiModelRegistration(variant="paper", tau=5.0, random_state=0).fit(X + 1000.0)
