"""DBSCANClustering: scikit-learn and Open3D backends, the border rule, transform."""

import importlib.util

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.sparse.csgraph import connected_components
from scipy.spatial.distance import cdist
from sklearn.cluster import DBSCAN

from mmreg.datasets import make_scene
from mmreg.init import DBSCANClustering
from mmreg.init._dbscan import AllOutliersWarning

HAS_OPEN3D = importlib.util.find_spec("open3d") is not None
needs_open3d = pytest.mark.skipif(not HAS_OPEN3D, reason="Open3D is not installed")


def blobs(seed, n=150, d=3):
    rng = np.random.default_rng(seed)
    centers = rng.uniform(-3, 3, size=(4, d))
    a = centers[rng.integers(4, size=n)] + rng.normal(scale=0.4, size=(n, d))
    return np.hstack([a, a + 1.0])


def reference(points, eps, min_samples):
    """DBSCAN from the dense distance matrix, border points to their nearest core point."""
    dist = cdist(points, points)
    core = (dist <= eps).sum(axis=1) >= min_samples
    _, components = connected_components((dist <= eps) & core & core[:, None], directed=False)
    labels = np.where(core, components, -1)
    border = ~core & (dist[:, core] <= eps).any(axis=1)
    if not border.any():  # also when there is no core point at all
        return labels
    nearest_core = np.flatnonzero(core)[np.argmin(dist[np.ix_(border, core)], axis=1)]
    labels[border] = labels[nearest_core]
    return labels


def renumbered(labels):
    """Renumber by first occurrence, so that two labellings can be compared directly."""
    out = np.full(len(labels), -1)
    seen = {}
    for i, label in enumerate(labels):
        if label >= 0:
            out[i] = seen.setdefault(label, len(seen))
    return out


# Small eps with many samples leaves every point noise: a case the definition covers too,
# whose warning is tested on its own below.
@pytest.mark.filterwarnings("ignore::mmreg.init._dbscan.AllOutliersWarning")
@given(seed=st.integers(0, 2**32 - 1), eps=st.floats(0.2, 1.0), min_samples=st.integers(1, 8))
def test_sklearn_backend_matches_definition(seed, eps, min_samples):
    X = blobs(seed)
    init = DBSCANClustering(eps, min_samples=min_samples, backend="sklearn").fit(X)
    expected = reference(X[:, :3], eps, min_samples)
    np.testing.assert_array_equal(init.labels_, renumbered(expected))
    assert init.n_clusters_ == len(np.unique(expected[expected >= 0]))
    core = np.flatnonzero((cdist(X[:, :3], X[:, :3]) <= eps).sum(axis=1) >= min_samples)
    np.testing.assert_array_equal(init.core_sample_indices_, core)
    # The core points are split as scikit-learn splits them.
    sk = DBSCAN(eps=eps, min_samples=min_samples).fit(X[:, :3]).labels_
    np.testing.assert_array_equal(renumbered(init.labels_[core]), renumbered(sk[core]))


def test_border_point_joins_nearest_core_point():
    # Two chains of points 0.25 apart; the border point (0.6, 0) is 0.6 from the left
    # chain's core point (0, 0) and 0.4 from the right one's (1, 0), with too few
    # neighbours to be a core point itself. scikit-learn gives it to the cluster it
    # finds first (the left one); the rule here gives it to the nearer core point.
    left = np.column_stack([[0.0, -0.25, -0.5, -0.75], np.zeros(4)])
    right = np.column_stack([[1.0, 1.25, 1.5, 1.75], np.zeros(4)])
    a = np.vstack([left, [[0.6, 0.0]], right])
    X = np.hstack([a, a])
    init = DBSCANClustering(eps=0.62, min_samples=4, backend="sklearn").fit(X)
    assert DBSCAN(eps=0.62, min_samples=4).fit(a).labels_.tolist() == [0] * 5 + [1] * 4
    assert init.labels_.tolist() == [0, 0, 0, 0, 1, 1, 1, 1, 1]
    assert 4 not in init.core_sample_indices_


