"""A walker beside a pole or a parked car, in raw sweeps 0.5 s apart: found, the pole left
at rest.

Within an island's radius of each other, the walker and the pole share one island. The
pole holds most of it and slides along itself, so that no motion of the whole island
passes; the walker's points, which the ego motion leaves unexplained, are a slow
mover's seed, but it moves 0.7 m, beyond the reach of an ICP started at the ego motion.
The seed starts again at its own translation starts. Where the island's ICP follows
the walker instead, the pole moved with it lands where nothing is, though the ego motion
explains it: such a motion is refused for the island.
"""

import numpy as np
import pytest

from mmreg import SweepRegistration
from mmreg.datasets._lidar import _walker_beside


def _registered(heading, gap, thing="pole"):
    """The walker's best IoU with a moving cluster, and the static clusters called moving.

    Two 64-beam sweeps 0.5 s apart; the walker walks 1.4 m/s towards ``heading`` (degrees)
    ``gap`` metres from the pole's axis or the parked car's side."""
    a, sweep, walker, static = _walker_beside(thing, np.radians(heading), gap)
    est = SweepRegistration(random_state=0).fit(a, sweep=sweep)
    moving = np.flatnonzero(est.moving_)
    iou = [
        ((est.labels_ == c) & walker).sum() / ((est.labels_ == c) | walker).sum() for c in moving
    ]
    return max(iou, default=0.0), [c for c in moving if static[est.labels_ == c].mean() > 0.5]


@pytest.mark.parametrize("heading", [90, 180])
def test_a_walker_beside_a_pole_is_found_and_the_pole_stays(heading):
    iou, static_moving = _registered(heading, gap=1.0)
    assert iou > 0.8
    assert static_moving == []


# At 0 degrees 1.3 m rather than 1.4 m: there the walker's seed passed the new-place test
# by half a point (97 of its 195 landing points explained at rest, against a bound of
# half), a threshold rather than a case; at 1.3 m it is 101 of 218.
@pytest.mark.parametrize(("heading", "gap"), [(0, 1.3), (90, 1.4), (45, 1.0)])
def test_an_island_motion_that_takes_the_pole_along_is_refused(heading, gap):
    # The island's ICP follows the walker; moved with it the pole lands nowhere, where
    # the ego motion explains it. Taken as one, the island was a moving cluster of the
    # walker and the pole (IoU 0.4-0.5, and at 45 degrees a static cluster called
    # moving); refused, the walker is found point by point.
    iou, static_moving = _registered(heading, gap)
    assert iou > 0.8
    assert static_moving == []


def test_a_walker_beside_a_parked_car_is_found():
    # 0.6 m from the car's side the walker shares its island and the cells of its
    # points; at half the cells' side it is a thing apart, and starts again.
    iou, static_moving = _registered(90, gap=0.6, thing="parked car")
    assert iou > 0.5
    assert static_moving == []
