"""The weighted Gaussian likelihood of eq. (7) and the classification step built on it.

The classification step needs, for every correspondence, the arg-max of
``log(pi_j phi_j(b_i | a_i))`` over the clusters the distance gate admits. A dense
``(n, K)`` table of scores would cost ``n * K`` work and memory per EM iteration, but the
gate admits only clusters near the point. So the correspondences are visited in
spatially compact blocks (Morton order of the a-points); each block scores only the
clusters whose bounding ball, grown by ``tau``, reaches the block's bounding box, with one
matrix product. Without a gate every block scores every cluster.
"""

import functools

import numpy as np
from threadpoolctl import ThreadpoolController

from mmreg._gate import gated_argmax
from mmreg._geometry import group_sums, residuals, squared_residuals_all

__all__ = ["CorrespondenceBlocks", "classify", "cluster_sigmas", "log_weighted_likelihood"]

# Correspondences per block: small enough for a compact bounding box (few clusters in
# reach), large enough that the per-block Python overhead is negligible.
_BLOCK_ROWS = 2048
# Largest (rows x clusters) score table scored at once: 8 MiB, about the size of a cache.
_BLOCK_CELLS = 2**20
# Bits of the Morton code per axis (at most 30 bits in all).
_MORTON_BITS = 10
_EPS = np.finfo(float).eps


@functools.cache
def _blas_controller():
    return ThreadpoolController()


def single_threaded_blas():
    """Context in which BLAS runs on one thread.

    The products here are small (a block of rows times a few dozen motions): a second
    BLAS thread only adds synchronisation, which costs far more than the product as
    soon as the cores are busy.
    """
    return _blas_controller().limit(limits=1, user_api="blas")


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


