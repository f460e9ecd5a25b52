"""The weighted Gaussian likelihood of eq. (7) and the classification step built on it."""

import numpy as np

from mmreg._gate import gated_argmax
from mmreg._geometry import group_sums, residuals, squared_residuals_all

__all__ = ["classify", "cluster_sigmas", "log_weighted_likelihood"]

# Rows per block in the (rows x K) score table: bounds its memory to about 128 MiB.
_BLOCK_CELLS = 2**24


def cluster_sigmas(a, b, rotations, translations, labels, n_clusters, sigma_floor):
    """Isotropic noise scale per cluster, ``sqrt(tr(cov(E_j)) / d)`` (Algorithm 1, line 6).

    ``cov`` is the sample covariance (``ddof=1``, numpy's default) of the residuals
    ``E_j``. A cluster of one point has no covariance; it and every cluster below the
    floor get ``sigma_floor``.
    """
    d = a.shape[1]
    res = residuals(a, b, rotations, translations, labels)
    counts = np.bincount(labels[labels >= 0], minlength=n_clusters)[:n_clusters]
    sums = group_sums(np.hstack([res, np.sum(res**2, axis=1, keepdims=True)]), labels, n_clusters)
    mean_sq_norm = np.sum(sums[:, :d] ** 2, axis=1) / np.maximum(counts, 1)
    scatter = np.maximum(sums[:, d] - mean_sq_norm, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        sigmas = np.sqrt(scatter / (d * (counts - 1)))
    sigmas[counts < 2] = sigma_floor
    return np.maximum(sigmas, sigma_floor)


def log_weighted_likelihood(a, b, rotations, translations, sigmas, weights):
    """``log(pi_j phi_j(b_i | a_i))`` up to a constant, for every pair, ``(n, K)``.

    ``phi_j`` is the isotropic Gaussian density of the residual ``b_i - R_j a_i - t_j`` with
    covariance ``sigma_j^2 I``. Working in log space avoids the underflow of ``exp(-r^2 /
    2 sigma^2)`` for small sigmas; the constant ``-d/2 log(2 pi)`` is dropped since only
    the arg-max over clusters matters.
    """
    d = a.shape[1]
    sq = squared_residuals_all(a, b, rotations, translations)
    with np.errstate(divide="ignore"):
        log_prior = np.log(weights) - d * np.log(sigmas)
    sq *= -0.5 / sigmas**2
    sq += log_prior
    return sq


def classify(a, b, rotations, translations, sigmas, weights, gate, own=None):
    """Classification step: each correspondence to its most likely admitted cluster.

    Blocks of rows keep the ``(rows x K)`` table small whatever ``n`` is. Returns labels
    with ``-1`` where the gate admits no cluster.
    """
    n = len(a)
    k = len(rotations)
    labels = np.full(n, -1, dtype=np.intp)
    if k == 0:
        return labels
    step = max(1, _BLOCK_CELLS // k)
    for start in range(0, n, step):
        block = slice(start, min(start + step, n))
        scores = log_weighted_likelihood(
            a[block], b[block], rotations, translations, sigmas, weights
        )
        labels[block] = gated_argmax(scores, a[block], gate, None if own is None else own[block])
    return labels
