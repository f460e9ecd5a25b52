"""Frames half a second apart: objects too slow for their pairs (a walker at 10 Hz).

The pair motion taken from the span's motion is exact for a constant twist, whatever the
sensor's poses; the frames kept are bounded and the partner is half a second back at any
rate; and on a generated 10 Hz street a walker that no pair shows moving is followed with
one id, where the log without the long span leaves it static.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from mmreg import SequenceRegistration
from mmreg.datasets import make_lidar_sequence
from mmreg.tracking._long_span import (
    _MOST_FRAMES,
    LONG_SPAN,
    kept_frames,
    long_partner,
    pair_motion,
)
from mmreg.tracking._motion import compose, inverse, predicted_motion, to_matrix


class _Frame:
    def __init__(self, index, time):
        self.index, self.time = index, time


def _pose(rotvec, translation):
    return to_matrix(Rotation.from_rotvec(rotvec).as_matrix(), translation)


vectors = st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3).map(np.array)


@settings(max_examples=60, deadline=None)
@given(
    omega=vectors,
    velocity=vectors,
    centre=vectors,
    turns=st.lists(vectors, min_size=3, max_size=3),
    shifts=st.lists(vectors, min_size=3, max_size=3),
    span=st.floats(0.2, 1.5),
    dt=st.floats(0.02, 0.6),
)
def test_the_pair_motion_of_a_constant_twist_is_exact(
    omega, velocity, centre, turns, shifts, span, dt
):
    omega, velocity, centre = 0.5 * omega, 20.0 * velocity, 30.0 * centre  # up to 0.87 rad/s
    first, second, earlier = (_pose(r, 50.0 * t) for r, t in zip(turns, shifts, strict=True))
    # The object's points in the first sweep's frame, carried back over the span.
    world_back = predicted_motion(omega, velocity, centre, -span)
    back = compose(inverse(earlier), world_back, first)
    expected = compose(inverse(second), predicted_motion(omega, velocity, centre, dt), first)
    found = pair_motion(back, (first, second, earlier), centre, span, dt)
    np.testing.assert_allclose(found, expected, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(rate=st.floats(1.0, 40.0), jitter=st.floats(0.0, 2e-4), seed=st.integers(0, 99))
def test_the_partner_is_half_a_second_back_and_the_frames_kept_are_bounded(rate, jitter, seed):
    rng = np.random.default_rng(seed)
    times = np.arange(60) / rate + rng.uniform(-jitter, jitter, 60)
    recent = []
    for k, time in enumerate(times):
        frame = _Frame(k, time)
        partner = long_partner(recent, frame)
        if partner is not None:
            assert frame.time - partner.time >= LONG_SPAN - 1e-3
            assert frame.index - partner.index >= 2
            # ... and the newest such frame: the one after it is too near.
            after = next(f for f in recent if f.index == partner.index + 1)
            assert frame.time - after.time < LONG_SPAN or after is frame
        recent = kept_frames(recent, frame)
        assert len(recent) <= _MOST_FRAMES
        assert recent[-1] is frame
    # A 10 Hz log (times in floating point: 0.1 * k is not exact) compares frames 5
    # apart, a 2 Hz log none, a 40 Hz log's half second is out of the memory's reach.
    if 9.9 < rate < 10.1:
        assert long_partner(recent[:-1], recent[-1]).index == 59 - 5


@pytest.mark.parametrize("rate, back", [(10.0, 5), (2.0, None), (20.0, 10), (4.0, 2)])
def test_partners_at_common_rates(rate, back):
    recent = []
    for k in range(30):
        frame = _Frame(k, k / rate)
        partner = long_partner(recent, frame)
        recent = kept_frames(recent, frame)
    expected = None if back is None else 29 - back
    assert (partner.index if partner is not None else None) == expected


def _walkers(random_state):
    """Ten 10 Hz frames of a street with two walkers, one standing thing, no cars."""
    return make_lidar_sequence(
        10,
        frame_rate=10.0,
        n_moving=0,
        n_braking=0,
        n_overtaking=0,
        n_walkers=2,
        n_cyclists=0,
        n_standing=1,
        n_azimuths=512,
        random_state=random_state,
    )


def test_a_walker_too_slow_for_its_pairs_is_followed_over_half_a_second(monkeypatch):
    log = _walkers(2)
    walker = 2  # 60-100 points a frame, 0.13 m a frame: about a spacing at its range
    assert log.kinds[walker] == "walker"
    est = SequenceRegistration(random_state=0).fit(log.frames, times=log.times)
    ids = set()
    for k in range(5, 10):  # from the first pair that sees it half a second back
        mine = log.labels[k] == walker
        assert est.moving_[k][mine].mean() > 0.9
        ids.add(int(np.bincount(est.labels_[k][mine].clip(0)).argmax()))
    assert len(ids) == 1 and ids.pop() > 0
    speeds = est.tracks_.loc[est.tracks_.frame >= 5, "speed"].to_numpy()
    truth = log.objects.loc[log.objects.id == walker, "speed"].to_numpy()
    # Its speed over the span (the first, from the pair it was born in, is noisier).
    assert abs(np.median(speeds) - truth.mean()) < 0.1 * truth.mean()
    # Nothing static moves (a few ground points at its feet at most).
    false = sum(np.count_nonzero(est.moving_[k] & ~log.moving[k]) for k in range(10))
    assert false <= 10
    # Its pairs alone leave it static in every frame.
    monkeypatch.setattr("mmreg.tracking._log.long_partner", lambda recent, frame: None)
    alone = SequenceRegistration(random_state=0).fit(log.frames, times=log.times)
    for k in range(10):
        assert not alone.moving_[k][log.labels[k] == walker].any()


def _braking_log():
    return make_lidar_sequence(
        16,
        frame_rate=10.0,
        n_moving=0,
        n_braking=1,
        n_overtaking=0,
        n_walkers=0,
        n_cyclists=0,
        n_standing=0,
        random_state=1,
    )


# At random state 0 the pair's evidence on the stopped car is a tie in one frame (every
# point explained both at rest and by half a second's average motion, 0.13 m a frame),
# after the pairs before had said it stopped: it must stay static there too.
@pytest.mark.parametrize("random_state", [0, 1, 2])
def test_a_car_that_stopped_is_static_though_it_moved_half_a_second_ago(random_state):
    log = _braking_log()
    car = next(i for i, kind in enumerate(log.kinds) if kind == "car")
    stopped = log.objects.loc[(log.objects.id == car) & ~log.objects.moving, "frame"]
    assert stopped.min() < 10  # at rest for six frames or more
    est = SequenceRegistration(random_state=random_state).fit(log.frames, times=log.times)
    for k in stopped:
        assert not est.moving_[k][log.labels[k] == car].any()


def test_without_the_pair_s_word_a_car_that_stopped_moves_on(monkeypatch):
    # Over half a second it still moved: without the pair's word, it would move on.
    log = _braking_log()
    car = next(i for i, kind in enumerate(log.kinds) if kind == "car")
    stopped = log.objects.loc[(log.objects.id == car) & ~log.objects.moving, "frame"]
    monkeypatch.setattr("mmreg.tracking._log.refuted", lambda *args, **kwargs: False)
    unrefuted = SequenceRegistration(random_state=0).fit(log.frames, times=log.times)
    held = [unrefuted.moving_[k][log.labels[k] == car].mean() for k in stopped]
    assert max(held) > 0.5
