"""Log-likelihood of correspondences under a fitted mixture of rigid motions.

The model behind the estimators' ``score``: correspondence ``(a, b)`` is drawn from
cluster ``j`` with probability ``pi_j``, then ``b ~ N(R_j a + t_j, (sigma_j g)^2 I)``
(eq. (7) and around it), or from the uniform outlier component, density ``pi_0 / V``
over the displacements ``b - a``. The gate of eq. (7) is part of the model: a cluster
whose fitted a-points all lie farther than ``tau`` from ``a`` has no share in ``(a, b)``,
exactly as it has none in the E-step. The density of ``(a, b)`` is then

    p(b | a) = sum over admitted j of pi_j N(b; R_j a + t_j, (sigma_j g)^2 I) + pi_0 / V

which is what :func:`mixture_log_likelihood` returns the logarithm of.
"""

import numpy as np
from scipy.special import logsumexp

__all__ = ["mixture_log_likelihood"]

_LOG_2PI = float(np.log(2 * np.pi))
# Largest (rows x clusters x d) residual table held at once: 2 MiB.
_TABLE_CELLS = 2**18


def admitted_clusters(gate, points):
    """Boolean ``(m, K)``: does the gate admit cluster ``j`` for point ``i``?

    The bounding balls rule out most pairs at once; the gate's exact test
    (:meth:`~mmreg.em._gate.ClusterGate.admits`) decides the pairs left, all in one call.
    """
    mask = gate.reach_boxes(points, points)
    if gate.radius is None:
        return mask
    rows, columns = np.nonzero(mask)
    if len(rows):
        mask[rows, columns] = gate.admits(points[rows], columns)
    return mask


def mixture_log_likelihood(
    a,
    b,
    rotations,
    translations,
    sigmas,
    weights,
    gate,
    log_outlier,
    noise_scale=None,
):
    """``log p(b_i | a_i)`` of every correspondence under a fitted mixture.

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
    rotations, translations, sigmas, weights : ndarray
        The ``K`` clusters' motions, noise scales and weights ``pi_j``.
    gate : ClusterGate
        Which clusters may explain each correspondence (eq. 7).
    log_outlier : float
        ``log(pi_0 / V)``, the outlier component's log-density; ``-inf`` for none.
    noise_scale : ndarray of shape (n,), default=None
        Relative noise scale ``g_i`` of each correspondence (None: all 1).

    Returns
    -------
    log_likelihood : ndarray of shape (n,)
        ``-inf`` where no cluster is admitted and there is no outlier component.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    n, d = a.shape
    k = len(rotations)
    out = np.full(n, float(log_outlier))
    if k == 0 or n == 0:
        return out
    sigmas = np.asarray(sigmas, dtype=float)
    with np.errstate(divide="ignore"):
        log_norm = np.log(weights) - d * np.log(sigmas) - 0.5 * d * _LOG_2PI
    half_precision = 0.5 / sigmas**2
    step = max(1, _TABLE_CELLS // (k * d))
    for start in range(0, n, step):
        rows = slice(start, start + step)
        pa, pb = a[rows], b[rows]
        residual = pb[:, None, :] - np.einsum("kij,mj->mki", rotations, pa) - translations
        squared = np.einsum("mki,mki->mk", residual, residual)
        if noise_scale is None:
            table = log_norm - half_precision * squared
        else:
            g = noise_scale[rows, None]
            table = log_norm - d * np.log(g) - half_precision * squared / g**2
        table[~admitted_clusters(gate, pa)] = -np.inf
        table = np.column_stack([table, out[rows]])
        with np.errstate(divide="ignore"):
            out[rows] = logsumexp(table, axis=1)
    return out
