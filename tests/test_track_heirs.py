"""A track born over a confirmed track's prediction, in the pair that missed that track,
goes on with its id once confirmed.

A car leaving the view shows a pair only its last visible part, whose motion does not
follow the car's track: the track misses, and the pair's cluster over its prediction
starts a new track. Confirmed, the new track is the same car: it takes the missed
track's id, and the missed track ends (nuScenes scene-0004 had such a car change id for
its last two frames).
"""

from types import SimpleNamespace

import numpy as np
import pytest

from mmreg.tracking._log import LogTracker
from mmreg.tracking._tracks import Track


def _tracker():
    return LogTracker(
        None,
        tau=5.0,
        lookahead=0,
        max_misses=3,
        frame_rate=None,
        min_points=10,
        rng=np.random.RandomState(0),
    )


def _track(key, x, frame, identity=0, heir_of=-1):
    points = np.random.default_rng(key).uniform(-1, 1, (30, 3)) + [x, 0.0, 0.0]
    return Track(
        key=key,
        points=points,
        time=float(frame),
        frame=frame,
        omega=np.zeros(3),
        velocity=np.array([4.0, 0.0, 0.0]),
        hits=2 if identity else 1,
        identity=identity,
        heir_of=heir_of,
    )


def _frame(index):
    return SimpleNamespace(index=index, time=float(index), rows=[])


def _missed_then_reborn(seen_again=False):
    """A confirmed car (key 0, id 1) missed in pair 5, where a cluster over its
    prediction was born as key 7; pair 6 sees key 7 again (and, if ``seen_again``, the
    car's own track too)."""
    tracker = _tracker()
    state = tracker._state
    car = _track(0, 0.0, 4, identity=1)
    state.n_confirmed, state.identity[0], state.last_seen[0] = 1, 1, 4
    born = _track(7, 2.0, 5, heir_of=0)
    state.tracks = [car, born]
    tracker._confirm_and_end(_frame(5), {7: 30})  # the car missed, the cluster born
    born.hits = 2
    seen = {7: 30, 0: 30} if seen_again else {7: 30}
    confirmed = tracker._confirm_and_end(_frame(6), seen)
    return tracker, car, born, confirmed


def test_the_track_born_where_a_track_was_missed_keeps_its_id():
    tracker, car, born, confirmed = _missed_then_reborn()
    assert confirmed == [born]
    assert born.identity == 1 and tracker._identity(7) == 1
    assert tracker._state.n_confirmed == 1  # no new id was given
    assert car not in tracker._state.tracks  # the missed track ended


def test_a_missed_track_seen_again_keeps_its_id_and_the_other_gets_a_new_one():
    tracker, car, born, confirmed = _missed_then_reborn(seen_again=True)
    assert confirmed == [born]
    assert born.identity == 2 and car.identity == 1
    assert car in tracker._state.tracks


@pytest.mark.parametrize("heir_of", [-1, 3])
def test_a_track_born_on_no_missed_track_gets_a_new_id(heir_of):
    tracker = _tracker()
    state = tracker._state
    state.n_confirmed = 1
    born = _track(7, 2.0, 5, heir_of=heir_of)  # key 3 was never a track
    born.hits = 2
    state.tracks = [born]
    assert tracker._confirm_and_end(_frame(6), {7: 30}) == [born]
    assert born.identity == 2
