"""The ICP's shortcuts against plain computations: the same answers, to the bit.

MovingNearest re-queries a moving point's nearest target point only where it may have
changed; multi_body_icp uses it, and SweepRegistration's EM rounds share the a-points'
voxel sample and neighbour table (PointMemo). Each is compared here with the plain
computation it replaces.
"""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from numpy.testing import assert_array_equal
from scipy.spatial import cKDTree
from test_two_sweeps import make_pair

import mmreg.estimators._two_sweeps as two_sweeps
import mmreg.sweeps._icp as icp
from mmreg import MultiModelRegistration, SweepRegistration
from mmreg._array.moving_nearest import MovingNearest
from mmreg._array.point_memo import PointMemo
from mmreg._array.point_tree import PointTree


class _PlainNearest:
    """What MovingNearest replaces: one query of every point, every time."""

    def __init__(self, tree, n, bound, workers=1):
        self.tree, self.bound, self.workers = tree, bound, workers

    def __call__(self, x, rows, gate=None):
        return self.tree.query(x, distance_upper_bound=self.bound, workers=self.workers)


@given(
    seed=st.integers(0, 2**32 - 1),
    on_grid=st.booleans(),
    step=st.sampled_from([1e-4, 1e-2, 0.3]),
    bound=st.sampled_from([0.2, 1.0, np.inf]),
    make_tree=st.sampled_from([cKDTree, PointTree]),
)
def test_moving_points_get_the_tree_s_nearest_point(seed, on_grid, step, bound, make_tree):
    rng = np.random.default_rng(seed)
    if on_grid:  # many equidistant target points: ties the tree must break itself
        target = rng.integers(0, 6, size=(300, 3)) * 0.25
    else:
        target = rng.uniform(0, 2, size=(300, 3))
    tree = make_tree(target)
    x = rng.uniform(-0.2, 2.2, size=(80, 3))
    nearest = MovingNearest(tree, len(x), bound)
    gate = np.full(len(x), 0.7 * bound if np.isfinite(bound) else 10.0)
    for _ in range(6):
        rows = np.flatnonzero(rng.random(len(x)) < 0.8)
        x[rows] += rng.normal(scale=step, size=(len(rows), 3))
        if on_grid:  # some points exactly between two target points
            x[rows[:5]] = target[rows[:5]] + [0.125, 0.0, 0.0]
        distance, index = nearest(x[rows], rows, gate[rows])
        expected_distance, expected_index = tree.query(x[rows], distance_upper_bound=bound)
        assert_array_equal(index, expected_index)
        assert_array_equal(distance <= gate[rows], expected_distance <= gate[rows])
        assert_array_equal(np.isfinite(distance), np.isfinite(expected_distance))
        finite = np.isfinite(distance)
        np.testing.assert_allclose(distance[finite], expected_distance[finite], rtol=1e-12)


def test_small_moves_need_no_new_query():
    rng = np.random.default_rng(0)
    target = rng.uniform(0, 10, size=(2000, 3))
    x = rng.uniform(0, 10, size=(500, 3))
    nearest = MovingNearest(cKDTree(target), len(x), np.inf)
    nearest(x, np.arange(len(x)))
    assert nearest.n_queried == len(x)
    # A hundred-thousandth of the spacing (about 0.4): the nearest is certain nearly
    # everywhere.
    _, index = nearest(x + 4e-6, np.arange(len(x)))
    assert nearest.n_queried < 1.05 * len(x)
    assert_array_equal(index, cKDTree(target).query(x + 4e-6)[1])


def test_multi_body_icp_equals_the_plain_query_loop(monkeypatch):
    a, _, labels, rotations, translations, sweep = make_pair(random_state=3)
    rng = np.random.default_rng(1)
    start = translations + rng.normal(scale=0.2, size=translations.shape)
    fast = icp.multi_body_icp(a, labels, rotations, start, sweep, max_distance=1.0)
    monkeypatch.setattr(icp, "MovingNearest", _PlainNearest)
    plain = icp.multi_body_icp(a, labels, rotations, start, sweep, max_distance=1.0)
    for name in ("rotations", "translations", "scales", "n_matched", "inlier_share"):
        assert_array_equal(getattr(fast, name), getattr(plain, name))
    assert fast.n_iter == plain.n_iter


def test_point_memo_recomputes_for_other_points():
    memo, calls = PointMemo(), []

    def count():
        calls.append(1)
        return len(calls)

    points = np.arange(12.0).reshape(4, 3)
    assert memo.get("k", points, count) == 1
    assert memo.get("k", points.copy(), count) == 1
    moved = points.copy()
    moved[2, 1] += 1e-12
    assert memo.get("k", moved, count) == 2
    assert memo.get("other", moved, count) == 3


def test_sweep_rounds_sharing_their_tables_change_no_label(monkeypatch):
    a, _, _, _, _, sweep = make_pair(random_state=5)

    def fit():
        inner = MultiModelRegistration(variant="sweep", tau=2.0, random_state=0)
        return SweepRegistration(inner, max_distance=1.5, max_rounds=2, random_state=0).fit(
            a, sweep=sweep
        )

    shared = fit()

    class _NoMemo(PointMemo):
        def get(self, key, points, compute):
            return compute()

    monkeypatch.setattr(two_sweeps, "PointMemo", _NoMemo)
    alone = fit()
    assert_array_equal(shared.labels_, alone.labels_)
    assert_array_equal(shared.flow_, alone.flow_)
