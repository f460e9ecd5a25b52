"""A log whose sensor sees no body of its own stops looking for one: once two pairs that
moved enough to show it showed none, the later pairs are not searched (the body is the
rig's, fixed in the sensor's frame)."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import mmreg.sweeps._pair as pair_module
import mmreg.tracking._pairs as pairs_module
from mmreg import SequenceRegistration
from mmreg.datasets import make_lidar_sequence
from mmreg.sweeps._ego_body import would_show_body


@given(
    angle=st.floats(0.0, 0.3),
    axis=st.sampled_from([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.6, 0.0, 0.8]]),
    scale=st.sampled_from([1e-3, 1.0, 1e3]),
)
def test_a_motion_shows_a_body_in_any_units(angle, axis, scale):
    rotation = Rotation.from_rotvec(angle * np.array(axis)).as_matrix()
    swing = 2 * np.sin(angle / 2) * 0.6 * 5.0  # how far the turn moves the reach's rim
    # Far beyond the carried distance (three matches of 5 cm) past the swing, and far short.
    assert would_show_body((rotation, [swing + 1.0, 0.0, 0.0]), 5.0)
    assert not would_show_body((rotation, [max(swing - 1.0, 0.0), 0.0, 0.0]), 5.0)
    for translation in ([swing + 1.0, 0.0, 0.0], [0.0, 0.02, 0.0]):
        plain = would_show_body((rotation, np.array(translation)), 5.0)
        assert would_show_body((rotation, scale * np.array(translation)), 5.0 * scale) == plain


def test_a_sensor_that_stands_still_shows_no_body():
    assert not would_show_body((np.eye(3), np.zeros(3)), 5.0)


def _searches(monkeypatch, frames, bodiless_pairs):
    calls = []
    original = pair_module.find_ego_body

    def counted(*args, **kwargs):
        found = original(*args, **kwargs)
        calls.append(found)
        return found

    monkeypatch.setattr(pair_module, "find_ego_body", counted)
    monkeypatch.setattr(pairs_module, "BODILESS_PAIRS", bodiless_pairs)
    est = SequenceRegistration(random_state=0).fit(frames, times=np.arange(len(frames)) * 0.1)
    return est, calls


@pytest.mark.filterwarnings("ignore")
def test_a_log_without_a_body_stops_looking_and_labels_alike(monkeypatch):
    # The sensor drives 1 m a frame: every pair would show a body, none does.
    frames = list(make_lidar_sequence(6, n_azimuths=256, random_state=4).frames)
    est, calls = _searches(monkeypatch, frames, 2)
    assert len(calls) == 2 and all(found is None for found in calls)
    always, every_call = _searches(monkeypatch, frames, len(frames))
    assert len(every_call) == len(frames) - 1
    for mine, theirs in zip(est.labels_, always.labels_, strict=True):
        np.testing.assert_array_equal(mine, theirs)
    np.testing.assert_allclose(est.ego_poses_, always.ego_poses_, atol=0)


@pytest.mark.filterwarnings("ignore")
def test_a_log_with_a_body_finds_it_first_and_carries_it(monkeypatch):
    rng = np.random.default_rng(7)
    roof = np.c_[rng.uniform(-2.0, 1.0, 300), rng.uniform(-0.9, 0.9, 300), np.full(300, -0.4)]
    frames = [
        np.vstack([f, roof]) for f in make_lidar_sequence(4, n_azimuths=256, random_state=4).frames
    ]
    est, calls = _searches(monkeypatch, frames, 2)
    assert len(calls) == 1 and calls[0] is not None  # then carried, never searched again
    for labels in est.labels_:
        assert np.all(labels[-len(roof) :] == -1)
