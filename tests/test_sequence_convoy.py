"""Two cars in a line, one frame's travel apart: the track's past says which motion.

At 2 Hz, two oncoming cars 8 m apart close on the sensor's car by 8 m a frame: in every
frame the second stands, in the sensor's frame, where the first stood in the frame
before. A pair alone lays the first car's points on the second and reports it moving
with the sensor's car, the wrong way at twice its speed. A log's track of the first car
tries its own prediction when the pair's motion does not follow it, and keeps the car.
"""

import numpy as np
import pytest

from mmreg import SequenceRegistration, SweepRegistration
from mmreg.datasets._lidar_sequence import _convoy_log

LEADER, FOLLOWER = 1, 2
SPEED = 8.0  # m/s, both cars and the sensor's car


@pytest.fixture(scope="module")
def log():
    return _convoy_log(6, frame_rate=2.0, ego_speed=SPEED, mover_speed=SPEED)


def _centre_in_sensor(log, k, car):
    row = log.objects.query("frame == @k and id == @car").iloc[0]
    pose = log.poses[k]
    return np.linalg.solve(pose, [row.x, row.y, row.z, 1.0])[:3]


def test_the_follower_stands_where_the_leader_stood_a_frame_before(log):
    for k in range(len(log.frames) - 1):
        np.testing.assert_allclose(
            _centre_in_sensor(log, k + 1, FOLLOWER), _centre_in_sensor(log, k, LEADER), atol=1e-9
        )


def test_a_pair_alone_moves_the_leader_with_the_sensor(log):
    """In the middle pairs the leader's flow is about nought in the sensor's frame (it
    truly moves by 8 m there) and the pair reports it moving."""
    for k in (1, 2, 3):
        pair = SweepRegistration(widen_reach=False, random_state=0)
        pair.fit(log.frames[k], sweep=log.frames[k + 1])
        leader = log.labels[k] == LEADER
        assert leader.sum() > 100
        flow = np.median(np.asarray(pair.flow_)[leader], axis=0)
        assert np.linalg.norm(flow) < 1.0
        labels = pair.labels_[leader]
        moving = (labels >= 0) & np.asarray(pair.moving_)[labels]  # -1: an outlier
        assert moving.mean() > 0.9


def test_a_log_keeps_the_leader_with_one_id_and_its_true_velocity(log):
    est = SequenceRegistration(random_state=0).fit(log.frames, times=log.times)
    ids = set()
    for k in (1, 2, 3):  # the pairs above
        leader = log.labels[k] == LEADER
        moving = est.moving_[k][leader]
        assert moving.mean() > 0.5
        ids |= set(np.unique(est.labels_[k][leader][moving]).tolist())
    assert len(ids) == 1
    rows = est.tracks_[est.tracks_.track == ids.pop()]
    assert len(rows) >= 3
    # Oncoming (against x) in every row, where the pair alone says +8 m/s; the speed is
    # measured on the parts each next frame shows (the leader leaves the view).
    assert (rows.vx < -0.5 * SPEED).all()
    assert abs(np.median(rows.speed) - SPEED) < 0.25 * SPEED
