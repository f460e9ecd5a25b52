"""The places a mover leaves and reaches (mmreg.tracking._births)."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from mmreg.sweeps._icp import SurfaceNormals
from mmreg.tracking._births import moved_places, new_place_share, place_starts
from mmreg.tracking._motion import to_matrix, transform
from mmreg.tracking._visibility import RangeView


def _grid(x, y, z):
    return np.stack(np.meshgrid(x, y, z, indexing="ij"), -1).reshape(-1, 3)


def _target(points):
    tree = cKDTree(points)
    return points, tree, SurfaceNormals(points, tree, 10)


def _reached(first, second, ego):
    """Per point of ``second``: whether ``first``, moved by ``ego``, leaves it unexplained
    (a place reached)."""
    _, new = moved_places(
        second, np.arange(len(second)), np.linalg.inv(ego), _target(first), 0.01, None,
        0.25, 0.25, 10,
    )  # fmt: skip
    reached = np.zeros(len(second), dtype=bool)
    reached[new] = True
    return reached


FLOOR = _grid(np.arange(-2.0, 14.0, 0.1), np.arange(-6.0, 6.0, 0.1), [-1.5])
BOX = _grid(np.arange(0.0, 0.5, 0.1), np.arange(0.0, 0.5, 0.1), np.arange(0.0, 1.0, 0.1))


def test_the_place_a_box_left_is_found_and_the_floor_is_not():
    box = BOX + [6.0, 2.0, -1.0]
    first = np.vstack([FLOOR, box])
    second = np.vstack([FLOOR, box + [1.0, 0.0, 0.0]])
    places, unexplained = moved_places(
        first, np.arange(len(first)), np.eye(4), _target(second), 0.01, RangeView(second),
        0.25, 0.25, 10,
    )  # fmt: skip
    assert len(places) == 1
    assert set(places[0]) == set(range(len(FLOOR), len(first)))
    assert set(unexplained) == set(places[0])


def test_a_place_the_other_sweep_could_not_see_is_no_place_left():
    # The box left its place, but in the second sweep a wall stands between the sensor
    # and that place: the second sweep could not have seen it empty.
    box = BOX + [6.0, 2.0, -1.0]
    wall = _grid([3.0], np.arange(0.0, 4.5, 0.05), np.arange(-1.4, 1.0, 0.05))
    first = np.vstack([FLOOR, box])
    second = np.vstack([FLOOR, wall, box + [0.0, -5.0, 0.0]])
    places, _ = moved_places(
        first, np.arange(len(FLOOR), len(first)), np.eye(4), _target(second), 0.01,
        RangeView(second), 0.25, 0.25, 10,
    )  # fmt: skip
    assert places == []
    # Without the range image, the box's place is one.
    places, _ = moved_places(
        first, np.arange(len(FLOOR), len(first)), np.eye(4), _target(second), 0.01, None,
        0.25, 0.25, 10,
    )  # fmt: skip
    assert len(places) == 1


def test_a_row_of_barriers_slid_by_one_period_lands_on_no_new_place():
    # Identical barriers every 2.5 m beside the road; the sensor moved 3 m along it.
    barrier = _grid(np.arange(0.0, 2.0, 0.1), [4.0, 4.4], np.arange(-1.4, -0.4, 0.1))
    row = np.vstack([barrier + [2.5 * i, 0.0, 0.0] for i in range(-2, 8)])
    ego = to_matrix(np.eye(3), [-3.0, 0.0, 0.0])
    first = np.vstack([FLOOR, row])
    second = transform(ego, first)  # the same world, seen 3 m further on
    target = _target(second)
    reached = _reached(first, second, ego)
    one_period = to_matrix(np.eye(3), [-3.0 + 2.5, 0.0, 0.0])  # ego, then one barrier on
    assert new_place_share(first[len(FLOOR) :], one_period, target, reached) == 0.0
    # A box that drove 1 m into free space lands on places reached.
    box = BOX + [6.0, -2.0, -1.0]
    second = np.vstack([second, transform(ego, box + [1.0, 0.0, 0.0])])
    first = np.vstack([first, box])
    target = _target(second)
    reached = _reached(first, second, ego)
    moved = ego @ to_matrix(np.eye(3), [1.0, 0.0, 0.0])
    assert new_place_share(box, moved, target, reached) > 0.9


@given(
    shift=st.tuples(*[st.floats(-3.0, 3.0)] * 3),
    n_far=st.integers(0, 3),
)
def test_place_starts_shift_onto_the_nearest_places_within_reach(shift, n_far):
    left = [BOX]
    near = BOX + shift
    far = [BOX + [50.0 + 10 * i, 0.0, 0.0] for i in range(n_far)]
    starts = place_starts(left, [*far, near], np.eye(4), reach=10.0)
    assert len(starts) == 1 and len(starts[0]) == 1
    np.testing.assert_allclose(starts[0][0][:3, 3], shift, atol=1e-9)
    np.testing.assert_allclose(starts[0][0][:3, :3], np.eye(3))


@pytest.mark.parametrize("reached", [[], [BOX + [30.0, 0.0, 0.0]]])
def test_no_place_reached_within_reach_gives_no_start(reached):
    assert place_starts([BOX], reached, np.eye(4), reach=10.0) == [[]]
