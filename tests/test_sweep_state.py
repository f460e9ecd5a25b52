"""One state per sweep of a log: each sweep's ground, trees, normals, islands and the ego
motion's voxels are computed once, and the pairs give what independent fits give."""

import hashlib

import numpy as np
import pytest
from scipy.spatial import cKDTree

import mmreg.sweeps._sweep_state as sweep_state
from mmreg import SweepRegistration
from mmreg.datasets import make_lidar_sequence
from mmreg.sweeps._sweep_state import SweepState


def _key(*arrays):
    """A digest of the arrays' bytes: the same points give the same key."""
    digest = hashlib.sha1()
    for array in arrays:
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def _count(monkeypatch, name, calls):
    """Wrap ``name`` of the state's module: every call's points recorded."""
    original = getattr(sweep_state, name)

    def counted(points, *args, **kwargs):
        calls.setdefault(name, []).append(_key(points))
        return original(points, *args, **kwargs)

    monkeypatch.setattr(sweep_state, name, counted)


def _body(n_frames):
    """The returns of the ego vehicle's roof and bonnet: fixed in the sensor's frame."""
    rng = np.random.default_rng(7)
    roof = np.c_[rng.uniform(-2.0, 1.0, 300), rng.uniform(-0.9, 0.9, 300), np.full(300, -0.4)]
    bonnet = np.c_[rng.uniform(1.0, 2.3, 120), rng.uniform(-0.9, 0.9, 120), np.full(120, -0.9)]
    return [np.vstack([roof, bonnet])] * n_frames


def _frames(seed, body=False, invalid=False):
    frames = list(make_lidar_sequence(4, n_azimuths=256, random_state=seed).frames)
    if body:
        frames = [np.vstack([f, b]) for f, b in zip(frames, _body(len(frames)), strict=True)]
    if invalid:  # a driver's failed returns (NaN) in the middle frames
        for k in (1, 2):
            frames[k] = frames[k].copy()
            frames[k][::50] = np.nan
    return frames


def _carried(body, frame):
    """The frame's rows within 5 cm of the last frame's body points (the same sensor
    coordinates), as a sequence carries the body."""
    rows = np.zeros(len(frame), dtype=bool)
    finite = np.flatnonzero(np.isfinite(frame).all(axis=1))
    distance, _ = cKDTree(body).query(frame[finite], distance_upper_bound=0.05)
    rows[finite] = np.isfinite(distance)
    return rows


def _log(frames, states=None):
    """Each consecutive pair fitted as a sequence fits it: the ego motion started from
    the last pair's, the interval given, the body found once and carried."""
    fits, ego, body = [], None, None
    for k in range(len(frames) - 1):
        kwargs = {"interval": 0.1}
        if ego is not None:
            kwargs["ego_motion"] = ego
        if body is not None and body.any():
            kwargs["ego_body"] = (body, _carried(frames[k][body], frames[k + 1]))
        if states is not None:
            kwargs["states"] = (states[k], states[k + 1])
        est = SweepRegistration(random_state=k).fit(frames[k], sweep=frames[k + 1], **kwargs)
        ego, body = est.ego_motion_, est.sweep_ego_body_mask_
        fits.append(est)
    return fits


COUNTED = ("ground_mask", "voxel_islands", "PointTree", "SurfaceNormals", "fine_cloud")


def test_each_frame_is_computed_once(monkeypatch):
    frames = _frames(0)
    calls = {}
    for name in COUNTED:
        _count(monkeypatch, name, calls)
    est = SweepRegistration(random_state=0)
    states = [est.sweep_state(frame) for frame in frames]
    fits = _log(frames, states)
    assert all(fit.ground_mask_ is not None for fit in fits)
    # One ground and one set of islands (of the points off the ground) per frame.
    assert len(calls["ground_mask"]) == len(frames)
    assert len(calls["voxel_islands"]) == len(frames)
    # Nothing computed twice for the same points: a tree and normals per point set (the
    # sweep whole, and off the ground), one ego motion's voxel cloud per frame.
    for name in COUNTED:
        assert len(set(calls[name])) == len(calls[name]), name
    assert len(calls["PointTree"]) <= 2 * len(frames)
    assert len(calls["fine_cloud"]) == len(frames)
    # Independent fits compute the middle frames twice.
    independent = {}
    for name in COUNTED:
        _count(monkeypatch, name, independent)
    _log(frames)
    assert len(independent["ground_mask"]) == 2 * (len(frames) - 1)
    assert len(set(independent["ground_mask"])) == len(frames)


