"""residual_table, own_residuals and apply_motions against the direct einsum readings."""

from dataclasses import dataclass

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import special_ortho_group

from mmreg._array.geometry import apply_motions, own_residuals, residual_table


@dataclass
class Motions:
    """``k`` rigid motions in ``d`` dimensions and ``n`` correspondences at ``scale``."""

    rotations: np.ndarray
    translations: np.ndarray
    a: np.ndarray
    b: np.ndarray
    scale: float
    rng: np.random.Generator

    def close(self, got, expected, power):
        """Equal to rounding, for values of the scale's ``power``."""
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12 * self.scale**power)


@st.composite
def motions(draw):
    d = draw(st.sampled_from([2, 3, 4]))
    k, n = draw(st.integers(1, 12)), draw(st.integers(0, 50))
    scale = draw(st.sampled_from([1e-3, 1.0, 1e3]))
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    rotations = special_ortho_group.rvs(d, size=k, random_state=seed).reshape(k, d, d)
    translations = rng.normal(scale=scale, size=(k, d))
    a = rng.normal(scale=scale, size=(n, d))
    b = a + rng.normal(scale=scale / 10, size=(n, d))
    return Motions(rotations, translations, a, b, scale, rng)


@settings(max_examples=100, deadline=None)
@given(motions())
def test_residual_table_is_the_direct_reading(m):
    a_rows, b_rows = np.ascontiguousarray(m.a.T), np.ascontiguousarray(m.b.T)
    got = residual_table(m.rotations, m.translations, a_rows, b_rows)
    assert got.shape == (len(m.rotations), len(m.a))
    moved = np.einsum("kij,nj->nki", m.rotations, m.a) + m.translations
    diff = m.b[:, None, :] - moved
    m.close(got, np.einsum("nki,nki->nk", diff, diff).T, 2)
    origins = m.a + m.rng.normal(scale=m.scale, size=m.a.shape)
    table, distance = residual_table(
        m.rotations, m.translations, a_rows, b_rows, origins=np.ascontiguousarray(origins.T)
    )
    np.testing.assert_array_equal(table, got)
    m.close(distance, np.linalg.norm(moved - origins[:, None, :], axis=2).T, 1)


def test_a_motion_that_explains_a_row_leaves_no_residual():
    a = np.array([[0.0, 1.0, 2.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])  # (d, n)
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    shift = np.array([1.0, 2.0, 3.0])
    b = turn @ a + shift[:, None]
    table = residual_table(np.stack([np.eye(3), turn]), np.stack([np.zeros(3), shift]), a, b)
    np.testing.assert_array_equal(table[1], 0.0)
    np.testing.assert_allclose(table[0], np.sum((b - a) ** 2, axis=0))


@settings(max_examples=100, deadline=None)
@given(motions())
def test_own_residuals_are_the_direct_reading(m):
    labels = m.rng.integers(0, len(m.rotations), size=len(m.a))
    moved = np.einsum("nij,nj->ni", m.rotations[labels], m.a) + m.translations[labels]
    diff = m.b - moved
    got = own_residuals(m.rotations, m.translations, labels, m.a.T, m.b.T)
    m.close(got, np.einsum("ij,ij->i", diff, diff), 2)


@settings(max_examples=100, deadline=None)
@given(motions())
def test_apply_motions_is_the_direct_reading(m):
    labels = m.rng.integers(-1, len(m.rotations), size=len(m.a))  # -1: left where it is
    got = apply_motions(m.a, m.rotations, m.translations, labels)
    keep = labels >= 0
    expected = m.a.copy()
    expected[keep] = np.einsum("nij,nj->ni", m.rotations[labels[keep]], m.a[keep])
    expected[keep] += m.translations[labels[keep]]
    m.close(got, expected, 1)
    np.testing.assert_array_equal(got[~keep], m.a[~keep])
