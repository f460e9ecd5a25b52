"""describe_partition: sizes and tau-connectivity of an initial partition."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.sparse.csgraph import connected_components
from scipy.spatial.distance import cdist

from mmreg.datasets import make_scene
from mmreg.init import EuclideanClustering, describe_partition


def brute_force_pieces(points, labels, tau):
    pieces = {}
    for cluster in np.unique(labels[labels >= 0]):
        own = points[labels == cluster]
        pieces[cluster] = connected_components(cdist(own, own) <= tau, directed=False)[0]
    return pieces


@given(seed=st.integers(0, 2**32 - 1), tau=st.floats(0.05, 2.0), n_labels=st.integers(1, 6))
def test_matches_brute_force(seed, tau, n_labels):
    rng = np.random.default_rng(seed)
    a = rng.uniform(0, 3, size=(60, 3))
    X = np.hstack([a, a])
    labels = rng.integers(-1, n_labels, size=60)
    table = describe_partition(labels, X, tau=tau)
    expected = brute_force_pieces(a, labels, tau)
    assert sorted(table["cluster"]) == sorted(expected)
    for row in table.itertuples():
        assert row.size == np.count_nonzero(labels == row.cluster)
        assert row.fraction == pytest.approx(row.size / 60)
        assert row.n_pieces == expected[row.cluster]
        assert row.tau_connected == (expected[row.cluster] == 1)
    assert list(table["size"]) == sorted(table["size"], reverse=True)
    assert table.attrs["n_unassigned"] == np.count_nonzero(labels < 0)
    assert table.attrs["n_clusters"] == len(expected)
    assert table.attrs["tau"] == tau


def test_euclidean_clusters_are_tau_connected():
    scene = make_scene(n_objects=3, n_points=900, random_state=0)
    init = EuclideanClustering(n_clusters=20, min_cluster_size=4).fit(scene.X)
    table = describe_partition(init.labels_, scene.X, tau=init.radius_)
    assert len(table) == init.n_clusters_
    assert table["tau_connected"].all()
    # Below the radius used some clusters fall apart.
    assert not describe_partition(init.labels_, scene.X, tau=init.radius_ / 2)[
        "tau_connected"
    ].all()


def test_without_tau_and_empty():
    X = np.zeros((4, 6))
    table = describe_partition([3, 3, 1, -1], X)
    assert isinstance(table, pd.DataFrame)
    assert list(table.columns) == ["cluster", "size", "fraction"]
    assert table["cluster"].tolist() == [3, 1] and table["size"].tolist() == [2, 1]
    empty = describe_partition([-1] * 4, X, tau=1.0)
    assert len(empty) == 0 and empty.attrs["n_unassigned"] == 4


def test_bad_input():
    X = np.zeros((4, 6))
    with pytest.raises(ValueError, match="one label per correspondence"):
        describe_partition([0, 1], X)
    with pytest.raises(ValueError, match="tau must be positive"):
        describe_partition([0, 0, 0, 0], X, tau=0.0)
    with pytest.raises(ValueError, match="even number of columns"):
        describe_partition([0, 0, 0, 0], X[:, :3])