def morton_order(points, bits=_MORTON_BITS):
    """Permutation that visits points along a Z-order (Morton) curve.

    Consecutive points in this order are close in space, so any run of them has a small
    bounding box. Points in the same cell keep their input order.

    Parameters
    ----------
    points : ndarray of shape (d, n)
        One coordinate per row.
    bits : int, default=10
        Cells per axis ``2**bits`` (fewer if ``d * bits`` would exceed 30).
    """
    d, n = points.shape
    if n == 0:
        return np.zeros(0, dtype=np.intp)
    bits = max(1, min(bits, 30 // d))
    low = points.min(axis=1)
    extent = float(np.max(points.max(axis=1) - low))
    scale = (2**bits - 1) / extent if extent > 0 else 0.0
    # spread[v] puts bit i of v at bit i * d: interleaving is then a sum of shifted
    # table look-ups, one per axis.
    values = np.arange(2**bits, dtype=np.int64)
    spread = np.zeros(2**bits, dtype=np.int64)
    for bit in range(bits):
        spread |= ((values >> bit) & 1) << (bit * d)
    code = np.arange(n, dtype=np.int64)
    for axis in range(d):
        cells = ((points[axis] - low[axis]) * scale).astype(np.intp)
        code += (spread[cells] << axis) * n
    # Unique keys (code, index) make any sorting algorithm give the same order.
    return np.argsort(code, kind="quicksort")


class CorrespondenceBlocks:
    """Correspondences in spatially compact blocks, with the features of their residuals.

    ``||b - R a - t||^2 = ||b||^2 + ||a||^2 + ||t||^2 - 2 b^T R a - 2 b.t + 2 a.(R^T t)``
    makes the squared residuals of a block under ``k`` motions one product of an
    ``(m, d^2 + 2d + 2)`` feature matrix with a ``(d^2 + 2d + 2, k)`` motion matrix. The
    features depend only on the points, so an EM run builds them once. Each block is
    centred on its own mean first, since the expansion loses about ``eps * ||x||^2`` of
    absolute precision and a block is small; :meth:`scores` also returns a bound on that
    loss, and :meth:`accurate_scores` recomputes rows from explicit residuals where the
    bound leaves a decision open.

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
        Corresponding points.
    block_rows : int, default=1024
        Correspondences per block.

    Attributes
    ----------
    order : ndarray of shape (n,)
        The correspondences in block order: block ``i`` holds ``order[starts[i]:stops[i]]``.
    a, b : ndarray of shape (n, d)
        The points in block order.
    """

    def __init__(self, a, b, block_rows=_BLOCK_ROWS):
        # Coordinates as rows: every per-point operation below runs over contiguous rows.
        a_rows = np.ascontiguousarray(np.asarray(a, dtype=float).T)
        b_rows = np.ascontiguousarray(np.asarray(b, dtype=float).T)
        d, n = a_rows.shape
        self.n, self.d = n, d
        self.order = morton_order(a_rows)
        a_rows = np.take(a_rows, self.order, axis=1)
        b_rows = np.take(b_rows, self.order, axis=1)
        self.a, self.b = a_rows.T, b_rows.T
        self.starts = np.arange(0, n, block_rows)
        self.stops = np.minimum(self.starts + block_rows, n)
        sizes = self.stops - self.starts
        self.low = np.minimum.reduceat(a_rows, self.starts, axis=1).T
        self.high = np.maximum.reduceat(a_rows, self.starts, axis=1).T
        self.mean_a = (np.add.reduceat(a_rows, self.starts, axis=1) / sizes).T
        self.mean_b = (np.add.reduceat(b_rows, self.starts, axis=1) / sizes).T
        ca = a_rows - np.repeat(self.mean_a.T, sizes, axis=1)
        cb = b_rows - np.repeat(self.mean_b.T, sizes, axis=1)
        norm_a, norm_b = np.einsum("ij,ij->j", ca, ca), np.einsum("ij,ij->j", cb, cb)
        # Largest ||a - mean_a|| + ||b - mean_b|| in each block, for the error bound.
        self.extent = np.maximum.reduceat(np.sqrt(norm_a) + np.sqrt(norm_b), self.starts)
        # Features as rows too; a block's (m, f) feature matrix is a transposed view.
        self._features = np.ones((d * d + 2 * d + 2, n))
        for p in range(d):
            for q in range(d):
                np.multiply(cb[p], ca[q], out=self._features[p * d + q])
        self._features[d * d : d * d + d] = cb
        self._features[d * d + d : d * d + 2 * d] = ca
        np.add(norm_a, norm_b, out=self._features[-2])

    def scores(self, block, rows, rotations, translations, scale, log_prior):
        """Scores ``log_prior + scale * ||b - R a - t||^2`` of some rows of a block.

        Parameters
        ----------
        block : int
        rows : slice
            Rows of the sorted correspondences, inside block ``block``.
        rotations, translations, scale, log_prior : ndarray
            The ``k`` motions to score and their score parameters (``scale < 0``).

        Returns
        -------
        scores : ndarray of shape (m, k)
        tolerance : ndarray of shape (k,)
            Bound on the rounding error of each column.
        """
        d = self.d
        k = len(rotations)
        mean_a, mean_b = self.mean_a[block], self.mean_b[block]
        # Residuals are unchanged when a and b are shifted and t becomes
        # t + R mean_a - mean_b.
        shifted = translations + rotations @ mean_a - mean_b
        shift_sq = np.einsum("kj,kj->k", shifted, shifted)
        # The scale is folded into the motion matrix: one product gives scale * r^2.
        coefs = np.empty((d * d + 2 * d + 2, k))
        coefs[: d * d] = rotations.reshape(k, d * d).T
        coefs[d * d : d * d + d] = shifted.T
        coefs[: d * d + d] *= -2.0 * scale
        coefs[d * d + d : d * d + 2 * d] = np.einsum("kji,kj->ik", rotations, shifted)
        coefs[d * d + d : d * d + 2 * d] *= 2.0 * scale
        coefs[-2] = scale
        coefs[-1] = scale * shift_sq
        out = self._features[:, rows].T @ coefs
        # scale < 0 and r^2 >= 0: clip what rounding pushed past zero.
        np.minimum(out, 0.0, out=out)
        out += log_prior
        # Every term of the expansion is at most (|a| + |b| + |t|)^2 in size, and the
        # shifted translation carries the rounding of the uncentred coordinates.
        size = self.extent[block] + np.sqrt(shift_sq)
        uncentred = (
            np.sqrt(np.einsum("kj,kj->k", translations, translations))
            + np.sqrt(mean_a @ mean_a)
            + np.sqrt(mean_b @ mean_b)
        )
        with np.errstate(invalid="ignore", over="ignore"):
            tolerance = _EPS * (
                -scale * (64 * size * (size + uncentred) + 8 * size**2) + 8 * np.abs(log_prior)
            )
        tolerance[~np.isfinite(tolerance)] = np.inf
        return out, tolerance

    def accurate_scores(self, rows, rotations, translations, scale, log_prior):
        """The same scores from explicit residual vectors, for rows (sorted indices)."""
        moved = np.einsum("kij,mj->mki", rotations, self.a[rows]) + translations
        residual = self.b[rows][:, None, :] - moved
        return log_prior + scale * np.einsum("mki,mki->mk", residual, residual)


def classify(a, b, rotations, translations, sigmas, weights, gate, own=None, *, blocks=None):
    """Classification step: each correspondence to its most likely admitted cluster.

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
    rotations, translations, sigmas, weights : ndarray
        The ``K`` clusters' motions, noise scales and weights ``pi_j``.
    gate : ClusterGate
    own : ndarray of shape (n,), default=None
        Current cluster of each correspondence (-1: none), which wins ties.
    blocks : CorrespondenceBlocks, default=None
        ``a`` and ``b`` already in blocks, to reuse across calls.

    Returns
    -------
    labels : ndarray of shape (n,)
        ``-1`` where the gate admits no cluster.
    """
    n, d = np.shape(a)
    k = len(rotations)
    labels = np.full(n, -1, dtype=np.intp)
    if k == 0 or n == 0:
        return labels
    if blocks is None:
        blocks = CorrespondenceBlocks(a, b)
    sigmas = np.asarray(sigmas, dtype=float)
    with np.errstate(divide="ignore"):
        log_prior = np.log(weights) - d * np.log(sigmas)
    scale = -0.5 / sigmas**2
    sorted_own = None if own is None else own[blocks.order]
    sorted_labels = np.full(n, -1, dtype=np.intp)
    with single_threaded_blas():
        _classify_blocks(
            blocks, rotations, translations, scale, log_prior, gate, sorted_own, sorted_labels
        )
    labels[blocks.order] = sorted_labels
    return labels


def _classify_blocks(
    blocks, rotations, translations, scale, log_prior, gate, sorted_own, sorted_labels
):
    """The loop of :func:`classify` over blocks, on the sorted correspondences."""
    in_reach = np.zeros(len(rotations), dtype=bool)
    for block, (start, stop) in enumerate(zip(blocks.starts, blocks.stops, strict=True)):
        columns = gate.reach_box(blocks.low[block], blocks.high[block])
        if sorted_own is not None:
            # A point's own cluster is always in reach; make sure rounding cannot drop it.
            in_reach[columns] = True
            in_reach[sorted_own[start:stop][sorted_own[start:stop] >= 0]] = True
            columns = np.flatnonzero(in_reach)
            in_reach[columns] = False
        if len(columns) == 0:
            continue
        motion = (rotations[columns], translations[columns], scale[columns], log_prior[columns])
        step = max(1, _BLOCK_CELLS // len(columns))
        for lo in range(start, stop, step):
            rows = slice(lo, min(lo + step, stop))
            scores, tolerance = blocks.scores(block, rows, *motion)
            sorted_labels[rows] = gated_argmax(
                scores,
                blocks.a[rows],
                gate,
                None if sorted_own is None else sorted_own[rows],
                columns=columns,
                tolerance=tolerance,
                refine=lambda local, lo=lo, motion=motion: blocks.accurate_scores(
                    lo + local, *motion
                ),
            )
