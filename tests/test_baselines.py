"""The baselines: Naive, Sequential RANSAC and T-Linkage, against references and scenes."""

import itertools
import pickle

import numpy as np
import pytest
from conftest import split_init
from numpy.testing import assert_allclose, assert_array_equal
from sklearn.base import clone
from sklearn.cluster import KMeans
from sklearn.metrics import adjusted_rand_score
from sklearn.model_selection import GridSearchCV
from sklearn.utils import check_random_state

from mmreg import MultiModelRegistration
from mmreg._array.geometry import fit_rigid, rotation_angle
from mmreg.baselines import NaiveRegistration, SequentialRANSAC, TLinkage
from mmreg.baselines._t_linkage import preference, tanimoto_linkage, unit_preferences
from mmreg.datasets import make_scene
from mmreg.em._hypotheses import (
    count_inliers,
    draw_minimal_samples,
    fit_minimal_samples,
    nearest_model,
)
from mmreg.estimators import DegenerateInputWarning


def matched_objects(labels_true, labels_pred):
    """For each estimated cluster, the true object it overlaps most."""
    return np.array(
        [
            np.bincount(labels_true[labels_pred == k] + 1).argmax() - 1
            for k in range(labels_pred.max() + 1)
        ]
    )


def brute_residuals(a, b, rotations, translations):
    """``||b_i - R_k a_i - t_k||`` by explicit broadcasting, shape (n, K)."""
    moved = np.einsum("kij,nj->nki", rotations, a) + translations[None]
    return np.linalg.norm(b[:, None, :] - moved, axis=2)


def random_motions(k, random_state):
    rng = check_random_state(random_state)
    q = rng.normal(size=(k, 3, 3))
    rotations = np.linalg.qr(q)[0]
    rotations[np.linalg.det(rotations) < 0] *= -1
    return rotations, rng.uniform(-2, 2, size=(k, 3))


# --- shared hypothesis machinery ----------------------------------------------------------


def test_fit_minimal_samples_exact_and_skips_degenerate():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(20, 3))
    a[10:13] = [[0, 0, 0], [1, 1, 1], [2, 2, 2]]  # collinear
    rotations, translations = random_motions(1, 0)
    b = a @ rotations[0].T + translations[0]
    samples = np.array([[0, 1, 2], [10, 11, 12], [3, 3, 4], [5, 6, 7]])
    rot, trans, valid = fit_minimal_samples(a, b, samples)
    assert_array_equal(valid, [True, False, False, True])
    assert_allclose(rot, np.repeat(rotations, 2, axis=0), atol=1e-12)
    assert_allclose(trans, np.repeat(translations, 2, axis=0), atol=1e-12)


def test_draw_minimal_samples_is_reproducible():
    first = draw_minimal_samples(check_random_state(3), 50, 100, 3)
    second = draw_minimal_samples(check_random_state(3), 50, 100, 3)
    assert first.shape == (100, 3)
    assert first.min() >= 0 and first.max() < 50
    assert_array_equal(first, second)


def test_count_inliers_and_nearest_model_match_brute_force():
    rng = np.random.default_rng(1)
    a = rng.uniform(-3, 3, size=(500, 3))
    rotations, translations = random_motions(7, 1)
    truth = rng.integers(0, 7, size=500)
    b = np.einsum("nij,nj->ni", rotations[truth], a) + translations[truth]
    b += rng.normal(scale=0.3, size=b.shape)
    dist = brute_residuals(a, b, rotations, translations)
    assert_array_equal(count_inliers(a, b, rotations, translations, 0.4), (dist <= 0.4).sum(0))
    expected = np.where(dist.min(1) <= 0.4, dist.argmin(1), -1)
    assert_array_equal(nearest_model(a, b, rotations, translations, 0.4), expected)
    assert_array_equal(nearest_model(a, b, rotations[:0], translations[:0], 0.4), -1)


# --- Naive ---------------------------------------------------------------------------------


