"""The fast EM against plain references: same labels, same models, on small scenes.

The EM visits the correspondences in spatial blocks, scores only the clusters that the
gate and a score bound leave in play, expands residuals into one matrix product and
recomputes near-ties exactly, and skips the points whose surroundings did not change.
None of that may change a single label: these tests compare it with the plain loop of
``benchmarks/straightforward_em.py`` and with dense, direct computations, with blocks
made tiny so that every path (many blocks and sub-blocks, merged runs, pruned clusters,
skipped sub-blocks, gate rounds) runs on scenes of a few hundred points.
"""

import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from sklearn.cluster import KMeans

import mmreg.em._likelihood as likelihood
import mmreg.em._paper as em
from mmreg._array.geometry import fit_rigid, fit_rigid_grouped, fit_rigid_rows
from mmreg.datasets import make_scene
from mmreg.em._gate import ClusterGate
from mmreg.em._paper import default_sigma_floor, fit_cluster_models
from mmreg.estimators import MultiModelRegistration, multi_model_em

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from conftest import split_init  # noqa: E402
from straightforward_em import straightforward_em  # noqa: E402


@pytest.fixture(params=["tiny blocks", "tiny blocks, two tiers", "default blocks"])
def block_sizes(request, monkeypatch):
    """Blocks of 64 rows in sub-blocks of 16 (pruning two tiers of rows whenever there
    are rows below the mean own score), and the defaults."""
    if request.param.startswith("tiny blocks"):
        monkeypatch.setattr(likelihood, "_BLOCK_ROWS", 64)
        monkeypatch.setattr(likelihood, "_SUB_ROWS", 16)
        # Score runs of sub-blocks together more eagerly, to exercise the merging.
        monkeypatch.setattr(likelihood, "_PASS_CELLS", 256)
    if request.param.endswith("two tiers"):
        monkeypatch.setattr(likelihood, "_WEAK_SCORE", 0.0)
        monkeypatch.setattr(likelihood, "_PASS_CELLS", -(2**20))
    return request.param


def both(a, b, init, **params):
    """Labels of the fast EM and of the plain loop, with the same sigma floor."""
    params.setdefault("sigma_floor", default_sigma_floor(b))
    fast = multi_model_em(a, b, init, **params)
    plain = straightforward_em(a, b, init, **params)
    return fast, plain


SCENES = {
    "noisy": dict(n_objects=3, n_points=600, noise=0.03),
    "outliers": dict(n_objects=3, n_points=600, noise=0.02, outlier_fraction=0.1),
    "noiseless": dict(n_objects=4, n_points=480),
    "same motion": dict(n_objects=3, n_points=450, noise=0.01, same_motion=1),
}


@pytest.mark.parametrize("scene_name", list(SCENES))
@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("tau", [1.5, 0.3, None])
def test_em_matches_plain_loop(block_sizes, scene_name, seed, tau):
    scene = make_scene(**SCENES[scene_name], random_state=seed)
    init = KMeans(n_clusters=24, n_init=1, random_state=seed).fit_predict(scene.a)
    fast, plain = both(scene.a, scene.b, init, tau=tau, max_iter=10)
    assert_array_equal(fast.labels, plain)


@pytest.mark.parametrize("seed", [0])
@pytest.mark.parametrize("min_cluster_size", [1, 15, 60])
@pytest.mark.parametrize("max_iter", [1, 10])
def test_em_matches_plain_loop_with_removals(block_sizes, seed, min_cluster_size, max_iter):
    # Uneven KMeans pieces, some below m_min: their points lose their cluster and must
    # be won by another one (or become outliers); some initial labels are -1.
    scene = make_scene(
        n_objects=3, n_points=540, noise=0.02, outlier_fraction=0.05, random_state=seed
    )
    init = KMeans(n_clusters=40, n_init=1, random_state=seed).fit_predict(scene.b)
    init[np.random.default_rng(seed).random(len(init)) < 0.05] = -1
    fast, plain = both(
        scene.a, scene.b, init, tau=0.8, min_cluster_size=min_cluster_size, max_iter=max_iter
    )
    assert_array_equal(fast.labels, plain)


@pytest.mark.parametrize("tau", [1.5, None])
def test_exact_ties_keep_the_own_cluster_then_the_lowest_index(block_sizes, tau):
    # Noiseless objects cut into equal pieces: pieces of an object fit the same motion
    # exactly, with the same weight and the floor as sigma, so scores tie exactly and
    # only the tie rules decide. Rounding in the fast scores must not.
    scene = make_scene(n_objects=3, n_points=600, random_state=3)
    init = split_init(scene.labels, pieces=4, ratio=1.0)
    fast, plain = both(scene.a, scene.b, init, tau=tau, max_iter=10)
    assert_array_equal(fast.labels, plain)


