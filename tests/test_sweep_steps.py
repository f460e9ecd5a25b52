"""The default's steps on their own: the noise's growth with range, the static world's
slow pieces, and the outliers judged by a false-alarm rate."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from mmreg.estimators._robust_steps import (
    estimate_range_growth,
    fit_clusters,
    merge_static_world,
    motion_beyond_scatter,
    motion_gap,
    reject_outliers,
)


def _clusters_at_ranges(rng, ranges, n=400, noise=0.03, growth=0.0, wrong=0.0):
    """Clusters of ``n`` points around each range; residuals ``noise (1 + growth r^2)``,
    a share ``wrong`` of them replaced by residuals 100 times larger."""
    a = np.vstack([rng.normal(size=(n, 3)) * 0.5 + [r, 0.0, 0.0] for r in ranges])
    labels = np.repeat(np.arange(len(ranges)), n)
    scale = noise * (1.0 + growth * np.einsum("ij,ij->i", a, a))
    residual = rng.normal(size=a.shape) * scale[:, None]
    bad = rng.random(len(a)) < wrong
    residual[bad] *= 100.0
    return a, np.einsum("ij,ij->i", residual, residual), labels


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    near=st.floats(0.5, 2.0),
    wrong=st.floats(0.0, 0.2),
)
def test_equal_noise_has_no_growth_even_with_a_near_cluster_and_wrong_rows(seed, near, wrong):
    # Table I's case: one object near the sensor, the others 5-8 m away, equal noise. The
    # truncated likelihood used to credit the near object's wrong-called rows with a tiny
    # scale's log-density and read a growth of 20-30 into it.
    rng = np.random.default_rng(seed)
    a, squared, labels = _clusters_at_ranges(rng, [near, 5.0, 6.0, 7.0, 8.0], wrong=wrong)
    for robust in (False, True):
        if robust or wrong == 0.0:
            assert estimate_range_growth(a, squared, labels, 5, 1e-6, robust=robust) == 0.0


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), wrong=st.floats(0.0, 0.2))
def test_noise_that_grows_with_range_is_found(seed, wrong):
    # Noise 0.01 (1 + 0.04 r^2): 5 times larger at 10 m than at the sensor.
    rng = np.random.default_rng(seed)
    a, squared, labels = _clusters_at_ranges(
        rng, [1.0, 3.0, 5.0, 7.0, 10.0], noise=0.01, growth=0.04, wrong=wrong
    )
    growth = estimate_range_growth(a, squared, labels, 5, 1e-6, robust=True)
    assert 0.01 < growth < 0.16


def _models(a, b, labels, n_clusters):
    return fit_clusters(a, b, labels, n_clusters, 1e-9)


def _scene_with_a_patch(rng, shift, scatter):
    """A static world standing still, a patch ``shift`` along x with ``scatter`` per axis."""
    world = rng.uniform(-20, 20, (3000, 3))
    patch = rng.uniform(-1, 1, (200, 3)) + [30.0, 0.0, 0.0]
    a = np.vstack([world, patch])
    b = a + rng.normal(size=a.shape) * 0.001
    b[3000:] += [shift, 0.0, 0.0]
    b[3000:] += rng.normal(size=(200, 3)) * scatter
    labels = np.repeat([0, 1], [3000, 200])
    return a, b, labels


def test_a_patch_that_errs_coherently_within_its_own_scatter_is_static():
    # ZeroFlow's wall 36 m away: shifted by 6 cm (above min_motion = 5 cm) with 2 cm of
    # scatter per axis (3.5 cm per point) is the static world's slow piece.
    rng = np.random.default_rng(0)
    a, b, labels = _scene_with_a_patch(rng, shift=0.06, scatter=0.02)
    models = _models(a, b, labels, 2)
    assert motion_gap(models, 0, [1])[0] > 0.05
    assert motion_beyond_scatter(models, 0, [1])[0] < 0.04
    static, root, _, n_merges, slow = merge_static_world(models, 3, 1e-9, min_motion=0.05)
    assert static == 0 and list(slow) == [1] and n_merges == 0


def test_a_pedestrian_beyond_its_scatter_moves():
    # 0.15 m between sweeps (1.5 m/s) with the same scatter: moving.
    rng = np.random.default_rng(1)
    a, b, labels = _scene_with_a_patch(rng, shift=0.15, scatter=0.02)
    models = _models(a, b, labels, 2)
    assert motion_beyond_scatter(models, 0, [1])[0] > 0.09
    static, _, _, _, slow = merge_static_world(models, 3, 1e-9, min_motion=0.05)
    assert static == 0 and len(slow) == 0


def test_false_alarms_keep_the_tail_of_the_noise_and_reject_wrong_rows():
    rng = np.random.default_rng(2)
    n = 20000
    a = rng.uniform(-10, 10, (n, 3))
    b = a + rng.normal(size=a.shape) * 0.01
    wrong = np.arange(n) < 50
    b[wrong] += rng.uniform(-5, 5, (50, 3))
    labels = np.zeros(n, dtype=np.intp)
    parameters = (np.eye(3)[None], np.zeros((1, 3)), np.array([0.01]), np.array([1.0]))
    # An outlier density that puts the plain test at a squared normalised residual of 17
    # (about 4 sigma), where 1 in 1,400 of the good rows lies: what classification-EM
    # settles on when its outlier weight is the share its own test rejects.
    log_outlier = -3 * np.log(0.01) - 1.5 * np.log(2 * np.pi) - 17 / 2
    plain = reject_outliers(a, b, labels, *parameters, log_outlier)
    judged = reject_outliers(a, b, labels, *parameters, log_outlier, false_alarms=0.01)
    assert np.all(plain[wrong] == -1) and np.all(judged[wrong] == -1)
    assert np.count_nonzero(plain[~wrong] == -1) > 5
    assert np.count_nonzero(judged[~wrong] == -1) == 0
