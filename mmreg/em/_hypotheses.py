"""Motion hypotheses from minimal samples and their consensus, shared by the baselines.

A rigid motion in ``d`` dimensions is fixed by ``d`` correspondences whose a-points
span ``d - 1`` dimensions (three non-collinear points in 3-D): a *minimal sample*.
Sequential RANSAC and T-Linkage draw many such samples at once, fit all of them with one
batched Horn/Kabsch solve, and score every hypothesis against every correspondence with
blocked matrix products.
"""

import numpy as np

from mmreg._array.geometry import degenerate_groups, fit_rigid_grouped, squared_residuals_all
from mmreg.em._likelihood import single_threaded_blas

__all__ = [
    "count_inliers",
    "draw_minimal_samples",
    "fit_minimal_samples",
    "minimal_sample_size",
    "nearest_model",
]

# Cells per block of a (rows x hypotheses) residual table: 2 MiB of float64, so that
# the block is still in cache when it is compared and counted.
BLOCK_CELLS = 2**18


def minimal_sample_size(d):
    """Correspondences that fix a rigid motion in ``d`` dimensions (3 in 3-D)."""
    return max(int(d), 1)


def draw_minimal_samples(rng, n_points, n_samples, size):
    """Indices of ``n_samples`` random samples of ``size`` points out of ``n_points``.

    Each index is drawn uniformly, so a sample may repeat a point; such a sample is
    degenerate and :func:`fit_minimal_samples` discards it. One call draws every sample,
    so a fixed ``rng`` state gives fixed samples.

    Returns
    -------
    samples : ndarray of shape (n_samples, size)
    """
    return rng.randint(n_points, size=(n_samples, size))


def fit_minimal_samples(a, b, samples):
    """Rigid motion of each minimal sample, skipping degenerate ones.

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
        Corresponding points.
    samples : ndarray of shape (n_samples, size)
        Row indices of each sample.

    Returns
    -------
    rotations : ndarray of shape (n_valid, d, d)
    translations : ndarray of shape (n_valid, d)
    valid : ndarray of shape (n_samples,)
        False for the samples whose a-points are coincident or collinear: they admit
        infinitely many motions, and any one of them would be an arbitrary hypothesis.
    """
    n_samples, size = samples.shape
    groups = np.repeat(np.arange(n_samples), size)
    flat = samples.ravel()
    valid = ~degenerate_groups(a[flat], groups, n_samples)
    rotations, translations, _ = fit_rigid_grouped(a[flat], b[flat], groups, n_samples)
    return rotations[valid], translations[valid], valid


def _row_blocks(n_rows, n_columns):
    step = max(1, BLOCK_CELLS // max(n_columns, 1))
    for start in range(0, n_rows, step):
        yield slice(start, min(start + step, n_rows))


def count_inliers(a, b, rotations, translations, threshold):
    """Number of correspondences within ``threshold`` of each motion.

    The ``(n, K)`` table of squared residuals is built in row blocks of bounded memory,
    one matrix product per block (:func:`~mmreg._array.geometry.squared_residuals_all`), on
    one BLAS thread: these thin products gain nothing from a second thread and lose a
    lot to it when the cores are busy.

    Returns
    -------
    counts : ndarray of shape (K,)
        ``#{i : ||b_i - R_k a_i - t_k|| <= threshold}`` for each motion ``k``.
    """
    k = len(rotations)
    counts = np.zeros(k, dtype=np.intp)
    limit = threshold**2
    with single_threaded_blas():
        for block in _row_blocks(len(a), k):
            sq = squared_residuals_all(a[block], b[block], rotations, translations)
            counts += np.count_nonzero(sq <= limit, axis=0)
    return counts


def nearest_model(a, b, rotations, translations, threshold):
    """Each correspondence to the motion of smallest residual, if within ``threshold``.

    Returns
    -------
    labels : ndarray of shape (n,)
        Index of the best motion; ``-1`` where no motion comes within ``threshold`` (or
        there are none). Ties go to the lowest index.
    """
    n = len(a)
    labels = np.full(n, -1, dtype=np.intp)
    k = len(rotations)
    if k == 0:
        return labels
    limit = threshold**2
    with single_threaded_blas():
        for block in _row_blocks(n, k):
            sq = squared_residuals_all(a[block], b[block], rotations, translations)
            best = np.argmin(sq, axis=1)
            within = sq[np.arange(len(best)), best] <= limit
            labels[block] = np.where(within, best, -1)
    return labels
