"""A log's pairs registered in a process of their own (SequenceRegistration's n_jobs).

The results are those of one process, wherever the worker takes over, and for the next
log the worker serves; what the worker warns or raises reaches the caller; a worker that
dies, or cannot rebuild the pair estimator, is said so; each sweep's state goes to the
worker and back without losing what either side computed.
"""

import multiprocessing
import pickle

import numpy as np
import pytest
from _pair_estimators import HereOnly, Pairs
from sklearn.utils._param_validation import InvalidParameterError

from mmreg import SequenceRegistration
from mmreg._validation import invalid_points
from mmreg.datasets import make_lidar_sequence
from mmreg.sweeps._sweep_state import SweepState
from mmreg.tracking import _pair_process
from mmreg.tracking._pairs import PairFit

N_FRAMES = 7


@pytest.fixture(scope="module")
def log():
    return make_lidar_sequence(N_FRAMES, frame_rate=10.0, n_azimuths=512, random_state=0)


@pytest.fixture(scope="module")
def alone(log):
    """The log fitted in one process."""
    return SequenceRegistration(random_state=0).fit(log.frames, times=log.times)


def _hand_over_at(monkeypatch, frame):
    """Make the worker take the pairs when frame ``frame`` comes (waiting for it to
    start); the fits it gives are counted in the list returned."""
    asked = []
    fits = []

    def ready(self):
        asked.append(True)  # asked at frames 1, 2, ... until the worker takes over
        return len(asked) >= frame and self._ready.wait(120)

    receive = _pair_process.PairProcess.receive

    def counted(self):
        fit = receive(self)
        if isinstance(fit, PairFit):
            fits.append(fit)
        return fit

    monkeypatch.setattr(_pair_process.PairProcess, "ready", ready)
    monkeypatch.setattr(_pair_process.PairProcess, "receive", counted)
    return fits


def _assert_same_log(a, b):
    for k in range(N_FRAMES):
        np.testing.assert_array_equal(a.labels_[k], b.labels_[k])
        np.testing.assert_array_equal(a.moving_[k], b.moving_[k])
        np.testing.assert_array_equal(a.flows_[k], b.flows_[k])
    np.testing.assert_array_equal(a.ego_poses_, b.ego_poses_)
    assert a.tracks_.equals(b.tracks_)


@pytest.mark.parametrize("frame", [1, 4])
def test_pairs_in_a_process_of_their_own_give_the_same_log(log, alone, monkeypatch, frame):
    fits = _hand_over_at(monkeypatch, frame)
    apart = SequenceRegistration(random_state=0, n_jobs=2).fit(log.frames, times=log.times)
    assert len(fits) == N_FRAMES - frame  # the pairs (frame - 1, frame), ... the worker's
    assert alone.n_tracks_ >= 1
    _assert_same_log(alone, apart)


def test_a_worker_serves_the_next_log_of_this_process(log, alone, monkeypatch):
    with _pair_process._idle_lock:  # no worker left by another test
        for process, _ in _pair_process._idle:
            process.close()
        _pair_process._idle.clear()
    started = []
    start = _pair_process.PairProcess.__init__

    def counted(self):
        started.append(self)
        start(self)

    monkeypatch.setattr(_pair_process.PairProcess, "__init__", counted)
    fits = _hand_over_at(monkeypatch, 1)
    first = SequenceRegistration(random_state=0, n_jobs=2).fit(log.frames, times=log.times)
    second = SequenceRegistration(random_state=0, n_jobs=2).fit(log.frames, times=log.times)
    assert len(started) == 1
    assert len(fits) == 2 * (N_FRAMES - 1)
    _assert_same_log(alone, first)
    _assert_same_log(alone, second)


def test_online_with_the_pairs_apart_gives_each_frame_a_frame_later(log, alone, monkeypatch):
    _hand_over_at(monkeypatch, 1)
    est = SequenceRegistration(random_state=0, n_jobs=2)
    results, final_at = [], {}
    for k, (points, time) in enumerate(zip(log.frames, log.times, strict=True)):
        for result in est.partial_fit(points, time=time).finished_:
            final_at[result.index] = k
            results.append(result)
    results += est.finish().finished_
    assert [r.index for r in results] == list(range(N_FRAMES))
    # Frame k is final once frame k + lookahead + 2 is in (one more than in one process).
    assert final_at == {k: k + est.lookahead + 2 for k in final_at}
    assert len(final_at) == N_FRAMES - est.lookahead - 2
    for k, result in enumerate(results):
        np.testing.assert_array_equal(result.labels, alone.labels_[k])
        np.testing.assert_array_equal(result.pose, alone.ego_poses_[k])