def test_naive_is_em_without_iterations(noisy_scene):
    init = split_init(noisy_scene.labels, pieces=3)
    naive = NaiveRegistration(init=init).fit(noisy_scene.X)
    em = MultiModelRegistration(init=init, max_iter=0, variant="paper").fit(noisy_scene.X)
    assert_array_equal(naive.labels_, em.labels_)
    for name in ("rotations_", "translations_", "sigmas_", "weights_"):
        assert_allclose(getattr(naive, name), getattr(em, name))
    assert adjusted_rand_score(init, naive.labels_) == 1.0
    # Horn's method on each initial cluster, nothing else.
    for k in range(naive.n_clusters_):
        rotation, translation = fit_rigid(
            noisy_scene.a[naive.labels_ == k], noisy_scene.b[naive.labels_ == k]
        )
        assert_allclose(naive.rotations_[k], rotation, atol=1e-12)
        assert_allclose(naive.translations_[k], translation, atol=1e-12)


def test_naive_predict_uses_nearest_a_point(noiseless_scene):
    scene = noiseless_scene
    init = split_init(scene.labels, pieces=3)
    init[:5] = -1
    est = NaiveRegistration(init=init).fit(scene.X)
    assert_array_equal(est.predict(scene.X), est.labels_)
    query = scene.X[::7] + np.random.default_rng(0).normal(scale=0.05, size=scene.X[::7].shape)
    dist = np.linalg.norm(query[:, None, :3] - scene.a[None], axis=2)
    assert_array_equal(est.predict(query), est.labels_[dist.argmin(1)])


# --- Sequential RANSAC ---------------------------------------------------------------------


def test_sransac_exact_on_noiseless_scene(noiseless_scene):
    scene = noiseless_scene
    est = SequentialRANSAC(residual_threshold=0.01, random_state=0).fit(scene.X)
    assert est.n_clusters_ == scene.labels.max() + 1
    assert adjusted_rand_score(scene.labels, est.labels_) == 1.0
    match = matched_objects(scene.labels, est.labels_)
    assert rotation_angle(est.rotations_, scene.rotations[match]).max() < 1e-6
    assert_allclose(est.translations_, scene.translations[match], atol=1e-10)


def test_sransac_on_noisy_scene(noisy_scene):
    scene = noisy_scene
    # Uniform noise on [-0.01, 0.01]^3: residuals of the true motion stay below 0.018.
    est = SequentialRANSAC(residual_threshold=0.03, random_state=0).fit(scene.X)
    assert adjusted_rand_score(scene.labels, est.labels_) == 1.0
    match = matched_objects(scene.labels, est.labels_)
    assert rotation_angle(est.rotations_, scene.rotations[match]).max() < 0.2
    # Every object found whole: its pose is Horn's fit on the object.
    for k, obj in enumerate(match):
        rotation, translation = fit_rigid(
            scene.a[scene.labels == obj], scene.b[scene.labels == obj]
        )
        assert_allclose(est.rotations_[k], rotation, atol=1e-12)
        assert_allclose(est.translations_[k], translation, atol=1e-12)


def test_sransac_outliers_left_over():
    scene = make_scene(n_objects=3, n_points=900, outlier_fraction=0.1, random_state=4)
    est = SequentialRANSAC(residual_threshold=0.01, random_state=0).fit(scene.X)
    assert_array_equal(est.labels_ < 0, scene.labels < 0)
    assert adjusted_rand_score(scene.labels, est.labels_) == 1.0


def test_sransac_deterministic_with_random_state(noisy_scene):
    est = SequentialRANSAC(residual_threshold=0.02, max_trials=50, random_state=3)
    first = clone(est).fit(noisy_scene.X)
    second = clone(est).fit(noisy_scene.X)
    assert_array_equal(first.labels_, second.labels_)
    assert_array_equal(first.rotations_, second.rotations_)


def test_sransac_stopping_rules(noiseless_scene):
    X = noiseless_scene.X
    two = SequentialRANSAC(residual_threshold=0.01, max_models=2, random_state=0).fit(X)
    assert two.n_clusters_ == 2
    assert np.count_nonzero(two.labels_ >= 0) == 400  # two objects of 200
    with pytest.warns(DegenerateInputWarning, match="No cluster survived"):
        none = SequentialRANSAC(residual_threshold=0.01, min_inliers=201, random_state=0).fit(X)
    assert_array_equal(none.labels_, -1)


