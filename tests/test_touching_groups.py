"""Neighbour queries by group: groups within a radius, the nearest point of a subset."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from mmreg._array.neighbors import NeighbourTable, touching_groups
from mmreg._array.point_tree import PointTree


def all_pairs_reference(points, labels, radius):
    """Every pair within the radius (the same KD-tree test), reduced to group pairs."""
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray")
    pairs = labels[pairs].reshape(-1, 2)
    return np.unique(np.sort(pairs[pairs[:, 0] != pairs[:, 1]], axis=1), axis=0)


@given(
    seed=st.integers(0, 2**32 - 1),
    d=st.sampled_from([1, 2, 3, 4]),
    n_groups=st.sampled_from([1, 2, 5, 40]),
    radius=st.sampled_from([0.05, 0.3, 1.0, 50.0]),
    quantised=st.booleans(),
)
def test_matches_every_pair_within_the_radius(seed, d, n_groups, radius, quantised):
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0, 6, size=(n_groups, d))
    labels = rng.integers(n_groups, size=300)
    points = centres[labels] + rng.normal(scale=0.4, size=(300, d))
    if quantised:
        # Points on a lattice of the radius's own step: many pairs exactly radius apart.
        points = np.round(points / radius) * radius
    expected = all_pairs_reference(points, labels, radius)
    np.testing.assert_array_equal(touching_groups(points, labels, radius), expected)


def test_far_groups_do_not_touch_and_near_ones_do():
    rng = np.random.default_rng(0)
    blob = rng.normal(scale=0.1, size=(200, 3))
    points = np.vstack([blob, blob + [0.5, 0, 0], blob + [30.0, 0, 0]])
    labels = np.repeat([0, 1, 2], 200)
    np.testing.assert_array_equal(touching_groups(points, labels, 0.3), [[0, 1]])
    assert touching_groups(points, labels, 0.001).shape == (0, 2)
    assert touching_groups(points[:1], labels[:1], 1.0).shape == (0, 2)


@pytest.mark.parametrize("radius", [0.0, np.inf])
def test_degenerate_radius_falls_back_to_every_pair(radius):
    points = np.array([[0.0, 0, 0], [0, 0, 0], [5, 0, 0]])
    labels = np.array([0, 1, 2])
    expected = [[0, 1]] if radius == 0 else [[0, 1], [0, 2], [1, 2]]
    np.testing.assert_array_equal(touching_groups(points, labels, radius), expected)


@given(
    seed=st.integers(0, 2**32 - 1),
    share=st.sampled_from([0.02, 0.3, 1.0]),
    k=st.sampled_from([1, 2, 16]),
    duplicates=st.booleans(),
    tree=st.sampled_from([cKDTree, PointTree]),
)
def test_nearest_among_is_the_query_of_the_qualifying_points(seed, share, k, duplicates, tree):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(400, 3))
    if duplicates:
        points[200:] = points[:200]
    among = rng.random(400) < share
    rows = np.flatnonzero(among)
    table = NeighbourTable(points, k=k, tree=tree)
    got = table.nearest_among(rows, among)
    if len(rows) < 2:
        assert np.all(np.isinf(got))
        return
    # The table's engine's own distances (PointTree's are scipy's to rounding).
    expected = tree(points[rows]).query(points[rows], k=2)[0][:, 1]
    np.testing.assert_array_equal(got, expected)
