"""SweepRegistration's ego step: any frame rate, a known ego motion, the ego vehicle's body.

Rendered streets (:func:`mmreg.datasets.make_lidar_sweeps`, 1 cm range noise): 0.1 s
apart the sensor drives 1 m, 0.5 s apart (2 Hz keyframes) 5 m and the cars up to 6 m.
"""

import numpy as np
import pytest

from mmreg import SweepRegistration
from mmreg.datasets import make_lidar_sweeps
from mmreg.metrics import objects_found


def _angle_deg(r1, r2):
    return np.degrees(np.arccos(np.clip((np.trace(r1.T @ r2) - 1) / 2, -1.0, 1.0)))


def _cars(scene):
    return [k for k in range(1, scene.labels.max() + 1) if (scene.labels == k).sum() >= 50]


def _static_moving(est, static):
    return [c for c in np.flatnonzero(est.moving_) if static[est.labels_ == c].mean() > 0.5]


@pytest.fixture(scope="module")
def far_street():
    return make_lidar_sweeps(interval=0.5, n_azimuths=1024, random_state=0)


def test_sweeps_half_a_second_apart_are_registered_from_the_identity(far_street):
    scene = far_street
    truth = scene.transforms[0]
    assert np.linalg.norm(truth[:3, 3]) > 4.5  # the sensor drove 5 m
    est = SweepRegistration(random_state=0).fit(scene.a, sweep=scene.sweep)
    rotation, translation = est.ego_motion_
    # As accurate as 0.1 s apart (0.01 degrees, a few millimetres on these streets).
    assert _angle_deg(rotation, truth[:3, :3]) < 0.05
    assert np.linalg.norm(translation - truth[:3, 3]) < 0.02
    assert objects_found(scene.labels, est.labels_, objects=_cars(scene), min_iou=0.5) == 1.0
    assert _static_moving(est, scene.labels == 0) == []
    error = np.linalg.norm(est.flow_ - scene.flow, axis=1)
    assert np.median(error[scene.labels == 0]) < 0.02
    # The objects' reach grew with the ego step (3 m would miss the oncoming car).
    assert est.max_displacement_ > 1.5 * 4.5


def test_a_known_ego_motion_is_the_start():
    scene = make_lidar_sweeps(n_moving=1, interval=0.5, n_azimuths=512, random_state=1)
    truth = scene.transforms[0]
    off = (truth[:3, :3], truth[:3, 3] + [0.3, -0.2, 0.05])  # odometry 37 cm off
    est = SweepRegistration(max_displacement=6.0, random_state=0)
    est.fit(scene.a, sweep=scene.sweep, ego_motion=off)
    rotation, translation = est.ego_motion_
    assert np.linalg.norm(translation - truth[:3, 3]) < 0.02
    assert _angle_deg(rotation, truth[:3, :3]) < 0.05


@pytest.mark.parametrize(
    ("motion", "message"),
    [
        ((np.eye(3), np.zeros(2)), r"t of shape \(3,\)"),
        ((2 * np.eye(3), np.zeros(3)), "not a rotation"),
        ((np.eye(3), [np.nan, 0, 0]), "NaN"),
        ("identity", "homogeneous matrix"),
    ],
)
def test_bad_ego_motions_are_refused(motion, message):
    scene = make_lidar_sweeps(n_moving=1, n_beams=8, n_azimuths=256, random_state=0)
    with pytest.raises(ValueError, match=message):
        SweepRegistration().fit(scene.a, sweep=scene.sweep, ego_motion=motion)


def test_a_known_ego_motion_needs_two_raw_sweeps():
    X = np.random.default_rng(0).normal(size=(50, 6))
    with pytest.raises(ValueError, match="two raw sweeps"):
        SweepRegistration().fit(X, ego_motion=(np.eye(3), np.zeros(3)))


def _roof(n, rng):
    """Returns from the sensor's own car: its roof, sides and ends below a roof sensor."""
    p = rng.uniform([-2.3, -0.9, -1.2], [2.3, 0.9, -0.3], (n, 3))
    face = rng.integers(0, 3, n)
    p[face == 0, 2] = -0.3
    p[face == 1, 1] = np.where(p[face == 1, 1] > 0, 0.9, -0.9)
    p[face == 2, 0] = np.where(p[face == 2, 0] > 0, 2.3, -2.3)
    return p[np.linalg.norm(p[:, :2], axis=1) > 0.5]  # the sensor's own blind spot


@pytest.mark.parametrize("interval", [0.1, 0.5])
def test_returns_of_the_ego_vehicle_are_dropped_and_counted(interval):
    scene = make_lidar_sweeps(n_moving=2, interval=interval, n_azimuths=1024, random_state=2)
    rng = np.random.default_rng(0)
    body = _roof(3000, rng)
    n = len(scene.a)
    # The body sits at the same sensor coordinates in both sweeps, up to the range noise.
    a = np.vstack([scene.a, body])
    sweep = np.vstack([scene.sweep, body + rng.normal(0.0, 0.005, body.shape)])
    est = SweepRegistration(random_state=0).fit(a, sweep=sweep)
    assert est.n_ego_body_ == len(body)
    assert est.ego_body_mask_[n:].all() and not est.ego_body_mask_[:n].any()
    assert np.all(est.labels_[n:] == -1)
    np.testing.assert_array_equal(est.flow_[n:], 0.0)
    truth = scene.transforms[0]
    rotation, translation = est.ego_motion_
    assert np.linalg.norm(translation - truth[:3, 3]) < 0.02
    assert _angle_deg(rotation, truth[:3, :3]) < 0.05
    assert objects_found(scene.labels, est.labels_[:n], objects=_cars(scene), min_iou=0.5) == 1


def test_a_street_without_a_body_drops_nothing():
    scene = make_lidar_sweeps(n_moving=2, n_azimuths=1024, random_state=2)
    est = SweepRegistration(random_state=0).fit(scene.a, sweep=scene.sweep)
    assert est.n_ego_body_ == 0 and not est.ego_body_mask_.any()


def test_a_standing_sensor_keeps_its_body_in_the_static_world():
    """Without an ego motion nothing tells the body from the static world: none dropped."""
    rng = np.random.default_rng(1)
    scene = make_lidar_sweeps(n_moving=1, n_beams=16, n_azimuths=512, random_state=0)
    body = _roof(1000, rng)
    a = np.vstack([scene.a, body])
    est = SweepRegistration(random_state=0).fit(a, sweep=a + rng.normal(0, 0.005, a.shape))
    assert est.n_ego_body_ == 0


def test_without_small_gicp_our_icp_finds_a_short_step(monkeypatch):
    """Intel macOS has no small_gicp wheel: the ego step falls back on our ICP alone."""
    import mmreg.sweeps._pair as pair

    monkeypatch.setattr(pair, "has_small_gicp", lambda: False)
    scene = make_lidar_sweeps(n_moving=1, n_beams=16, n_azimuths=512, random_state=0)
    truth = scene.transforms[0]
    est = SweepRegistration(random_state=0).fit(scene.a, sweep=scene.sweep)
    rotation, translation = est.ego_motion_
    assert est.n_ego_body_ == 0
    assert np.linalg.norm(translation - truth[:3, 3]) < 0.1
    assert _angle_deg(rotation, truth[:3, :3]) < 0.2
