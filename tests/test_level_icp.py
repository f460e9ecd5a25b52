"""The level ICP (a turn about the vertical and a shift across it) in any units."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from mmreg.sweeps._icp import SurfaceNormals
from mmreg.sweeps._level_icp import _median, level_icp


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
