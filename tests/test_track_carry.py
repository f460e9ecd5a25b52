"""A track carried onto the next sweep takes the points its motion lands on, not the road.

Where the next pair misses an object (or there is no next pair), the points of the next
sweep that the track's motion lands its points on are its. A car that has left the view
lands its lowest points on the road it drove on: where the road is all it lands on, the
object is gone and the road stays the static world's. A car still there keeps its
lowest points, even those the ground's segmentation took.
"""

import numpy as np
import pytest
from _trackers import bare_tracker

from mmreg.tracking._log import LogFrame


def _frame(index, points):
    frame = LogFrame(index=index, points=points, valid=np.ones(len(points), bool), time=index)
    frame.body = np.zeros(len(points), dtype=bool)
    return frame


def _car(x, spacing):
    """A car's surface from its bottom (0.05 m over the road) up, every ``spacing``."""
    g = np.arange(0.0, 1.0, spacing)
    along, across, up = np.meshgrid(4.0 * g, 1.8 * g, 0.05 + 1.4 * g, indexing="ij")
    box = np.stack([along + x, across, up], -1).reshape(-1, 3)
    lo, hi = box.min(axis=0), box.max(axis=0)
    on_face = np.any(np.isclose(box, lo) | np.isclose(box, hi), axis=1)
    return box[on_face]


@pytest.mark.parametrize("scale", [1.0, 100.0])  # metres, centimetres
def test_a_car_carried_keeps_its_lowest_points_and_a_car_gone_leaves_the_road(scale):
    g = np.arange(-10.0, 20.0, 0.1)
    road = np.stack(np.meshgrid(g, np.arange(-3.0, 5.0, 0.1), [0.0], indexing="ij"), -1)
    road = road.reshape(-1, 3)
    car = _car(0.0, 0.05)
    step = np.eye(4)
    step[0, 3] = 1.0 * scale  # the car drives 1 m along x

    previous = _frame(0, np.vstack([road, car]) * scale)
    previous.track_of = np.r_[np.full(len(road), -1), np.full(len(car), 7)]
    previous.motions = {7: step}
    tracker = bare_tracker(5.0 * scale)

    # The car is there, 1 m on (hiding the road beneath it); the ground's segmentation
    # took its lowest ring too.
    moved = _car(1.0, 0.05)
    beneath = (road[:, 0] > 0.5) & (road[:, 0] < 5.5) & (road[:, 1] > -0.5) & (road[:, 1] < 2.3)
    seen = road[~beneath]
    there = _frame(1, np.vstack([seen, moved]) * scale)
    low = np.r_[np.zeros(len(seen), bool), moved[:, 2] < 0.1]
    ground = np.r_[np.ones(len(seen), bool), np.zeros(len(moved), bool)] | low
    tracker._carry(previous, there, ground)
    carried = there.carried == 7
    assert carried[len(seen) :].all()  # every point of the car, its lowest ones included
    assert carried[low].all() and low.sum() > 10
    assert not carried[: len(seen)].any()  # the road around it is not

    # The car has left the view: its motion lands its bottom on the road alone.
    gone = _frame(1, road * scale)
    tracker._carry(previous, gone, np.ones(len(road), dtype=bool))
    assert (gone.carried == -1).all()
    # Without the ground's word, those road points would be the car's (the rule's reason).
    tracker._carry(previous, gone, np.zeros(len(road), dtype=bool))
    assert (gone.carried == 7).sum() > 100
