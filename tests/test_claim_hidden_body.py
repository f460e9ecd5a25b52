"""A track's claim keeps the parts of its body that the next sweep could not see.

Where the motion puts a part of the object behind something nearer to the next sensor (a
walker stepping in front of a passing car), the next sweep has nothing there: that is no
evidence against the motion, and the part stays the object's. Before, a car passing behind
a walker lost its hidden middle to the static world in that pair.
"""

import numpy as np
import pytest
from _surfaces import grid
from scipy.spatial import cKDTree

from mmreg.sweeps._icp import SurfaceNormals
from mmreg.tracking._evidence import track_claim
from mmreg.tracking._visibility import RangeView


def _car(x):
    """A car's side facing the sensor 6 m off and its two ends, from ``x`` along it."""
    side = grid([x, 6.0, -1.0], [x + 4.4, 6.0, 0.4])
    rear = grid([x, 6.1, -1.0], [x, 7.8, 0.4])
    front = grid([x + 4.4, 6.1, -1.0], [x + 4.4, 7.8, 0.4])
    return np.vstack([side, rear, front])


@pytest.mark.parametrize("scale", [1.0, 100.0])  # metres, centimetres
def test_the_part_of_a_car_hidden_in_the_next_sweep_stays_the_car_s(scale):
    car, moved = _car(0.0), _car(1.0)  # it drives 1 m along x
    # In the next sweep a walker 3 m off hides the middle of the car's side (the
    # directions through x in 0.9-1.5 m at 3 m: 1.8-3.0 m along the side).
    walker = grid([0.9, 3.0, -1.0], [1.5, 3.0, 1.0], 0.05)
    ratio = moved[:, 0] / moved[:, 1]
    seen = ~((ratio > 0.29) & (ratio < 0.51))
    first = car * scale
    second = np.vstack([moved[seen], walker]) * scale
    tree = cKDTree(second)
    target = (second, tree, SurfaceNormals(second, tree, 10))
    start = np.eye(4)
    start[0, 3] = 1.0 * scale
    rows = np.arange(len(first))

    def claim(view):
        return track_claim(
            first,
            rows,
            rows,
            [start],
            np.eye(4),
            target,
            0.002 * scale,
            max_distance=1.0 * scale,
            min_evidence=20,
            up=np.array([0.0, 0.0, 1.0]),
            view=view,
            margin=0.25 * scale,
        )

    hidden = np.flatnonzero(~seen)
    assert len(hidden) > 100
    found = claim(RangeView(second))
    assert found.motion[0, 3] == pytest.approx(1.0 * scale, abs=0.02 * scale)
    np.testing.assert_array_equal(found.rows, rows)  # the whole car, its hidden middle too
    # Without the next sweep's view, the hidden middle is not the car's.
    blind = claim(None)
    assert np.isin(hidden, blind.rows).mean() < 0.5  # a quarter: those beside what it sees
