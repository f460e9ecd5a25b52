"""The places a mover leaves and reaches (mmreg.tracking._births)."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from mmreg import SequenceRegistration
from mmreg.datasets import make_lidar_sequence
from mmreg.sweeps._ambiguous_shapes import slides_along_line
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


@given(
    angles=st.tuples(*[st.floats(-np.pi, np.pi)] * 3),
    length=st.floats(0.5, 10.0),
    shift=st.floats(0.2, 5.0),
    seed=st.integers(0, 2**16),
)
def test_a_line_slides_along_itself_not_across(angles, length, shift, seed):
    rng = np.random.default_rng(seed)
    turn = Rotation.from_euler("xyz", angles).as_matrix()
    strip = np.c_[rng.uniform(0, length, 80), rng.normal(0, 0.01, (80, 2))] @ turn.T + [5, 2, 0]
    along, side = turn[:, 0], turn[:, 1]
    ego = (Rotation.from_euler("z", 0.1).as_matrix(), np.array([1.0, 0.0, 0.0]))
    # Along the line; and at 0.8 of the length across it (0.5 is the bound).
    steps = [along, 0.6 * along + 0.8 * side]
    translations = np.array([ego[1] + shift * ego[0] @ step for step in steps])
    rotations = np.stack([ego[0], ego[0]])
    groups = np.repeat([0, 1], 80)
    slides = slides_along_line(np.vstack([strip, strip]), groups, 2, (rotations, translations), ego)
    assert slides.tolist() == [True, False]
    # A square patch is no line: it never slides along one.
    patch = np.c_[rng.uniform(0, length, (80, 2)), np.zeros(80)] @ turn.T
    motion = (rotations[:1], translations[:1])
    assert not slides_along_line(patch, np.zeros(80, int), 1, motion, ego)[0]


def test_scan_rings_across_a_wall_are_no_mover():
    # A street with nothing moving, scanned by 21 rings 2 degrees apart (a VLP-16's
    # spacing): one ring's curve across a far facade travels with the sensor, a place
    # left and one reached every pair. Before such a line's slide along itself was
    # refused, a track was born on it and held 45-49 points moving in each of the last
    # three frames.
    log = make_lidar_sequence(
        8, n_moving=0, n_braking=0, n_overtaking=0, n_walkers=0, n_cyclists=0,
        n_standing=0, n_beams=21, random_state=0,
    )  # fmt: skip
    est = SequenceRegistration(random_state=0).fit(log.frames, times=log.times)
    assert est.n_tracks_ == 0
    assert not any(moving.any() for moving in est.moving_)
