"""A log's pairs search once within the islands' reach; the places find what lies beyond.

2 Hz keyframes from a slow car (3 m/s) leave a car driving away at 10 m/s 5 m on between
frames, beyond the 3 m the islands search. A pair alone finds it only by searching again
twice as far (``SweepRegistration``'s ``widen_reach``); ``SequenceRegistration``'s pairs
do not, and its tracks find the car from the place it leaves and the place it reaches.
"""

import numpy as np
import pytest

from mmreg import SequenceRegistration, SweepRegistration
from mmreg.datasets import make_lidar_sequence


@pytest.fixture(scope="module")
def log():
    return make_lidar_sequence(
        6,
        frame_rate=2.0,
        n_moving=1,
        n_braking=0,
        n_overtaking=0,
        n_walkers=0,
        n_cyclists=0,
        n_parked=2,
        n_standing=0,
        ego_speed=3.0,
        car_speed=10.0,
        random_state=2,
    )


def test_the_car_moves_beyond_the_islands_reach(log):
    car = log.objects.query("id == 1")
    assert (car.speed / 2.0 > 4.5).all()  # metres per frame, against a 3 m reach
    pair = SweepRegistration(max_icp_iter=15, widen_reach=False, random_state=0)
    pair.fit(log.frames[0], sweep=log.frames[1])
    assert pair.max_displacement_ == 3.0
    moving = np.asarray(pair.moving_)[pair.labels_] & (pair.labels_ >= 0)
    assert not moving[log.labels[0] == 1].any()
    widened = SweepRegistration(max_icp_iter=15, random_state=0)
    widened.fit(log.frames[0], sweep=log.frames[1])
    moving = np.asarray(widened.moving_)[widened.labels_] & (widened.labels_ >= 0)
    assert moving[log.labels[0] == 1].mean() > 0.9


def test_a_log_tracks_it_without_the_wider_search(log):
    est = SequenceRegistration(random_state=0).fit(log.frames, times=log.times)
    assert est.pair_estimator is None  # the default pairs: no wider search
    ids = set()
    for labels, moving, truth in zip(est.labels_, est.moving_, log.labels, strict=True):
        car = truth == 1
        if car.sum() < 40:  # the last two frames hold a few far points (24, 18)
            continue
        assert (moving & car).sum() > 0.9 * car.sum()
        assert not (moving & (truth == 0)).any()
        ids |= set(np.unique(labels[car & moving]).tolist())
    assert len(ids) == 1
