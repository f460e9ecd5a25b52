"""estimate_range_growth(robust=True): the noise's growth with range, unharmed by outliers."""

import numpy as np
import pytest

from mmreg.estimators._robust_steps import estimate_range_growth


def _residuals(rng, n, growth, outliers):
    a = rng.normal(size=(n, 3))
    a *= rng.uniform(1.0, 30.0, n)[:, None] / np.linalg.norm(a, axis=1, keepdims=True)
    sigma = 0.01 * (1.0 + growth * np.einsum("ij,ij->i", a, a))
    squared = np.sum((rng.normal(size=(n, 3)) * sigma[:, None]) ** 2, axis=1)
    wrong = rng.random(n) < outliers
    squared[wrong] = rng.uniform(0.0, 25.0, wrong.sum())  # wrong correspondences
    return a, squared


@pytest.mark.parametrize("seed", range(3))
def test_constant_noise_with_wrong_correspondences_has_no_growth(seed):
    rng = np.random.default_rng(seed)
    a, squared = _residuals(rng, 6000, 0.0, outliers=0.1)
    labels = rng.integers(0, 5, len(a))
    growth = estimate_range_growth(a, squared, labels, 5, 1e-6, per_cluster=False, robust=True)
    assert growth == 0.0


@pytest.mark.parametrize("seed", range(3))
def test_growing_noise_is_found_among_wrong_correspondences(seed):
    rng = np.random.default_rng(seed)
    a, squared = _residuals(rng, 6000, 0.01, outliers=0.1)
    labels = np.zeros(len(a), dtype=np.intp)
    growth = estimate_range_growth(a, squared, labels, 1, 1e-6, per_cluster=False, robust=True)
    # The grid is logarithmic, 4 values a decade: within a factor of 3 of the truth.
    assert 0.01 / 3 < growth < 0.01 * 3