def test_sransac_skips_collinear_samples():
    t = np.linspace(0, 1, 40)[:, None]
    a = t * [1.0, 2.0, 3.0]
    X = np.hstack([a, a + 1.0])
    with pytest.warns(DegenerateInputWarning, match="No cluster survived"):
        est = SequentialRANSAC(residual_threshold=0.01, random_state=0).fit(X)
    assert est.n_clusters_ == 0
    assert_array_equal(est.predict(X), -1)


def test_sransac_predict_held_out():
    scene = make_scene(
        n_objects=3, n_points=1200, noise=0.005, outlier_fraction=0.05, random_state=6
    )
    train = np.random.default_rng(0).random(len(scene.X)) < 0.7
    est = SequentialRANSAC(residual_threshold=0.02, random_state=0).fit(scene.X[train])
    match = matched_objects(scene.labels[train], est.labels_)
    predicted = est.predict(scene.X[~train])
    mapped = np.where(predicted >= 0, match[np.maximum(predicted, 0)], -1)
    assert np.mean(mapped == scene.labels[~train]) > 0.99
    dist = brute_residuals(scene.a[~train], scene.b[~train], est.rotations_, est.translations_)
    assert_array_equal(predicted, np.where(dist.min(1) <= 0.02, dist.argmin(1), -1))


def test_sransac_grid_search(noiseless_scene):
    scene = noiseless_scene

    def ari(estimator, X, y):
        return adjusted_rand_score(y, estimator.fit_predict(X))

    everything = np.arange(len(scene.X))
    search = GridSearchCV(
        SequentialRANSAC(random_state=0),
        {"residual_threshold": [0.01, 10.0]},
        scoring=ari,
        cv=[(everything, everything)],
    )
    search.fit(scene.X, scene.labels)
    assert search.best_params_ == {"residual_threshold": 0.01}
    assert search.best_score_ == 1.0


# --- T-Linkage -----------------------------------------------------------------------------


def test_preference_function_is_eq_8():
    d = np.array([0.0, 0.1, 0.999, 1.0, 1.0001, 7.0])
    expected = [1.0, np.exp(-0.5), np.exp(-4.995), np.exp(-5.0), 0.0, 0.0]
    assert_allclose(preference(d, tau_t=0.2), expected)


def test_unit_preferences_are_min_over_members():
    rng = np.random.default_rng(2)
    a = rng.uniform(-1, 1, size=(60, 3))
    rotations, translations = random_motions(5, 2)
    b = a @ rotations[0].T + translations[0] + rng.normal(scale=0.3, size=a.shape)
    units = rng.integers(0, 9, size=60)
    psi = preference(brute_residuals(a, b, rotations, translations), 0.2)
    expected = np.array([psi[units == u].min(axis=0) for u in range(9)])
    assert_allclose(unit_preferences(a, b, units, 9, rotations, translations, 0.2), expected)


def brute_force_linkage(pref):
    """T-Linkage on preference rows: merge the closest pair until all are at distance 1."""
    clusters = [[i] for i in range(len(pref))]
    prefs = [row.astype(float) for row in pref]
    while True:
        best = None
        for i, j in itertools.combinations(range(len(prefs)), 2):
            inner = prefs[i] @ prefs[j]
            if inner > 0:
                dist = 1 - inner / (prefs[i] @ prefs[i] + prefs[j] @ prefs[j] - inner)
                if best is None or dist < best[0]:
                    best = (dist, i, j)
        if best is None:
            break
        _, i, j = best
        prefs[i] = np.minimum(prefs[i], prefs[j])
        clusters[i] += clusters.pop(j)
        prefs.pop(j)
    labels = np.empty(len(pref), dtype=int)
    for k, members in enumerate(clusters):
        labels[members] = k
    return labels


@pytest.mark.parametrize("seed", range(6))
def test_tanimoto_linkage_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    n_units, n_hyp = 40, 15
    pref = rng.uniform(0.01, 1, size=(n_units, n_hyp)) * (rng.random((n_units, n_hyp)) < 0.2)
    assert adjusted_rand_score(brute_force_linkage(pref), tanimoto_linkage(pref)) == 1.0


