"""PointTree against scipy's cKDTree: the same distances, a point at each, "none" alike."""

import pickle

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial import cKDTree

import mmreg._array.point_tree as point_tree
from mmreg._array.point_tree import PointTree


def _points(rng, n, on_grid):
    if on_grid:  # many equidistant points, and duplicates: ties the engines break apart
        return rng.integers(0, 5, size=(n, 3)) * 0.5
    return rng.uniform(-3, 3, size=(n, 3))


@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 400),
    k=st.integers(1, 6),
    on_grid=st.booleans(),
    bound=st.sampled_from([0.3, 1.7, np.inf]),
    small_gicp=st.booleans(),
)
def test_query_finds_scipy_s_distances(seed, n, k, on_grid, bound, small_gicp):
    rng = np.random.default_rng(seed)
    points = _points(rng, n, on_grid)
    x = rng.uniform(-4, 4, size=(50, 3))
    tree = PointTree(points)
    if not small_gicp:
        tree._engine = False  # as where small_gicp is not installed
    distance, index = tree.query(x, k=k, distance_upper_bound=bound)
    expected, _ = cKDTree(points).query(x, k=k, distance_upper_bound=bound)
    assert distance.shape == index.shape == expected.shape
    # A distance within rounding of the bound may fall either side of it: not compared.
    clear = np.abs(np.where(np.isfinite(expected), expected, 1e300) - bound) > 1e-9
    assert_array_equal(np.isfinite(distance)[clear], np.isfinite(expected)[clear])
    both = np.isfinite(distance) & np.isfinite(expected)
    assert_allclose(distance[both], expected[both], rtol=1e-12, atol=1e-12)
    # Every index listed is a point at its distance, "none" (n) where there is none.
    found = np.isfinite(distance)
    assert_array_equal(index[~found], n)
    rows = np.broadcast_to(np.arange(len(x))[:, None] if k > 1 else np.arange(len(x)), index.shape)
    gap = np.linalg.norm(points[index[found]] - x[rows[found]], axis=-1)
    assert_allclose(gap, distance[found], rtol=1e-12, atol=1e-12)


def test_more_neighbours_than_points_are_none():
    tree = PointTree(np.array([[0.0, 0, 0], [2, 0, 0]]))
    distance, index = tree.query([[0.5, 0, 0]], k=4)
    assert_allclose(distance, [[0.5, 1.5, np.inf, np.inf]])
    assert_array_equal(index, [[0, 1, 2, 2]])


def test_other_questions_are_scipy_s():
    rng = np.random.default_rng(0)
    points, other = rng.uniform(0, 1, (200, 3)), rng.uniform(0, 1, (50, 3))
    tree, reference = PointTree(points), cKDTree(points)
    assert sorted(tree.query_ball_point([0.5, 0.5, 0.5], r=0.3)) == sorted(
        reference.query_ball_point([0.5, 0.5, 0.5], r=0.3)
    )
    near = tree.sparse_distance_matrix(PointTree(other), 0.2, output_type="ndarray")
    expected = reference.sparse_distance_matrix(cKDTree(other), 0.2, output_type="ndarray")
    assert len(near) == len(expected) > 0
    # A single point (1-D), eps and p are scipy's too.
    assert_array_equal(tree.query(points[3]), reference.query(points[3]))
    assert_array_equal(tree.query(points[:5], p=1), reference.query(points[:5], p=1))


def test_a_tree_pickles_and_answers_after():
    points = np.random.default_rng(1).uniform(0, 1, (100, 3))
    tree = PointTree(points)
    tree.query(points[:3])  # the engine exists before the pickle
    again = pickle.loads(pickle.dumps(tree))
    assert_array_equal(again.data, points)
    assert_allclose(again.query(points[:10])[0], 0.0)


def test_empty_queries_and_trees():
    tree = PointTree(np.zeros((0, 3)))
    distance, index = tree.query(np.ones((2, 3)))
    assert_array_equal(index, [0, 0])
    assert np.isinf(distance).all()
    distance, index = PointTree(np.ones((4, 3))).query(np.zeros((0, 3)), k=2)
    assert distance.shape == index.shape == (0, 2)


def test_points_must_be_rows():
    with pytest.raises(ValueError, match="2-D"):
        PointTree(np.zeros(3))


@pytest.mark.skipif(not point_tree._HAS_SMALL_GICP, reason="small_gicp is not installed")
def test_nearest_queries_run_on_small_gicp():
    tree = PointTree(np.random.default_rng(2).uniform(0, 1, (50, 3)))
    tree.query(np.zeros((3, 3)), k=2)
    assert tree._engine
    assert tree._scipy is None  # no cKDTree was built for them
