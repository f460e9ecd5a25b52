"""MultiModelRegistration: recovery, the gate, predict, bad input, degenerate input."""

import pickle
import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial.transform import Rotation
from sklearn.base import clone
from sklearn.cluster import KMeans
from sklearn.metrics import adjusted_rand_score
from sklearn.model_selection import GridSearchCV
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import FunctionTransformer

from mmreg import MultiModelRegistration
from mmreg._array.geometry import rotation_angle
from mmreg.datasets import make_scene
from mmreg.estimators import DegenerateInputWarning, ScaleWarning, multi_model_em

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from conftest import split_init  # noqa: E402
from straightforward_em import straightforward_em  # noqa: E402


def object_of_cluster(labels_true, labels_pred):
    """For each estimated cluster, the true object it overlaps most."""
    k = labels_pred.max() + 1
    table = np.zeros((k, labels_true.max() + 2), dtype=int)
    keep = labels_pred >= 0
    np.add.at(table, (labels_pred[keep], labels_true[keep] + 1), 1)
    return table.argmax(axis=1) - 1


def assert_objects_recovered(scene, est):
    """Each true object is exactly one estimated cluster, and vice versa."""
    inliers = scene.labels >= 0
    assert est.n_clusters_ == scene.labels.max() + 1
    assert adjusted_rand_score(scene.labels[inliers], est.labels_[inliers]) == 1.0
    return object_of_cluster(scene.labels, est.labels_)


def test_exact_recovery_noiseless(noiseless_scene):
    scene = noiseless_scene
    est = MultiModelRegistration(init=split_init(scene.labels, pieces=4)).fit(scene.X)
    match = assert_objects_recovered(scene, est)
    rot_err = rotation_angle(est.rotations_, scene.rotations[match])
    assert rot_err.max() < 1e-6
    assert_allclose(est.translations_, scene.translations[match], atol=1e-10)
    assert est.converged_
    assert_allclose(np.linalg.det(est.rotations_), 1.0)
    assert_allclose(est.weights_.sum(), 1.0)


def test_recovery_under_bounded_noise(noisy_scene):
    scene = noisy_scene
    # Theorem 1 needs m_min large enough that a cluster cannot overfit its own noise: with
    # m_min = 4, a 5-point remnant fits its points to sigma ~ 0.001 and keeps them.
    est = MultiModelRegistration(init=split_init(scene.labels, pieces=3), min_cluster_size=20)
    est.fit(scene.X)
    match = assert_objects_recovered(scene, est)
    # Uniform noise on [-0.01, 0.01]^3 over ~300 points per object of diameter 1.
    assert rotation_angle(est.rotations_, scene.rotations[match]).max() < 0.2
    # The estimated motion moves every point to within the noise bound of where the true
    # motion moves it.
    truth = scene.labels
    moved_est = np.einsum("nij,nj->ni", est.rotations_[est.labels_], scene.a)
    moved_est += est.translations_[est.labels_]
    moved_true = np.einsum("nij,nj->ni", scene.rotations[truth], scene.a)
    moved_true += scene.translations[truth]
    assert np.abs(moved_est - moved_true).max() < 0.01
    # sigma of uniform noise: 0.01 / sqrt(3) per axis.
    assert_allclose(est.sigmas_, 0.01 / np.sqrt(3), rtol=0.15)


def test_gate_separates_far_objects_with_same_motion():
    scene = make_scene(n_objects=3, n_points=600, noise=0.005, same_motion=1, random_state=3)
    # Object 0 starts whole, the others in pieces: object 0's cluster is the largest one
    # with that motion, so without the gate it wins object 1's correspondences. The two
    # alike hold two thirds of the scene, which the default reads as one static world
    # (test_sweep_variant_takes_a_majority_motion_for_one_static_world); without a
    # static world the gate keeps them apart, as in Algorithm 1.
    init = split_init(scene.labels, pieces=2)
    init[scene.labels == 0] = init.max() + 1
    params = {"init": init, "min_cluster_size": 20, "static_share": None}
    gated = MultiModelRegistration(tau=1.5, **params).fit(scene.X)
    vanilla = MultiModelRegistration(tau=None, **params).fit(scene.X)
    assert_objects_recovered(scene, gated)
    # Without the gate, the two objects with one motion end up in one cluster.
    assert vanilla.n_clusters_ == 2
    merged = vanilla.labels_[scene.labels == 0]
    assert np.all(merged == merged[0])
    assert np.all(vanilla.labels_[scene.labels == 1] == merged[0])


