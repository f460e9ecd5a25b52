"""residual_table, own_residuals and apply_motions against the direct einsum readings."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import special_ortho_group

from mmreg._geometry import apply_motions, own_residuals, residual_table


def direct(rotations, translations, a, b):
    moved = np.einsum("kij,nj->nki", rotations, a) + translations
    diff = b[:, None, :] - moved
    return np.einsum("nki,nki->nk", diff, diff).T


@settings(max_examples=100, deadline=None)
@given(
    d=st.sampled_from([2, 3, 4]),
    k=st.integers(1, 12),
    n=st.integers(0, 50),
    scale=st.sampled_from([1e-3, 1.0, 1e3]),
    seed=st.integers(0, 2**16),
)
def test_residual_table_is_the_direct_reading(d, k, n, scale, seed):
    rng = np.random.default_rng(seed)
    rotations = special_ortho_group.rvs(d, size=k, random_state=seed).reshape(k, d, d)
    translations = rng.normal(scale=scale, size=(k, d))
    a = rng.normal(scale=scale, size=(n, d))
    b = a + rng.normal(scale=scale / 10, size=(n, d))
    got = residual_table(rotations, translations, np.ascontiguousarray(a.T), b.T.copy())
    assert got.shape == (k, n)
    expected = direct(rotations, translations, a, b)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12 * scale**2)
    origins = a + rng.normal(scale=scale, size=(n, d))
    table, distance = residual_table(
        rotations, translations, np.ascontiguousarray(a.T), b.T.copy(), origins=origins.T.copy()
    )
    np.testing.assert_array_equal(table, got)
    moved = np.einsum("kij,nj->kni", rotations, a) + translations[:, None, :]
    expected = np.linalg.norm(moved - origins, axis=2)
    np.testing.assert_allclose(distance, expected, rtol=1e-12, atol=1e-12 * scale)


def test_a_motion_that_explains_a_row_leaves_no_residual():
    a = np.array([[0.0, 1.0, 2.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])  # (d, n)
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    shift = np.array([1.0, 2.0, 3.0])
    b = turn @ a + shift[:, None]
    table = residual_table(np.stack([np.eye(3), turn]), np.stack([np.zeros(3), shift]), a, b)
    np.testing.assert_array_equal(table[1], 0.0)
    np.testing.assert_allclose(table[0], np.sum((b - a) ** 2, axis=0))


@settings(max_examples=100, deadline=None)
@given(
    d=st.sampled_from([2, 3, 4]),
    k=st.integers(1, 12),
    n=st.integers(0, 50),
    scale=st.sampled_from([1e-3, 1.0, 1e3]),
    seed=st.integers(0, 2**16),
)
def test_own_residuals_are_the_direct_reading(d, k, n, scale, seed):
    rng = np.random.default_rng(seed)
    rotations = special_ortho_group.rvs(d, size=k, random_state=seed).reshape(k, d, d)
    translations = rng.normal(scale=scale, size=(k, d))
    labels = rng.integers(0, k, size=n)
    a = rng.normal(scale=scale, size=(n, d))
    b = a + rng.normal(scale=scale / 10, size=(n, d))
    diff = b - np.einsum("nij,nj->ni", rotations[labels], a) - translations[labels]
    got = own_residuals(rotations, translations, labels, a.T, b.T)
    expected = np.einsum("ij,ij->i", diff, diff)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12 * scale**2)


@settings(max_examples=100, deadline=None)
@given(
    d=st.sampled_from([2, 3, 4]),
    k=st.integers(1, 12),
    n=st.integers(0, 50),
    scale=st.sampled_from([1e-3, 1.0, 1e3]),
    seed=st.integers(0, 2**16),
)
def test_apply_motions_is_the_direct_reading(d, k, n, scale, seed):
    rng = np.random.default_rng(seed)
    rotations = special_ortho_group.rvs(d, size=k, random_state=seed).reshape(k, d, d)
    translations = rng.normal(scale=scale, size=(k, d))
    labels = rng.integers(-1, k, size=n)  # -1: left where it is
    a = rng.normal(scale=scale, size=(n, d))
    got = apply_motions(a, rotations, translations, labels)
    keep = labels >= 0
    expected = a.copy()
    expected[keep] = np.einsum("nij,nj->ni", rotations[labels[keep]], a[keep])
    expected[keep] += translations[labels[keep]]
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12 * scale)
    np.testing.assert_array_equal(got[~keep], a[~keep])
