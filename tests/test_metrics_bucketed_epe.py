"""Bucket normalised EPE: a hand computation, a per-point loop, and the rules it follows."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mmreg.metrics import bucketed_epe
from mmreg.metrics._scene_flow import BUCKET_EDGES


def test_bucket_edges_are_the_challenges():
    # 51 edges 0, 0.04, ..., 2.0 m per frame (0.4 m/s buckets at 10 Hz) and one above.
    assert len(BUCKET_EDGES) == 52 and BUCKET_EDGES[-1] == math.inf
    assert BUCKET_EDGES[1] == pytest.approx(0.04) and BUCKET_EDGES[-2] == pytest.approx(2.0)


def test_hand_computation():
    # Speeds (true flow norms) and end-point errors, chosen away from every bucket edge:
    #   class 0: static points, errors 0.1 and 0.3               -> static EPE 0.2
    #            speeds 0.09 and 0.11 (bucket [0.08, 0.12)), errors 0.09 and 0
    #            -> mean error 0.045 / mean speed 0.1 = 0.45 (a mean of ratios is 0.5)
    #            speed 1.0 (bucket [1.0, 1.04)), error 0.2 -> 0.2
    #            dynamic normalised EPE: (0.45 + 0.2) / 2 = 0.325
    #   class 1: one static point, error 0.05 -> static 0.05; no moving point -> NaN
    #   class 2: speed 3.0 (the last bucket, from 2.0 m up), error 1.5 -> 0.5; no static
    speeds = [0.0, 0.0, 0.09, 0.11, 1.0, 0.0, 3.0]
    errors = [0.1, 0.3, 0.09, 0.0, 0.2, 0.05, 1.5]
    classes = [0, 0, 0, 0, 0, 1, 2]
    truth = np.array([[s, 0.0, 0.0] for s in speeds])
    estimate = truth + np.array([[0.0, e, 0.0] for e in errors])
    got = bucketed_epe(truth, estimate, classes=classes)
    assert got["per_class"][0]["static_epe"] == pytest.approx(0.2)
    assert got["per_class"][0]["dynamic_normalized_epe"] == pytest.approx(0.325)
    assert got["per_class"][1]["static_epe"] == pytest.approx(0.05)
    assert math.isnan(got["per_class"][1]["dynamic_normalized_epe"])
    assert math.isnan(got["per_class"][2]["static_epe"])
    assert got["per_class"][2]["dynamic_normalized_epe"] == pytest.approx(0.5)
    assert got["mean_static_epe"] == pytest.approx((0.2 + 0.05) / 2)
    assert got["mean_dynamic_normalized_epe"] == pytest.approx((0.325 + 0.5) / 2)


def reference(speed, error, classes, edges):
    """The definition point by point, in plain Python: per class, per bucket, then means."""
    per_class = {}
    for name in sorted(set(classes)):
        buckets = []
        for low, high in zip(edges[:-1], edges[1:], strict=True):
            rows = [i for i, c in enumerate(classes) if c == name and low <= speed[i] < high]
            if not rows:
                buckets.append(None)
                continue
            mean_error = sum(error[i] for i in rows) / len(rows)
            mean_speed = sum(speed[i] for i in rows) / len(rows)
            buckets.append((mean_error, mean_speed))
        static = buckets[0][0] if buckets[0] else math.nan
        moving = [e / s for b in buckets[1:] if b for e, s in [b]]
        per_class[name] = (static, sum(moving) / len(moving) if moving else math.nan)
    return per_class


@settings(max_examples=50, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.integers(0, 2),  # class
            st.integers(0, 60),  # speed: 0.003 + 0.012 k metres (see below)
            st.floats(0, 2),  # error along y
        ),
        min_size=1,
        max_size=30,
    )
)
def test_matches_a_loop(rows):
    # Speeds 0.003 + 0.012 k stay at least 1 mm from every edge (edges of our own).
    edges = np.array([0.0, 0.05, 0.1, 0.2, 0.4, np.inf])
    classes = [c for c, _, _ in rows]
    speed = [0.003 + 0.012 * k for _, k, _ in rows]
    error = [e for _, _, e in rows]
    truth = np.array([[s, 0.0, 0.0] for s in speed])
    estimate = truth + np.array([[0.0, e, 0.0] for e in error])
    got = bucketed_epe(truth, estimate, classes=classes, bucket_edges=edges)
    expected = reference(speed, error, classes, edges.tolist())
    assert set(got["per_class"]) == set(expected)
    for name, (static, moving) in expected.items():
        values = got["per_class"][name]
        assert values["static_epe"] == pytest.approx(static, nan_ok=True)
        assert values["dynamic_normalized_epe"] == pytest.approx(moving, nan_ok=True)


def test_zero_flow_scores_one_on_moving_buckets():
    rng = np.random.default_rng(0)
    truth = rng.normal(size=(50, 3))
    truth *= (rng.uniform(0.3, 3.0, 50) / np.linalg.norm(truth, axis=1))[:, None]
    got = bucketed_epe(truth, np.zeros_like(truth))
    assert got["mean_dynamic_normalized_epe"] == pytest.approx(1.0)
    assert math.isnan(got["mean_static_epe"])  # no static point
    assert list(got["per_class"]) == ["all"]


def test_perfect_estimate_scores_zero():
    truth = np.array([[0.0, 0, 0], [0.5, 0, 0], [0, 2.5, 0]])
    got = bucketed_epe(truth, truth, classes=["a", "b", "b"])
    assert got["mean_static_epe"] == 0.0 and got["mean_dynamic_normalized_epe"] == 0.0


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"classes": [0, 1]}, "classes must have shape"),
        ({"bucket_edges": [0.0, 1.0]}, "at least 3 edges"),
        ({"bucket_edges": [0.1, 0.2, 0.3]}, "start at 0"),
        ({"bucket_edges": [0.0, 0.2, 0.2]}, "increase strictly"),
    ],
)
def test_bad_input(kwargs, message):
    flow = np.zeros((3, 3))
    with pytest.raises(ValueError, match=message):
        bucketed_epe(flow, flow, **kwargs)