@pytest.mark.parametrize(
    ("seed", "body", "invalid"), [(0, False, False), (1, True, False), (2, True, True)]
)
def test_shared_states_give_what_independent_fits_give(seed, body, invalid):
    frames = _frames(seed, body=body, invalid=invalid)
    est = SweepRegistration(random_state=0)
    shared = _log(frames, [est.sweep_state(frame) for frame in frames])
    alone = _log(frames)
    if body:
        assert all(fit.n_ego_body_ > 0 for fit in alone)
    for one, other in zip(shared, alone, strict=True):
        for name in ("labels_", "flow_", "rotations_", "translations_", "ego_body_mask_"):
            np.testing.assert_array_equal(getattr(one, name), getattr(other, name))
        np.testing.assert_array_equal(one.ego_motion_[1], other.ego_motion_[1])


def test_a_state_serves_any_estimator_of_the_same_lengths():
    frames = _frames(3)
    states = [SweepRegistration().sweep_state(frame) for frame in frames[:2]]
    one = SweepRegistration(random_state=5).fit(frames[0], sweep=frames[1], states=states)
    other = SweepRegistration(random_state=5).fit(frames[0], sweep=frames[1])
    np.testing.assert_array_equal(one.labels_, other.labels_)
    np.testing.assert_array_equal(one.flow_, other.flow_)


def test_the_state_keeps_what_it_computed():
    rng = np.random.default_rng(0)
    state = SweepState(rng.uniform(-20, 20, (2000, 3)) * [1, 1, 0.05])
    keep = state.points[:, 0] > 0
    assert state.tree is state.tree and state.normals is state.normals
    assert state.ground(5.0) is state.ground(5.0)
    assert state.subset(keep) is state.subset(keep.copy())
    assert state.subset(keep) is not state.subset(~keep)
    assert state.islands(0.5, 3) is state.islands(0.5, 3)
    assert state.islands(0.5, 3) is not state.islands(0.5, 4)
    np.testing.assert_array_equal(state.subset(keep).points, state.points[keep])


def test_bad_states_are_refused():
    frames = _frames(0)
    est = SweepRegistration(random_state=0)
    first, second = est.sweep_state(frames[0]), est.sweep_state(frames[1])
    with pytest.raises(ValueError, match=r"states\[1\] holds other points than sweep"):
        est.fit(frames[0], sweep=frames[2], states=(first, second))
    with pytest.raises(ValueError, match=r"states\[0\] holds other points than X"):
        est.fit(frames[1], sweep=frames[1], states=(first, second))
    with pytest.raises(TypeError, match=r"states\[0\] must be a SweepState"):
        est.fit(frames[0], sweep=frames[1], states=(frames[0], second))
    with pytest.raises(ValueError, match="states go with two raw sweeps"):
        est.fit(np.hstack([frames[0], frames[0]]), sweep=frames[1], states=(first, second))
    with pytest.raises(ValueError, match="states go with two raw sweeps"):
        est.fit(frames[0], sweep=frames[1], states=(first,))
    with pytest.raises(ValueError, match=r"\(n, 3\) array of numbers"):
        est.sweep_state(frames[0][:, :2])
    with pytest.raises(ValueError, match="infinity"):
        est.sweep_state(np.where(np.arange(len(frames[0]))[:, None] == 3, np.inf, frames[0]))
    with pytest.raises(ValueError, match=r"rows must have shape"):
        first.subset(np.ones(3, dtype=bool))
