"""Counter-examples: what breaks when a hypothesis of Theorem 1 is dropped.

Each ``test_counterexample_*`` builds a small scene by hand, shows with the checkers which
condition of Definition 1 or 2 it violates (or how weakly it meets it), and asserts that
Algorithm 1 (``variant="paper"``) then does *not* return every object as one cluster.
Where it helps, a contrast case next to it keeps everything equal but the broken
condition and recovers.

The scenes are flat 10 x 10 grids of spacing 0.1 (100 correspondences) with
``tau = 0.15``, so the pieces below are tau-connected through the grid.
"""

import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mmreg import MultiModelRegistration
from mmreg.theory import is_good_clustering, satisfies_ground_truth

TAU = 0.15
ROTATION = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
TRANSLATION = np.array([1.0, 2.0, 0.5])


def grid(shift=(0.0, 0.0, 0.0), n=10, step=0.1):
    x, y = np.meshgrid(np.arange(n) * step, np.arange(n) * step, indexing="ij")
    return np.column_stack([x.ravel(), y.ravel(), np.zeros(n * n)]) + shift


def move(a, sigma=0.0, seed=0):
    """``b = R a + t`` plus noise drawn uniformly from ``[-sigma, sigma]^3``."""
    noise = np.random.RandomState(seed).uniform(-sigma, sigma, a.shape)
    return a @ ROTATION.T + TRANSLATION + noise


def fit(X, init, min_cluster_size, tau=TAU):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return MultiModelRegistration(
            init=init, tau=tau, min_cluster_size=min_cluster_size, max_iter=200, variant="paper"
        ).fit(X)


def n_clusters_on(labels, mask):
    return len(np.unique(labels[mask]))


def test_counterexample_tie_alpha_one_keeps_both_halves():
    # Noiseless, so the weights pi_j alone decide; two equal halves have equal weights.
    a = grid()
    X = np.hstack([a, move(a)])
    truth = np.zeros(100, dtype=int)
    halves = (a[:, 0] > 0.45).astype(int)  # 50 / 50
    report = is_good_clustering(halves, truth, X, TAU, alpha=1, m0=50)
    assert [c.name for c in report.failures] == ["identifying"]
    assert report.max_alpha == 1.0
    estimator = fit(X, halves, min_cluster_size=10)
    assert estimator.n_clusters_ == 2  # the object stays cut in two
    np.testing.assert_array_equal(estimator.labels_[halves == 0], estimator.labels_[0])

    # Contrast: 60 / 40 (alpha = 1.5) merges, since the larger weight wins every tie.
    uneven = (a[:, 0] > 0.55).astype(int)
    assert is_good_clustering(uneven, truth, X, TAU, alpha=1.4, m0=40)
    assert fit(X, uneven, min_cluster_size=10).n_clusters_ == 1


def test_counterexample_small_alpha_with_noise_sharpens_the_smaller_cluster():
    # With noise, each cluster's sigma_j is an estimate; when the smaller cluster's happens
    # to be tighter, (sigma_1 / sigma_2)^3 can beat pi_1 / pi_2 = 1.5: the smaller cluster
    # keeps its best-fitting points, its sigma shrinks further, and it never dissolves.
    # The proof needs (1 + eps) / (1 - eps) < alpha; over 100 noise seeds a 60 / 40 split
    # failed 10 times, 70 / 30 once and 80 / 20 never.
    a = grid()
    X = np.hstack([a, move(a, sigma=0.05, seed=10)])
    truth = np.zeros(100, dtype=int)
    assert satisfies_ground_truth(X, truth, ([ROTATION], [TRANSLATION]), TAU, sigma=0.05)
    split = (a[:, 0] > 0.55).astype(int)  # 60 / 40
    assert is_good_clustering(split, truth, X, TAU, alpha=1.4, m0=40)
    estimator = fit(X, split, min_cluster_size=10)
    assert estimator.n_clusters_ == 2
    assert estimator.sigmas_[1] < 0.9 * estimator.sigmas_[0]  # the sharpened survivor

    # Contrast: the same noise, an 80 / 20 split (alpha = 4) is recovered.
    lopsided = (a[:, 0] > 0.75).astype(int)
    assert fit(X, lopsided, min_cluster_size=10).n_clusters_ == 1


