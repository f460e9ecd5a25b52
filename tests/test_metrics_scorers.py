"""Scorers inside GridSearchCV / cross_validate, and the evaluate() table."""

import numpy as np
import pandas as pd
import pytest
from conftest import split_init
from sklearn.base import clone
from sklearn.cluster import KMeans
from sklearn.metrics import adjusted_rand_score
from sklearn.model_selection import GridSearchCV, cross_validate

from mmreg import MultiModelRegistration
from mmreg.datasets import make_scene
from mmreg.metrics import (
    evaluate,
    ground_truth_poses,
    iou_score,
    make_iou_scorer,
    make_misclassification_scorer,
    make_per_point_error_scorer,
    make_rotation_error_scorer,
    make_translation_error_scorer,
    misclassification_error,
    per_point_error,
    registration_scorers,
    rotation_error,
    translation_error,
)


@pytest.fixture(scope="module")
def scene():
    return make_scene(n_objects=3, n_points=450, noise=0.01, outlier_fraction=0.05, random_state=3)


@pytest.fixture(scope="module")
def fitted(scene):
    return MultiModelRegistration(init=split_init(scene.labels, pieces=3)).fit(scene.X)


def direct_scores(estimator, X, y, transforms_true=None):
    labels_pred = estimator.predict(X)
    pred = (estimator.rotations_, estimator.translations_)
    true = ground_truth_poses(X, y) if transforms_true is None else transforms_true
    return {
        "iou": iou_score(y, labels_pred),
        "neg_per_point_error": -per_point_error(X, y, labels_pred, true, pred),
        "neg_rotation_error": -rotation_error(y, labels_pred, true, pred),
        "neg_translation_error": -translation_error(y, labels_pred, true, pred),
        "neg_misclassification_error": -misclassification_error(y, labels_pred),
        "adjusted_rand": adjusted_rand_score(y, labels_pred),
    }


def test_scorers_equal_the_metrics_on_predict(scene, fitted):
    expected = direct_scores(fitted, scene.X, scene.labels)
    scorers = registration_scorers()
    assert set(scorers) == set(expected)
    for name, scorer in scorers.items():
        assert scorer(fitted, scene.X, scene.labels) == pytest.approx(expected[name]), name
    assert make_iou_scorer()(fitted, scene.X, scene.labels) == expected["iou"]
    assert make_misclassification_scorer()(fitted, scene.X, scene.labels) == pytest.approx(
        expected["neg_misclassification_error"]
    )


def test_pose_scorers_with_fixed_true_motions(scene, fitted):
    true = (scene.rotations, scene.translations)
    expected = direct_scores(fitted, scene.X, scene.labels, transforms_true=true)
    for name, make in [
        ("neg_per_point_error", make_per_point_error_scorer),
        ("neg_rotation_error", make_rotation_error_scorer),
        ("neg_translation_error", make_translation_error_scorer),
    ]:
        score = make(transforms_true=true)(fitted, scene.X, scene.labels)
        assert score == pytest.approx(expected[name])
        assert score <= 0.0
    with pytest.raises(ValueError, match="translations"):
        make_rotation_error_scorer(transforms_true=(scene.rotations, scene.translations[:1]))


def test_pose_scorers_need_y(scene, fitted):
    with pytest.raises(ValueError, match="ground-truth labels as y"):
        make_rotation_error_scorer()(fitted, scene.X, None)


def test_scorers_fall_back_to_horn_for_plain_clusterers(scene):
    kmeans = KMeans(n_clusters=3, n_init=1, random_state=0).fit(scene.X)
    labels_pred = kmeans.predict(scene.X)
    true = ground_truth_poses(scene.X, scene.labels)
    expected = translation_error(
        scene.labels, labels_pred, true, ground_truth_poses(scene.X, labels_pred)
    )
    assert make_translation_error_scorer()(kmeans, scene.X, scene.labels) == pytest.approx(
        -expected
    )


def test_grid_search_with_whole_scene_split(scene):
    everything = np.arange(len(scene.X))
    search = GridSearchCV(
        MultiModelRegistration(init=split_init(scene.labels, pieces=3), min_cluster_size=10),
        {"max_iter": [0, 10]},
        scoring=registration_scorers(),
        refit="iou",
        cv=[(everything, everything)],
    ).fit(scene.X, scene.labels)
    results = search.cv_results_
    # Naive (max_iter=0) keeps the random initial pieces; the EM recovers the objects.
    assert search.best_params_ == {"max_iter": 10}
    assert results["mean_test_iou"][1] > 0.95 > results["mean_test_iou"][0]
    assert results["mean_test_neg_rotation_error"][1] > results["mean_test_neg_rotation_error"][0]
    for name in registration_scorers():
        assert np.all(np.isfinite(results[f"mean_test_{name}"])), name
    expected = direct_scores(search.best_estimator_, scene.X, scene.labels)
    for name, value in expected.items():
        assert results[f"mean_test_{name}"][1] == pytest.approx(value), name


