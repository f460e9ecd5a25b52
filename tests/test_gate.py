"""ClusterGate.admits against a plain reading of the gate: the nearest member within tau."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import mmreg.em._gate as gate_module
from mmreg.em._gate import ClusterGate


def plain_gate(points, labels, radius, query, clusters):
    """Whether a member of ``clusters[i]`` lies within ``radius`` of ``query[i]``."""
    out = np.zeros(len(query), dtype=bool)
    for i, (q, c) in enumerate(zip(query, clusters, strict=True)):
        members = points[labels == c]
        if len(members):
            out[i] = np.sqrt(np.sum((members - q) ** 2, axis=1)).min() <= radius
    return out


@st.composite
def gated_scenes(draw):
    d = draw(st.sampled_from([2, 3]))
    n = draw(st.integers(1, 200))
    coordinate = st.floats(-20, 20, allow_nan=False)
    points = draw(arrays(np.float64, (n, d), elements=coordinate))
    k = draw(st.integers(1, 5))
    labels = draw(arrays(np.intp, n, elements=st.integers(-1, k - 1)))
    radius = draw(st.floats(0.05, 15))
    m = draw(st.integers(1, 40))
    # Queries beside the points (within 1.5 tau on each axis), where the gate is hard
    # to call, and anywhere.
    near = draw(arrays(np.intp, m, elements=st.integers(0, n - 1)))
    shift = draw(arrays(np.float64, (m, d), elements=st.floats(-1.5, 1.5)))
    anywhere = draw(arrays(np.float64, (m, d), elements=coordinate))
    beside = draw(arrays(np.bool_, m))
    query = np.where(beside[:, None], points[near] + radius * shift, anywhere)
    clusters = draw(arrays(np.intp, m, elements=st.integers(0, k - 1)))
    return points, labels, k, radius, query, clusters


@settings(max_examples=300, deadline=None)
@given(gated_scenes(), st.booleans())
def test_admits_is_the_nearest_member_within_radius(scene, brute_force):
    points, labels, k, radius, query, clusters = scene
    expected = plain_gate(points, labels, radius, query, clusters)
    with pytest.MonkeyPatch.context() as patch:
        # Both exact tests: brute force for every query, or a KD-tree for every one.
        patch.setattr(gate_module, "_BRUTE_FORCE_PAIRS", 2**40 if brute_force else 0)
        got = ClusterGate(points, labels, k, radius).admits(query, clusters)
    np.testing.assert_array_equal(got, expected)


def test_a_query_beside_the_middle_of_a_line_is_decided_exactly():
    # A line of members 1 apart: its representatives (first, last, nearest the centroid)
    # are all far from a query beside its middle, so the exact test decides.
    line = np.column_stack([np.arange(101.0), np.zeros(101), np.zeros(101)])
    gate = ClusterGate(line, np.zeros(101, dtype=np.intp), 1, 2.0)
    query = np.array([[25.3, 1.6, 0.0], [25.3, 2.6, 0.0]])  # 1.6 and 2.6 from the line
    assert gate.admits(query, np.array([0, 0])).tolist() == [True, False]
