"""A track's claim grows to the body of the points near its prediction, no longer than a car.

A car coming into view shows its first pair only a part (its front, far off); its track is
born on that part, and the rest of the car, nearer as it passes, lies beyond the reach of
the track's points. The claim takes the islands that hold those points, as a place left
takes its car. A walker beside a wall shares the wall's island: a body longer than a car
is no road user's, and the claim keeps to the points near its prediction.
"""

import numpy as np
import pytest
from _trackers import bare_tracker


def _box(low, high, spacing, rng):
    """Points filling a box at about ``spacing`` (a solid: every voxel of it occupied)."""
    low, high = np.asarray(low, float), np.asarray(high, float)
    n = int(np.prod(np.ceil((high - low) / spacing)))
    return rng.uniform(low, high, (4 * n, 3))


@pytest.mark.parametrize("scale", [1.0, 100.0])  # metres, centimetres
def test_a_car_s_front_grows_to_the_car_and_a_walker_not_to_the_wall(scale):
    rng = np.random.default_rng(0)
    car = _box([0.0, 0.0, 0.0], [4.4, 1.8, 1.5], 0.2, rng)
    other = _box([0.0, 4.0, 0.0], [4.4, 5.8, 1.5], 0.2, rng)  # 2.2 m beside it
    walker = _box([20.0, 0.0, 0.0], [20.5, 0.5, 1.7], 0.1, rng)
    wall = _box([14.0, 0.55, 0.0], [26.0, 0.75, 2.0], 0.2, rng)  # touching the walker
    points = np.vstack([car, other, walker, wall]) * scale
    label = np.repeat(np.arange(4), [len(car), len(other), len(walker), len(wall)])
    free = np.ones(len(points), dtype=bool)
    tracker = bare_tracker(5.0 * scale)

    front = np.flatnonzero((label == 0) & (points[:, 0] > 3.0 * scale))
    grown = tracker._grown(points, front, free)
    np.testing.assert_array_equal(grown, np.flatnonzero(label == 0))  # the car, no more

    held = np.flatnonzero(label == 2)
    np.testing.assert_array_equal(tracker._grown(points, held, free), held)

    # Points another track holds (not free) are not taken.
    free[label == 0] = points[label == 0, 0] > 2.0 * scale
    np.testing.assert_array_equal(
        tracker._grown(points, front, free), np.flatnonzero(free & (label == 0))
    )


@pytest.mark.parametrize("yaw", [0.0, 30.0, 45.0, 70.0])
@pytest.mark.parametrize("scale", [1.0, 100.0])
def test_a_body_is_as_long_as_it_is_whichever_way_it_faces(yaw, scale):
    # Along the sensor's axes a body seen diagonally is shorter than it is: a 6.5 m
    # wall at 45 degrees spans 4.6 m in x and in y, and a walker's claim took it.
    rng = np.random.default_rng(1)
    car = _box([0.0, 0.0, 0.0], [4.4, 1.8, 1.5], 0.2, rng)
    walker = _box([20.0, 0.0, 0.0], [20.5, 0.5, 1.7], 0.1, rng)
    wall = _box([17.0, 0.55, 0.0], [23.5, 0.75, 2.0], 0.2, rng)  # 6.5 m, touching the walker
    points = np.vstack([car, walker, wall])
    label = np.repeat(np.arange(3), [len(car), len(walker), len(wall)])
    c, s = np.cos(np.radians(yaw)), np.sin(np.radians(yaw))
    points = points @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T * scale
    free = np.ones(len(points), dtype=bool)
    tracker = bare_tracker(5.0 * scale)

    front = np.flatnonzero((label == 0) & (_unturned_x(points, yaw, scale) > 3.0))
    np.testing.assert_array_equal(tracker._grown(points, front, free), np.flatnonzero(label == 0))
    held = np.flatnonzero(label == 1)
    np.testing.assert_array_equal(tracker._grown(points, held, free), held)


def _unturned_x(points, yaw, scale):
    """The points' x before the scene was turned by ``yaw`` and scaled."""
    c, s = np.cos(np.radians(yaw)), np.sin(np.radians(yaw))
    return (points[:, 0] * c + points[:, 1] * s) / scale