def test_counterexample_tiny_clusters_overfit_and_survive():
    # Twenty one-point clusters next to one of 80: a (tau, 80, 1)-good clustering. A
    # single correspondence fits its own motion exactly, so its sigma is the floor and no
    # weight can outbid it: with min_cluster_size=1 every singleton survives.
    a = grid()
    X = np.hstack([a, move(a, sigma=0.05, seed=0)])
    truth = np.zeros(100, dtype=int)
    init = np.zeros(100, dtype=int)
    init[:20] = np.arange(1, 21)
    report = is_good_clustering(init, truth, X, TAU, alpha=79, m0=1)
    assert report and report.max_alpha == 80 and report.max_m0 == 1
    estimator = fit(X, init, min_cluster_size=1)
    assert estimator.n_clusters_ == 21
    assert n_clusters_on(estimator.labels_, truth == 0) == 21

    # Contrast: min_cluster_size=2 removes the singletons before the first M-step.
    assert fit(X, init, min_cluster_size=2).n_clusters_ == 1


@pytest.mark.parametrize("piece", [2, 3])
def test_counterexample_small_pieces_with_noise(piece):
    # The same with pieces of two and three: Horn's method on 2 points leaves one
    # residual degree of freedom, so some pairs stay tighter than the large cluster and
    # survive; triples already dissolve (on this scene).
    a = grid()
    X = np.hstack([a, move(a, sigma=0.05, seed=0)])
    init = np.zeros(100, dtype=int)
    init[:20] = 1 + np.arange(20) // piece
    estimator = fit(X, init, min_cluster_size=piece)
    survivors = estimator.n_clusters_ - 1
    if piece == 2:
        assert survivors >= 1
    else:
        assert survivors == 0


def test_counterexample_cluster_not_tau_connected_joins_two_objects():
    # Two objects with the same motion, 1.0 apart: Definition 1 holds. One initial cluster
    # spanning both is not tau-connected; the gate never splits a cluster, and the shared
    # motion fits both, so the objects stay merged.
    a = np.vstack([grid(), grid(shift=(1.9, 0, 0))])
    X = np.hstack([a, move(a)])
    truth = np.repeat([0, 1], 100)
    motions = ([ROTATION, ROTATION], [TRANSLATION, TRANSLATION])
    assert satisfies_ground_truth(X, truth, motions, TAU, sigma=0)
    joined = np.zeros(200, dtype=int)
    report = is_good_clustering(joined, truth, X, TAU, alpha=1.5, m0=10)
    assert {"connected", "pure", "count"} <= {c.name for c in report.failures}
    assert fit(X, joined, min_cluster_size=10).n_clusters_ == 1

    # Contrast: one cluster per object keeps them apart, although they move alike.
    estimator = fit(X, truth, min_cluster_size=10)
    assert estimator.n_clusters_ == 2
    assert n_clusters_on(estimator.labels_, truth == 0) == 1


def test_counterexample_objects_closer_than_tau_merge():
    # The same two objects only 0.12 < tau apart (separation fails): the larger one's
    # cluster is admitted at the other's edge and wins it row by row.
    a = np.vstack([grid(), grid(shift=(1.02, 0, 0), n=8)])
    X = np.hstack([a, move(a)])
    truth = np.repeat([0, 1], [100, 64])
    motions = ([ROTATION, ROTATION], [TRANSLATION, TRANSLATION])
    report = satisfies_ground_truth(X, truth, motions, TAU, sigma=0)
    assert [c.name for c in report.failures] == ["separation"]
    assert is_good_clustering(truth, truth, X, TAU, alpha=1.5, m0=10)
    estimator = fit(X, truth, min_cluster_size=10)
    assert estimator.n_clusters_ == 1


def test_theorem_1_at_gaps_of_exactly_tau():
    # Not a counter-example any more: eq. (7) gates with d_cluster < tau, Definitions 1-2
    # allow gaps <= tau, so with a strict gate pieces exactly tau apart never met. The
    # gate admits d_cluster <= tau. A grid of spacing exactly 1 with tau = 1 (integer
    # coordinates: the gaps equal tau exactly, in floating point too, on any machine):
    a = grid(step=1.0)
    X = np.hstack([a, move(a)])
    truth = np.zeros(100, dtype=int)
    split = (a[:, 0] > 6.5).astype(int)  # 70 / 30, both tau-connected
    assert satisfies_ground_truth(X, truth, ([ROTATION], [TRANSLATION]), 1.0, sigma=0)
    assert is_good_clustering(split, truth, X, 1.0, alpha=2, m0=30)
    assert fit(X, split, min_cluster_size=10, tau=1.0).n_clusters_ == 1
