"""Sufficient statistics of rigid fits against plain per-group computations."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from mmreg._array.moments import group_moments


def _plain_moments(a, b, labels, n_groups, w):
    """One group at a time, straight from the definitions."""
    out = {k: [] for k in ("count", "mean_a", "mean_b", "cross", "scatter_a", "scatter_b")}
    for g in range(n_groups):
        rows = labels == g
        wg, ag, bg = w[rows], a[rows], b[rows]
        count = wg.sum()
        mean_a = (wg[:, None] * ag).sum(axis=0) / count if count else np.zeros(3)
        mean_b = (wg[:, None] * bg).sum(axis=0) / count if count else np.zeros(3)
        ca, cb = ag - mean_a, bg - mean_b
        out["count"].append(count)
        out["mean_a"].append(mean_a)
        out["mean_b"].append(mean_b)
        out["cross"].append((wg[:, None, None] * ca[:, :, None] * cb[:, None, :]).sum(axis=0))
        out["scatter_a"].append((wg * (ca**2).sum(axis=1)).sum())
        out["scatter_b"].append((wg * (cb**2).sum(axis=1)).sum())
    return {k: np.array(v) for k, v in out.items()}


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(1, 300),
    n_groups=st.integers(1, 12),
    left_out=st.floats(0.0, 1.0),
    weighted=st.booleans(),
)
def test_group_moments_match_each_group_computed_alone(seed, n, n_groups, left_out, weighted):
    # Rows labelled -1 take no part, whatever their weights (here huge) and values.
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, 3)) * 10.0 + 100.0
    b = rng.normal(size=(n, 3)) * 10.0 - 50.0
    labels = rng.integers(n_groups, size=n)
    labels[rng.random(n) < left_out] = -1
    w = rng.uniform(0.1, 3.0, n) if weighted else np.ones(n)
    w_given = np.where(labels >= 0, w, 1e300) if weighted else None
    moments = group_moments(a, b, labels, n_groups, w_given)
    expected = _plain_moments(a, b, labels, n_groups, w)
    for name, value in expected.items():
        np.testing.assert_allclose(getattr(moments, name), value, rtol=1e-9, atol=1e-8)
    sizes = np.bincount(labels[labels >= 0], minlength=n_groups)
    np.testing.assert_array_equal(moments.size, sizes)