def test_tlinkage_improves_over_naive(noiseless_scene):
    scene = noiseless_scene
    init = split_init(scene.labels, pieces=4)
    naive = NaiveRegistration(init=init).fit(scene.X)
    est = TLinkage(init=init).fit(scene.X)
    assert adjusted_rand_score(scene.labels, naive.labels_) < 0.6
    assert adjusted_rand_score(scene.labels, est.labels_) == 1.0
    match = matched_objects(scene.labels, est.labels_)
    assert rotation_angle(est.rotations_, scene.rotations[match]).max() < 1e-6


def test_tlinkage_on_noisy_scene():
    scene = make_scene(n_objects=4, n_points=1200, noise=0.03, random_state=1)
    init = split_init(scene.labels, pieces=3)
    naive_ari = adjusted_rand_score(scene.labels, NaiveRegistration(init=init).fit_predict(scene.X))
    est = TLinkage(init=init, n_hypotheses=200, random_state=0).fit(scene.X)
    assert adjusted_rand_score(scene.labels, est.labels_) > naive_ari + 0.3
    match = matched_objects(scene.labels, est.labels_)
    assert rotation_angle(est.rotations_, scene.rotations[match]).max() < 1.0


def test_tlinkage_merges_far_objects_with_the_same_motion():
    # Preferences see motions only: unlike the EM's gate, nothing keeps them apart.
    scene = make_scene(n_objects=3, n_points=600, noise=0.005, same_motion=1, random_state=3)
    est = TLinkage(init=split_init(scene.labels, pieces=2)).fit(scene.X)
    assert est.n_clusters_ == 2
    assert len(np.unique(est.labels_[scene.labels <= 1])) == 1


def test_tlinkage_outliers_prefer_nothing():
    scene = make_scene(n_objects=3, n_points=900, outlier_fraction=0.1, random_state=4)
    # Outliers are left out of the initial clusters, so each starts as a unit of its own.
    est = TLinkage(init=split_init(scene.labels, pieces=3), tau_t=0.01).fit(scene.X)
    assert_array_equal(est.labels_ < 0, scene.labels < 0)
    assert adjusted_rand_score(scene.labels, est.labels_) == 1.0


def test_tlinkage_from_single_points_is_plain_t_linkage():
    scene = make_scene(n_objects=3, n_points=150, random_state=0)
    est = TLinkage(init=np.full(150, -1), n_hypotheses=300, tau_t=0.01, random_state=0)
    assert adjusted_rand_score(scene.labels, est.fit_predict(scene.X)) == 1.0


def test_tlinkage_small_clusters_are_outliers(noiseless_scene):
    init = split_init(noiseless_scene.labels, pieces=2)
    with pytest.warns(DegenerateInputWarning, match="No cluster survived"):
        est = TLinkage(init=init, min_cluster_size=201).fit(noiseless_scene.X)
    assert_array_equal(est.labels_, -1)


def test_tlinkage_deterministic_with_random_state(noisy_scene):
    est = TLinkage(init=KMeans(n_clusters=12, n_init=1), n_hypotheses=100, random_state=0)
    first = clone(est).fit(noisy_scene.X)
    second = clone(est).fit(noisy_scene.X)
    assert_array_equal(first.init_labels_, second.init_labels_)
    assert_array_equal(first.labels_, second.labels_)
    assert_array_equal(first.rotations_, second.rotations_)


def test_tlinkage_predict_within_preference_support(noisy_scene):
    scene = noisy_scene
    est = TLinkage(init=split_init(scene.labels), tau_t=0.01).fit(scene.X)
    assert_array_equal(est.predict(scene.X), est.labels_)
    # Moving b-points by 0.03 keeps them within 5 tau_t = 0.05 of their motion; by 0.1 not.
    moved = scene.X.copy()
    moved[::2, 3] += 0.03
    moved[1::2, 3] += 0.1
    predicted = est.predict(moved)
    dist = brute_residuals(scene.a, moved[:, 3:], est.rotations_, est.translations_)
    assert_array_equal(predicted, np.where(dist.min(1) <= 0.05, dist.argmin(1), -1))
    assert np.all(predicted[1::2] == -1)
    assert np.mean(predicted[::2] == est.labels_[::2]) > 0.95