def test_sweep_variant_takes_a_majority_motion_for_one_static_world():
    # The two objects with one motion hold two thirds of the scene: variant="sweep"
    # reads that majority as the static world, one cluster however far apart;
    # static_share=None keeps them apart as the gate of eq. (7) does.
    scene = make_scene(n_objects=3, n_points=600, noise=0.005, same_motion=1, random_state=3)
    init = split_init(scene.labels, pieces=2)
    est = MultiModelRegistration(init=init, tau=1.5, min_cluster_size=20, variant="sweep")
    # The majority turns by far more than a sensor between two frames: the fit says so.
    with pytest.warns(ScaleWarning, match="static world .* turns"):
        est.fit(scene.X)
    alike = np.isin(scene.labels, [0, 1])
    assert est.n_clusters_ == 2
    assert np.all(est.labels_[alike] == est.static_cluster_)
    assert not est.moving_[est.static_cluster_]
    assert est.moving_[est.labels_[scene.labels == 2][0]]
    apart = est.set_params(static_share=None).fit(scene.X)
    assert_objects_recovered(scene, apart)
    assert apart.static_cluster_ == -1


def test_outliers_far_from_objects_are_labelled_minus_one():
    scene = make_scene(n_objects=3, n_points=900, outlier_fraction=0.1, random_state=4)
    est = MultiModelRegistration(init=split_init(scene.labels, pieces=3)).fit(scene.X)
    assert_objects_recovered(scene, est)
    assert_array_equal(est.labels_ < 0, scene.labels < 0)


def test_matches_straightforward_implementation():
    scene = make_scene(n_objects=3, n_points=450, noise=0.05, random_state=5)
    init = KMeans(n_clusters=12, n_init=1, random_state=0).fit_predict(scene.a)
    for tau, max_iter in [(1.5, 1), (1.5, 3), (0.3, 10), (None, 10)]:
        fast = multi_model_em(
            scene.a, scene.b, init, tau=tau, max_iter=max_iter, sigma_floor=1e-6
        ).labels
        plain = straightforward_em(
            scene.a, scene.b, init, tau=tau, max_iter=max_iter, sigma_floor=1e-6
        )
        assert_array_equal(fast, plain)


def test_predict_held_out_correspondences():
    scene = make_scene(
        n_objects=3, n_points=1200, noise=0.01, outlier_fraction=0.05, random_state=6
    )
    rng = np.random.default_rng(0)
    train = rng.random(len(scene.X)) < 0.7
    est = MultiModelRegistration(init=split_init(scene.labels[train], pieces=3))
    est.fit(scene.X[train])
    match = object_of_cluster(scene.labels[train], est.labels_)
    predicted = est.predict(scene.X[~train])
    truth = scene.labels[~train]
    mapped = np.where(predicted >= 0, match[np.maximum(predicted, 0)], -1)
    assert np.mean(mapped == truth) > 0.99
    assert_array_equal(mapped[truth < 0], -1)
    # predict on the training data reproduces the fitted labels.
    assert_array_equal(est.predict(scene.X[train]), est.labels_)


def test_fit_predict_equals_labels(noiseless_scene):
    est = MultiModelRegistration(init=split_init(noiseless_scene.labels))
    assert_array_equal(est.fit_predict(noiseless_scene.X), est.labels_)


