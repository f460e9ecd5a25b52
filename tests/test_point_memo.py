"""SweepRegistration's EM rounds share the a-points' voxel sample and neighbour table
(PointMemo): the same answers, to the bit, as computing them again."""

import numpy as np
from numpy.testing import assert_array_equal
from test_two_sweeps import make_pair

import mmreg.estimators._two_sweeps as two_sweeps
from mmreg import MultiModelRegistration, SweepRegistration
from mmreg._array.point_memo import PointMemo


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