# --- what every baseline shares --------------------------------------------------------------

GOOD = make_scene(n_objects=2, n_points=40, random_state=0)
GOOD_INIT = split_init(GOOD.labels, pieces=2)

FACTORIES = {
    "naive": lambda **kw: NaiveRegistration(**{"init": GOOD_INIT, **kw}),
    "sransac": lambda **kw: SequentialRANSAC(**{"random_state": 0, **kw}),
    "tlinkage": lambda **kw: TLinkage(**{"init": GOOD_INIT, **kw}),
}


@pytest.mark.parametrize("method", FACTORIES)
@pytest.mark.parametrize(
    ("X", "match"),
    [
        (np.where(np.eye(40, 6) == 1, np.nan, GOOD.X), "NaN"),
        (np.where(np.eye(40, 6) == 1, np.inf, GOOD.X), "infinity"),
        (GOOD.X[:, :5], "even number of columns"),
        (GOOD.X[:, 0], "2D array"),
        (np.empty((0, 6)), "0 sample"),
        (GOOD.X[:2], "minimum of 3"),
        (GOOD.X.astype(str).astype(object) + "m", "could not convert"),
    ],
    ids=["nan", "inf", "odd-columns", "1d", "empty", "two-rows", "strings"],
)
def test_bad_X(method, X, match):
    # Labels of the right length, so that only X itself can be wrong.
    est = FACTORIES[method]()
    if "init" in est.get_params():
        est.set_params(init=np.zeros(len(X), dtype=int))
    with pytest.raises(ValueError, match=match):
        est.fit(X)


@pytest.mark.parametrize(
    ("method", "params", "match"),
    [
        ("naive", {"init": "kmeans"}, "init"),
        ("naive", {"init": 3}, "init"),
        ("naive", {"sigma_floor": 0.0}, "sigma_floor"),
        ("sransac", {"residual_threshold": 0.0}, "residual_threshold"),
        ("sransac", {"residual_threshold": -1.0}, "residual_threshold"),
        ("sransac", {"max_trials": 0}, "max_trials"),
        ("sransac", {"min_inliers": 3}, "min_inliers"),
        ("sransac", {"max_models": 0}, "max_models"),
        ("sransac", {"random_state": "seed"}, "random_state"),
        ("tlinkage", {"tau_t": 0.0}, "tau_t"),
        ("tlinkage", {"n_hypotheses": -1}, "n_hypotheses"),
        ("tlinkage", {"min_cluster_size": 0}, "min_cluster_size"),
        ("tlinkage", {"init": "kmeans"}, "init"),
    ],
)
def test_bad_parameters(method, params, match):
    with pytest.raises(ValueError, match=match):
        FACTORIES[method](**params).fit(GOOD.X)


@pytest.mark.parametrize("method", ["naive", "tlinkage"])
def test_bad_init_labels(method):
    with pytest.raises(ValueError, match="length 39 but X has 40"):
        FACTORIES[method](init=GOOD_INIT[:-1]).fit(GOOD.X)
    with pytest.raises(TypeError, match="integers"):
        FACTORIES[method](init=GOOD_INIT + 0.5).fit(GOOD.X)


@pytest.mark.parametrize("method", FACTORIES)
def test_fit_predict_pickle_and_predict_checks(method):
    est = FACTORIES[method](**({"residual_threshold": 0.01} if method == "sransac" else {}))
    labels = est.fit_predict(GOOD.X)
    assert_array_equal(labels, est.labels_)
    assert est.rotations_.shape == (est.n_clusters_, 3, 3)
    assert_allclose(np.linalg.det(est.rotations_), 1.0)
    restored = pickle.loads(pickle.dumps(est))
    assert_array_equal(restored.predict(GOOD.X), est.predict(GOOD.X))
    with pytest.raises(ValueError, match="features"):
        est.predict(GOOD.X[:, :4])
    with pytest.raises(ValueError, match="NaN"):
        est.predict(np.full((3, 6), np.nan))
