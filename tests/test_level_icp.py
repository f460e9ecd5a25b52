"""The level ICP (a turn about the vertical and a shift across it) in any units."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from mmreg.sweeps._icp import SurfaceNormals
from mmreg.sweeps._level_icp import _median, level_icp, level_icps


def _box(n, rng):
    """Points on the faces of a 4 x 2 x 1.4 box about the origin."""
    half = np.array([2.0, 1.0, 0.7])
    p = rng.uniform(-1, 1, (n, 3)) * half
    side = rng.integers(0, 3, n)
    p[np.arange(n), side] = np.sign(rng.uniform(-1, 1, n)) * half[side]
    return p


def _turn(yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@settings(max_examples=12, deadline=None)
@given(
    yaw=st.floats(-0.1, 0.1),
    shift=st.tuples(st.floats(-0.4, 0.4), st.floats(-0.4, 0.4)),
    scale=st.sampled_from([1e-3, 1.0, 1e3]),
)
def test_a_box_s_turn_and_shift_are_found_in_any_units(yaw, shift, scale):
    rng = np.random.default_rng(0)
    moved = np.array([shift[0], shift[1], 0.0])
    sweep = (_box(20000, rng) @ _turn(yaw).T + moved) * scale
    tree = cKDTree(sweep)
    target = (sweep, tree, SurfaceNormals(sweep, tree, 10))
    fit = level_icp(_box(2000, rng) * scale, np.eye(4), np.eye(4), target, max_distance=scale)
    found_yaw = np.arctan2(fit.motion[1, 0], fit.motion[0, 0])
    assert abs(found_yaw - yaw) < 2e-3
    assert np.abs(fit.motion[:3, 3] / scale - moved).max() < 0.01


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(0, 1e6, allow_subnormal=False), min_size=1, max_size=60))
def test_the_steps_median_is_numpys_to_the_bit(values):
    values = np.array(values)
    assert _median(values) == float(np.median(values))


@settings(max_examples=15, deadline=None)
@given(
    shifts=st.lists(
        st.tuples(st.floats(-0.4, 0.4), st.floats(-0.4, 0.4), st.floats(-0.1, 0.1)),
        min_size=1,
        max_size=4,
    ),
    tiny=st.integers(0, 4),
    turn=st.booleans(),
)
def test_parts_refined_at_once_move_as_each_alone(shifts, tiny, turn):
    """Boxes 10 m apart, each moved its own way, and one part of ``tiny`` points (too few
    to match): refined at once, every part ends where it ends alone, in any order."""
    rng = np.random.default_rng(1)
    centres = [np.array([10.0 * k, 0.0, 0.0]) for k in range(len(shifts))]
    boxes = [_box(600, rng) + centre for centre in centres]
    # Each box turned about its own centre and shifted, sampled densely again.
    sweep = np.vstack(
        [
            _box(8000, rng) @ _turn(yaw).T + centre + [x, y, 0.0]
            for centre, (x, y, yaw) in zip(centres, shifts, strict=True)
        ]
    )
    tree = cKDTree(sweep)
    parts = [*boxes, rng.uniform(-50, -40, (tiny, 3))]
    starts = [np.eye(4)] * len(parts)

    def refined(parts, starts):
        target = (sweep, tree, SurfaceNormals(sweep, tree, 10))
        return level_icps(parts, starts, np.eye(4), target, max_distance=1.0, turn=turn)

    together = refined(parts, starts)
    backwards = refined(parts[::-1], starts[::-1])[::-1]
    for k, part in enumerate(parts):
        alone = refined([part], [starts[k]])[0]
        for fit in (together[k], backwards[k]):
            np.testing.assert_allclose(fit.motion, alone.motion, atol=1e-9)
            np.testing.assert_allclose(fit.scale, alone.scale, rtol=1e-9, atol=1e-12)
    assert np.isnan(together[-1].scale)  # too few points: left at its start
    np.testing.assert_array_equal(together[-1].motion, np.eye(4))