def test_max_iter_zero_returns_initial_clusters(noiseless_scene):
    init = split_init(noiseless_scene.labels, pieces=3)
    est = MultiModelRegistration(init=init, max_iter=0).fit(noiseless_scene.X)
    assert est.n_iter_ == 0
    assert est.n_clusters_ == init.max() + 1
    assert adjusted_rand_score(init, est.labels_) == 1.0


def test_two_dimensional_correspondences():
    rng = np.random.default_rng(0)
    a = np.vstack([rng.uniform(0, 1, (60, 2)), rng.uniform(4, 5, (40, 2))])
    angles = [0.3, -1.0]
    truth = np.repeat([0, 1], [60, 40])
    rot = np.array([[[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]] for t in angles])
    b = np.einsum("nij,nj->ni", rot[truth], a) + np.array([[1.0, 2.0], [-3.0, 0.5]])[truth]
    est = MultiModelRegistration(init=split_init(truth, pieces=3)).fit(np.hstack([a, b]))
    match = object_of_cluster(truth, est.labels_)
    assert_allclose(est.rotations_, rot[match], atol=1e-10)


def test_deterministic_with_random_state():
    scene = make_scene(n_objects=3, n_points=600, noise=0.02, random_state=7)
    est = MultiModelRegistration(init=KMeans(n_clusters=15, n_init=1), random_state=0)
    first = clone(est).fit(scene.X)
    second = clone(est).fit(scene.X)
    assert_array_equal(first.labels_, second.labels_)
    assert_array_equal(first.rotations_, second.rotations_)
    # The estimator's seed reached the clusterer, which was cloned, not fitted in place.
    assert not hasattr(est.init, "labels_")


def test_pickle_round_trip(noiseless_scene):
    est = MultiModelRegistration(init=split_init(noiseless_scene.labels)).fit(noiseless_scene.X)
    restored = pickle.loads(pickle.dumps(est))
    assert_array_equal(restored.predict(noiseless_scene.X), est.labels_)


def test_pipeline_and_grid_search(noiseless_scene):
    scene = noiseless_scene
    pipe = make_pipeline(
        FunctionTransformer(), MultiModelRegistration(init=split_init(scene.labels))
    )
    assert_array_equal(pipe.fit(scene.X).predict(scene.X), pipe[-1].labels_)

    def ari(estimator, X, y):
        return adjusted_rand_score(y, estimator.predict(X))

    everything = np.arange(len(scene.X))
    # Each object has 200 correspondences: min_cluster_size=300 drops all of them, and
    # without the gate two motions never separate in Algorithm 1.
    search = GridSearchCV(
        MultiModelRegistration(init=split_init(scene.labels)),
        {"variant": ["paper", "sweep"], "min_cluster_size": [4, 300]},
        scoring=ari,
        cv=[(everything, everything)],
    )
    with pytest.warns(DegenerateInputWarning, match="No cluster survived"):
        search.fit(scene.X, scene.labels)
    assert search.best_params_["min_cluster_size"] == 4
    assert search.best_score_ == 1.0
    results = search.cv_results_
    dropped = results["param_min_cluster_size"] == 300
    assert np.all(results["mean_test_score"][dropped] < 0.5)


# --- bad input ---------------------------------------------------------------------------

GOOD = make_scene(n_objects=2, n_points=40, random_state=0)
GOOD_INIT = split_init(GOOD.labels, pieces=2)


@pytest.mark.parametrize(
    ("X", "error", "match"),
    [
        (np.where(np.eye(40, 6) == 1, np.inf, GOOD.X), ValueError, "infinity"),
        (GOOD.X[:, :5], ValueError, "even number of columns"),
        (GOOD.X[:, 0], ValueError, "2D array"),
        (np.empty((0, 6)), ValueError, "0 sample"),
        (GOOD.X[:2], ValueError, "minimum of 3"),
        (GOOD.X.astype(str).astype(object) + "m", ValueError, "could not convert"),
    ],
    ids=["inf", "odd-columns", "1d", "empty", "two-rows", "strings"],
)
def test_bad_X(X, error, match):
    with pytest.raises(error, match=match):
        MultiModelRegistration(init=np.zeros(len(X), dtype=int)).fit(X)