@needs_open3d
@pytest.mark.parametrize("seed", range(5))
def test_open3d_backend_agrees_with_sklearn(seed):
    X = blobs(seed, n=400)
    sk = DBSCANClustering(0.3, min_samples=5, backend="sklearn").fit(X)
    o3d = DBSCANClustering(0.3, min_samples=5, backend="open3d").fit(X)
    assert o3d.backend_ == "open3d"
    np.testing.assert_array_equal(o3d.labels_, sk.labels_)
    np.testing.assert_array_equal(o3d.core_sample_indices_, sk.core_sample_indices_)


@needs_open3d
def test_open3d_backend_on_scene():
    scene = make_scene(n_objects=3, n_points=900, random_state=0)
    init = DBSCANClustering(eps=0.3, min_samples=5).fit(scene.X)
    assert init.backend_ == "open3d"
    assert init.n_clusters_ == 3
    np.testing.assert_array_equal(init.labels_, renumbered(scene.labels))


def test_backend_resolution_and_errors():
    X2 = blobs(0, d=2)
    assert DBSCANClustering(0.5).fit(X2).backend_ == "sklearn"
    with pytest.raises(ValueError, match="3-D points only"):
        DBSCANClustering(0.5, backend="open3d").fit(X2)
    with pytest.raises(ValueError, match="backend"):
        DBSCANClustering(backend="pcl").fit(X2)
    with pytest.raises(ValueError, match="eps"):
        DBSCANClustering(eps=0).fit(X2)
    with pytest.raises(ValueError, match="even number of columns"):
        DBSCANClustering().fit(X2[:, :3])
    if HAS_OPEN3D:
        assert DBSCANClustering(0.5).fit(blobs(0)).backend_ == "open3d"


def test_all_noise():
    X = blobs(1, n=20)
    with pytest.warns(AllOutliersWarning, match="found no cluster"):
        init = DBSCANClustering(eps=1e-3, min_samples=2, backend="sklearn").fit(X)
    assert init.n_clusters_ == 0 and np.all(init.labels_ == -1)
    assert init.transform(X).shape == (20, 0)


def test_transform_matches_labels_and_assigns_new_points():
    X = blobs(2, n=200)
    init = DBSCANClustering(eps=0.4, min_samples=5, backend="sklearn")
    membership = init.fit_transform(X).toarray()
    rows = np.flatnonzero(init.labels_ >= 0)
    expected = np.zeros_like(membership)
    expected[rows, init.labels_[rows]] = 1
    np.testing.assert_array_equal(membership, expected)
    np.testing.assert_array_equal(init.transform(X).toarray(), expected)
    core = init.core_sample_indices_[0]
    new = np.vstack([X[core] + 0.01, X[core] + 50.0])
    got = init.transform(new).toarray()
    assert got[0].argmax() == init.labels_[core] and got[0].sum() == 1
    assert got[1].sum() == 0


# --------------------------------------------------------------------------- default eps
@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_default_eps_follows_the_spacing_of_the_points(scale):
    """eps=None: the same clusters in any unit (a fixed eps=0.05 found none in mm)."""
    scene = make_scene(n_objects=3, n_points=3000, random_state=0)
    reference = DBSCANClustering(backend="sklearn").fit(scene.X)
    scaled = DBSCANClustering(backend="sklearn").fit(scene.X * scale)
    assert reference.n_clusters_ >= 3
    assert np.mean(reference.labels_ < 0) < 0.05
    np.testing.assert_array_equal(scaled.labels_, reference.labels_)
    assert scaled.eps_ == pytest.approx(reference.eps_ * scale)


def test_default_eps_is_four_times_the_median_spacing():
    grid = np.stack(np.meshgrid(np.arange(12.0), np.arange(12.0), [0.0]), -1).reshape(-1, 3)
    X = np.hstack([0.3 * grid, 0.3 * grid])
    init = DBSCANClustering(backend="sklearn").fit(X)
    assert init.eps_ == pytest.approx(1.2)
    assert init.n_clusters_ == 1
    same = np.hstack([np.zeros((10, 3)), np.ones((10, 3))])  # every point the same
    assert DBSCANClustering(backend="sklearn").fit(same).n_clusters_ == 1


def test_all_noise_is_reported():
    from mmreg.init._dbscan import AllOutliersWarning

    X = blobs(0)
    with pytest.warns(AllOutliersWarning, match=r"all 150 a-points are noise with eps=0\.001"):
        init = DBSCANClustering(eps=0.001, backend="sklearn").fit(X)
    assert init.n_clusters_ == 0 and init.eps_ == 0.001