def test_what_the_worker_warns_is_warned_here(log, monkeypatch):
    fits = _hand_over_at(monkeypatch, 1)
    est = SequenceRegistration(Pairs(warns=True), random_state=0, n_jobs=2)
    with pytest.warns(UserWarning) as raised:
        est.fit(log.frames, times=log.times)
    said = [str(w.message) for w in raised if str(w.message).startswith("pair of")]
    sizes = [int(np.count_nonzero(~invalid_points(f))) for f in log.frames]
    assert len(fits) == N_FRAMES - 1
    assert said == [
        f"pair of {a} and {b} points" for a, b in zip(sizes[:-1], sizes[1:], strict=True)
    ]
    # Attributed to the user's line (this file), as one process's warnings are.
    assert {w.filename for w in raised if str(w.message).startswith("pair of")} == {__file__}


def test_what_the_worker_raises_is_raised_here(log, monkeypatch):
    _hand_over_at(monkeypatch, 1)
    third = int(np.count_nonzero(~invalid_points(log.frames[2])))
    est = SequenceRegistration(Pairs(fails=third), random_state=0, n_jobs=2)
    with pytest.raises(ValueError, match=f"a pair of {third} points refused") as raised:
        est.fit(log.frames, times=log.times)
    assert "Traceback" in str(raised.value.__cause__)  # the worker's, as the cause
    assert _pair_process._idle == []  # a log stopped by an error leaves no worker


def test_a_worker_that_dies_is_an_error_that_says_so(log, monkeypatch):
    _hand_over_at(monkeypatch, 1)
    third = int(np.count_nonzero(~invalid_points(log.frames[2])))
    est = SequenceRegistration(Pairs(dies=third), random_state=0, n_jobs=2)
    with pytest.raises(RuntimeError, match=r"ended unexpectedly \(exit code 3\)"):
        est.fit(log.frames, times=log.times)


def test_a_pair_estimator_the_worker_cannot_rebuild_keeps_the_pairs_here(log, monkeypatch):
    fits = _hand_over_at(monkeypatch, 1)
    here = SequenceRegistration(HereOnly(), random_state=0)
    with pytest.warns(RuntimeWarning, match="pairs stay in this process.*not importable here"):
        apart = here.set_params(n_jobs=2).fit(log.frames, times=log.times)
    assert fits == []
    _assert_same_log(SequenceRegistration(HereOnly(), random_state=0).fit(
        log.frames, times=log.times), apart)  # fmt: skip


def test_a_daemonic_process_keeps_the_pairs_in_itself(log, alone, monkeypatch):
    # A Dask worker's process may not start processes of its own.
    def no_process():
        raise AssertionError("a daemonic process started a process")

    monkeypatch.setattr(_pair_process, "PairProcess", no_process)
    monkeypatch.setattr(multiprocessing.current_process(), "daemon", True)
    est = SequenceRegistration(random_state=0, n_jobs=2).fit(log.frames, times=log.times)
    _assert_same_log(alone, est)


def test_n_jobs_is_checked(log):
    with pytest.raises(ValueError, match="n_jobs=0"):
        SequenceRegistration(n_jobs=0).fit(log.frames, times=log.times)
    with pytest.raises(InvalidParameterError, match="n_jobs"):
        SequenceRegistration(n_jobs=1.5).fit(log.frames, times=log.times)


def test_a_sweep_state_sent_away_and_back_keeps_what_each_side_computed(monkeypatch):
    rng = np.random.default_rng(0)
    points = rng.uniform(0, 10, (400, 3))
    here = SweepState(points)
    here.normals(np.arange(0, 100))
    here.ego_cloud(0.1)  # small_gicp's objects, which do not pickle
    there = pickle.loads(pickle.dumps(here))
    there.normals(np.arange(50, 200))
    here.learn(there)

    # Every normal either side computed is known here: none is asked of the tree again.
    def no_query(*args, **kwargs):
        raise AssertionError("a normal computed again")

    monkeypatch.setattr(here.normals.tree, "query", no_query)
    normals, variation, flatness = here.normals(np.arange(200))
    monkeypatch.undo()
    fresh = SweepState(points).normals(np.arange(200))
    np.testing.assert_array_equal(normals, fresh[0])
    np.testing.assert_array_equal(variation, fresh[1])
    np.testing.assert_array_equal(flatness, fresh[2])
    with pytest.raises(ValueError, match="the same points"):
        here.learn(SweepState(points[:10]))