def test_cross_validate_one_scene_per_split():
    scenes = [make_scene(n_objects=2, n_points=200, random_state=s) for s in (0, 1)]
    X = np.vstack([s.X for s in scenes])
    y = np.concatenate([s.labels for s in scenes])
    rows = np.split(np.arange(len(X)), [200])
    estimator = MultiModelRegistration(init=KMeans(n_clusters=6, n_init=1), random_state=0)
    scores = cross_validate(
        estimator,
        X,
        y,
        cv=[(r, r) for r in rows],
        scoring={"iou": make_iou_scorer(), "rot": make_rotation_error_scorer()},
    )
    for r, scene, iou, rot in zip(
        rows, scenes, scores["test_iou"], scores["test_rot"], strict=True
    ):
        fitted = MultiModelRegistration(init=KMeans(n_clusters=6, n_init=1), random_state=0)
        fitted.fit(X[r])
        expected = direct_scores(fitted, scene.X, scene.labels)
        assert iou == pytest.approx(expected["iou"])
        assert rot == pytest.approx(expected["neg_rotation_error"])


# ---------------------------------------------------------------------- evaluate


def test_evaluate_table_matches_the_metrics():
    scenes = {
        "bunch": make_scene(n_objects=2, n_points=200, noise=0.01, random_state=0),
        "tuple": None,
    }
    other = make_scene(n_objects=3, n_points=240, random_state=1)
    scenes["tuple"] = (other.X, other.labels)
    estimators = {
        "ours": MultiModelRegistration(init=KMeans(n_clusters=8, n_init=1), random_state=0),
        "kmeans": KMeans(n_clusters=3, n_init=1, random_state=0),
    }
    table = evaluate(estimators, scenes)
    assert isinstance(table, pd.DataFrame)
    assert table[["method", "scene"]].values.tolist() == [
        ["ours", "bunch"],
        ["ours", "tuple"],
        ["kmeans", "bunch"],
        ["kmeans", "tuple"],
    ]
    assert not hasattr(estimators["ours"], "labels_"), "evaluate must fit clones"
    assert (table["runtime_s"] > 0).all()
    for row in table.itertuples():
        scene = scenes[row.scene]
        X, labels = (scene.X, scene.labels) if row.scene == "bunch" else scene
        true = (
            (scene.rotations, scene.translations)
            if row.scene == "bunch"
            else ground_truth_poses(X, labels)
        )
        est = estimators[row.method]
        fitted = clone(est).fit(X)
        pred_labels = fitted.labels_
        if row.method == "ours":
            pred = (fitted.rotations_, fitted.translations_)
            assert row.n_clusters == fitted.n_clusters_
        else:
            pred = ground_truth_poses(X, pred_labels)
            assert row.n_clusters == len(np.unique(pred_labels))
        assert row.iou == pytest.approx(iou_score(labels, pred_labels))
        assert row.per_point_error == pytest.approx(
            per_point_error(X, labels, pred_labels, true, pred)
        )
        assert row.rotation_error == pytest.approx(rotation_error(labels, pred_labels, true, pred))
        assert row.translation_error == pytest.approx(
            translation_error(labels, pred_labels, true, pred)
        )
        assert row.misclassification_error == pytest.approx(
            misclassification_error(labels, pred_labels)
        )
        assert row.ari == pytest.approx(adjusted_rand_score(labels, pred_labels))


def test_evaluate_list_of_scenes_is_named_by_position():
    scenes = [make_scene(n_objects=2, n_points=100, random_state=s) for s in (0, 1)]
    table = evaluate({"kmeans": KMeans(n_clusters=2, n_init=1, random_state=0)}, scenes)
    assert table["scene"].tolist() == [0, 1]
    long = table.melt(id_vars=["method", "scene"])
    assert len(long) == 2 * (table.shape[1] - 2)


@pytest.mark.parametrize(
    ("estimators", "scenes", "error", "match"),
    [
        ({}, [], TypeError, "non-empty dict"),
        ([KMeans()], [], TypeError, "non-empty dict"),
        ({"k": KMeans()}, "scene", TypeError, "list of scenes"),
        ({"k": KMeans()}, [np.zeros((4, 6))], TypeError, "Bunch"),
        ({"k": KMeans()}, [{"X": np.zeros((4, 6))}], ValueError, "'labels'"),
    ],
)
def test_evaluate_bad_input(estimators, scenes, error, match):
    with pytest.raises(error, match=match):
        evaluate(estimators, scenes)
