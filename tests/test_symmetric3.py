"""The closed-form eigen-solver of 3 x 3 covariances (mmreg._array.symmetric3) against LAPACK."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from mmreg._array.symmetric3 import _FEW, least_eigenvectors
from mmreg.sweeps._icp import SurfaceNormals


def _rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.diag(r))


def _check_against_lapack(covariance):
    values, vectors = least_eigenvectors(covariance)
    expected_values, expected_vectors = np.linalg.eigh(covariance)
    scale = np.abs(expected_values).max(axis=1, keepdims=True) + 1e-300
    assert np.all(np.abs(values - expected_values) <= 1e-10 * scale)
    assert np.allclose(np.linalg.norm(vectors, axis=1), 1.0)
    # An eigenvector of the least eigenvalue: A v = l_0 v (either sign, any vector of a
    # repeated eigenvalue's space).
    residual = np.einsum("nij,nj->ni", covariance, vectors) - values[:, :1] * vectors
    assert np.all(np.linalg.norm(residual, axis=1) <= 1e-8 * scale[:, 0])
    # Where the least eigenvalue stands apart, the eigenvector is LAPACK's, up to sign.
    apart = (expected_values[:, 1] - expected_values[:, 0]) > 1e-3 * scale[:, 0]
    agree = np.abs(np.einsum("ni,ni->n", vectors, expected_vectors[:, :, 0]))
    assert np.all(agree[apart] > 1 - 1e-9)


@settings(max_examples=60, deadline=None)
@given(
    st.integers(0, 2**32 - 1),
    st.sampled_from(["blob", "plane", "line", "point", "two planes"]),
    st.floats(1e-3, 1e3),
    st.sampled_from([3, 2 * _FEW]),
)
def test_eigenpairs_of_neighbourhood_covariances_match_lapack(seed, shape, size, n):
    """Covariances of 10-point neighbourhoods of every shape a sweep holds, at any scale
    and orientation, the degenerate ones included (a line, one point repeated), in
    batches LAPACK solves and batches the closed form does."""
    rng = np.random.default_rng(seed)
    spread = {
        "blob": [1.0, 0.7, 0.4],
        "plane": [1.0, 0.6, 1e-4],
        "line": [1.0, 1e-4, 1e-4],
        "point": [0.0, 0.0, 0.0],
        "two planes": [1.0, 1.0, 1e-5],
    }[shape]
    hoods = np.stack(
        [rng.normal(size=(10, 3)) * spread @ _rotation(rng).T * size for _ in range(n)]
    )
    hoods -= hoods.mean(axis=1, keepdims=True)
    _check_against_lapack(np.matmul(hoods.transpose(0, 2, 1), hoods))


def test_exact_planes_and_lines_give_their_normals():
    """A noiseless plane's normal is exact; a line (no plane) and a repeated point are
    solved by LAPACK, whatever vector it gives, as before."""
    g = np.arange(4.0)
    plane = np.stack(np.meshgrid(g, g, [2.0], indexing="ij"), -1).reshape(-1, 3)
    line = np.stack([g, 2 * g, 0 * g], 1)
    hoods = [plane - plane.mean(0), line - line.mean(0), np.zeros((4, 3))]
    covariance = np.stack([h.T @ h for h in hoods] * _FEW)  # enough for the closed form
    values, vectors = least_eigenvectors(covariance)
    assert np.allclose(np.abs(vectors[0]), [0.0, 0.0, 1.0], rtol=0, atol=1e-12)
    assert abs(values[0, 0]) <= 1e-12 * values[0, 2] and values[2].tolist() == [0.0, 0.0, 0.0]
    assert np.allclose(covariance[1] @ vectors[1], 0.0)


def test_surface_normals_of_a_tilted_plane():
    """SurfaceNormals, which uses the solver, gives a noisy tilted plane's normal."""
    rng = np.random.default_rng(3)
    u, v = rng.uniform(-5, 5, (2, 2000))
    normal = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    basis = np.linalg.svd(normal[None])[2][1:]
    points = np.outer(u, basis[0]) + np.outer(v, basis[1]) + rng.normal(0, 1e-3, (2000, 1)) * normal
    normals, variation, flatness = SurfaceNormals(points, cKDTree(points), 10)(np.arange(2000))
    assert np.all(np.abs(normals @ normal) > 0.99)
    assert np.all(variation < 0.01) and np.median(flatness) > 0.2