def test_two_dimensional_points_match_plain_loop(block_sizes):
    rng = np.random.default_rng(0)
    centres = np.array([[0.0, 0.0], [3.0, 0.5], [1.0, 4.0]])
    truth = rng.integers(0, 3, 450)
    a = centres[truth] + rng.uniform(-0.6, 0.6, (450, 2))
    angles = np.array([0.2, -0.7, 1.3])
    rot = np.stack([[[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]] for t in angles])
    b = np.einsum("nij,nj->ni", rot[truth], a) + rng.normal(size=(3, 2))[truth]
    b += rng.normal(scale=0.02, size=b.shape)
    init = KMeans(n_clusters=15, n_init=1, random_state=0).fit_predict(a)
    for tau in (1.0, None):
        fast, plain = both(a, b, init, tau=tau)
        assert_array_equal(fast.labels, plain)


def test_far_from_origin_matches_plain_loop(block_sizes):
    # Coordinates in the thousands: centring keeps the expansion of the residuals exact
    # enough, and the bound on its rounding sends any close call to the exact scores.
    scene = make_scene(n_objects=3, n_points=450, noise=0.02, random_state=4)
    shift = np.array([4000.0, -2500.0, 1000.0])
    init = KMeans(n_clusters=20, n_init=1, random_state=0).fit_predict(scene.a)
    fast, plain = both(scene.a + shift, scene.b + shift, init, tau=1.5)
    assert_array_equal(fast.labels, plain)


@pytest.mark.parametrize("max_iter", [2, 10])
def test_final_models_are_those_of_the_final_clusters(block_sizes, max_iter):
    # After convergence the last M-step's models are reused, renumbered; they must be
    # exactly those a refit on the final clusters gives.
    scene = make_scene(n_objects=3, n_points=600, noise=0.03, random_state=5)
    init = KMeans(n_clusters=20, n_init=1, random_state=0).fit_predict(scene.a)
    result = multi_model_em(scene.a, scene.b, init, max_iter=max_iter)
    refit = fit_cluster_models(
        scene.a,
        scene.b,
        result.labels,
        result.labels.max() + 1,
        default_sigma_floor(scene.b),
    )
    for got, expected in zip(
        (result.rotations, result.translations, result.sigmas, result.weights),
        refit[:4],
        strict=True,
    ):
        assert_array_equal(got, expected)
    sizes = np.bincount(result.labels[result.labels >= 0])
    assert np.all(np.diff(sizes) <= 0)


def test_refitting_changed_clusters_only_equals_a_full_fit(monkeypatch):
    # After the first M-step, only the clusters whose members changed are refitted; the
    # others keep their models, which must be those a full fit gives, bit for bit.
    refit = em._refit
    checked = []

    def compare(fitted, a_rows, b_rows, labels, changed, sigma_floor):
        out = refit(fitted, a_rows, b_rows, labels, changed, sigma_floor)
        full = em._fit_clusters(a_rows, b_rows, labels, len(changed), sigma_floor)
        for name in ("rotations", "translations", "sigmas", "weights", "counts", "centroids"):
            assert_array_equal(getattr(out, name), getattr(full, name))
        clustered = labels >= 0
        assert_array_equal(out.squared[clustered], full.squared[clustered])
        assert_array_equal(out.spread[clustered], full.spread[clustered])
        checked.append(changed.mean())
        return out

    monkeypatch.setattr(em, "_refit", compare)
    for seed in range(3):
        scene = make_scene(
            n_objects=4, n_points=1200, noise=0.02, outlier_fraction=0.05, random_state=seed
        )
        init = KMeans(n_clusters=30, n_init=1, random_state=seed).fit_predict(scene.a)
        for tau, min_cluster_size in [(1.5, 4), (0.5, 30), (None, 4)]:
            em.multi_model_em(
                scene.a + 100.0 * seed, scene.b, init, tau=tau, min_cluster_size=min_cluster_size
            )
    # Some refits left clusters alone.
    assert checked and min(checked) < 1


# --- the classification step against a dense reference -----------------------------------


