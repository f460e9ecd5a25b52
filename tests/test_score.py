"""score and score_samples: the log-likelihood under the fitted mixture, gate included."""

import warnings

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.distance import cdist
from scipy.spatial.transform import Rotation
from scipy.special import logsumexp
from sklearn.cluster import KMeans
from sklearn.exceptions import NotFittedError
from sklearn.model_selection import GridSearchCV, KFold

from mmreg import MultiModelRegistration
from mmreg.baselines import NaiveRegistration, SequentialRANSAC, TLinkage

TAU = 1.5


def two_objects(rng, n=120, noise=0.02):
    """Object 0 moves without noise, object 1 with noise; three more far apart, each alone.

    Returns X, the object of each row and (R, t) of every object.
    """
    centres = np.array([[0.0, 0, 0], [4, 0, 0], [0, 4, 0], [4, 4, 0], [2, 8, 0]])
    rotations = Rotation.from_rotvec(rng.normal(scale=0.3, size=(5, 3))).as_matrix()
    translations = rng.normal(scale=1.0, size=(5, 3))
    objects = rng.integers(0, 5, n)
    a = centres[objects] + rng.uniform(-0.5, 0.5, (n, 3))
    b = np.einsum("nij,nj->ni", rotations[objects], a) + translations[objects]
    b[objects > 0] += rng.normal(scale=noise, size=(np.count_nonzero(objects > 0), 3))
    return np.hstack([a, b]), objects


def reference_log_likelihood(est, X_fit, X, log_outlier, growth=0.0, tau=TAU):
    """The mixture's log-density, plainly: a loop over the clusters and a dense gate."""
    a_fit = X_fit[:, :3]
    a, b = X[:, :3], X[:, 3:]
    terms = [np.full(len(X), log_outlier)]
    for j in range(est.n_clusters_):
        members = a_fit[est.labels_ == j]
        nearest = cdist(a, members).min(axis=1)
        sigma = est.sigmas_[j] * (1.0 + growth * np.sum(a**2, axis=1))
        residual = b - a @ est.rotations_[j].T - est.translations_[j]
        log_density = (
            np.log(est.weights_[j])
            - 3 * np.log(sigma)
            - 1.5 * np.log(2 * np.pi)
            - np.sum(residual**2, axis=1) / (2 * sigma**2)
        )
        terms.append(np.where(nearest <= tau, log_density, -np.inf))
    return logsumexp(np.vstack(terms), axis=0)


def plain_log_outlier(labels, X_fit):
    """``log(pi_0 / V)``: the share of -1 labels (at least 1/n), the box of ``b - a``."""
    share = max(np.mean(labels < 0), 1.0 / len(labels))
    return np.log(share) - np.sum(np.log(np.ptp(X_fit[:, 3:] - X_fit[:, :3], axis=0)))


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(0)
    X, objects = two_objects(rng)
    # Two pieces per object; a few wrong b-points.
    init = 2 * objects + (rng.random(len(X)) < 0.4)
    wrong = rng.random(len(X)) < 0.08
    X[wrong, 3:] += rng.uniform(-3, 3, (np.count_nonzero(wrong), 3))
    X_new, _ = two_objects(np.random.default_rng(1), n=60)
    # New correspondences, some of them far from every fitted cluster (outliers only).
    X_new[:5, :3] += [30.0, 0, 0]
    return X, init, X_new


@pytest.mark.parametrize("variant", ["robust", "paper", "sweep"])
def test_score_is_the_mixture_log_likelihood(scene, variant):
    X, init, X_new = scene
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the paper variant may not settle
        est = MultiModelRegistration(init=init, variant=variant, random_state=0).fit(X)
    assert est.n_clusters_ >= 2
    growth = getattr(est, "noise_growth_", 0.0)
    log_outlier = plain_log_outlier(est.labels_, X)
    if variant != "paper":
        # The robust variants' fitted outlier component is that same density.
        assert_allclose(est.log_outlier_density_, log_outlier, rtol=1e-12)
    if variant == "sweep" and est.static_cluster_ >= 0:
        pytest.skip("the static world is admitted everywhere: see the test below")
    for data in (X, X_new):
        samples = est.score_samples(data)
        expected = reference_log_likelihood(est, X, data, log_outlier, growth)
        assert np.all(np.isfinite(samples))
        assert_allclose(samples, expected, rtol=1e-9, atol=1e-9)
        assert est.score(data) == pytest.approx(np.mean(samples), rel=1e-12)
    # Far from every cluster, only the outlier component explains a correspondence.
    assert_allclose(est.score_samples(X_new[:5]), log_outlier, rtol=1e-12)