@pytest.mark.parametrize(
    ("params", "match"),
    [
        ({"tau": 0}, "tau"),
        ({"tau": -1.0}, "tau"),
        ({"min_cluster_size": 0}, "min_cluster_size"),
        ({"max_iter": -1}, "max_iter"),
        ({"sigma_floor": 0.0}, "sigma_floor"),
        ({"init": "kmeans"}, "init"),
        ({"init": 3}, "init"),
    ],
)
def test_bad_parameters(params, match):
    with pytest.raises(ValueError, match=match):
        MultiModelRegistration(**{"init": GOOD_INIT, **params}).fit(GOOD.X)


def test_bad_init_labels():
    with pytest.raises(ValueError, match="length 39 but X has 40"):
        MultiModelRegistration(init=GOOD_INIT[:-1]).fit(GOOD.X)
    with pytest.raises(TypeError, match="integers"):
        MultiModelRegistration(init=GOOD_INIT + 0.5).fit(GOOD.X)
    with pytest.raises(ValueError, match="NaN"):
        MultiModelRegistration(init=np.full(40, np.nan)).fit(GOOD.X)
    with pytest.raises(TypeError, match="instance"):
        MultiModelRegistration(init=KMeans).fit(GOOD.X)


def test_predict_checks_input(noiseless_scene):
    est = MultiModelRegistration(init=split_init(noiseless_scene.labels)).fit(noiseless_scene.X)
    with pytest.raises(ValueError, match="features"):
        est.predict(noiseless_scene.X[:, :4])
    # Rows with NaN hold no measurement: no cluster takes them (see test_input_rows.py).
    assert_array_equal(est.predict(np.full((3, 6), np.nan)), -1)


# --- degenerate but valid input -------------------------------------------------------------


def test_collinear_points_give_a_rotation_and_a_warning():
    t = np.linspace(0, 1, 30)[:, None]
    a = t * [1.0, 2.0, 3.0]
    b = a @ Rotation.from_rotvec([0.1, 0.2, 0.3]).as_matrix().T + 1.0
    # One motion for every row is a static world, turning far beyond a sensor between frames.
    with pytest.warns(DegenerateInputWarning, match="collinear"), pytest.warns(ScaleWarning):
        est = MultiModelRegistration(init=np.zeros(30, dtype=int)).fit(np.hstack([a, b]))
    assert np.all(np.isfinite(est.rotations_))
    assert_allclose(np.linalg.det(est.rotations_), 1.0)
    # Any optimal rotation maps the line onto its image.
    assert_allclose(a @ est.rotations_[0].T + est.translations_[0], b, atol=1e-9)


def test_identical_points():
    X = np.tile([[1.0, 2, 3, 4, 5, 6]], (10, 1))
    with pytest.warns(DegenerateInputWarning):
        est = MultiModelRegistration(init=np.zeros(10, dtype=int)).fit(X)
    assert np.all(np.isfinite(est.rotations_))
    assert_allclose(est.rotations_[0] @ X[0, :3] + est.translations_[0], X[0, 3:])


def test_every_cluster_removed():
    with pytest.warns(DegenerateInputWarning, match="No cluster survived"):
        est = MultiModelRegistration(init=GOOD_INIT, min_cluster_size=1000).fit(GOOD.X)
    assert_array_equal(est.labels_, -1)
    assert est.n_clusters_ == 0
    assert est.rotations_.shape == (0, 3, 3)
    assert_array_equal(est.predict(GOOD.X), -1)


def test_noiseless_exact_fit_has_no_underflow():
    # sigma at the floor and residuals of other objects in the thousands of sigmas: the
    # log-space E-step must still pick the right clusters without NaN or warnings.
    scene = make_scene(n_objects=2, n_points=200, random_state=8)
    with np.errstate(all="raise"):
        est = MultiModelRegistration(init=split_init(scene.labels), tau=None).fit(scene.X)
    assert_objects_recovered(scene, est)