def dense_classify(a, b, rotations, translations, sigmas, weights, points, labels, tau, own):
    """Arg-max of the direct scores over the gated clusters, ties to own then lowest."""
    d = a.shape[1]
    residual = b[:, None, :] - np.einsum("kij,nj->nki", rotations, a) - translations
    scores = np.log(weights) - d * np.log(sigmas) - np.sum(residual**2, axis=-1) / (2 * sigmas**2)
    if tau is not None:
        for j in range(len(rotations)):
            members = points[labels == j]
            dist = cKDTree(members).query(a)[0] if len(members) else np.full(len(a), np.inf)
            scores[dist > tau, j] = -np.inf
    out = np.full(len(a), -1)
    for i in range(len(a)):
        if not np.isfinite(scores[i]).any():
            continue
        best = int(np.argmax(scores[i]))
        if own is not None and own[i] >= 0 and scores[i, own[i]] >= scores[i, best]:
            best = own[i]
        out[i] = best
    return out


def random_models(rng, n_clusters, duplicate=False):
    rotations = Rotation.random(n_clusters, random_state=rng.integers(1 << 30)).as_matrix()
    translations = rng.normal(size=(n_clusters, 3))
    sigmas = rng.uniform(0.05, 0.5, n_clusters)
    weights = rng.dirichlet(np.ones(n_clusters))
    if duplicate:
        # Clusters 1 and 3 copy cluster 0: exact ties in every score.
        for j in (1, 3):
            rotations[j], translations[j] = rotations[0], translations[0]
            sigmas[j], weights[j] = sigmas[0], weights[0]
    return rotations, translations, sigmas, weights


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("tau", [0.4, 2.0, None])
@pytest.mark.parametrize("with_own", [True, False])
def test_classify_matches_dense_reference(seed, tau, with_own):
    rng = np.random.default_rng(seed)
    n, k = 500, 12
    a = rng.uniform(-3, 3, (n, 3))
    labels = KMeans(n_clusters=k, n_init=1, random_state=seed).fit_predict(a)
    labels[rng.random(n) < 0.1] = -1
    models = random_models(rng, k, duplicate=seed % 2 == 1)
    # b from each point's cluster motion, plus noise: the own cluster is usually best.
    truth = np.where(labels >= 0, labels, rng.integers(0, k, n))
    b = np.einsum("nij,nj->ni", models[0][truth], a) + models[1][truth]
    b += rng.normal(scale=0.3, size=b.shape)
    own = labels if with_own else None
    expected = dense_classify(a, b, *models, a, labels, tau, own)
    for block_rows, sub_rows in [(64, 16), (128, 128), (None, None)]:
        blocks = likelihood.CorrespondenceBlocks(a, b, block_rows, sub_rows)
        gate = ClusterGate(a, labels, k, tau)
        got = likelihood.classify(a, b, *models, gate, own, blocks=blocks)
        assert_array_equal(got, expected)


def test_predict_matches_dense_reference():
    scene = make_scene(n_objects=3, n_points=900, noise=0.02, outlier_fraction=0.05, random_state=6)
    train = np.random.default_rng(0).random(len(scene.X)) < 0.6
    est = MultiModelRegistration(init=split_init(scene.labels[train], pieces=3))
    est.fit(scene.X[train])
    a, b = scene.a[~train], scene.b[~train]
    expected = dense_classify(
        a,
        b,
        est.rotations_,
        est.translations_,
        est.sigmas_,
        est.weights_,
        scene.a[train],
        est.labels_,
        est.tau,
        None,
    )
    assert_array_equal(est.predict(scene.X[~train]), expected)


# --- the M-step's building blocks -----------------------------------------------------------


def test_fit_rigid_rows_matches_one_group_at_a_time():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(300, 3)) + 50.0
    labels = rng.integers(-1, 6, 300)
    b = a @ Rotation.random(random_state=1).as_matrix().T + rng.normal(scale=0.01, size=a.shape)
    rotations, translations, counts = fit_rigid_grouped(a, b, labels, 7)
    for j in range(7):
        members = labels == j
        assert counts[j] == members.sum()
        if members.sum() >= 3:
            rotation, translation = fit_rigid(a[members], b[members])
            np.testing.assert_allclose(rotations[j], rotation, atol=1e-12)
            np.testing.assert_allclose(translations[j], translation, atol=1e-10)
    assert_array_equal(rotations[6], np.eye(3))
    keep = labels >= 0
    fit = fit_rigid_rows(a[keep].T.copy(), b[keep].T.copy(), labels[keep], 7)
    expected = b[keep] - np.einsum("nij,nj->ni", rotations[labels[keep]], a[keep])
    expected -= translations[labels[keep]]
    np.testing.assert_allclose(fit.residuals.T, expected, atol=1e-12)