def test_the_static_world_is_admitted_everywhere():
    # Two far-apart objects that move alike are two thirds of the scene: the sweep
    # variant's static world, which the gate admits however far from its points.
    rng = np.random.default_rng(3)
    a = np.vstack(
        [rng.uniform(0, 1, (80, 3)), rng.uniform(8, 9, (80, 3)), rng.uniform(4, 5, (80, 3))]
    )
    b = a + rng.normal(scale=0.01, size=a.shape)
    b[160:] += [0.0, 1.0, 0.0]
    X = np.hstack([a, b])
    init = np.repeat(np.arange(6), 40)
    est = MultiModelRegistration(init=init, variant="sweep", noise_model="constant")
    est.fit(X)
    assert est.static_cluster_ >= 0 and est.n_clusters_ == 2
    far = np.hstack([a[:10] - [0, 0, 4.0], b[:10] - [0, 0, 4.0]])  # 3 from any a-point
    static = est.static_cluster_
    sigma = est.sigmas_[static] * (1 + est.noise_growth_ * np.sum(far[:, :3] ** 2, axis=1))
    residual = far[:, 3:] - far[:, :3] @ est.rotations_[static].T - est.translations_[static]
    world = (
        np.log(est.weights_[static])
        - 3 * np.log(sigma)
        - 1.5 * np.log(2 * np.pi)
        - np.sum(residual**2, axis=1) / (2 * sigma**2)
    )
    expected = np.logaddexp(world, est.log_outlier_density_)
    assert_allclose(est.score_samples(far), expected, rtol=1e-9)
    # Far above the outlier density alone: the world explains them.
    assert np.all(est.score_samples(far) > est.log_outlier_density_ + 5)


def test_right_number_of_motions_scores_higher_on_held_out_data():
    rng = np.random.default_rng(5)
    X, objects = two_objects(rng, n=600)
    held_out = rng.random(len(X)) < 0.3
    train = ~held_out
    right = MultiModelRegistration(init=2 * objects[train] + (rng.random(train.sum()) < 0.5))
    right.fit(X[train])
    assert right.n_clusters_ == 5
    # One motion for the whole scene: a deliberately worse model.
    worse = MultiModelRegistration(init=np.zeros(train.sum(), dtype=int), variant="paper")
    worse.fit(X[train])
    assert worse.n_clusters_ == 1
    # Better by far more than any tie or rounding: nats per correspondence.
    assert right.score(X[held_out]) > worse.score(X[held_out]) + 3.0


def test_grid_search_without_labels_picks_by_score():
    rng = np.random.default_rng(2)
    X, _ = two_objects(rng, n=450)
    search = GridSearchCV(
        MultiModelRegistration(variant="paper", init=KMeans(n_init=1, random_state=0)),
        {"init__n_clusters": [1, 10]},
        cv=KFold(3, shuffle=True, random_state=0),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # one initial cluster of five motions may not settle
        search.fit(X)  # no y
    scores = search.cv_results_["mean_test_score"]
    assert np.all(np.isfinite(scores))
    assert search.best_index_ == int(np.argmax(scores))
    assert search.best_params_ == {"init__n_clusters": 10}
    assert scores[1] > scores[0] + 3.0


@pytest.mark.parametrize(
    "estimator",
    [
        NaiveRegistration(),
        SequentialRANSAC(residual_threshold=0.1, random_state=0),
        TLinkage(),
    ],
    ids=["naive", "sequential_ransac", "t_linkage"],
)
def test_baselines_score_their_mixture_without_a_gate(scene, estimator):
    X, init, X_new = scene
    if "init" in estimator.get_params():
        estimator.set_params(init=init)
    est = estimator.fit(X)
    assert est.n_clusters_ >= 2
    log_outlier = plain_log_outlier(est.labels_, X)
    for data in (X, X_new):
        expected = reference_log_likelihood(est, X, data, log_outlier, tau=np.inf)
        assert_allclose(est.score_samples(data), expected, rtol=1e-9, atol=1e-9)
        assert est.score(data) == pytest.approx(np.mean(expected), rel=1e-12)


def test_score_checks_input_and_fit(scene):
    X, init, _ = scene
    with pytest.raises(NotFittedError):
        MultiModelRegistration().score(X)
    est = MultiModelRegistration(init=init).fit(X)
    with pytest.raises(ValueError, match="features"):
        est.score(X[:, :4])
    # Rows with NaN hold no measurement: NaN, the others scored as without them.
    padded = np.where(np.eye(len(X), 6) == 1, np.nan, X)
    scores = est.score_samples(padded)
    assert np.isnan(scores[:6]).all()
    np.testing.assert_array_equal(scores[6:], est.score_samples(X[6:]))
    with pytest.raises(ValueError, match="infinity"):
        est.score_samples(np.where(np.eye(len(X), 6) == 1, np.inf, X))


def test_a_refit_as_the_paper_variant_drops_the_robust_attributes(scene):
    X, init, _ = scene
    est = MultiModelRegistration(init=init).fit(X)
    assert hasattr(est, "log_outlier_density_")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est.set_params(variant="paper").fit(X)
    assert not hasattr(est, "log_outlier_density_")
    assert not hasattr(est, "static_cluster_")
    log_outlier = plain_log_outlier(est.labels_, X)
    assert_allclose(est.score_samples(X), reference_log_likelihood(est, X, X, log_outlier))
