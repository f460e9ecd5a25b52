"""Initialisers plugged into MultiModelRegistration: every kind of init, parameter search."""

import warnings

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.cluster import HDBSCAN, AgglomerativeClustering, KMeans
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import adjusted_rand_score
from sklearn.model_selection import GridSearchCV, KFold
from sklearn.pipeline import Pipeline

from mmreg import MultiModelRegistration
from mmreg.datasets import make_scene
from mmreg.init import (
    DBSCANClustering,
    EuclideanClustering,
    PrecomputedLabels,
    PrecomputedMasks,
    initial_labels,
)


@pytest.fixture(scope="module")
def scene():
    return make_scene(n_objects=4, n_points=1200, noise=0.01, random_state=0)


def grid_masks(labels, pieces=3, width=40):
    """Each correspondence at its own pixel; a mask per third of each object, then one
    per whole object (SAM-like nesting: parts inside wholes)."""
    n = len(labels)
    pixels = np.column_stack([np.arange(n) % width, np.arange(n) // width])
    image = np.full((-(-n // width), width), -1)
    rank = np.zeros(n, dtype=int)
    for obj in np.unique(labels):
        members = np.flatnonzero(labels == obj)
        rank[members] = np.arange(len(members)) * pieces // len(members)
    image[pixels[:, 1], pixels[:, 0]] = labels * pieces + rank
    parts = [image == j for j in range(image.max() + 1)]
    wholes = [(image >= 0) & (image // pieces == obj) for obj in np.unique(labels)]
    return parts + wholes, pixels


def make_inits(scene):
    masks, pixels = grid_masks(scene.labels)
    return {
        "euclidean": EuclideanClustering(n_clusters=20),
        "dbscan": DBSCANClustering(eps=0.15, min_samples=4),
        "labels": PrecomputedLabels(scene.labels * 2 + (np.arange(1200) % 5 == 0)),
        # The wholes win: one initial cluster per object.
        "masks": PrecomputedMasks(masks, pixels, overlap="largest"),
        "kmeans": KMeans(n_clusters=4, n_init=3),
        "agglomerative": AgglomerativeClustering(n_clusters=4, linkage="single"),
        "hdbscan": HDBSCAN(min_cluster_size=10, copy=True),
        "array": scene.labels.copy(),
    }


@pytest.mark.parametrize(
    "name",
    [
        "euclidean",
        "dbscan",
        "labels",
        "masks",
        "kmeans",
        "agglomerative",
        "hdbscan",
        "array",
    ],
)
def test_every_init_recovers_the_objects(scene, name):
    init = make_inits(scene)[name]
    est = MultiModelRegistration(init=init, random_state=0).fit(scene.X)
    assert adjusted_rand_score(scene.labels, est.labels_) == 1.0
    assert len(est.init_labels_) == len(scene.X)
    if hasattr(init, "fit"):
        # init is cloned, never fitted in place.
        assert not hasattr(init, "labels_")


def test_masks_as_init_use_the_mask_labels(scene):
    masks, pixels = grid_masks(scene.labels)
    init = PrecomputedMasks(masks, pixels)
    est = MultiModelRegistration(init=init, max_iter=0).fit(scene.X)
    np.testing.assert_array_equal(est.init_labels_, clone(init).fit_predict(scene.X))
    # The parts win: three per object, numbered object by object.
    assert est.init_labels_.max() + 1 == 12
    np.testing.assert_array_equal(est.init_labels_ // 3, scene.labels)


def test_sklearn_clusterers_see_only_the_a_points(scene):
    labels = initial_labels(KMeans(n_clusters=4, n_init=3, random_state=0), scene.X)
    expected = KMeans(n_clusters=4, n_init=3, random_state=0).fit_predict(scene.a)
    np.testing.assert_array_equal(labels, expected)
    # The registration's random_state reaches a clusterer whose own is None.
    first = initial_labels(KMeans(n_clusters=7, n_init=1), scene.X, random_state=3)
    again = initial_labels(KMeans(n_clusters=7, n_init=1), scene.X, random_state=3)
    np.testing.assert_array_equal(first, again)


def test_dbscan_shortcut_is_the_default_dbscan(scene):
    est = MultiModelRegistration(init="dbscan", max_iter=0).fit(scene.X)
    np.testing.assert_array_equal(est.init_labels_, DBSCANClustering().fit_predict(scene.X))


def test_default_init_is_euclidean_with_100_clusters():
    # The paper's setting: 7 objects, 22,395 correspondences, about 100 initial clusters.
    scene = make_scene(noise=0.03, random_state=0)
    est = MultiModelRegistration().fit(scene.X)
    assert est.init == "euclidean"
    expected = EuclideanClustering(n_clusters=100).fit(scene.X)
    assert expected.n_clusters_ == 100
    np.testing.assert_array_equal(est.init_labels_, expected.labels_)
    assert adjusted_rand_score(scene.labels, est.labels_) == 1.0


def ari_scorer(estimator, X, y):
    return adjusted_rand_score(y, estimator.predict(X))


# One initial cluster for four objects is one motion for the whole scene: a "static world"
# that turns by far more than a sensor does, which the fit reports as a ScaleWarning.
@pytest.mark.filterwarnings("ignore::mmreg.estimators.ScaleWarning")
def test_grid_search_over_init_parameters(scene):
    est = MultiModelRegistration(init=EuclideanClustering())
    assert "init__n_clusters" in est.get_params()
    cv = KFold(3, shuffle=True, random_state=0)
    grid = {"init__n_clusters": [1, 20], "init__min_cluster_size": [4]}
    search = GridSearchCV(est, grid, scoring=ari_scorer, cv=cv).fit(scene.X, scene.labels)
    # One initial cluster for four objects cannot be undone; twenty can.
    assert search.best_params_ == {"init__min_cluster_size": 4, "init__n_clusters": 20}
    assert search.best_estimator_.init.n_clusters == 20
    # The scores are those of fitting each candidate on each training fold by hand.
    for i, n_clusters in enumerate([1, 20]):
        scores = []
        for train, test in cv.split(scene.X):
            fitted = MultiModelRegistration(init=EuclideanClustering(n_clusters=n_clusters))
            fitted.fit(scene.X[train])
            scores.append(ari_scorer(fitted, scene.X[test], scene.labels[test]))
        assert search.cv_results_["mean_test_score"][i] == pytest.approx(np.mean(scores))
    assert search.cv_results_["mean_test_score"][0] < 0.5
    assert search.cv_results_["mean_test_score"][1] > 0.95


def test_grid_search_over_dbscan_parameters(scene):
    est = MultiModelRegistration(init=DBSCANClustering(min_samples=4, backend="sklearn"))
    search = GridSearchCV(
        est,
        {"init__eps": [0.01, 0.15]},
        scoring=ari_scorer,
        cv=KFold(2, shuffle=True, random_state=0),
    )
    with warnings.catch_warnings():
        # eps=0.01 leaves every point noise: no cluster survives.
        warnings.simplefilter("ignore")
        search.fit(scene.X, scene.labels)
    assert search.best_params_ == {"init__eps": 0.15}


def test_initialiser_transform_in_a_pipeline(scene):
    # The one-hot membership is a feature matrix like any other.
    pipe = Pipeline(
        [
            ("init", EuclideanClustering(n_clusters=8, min_cluster_size=1)),
            ("classify", LogisticRegression()),
        ]
    )
    pipe.fit(scene.X, scene.labels)
    assert pipe.score(scene.X, scene.labels) == 1.0
    assert pipe[:-1].transform(scene.X).shape == (1200, pipe[0].n_clusters_)


def test_default_init_on_a_small_scene_warns_nothing():
    # 150 rows cannot hold the shortcut's 100 clusters of 4 points: the scene is clustered
    # as finely as it allows, with no warning the user did not ask for.
    scene = make_scene(n_objects=3, n_points=150, random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        est = MultiModelRegistration(random_state=0).fit(scene.X)
    assert adjusted_rand_score(scene.labels, est.labels_) == 1.0
    with pytest.warns(UserWarning, match="No radius tried gives n_clusters=100"):
        EuclideanClustering(n_clusters=100).fit(scene.X)
