"""Algorithm 1 written plainly: the yardstick for speed and the reference for correctness.

A loop over clusters, one KD-tree per cluster for the distance gate, one SVD per cluster.
It follows the same documented conventions as :func:`mmreg.estimators.multi_model_em`
(sample covariance with ``ddof=1`` and a floor on sigma, ties kept in the current cluster,
then the lowest cluster index, gate ``d <= tau``, final clusters numbered by decreasing
size), so the two must return the same partition. It imports nothing from mmreg.
"""

import numpy as np
from scipy.spatial import cKDTree


def horn(a, b):
    """Least-squares rotation and translation with ``b ~ R a + t`` (reflection-safe)."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.ones(a.shape[1])
    d[-1] = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    rotation = vt.T @ np.diag(d) @ u.T
    return rotation, cb - rotation @ ca


def straightforward_em(
    a, b, init_labels, tau=1.5, min_cluster_size=4, max_iter=10, sigma_floor=1e-6
):
    n, dim = a.shape
    clusters = [np.flatnonzero(init_labels == k) for k in np.unique(init_labels[init_labels >= 0])]
    for _ in range(max_iter):
        old = np.full(n, -1)
        for j, members in enumerate(clusters):
            old[members] = j
        log_w = np.full((n, len(clusters)), -np.inf)
        for j, members in enumerate(clusters):
            if len(members) < min_cluster_size:  # removed before the M-step
                continue
            rotation, translation = horn(a[members], b[members])
            errors = b[members] - a[members] @ rotation.T - translation
            if len(members) > 1:
                sigma = np.sqrt(np.trace(np.atleast_2d(np.cov(errors.T))) / dim)
            else:
                sigma = sigma_floor
            sigma = max(sigma, sigma_floor)
            r2 = np.sum((b - a @ rotation.T - translation) ** 2, axis=1)
            log_w[:, j] = np.log(len(members) / n) - dim * np.log(sigma) - r2 / (2 * sigma**2)
            if tau is not None:
                dist, _ = cKDTree(a[members]).query(a)
                log_w[dist > tau, j] = -np.inf
        new = np.full(n, -1)
        for i in range(n):
            if not np.isfinite(log_w[i]).any():
                continue
            best = int(np.argmax(log_w[i]))
            own = old[i]
            if own >= 0 and np.isfinite(log_w[i, own]) and log_w[i, own] >= log_w[i, best]:
                best = own
            new[i] = best
        if np.array_equal(new, old):
            break
        clusters = [np.flatnonzero(new == j) for j in range(len(clusters)) if np.any(new == j)]
    labels = np.full(n, -1)
    for rank, members in enumerate(sorted(clusters, key=len, reverse=True)):
        labels[members] = rank
    return labels
