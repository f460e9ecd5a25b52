"""Sufficient statistics of rigid fits: pose and residuals of any union of groups.

Horn's method needs only each group's size, centroids and cross-covariance, and the sum
of squared residuals under any motion follows from the same few numbers. So the joint
motion of two clusters, and how much worse it explains each of them than its own, cost
one ``d x d`` SVD per pair and never touch the points: what a merge test over every
pair of adjacent clusters needs.
"""

from dataclasses import dataclass

import numpy as np

__all__ = ["Moments", "group_moments", "rotations_from_cross"]


def rotations_from_cross(cross):
    """Proper rotations ``R`` maximising ``tr(R H)`` for a stack of ``H = sum a_c b_c^T``.

    Parameters
    ----------
    cross : ndarray of shape (k, d, d)

    Returns
    -------
    rotations : ndarray of shape (k, d, d)
        ``V diag(1, ..., 1, s) U^T`` with ``H = U S V^T`` and ``s = det(V U^T)`` (Umeyama's
        fix), so every result has determinant ``+1``.
    """
    u, _, vt = np.linalg.svd(cross)
    v = np.swapaxes(vt, -1, -2)
    sign = np.sign(np.linalg.det(v @ np.swapaxes(u, -1, -2)))
    sign[sign == 0] = 1.0
    v[:, :, -1] *= sign[:, None]
    return v @ np.swapaxes(u, -1, -2)


@dataclass
class Moments:
    """Per-group weighted statistics of correspondences.

    With row weights ``w`` (all 1 unless given): ``count = sum w``, the weighted means,
    ``cross = sum w (a - mean_a)(b - mean_b)^T`` and ``scatter_x = sum w ||x - mean_x||^2``
    over the group's rows; ``size`` is the number of rows, whatever their weights.
    """

    count: np.ndarray
    mean_a: np.ndarray
    mean_b: np.ndarray
    cross: np.ndarray
    scatter_a: np.ndarray
    scatter_b: np.ndarray
    size: np.ndarray

    def take(self, index):
        """The statistics of the groups ``index``, in that order."""
        return Moments(*(np.asarray(x)[index] for x in vars(self).values()))

    def scaled(self, factor):
        """Every row weighted by ``factor`` (one per group): means unchanged."""
        factor = np.asarray(factor, dtype=float)
        return Moments(
            self.count * factor,
            self.mean_a,
            self.mean_b,
            self.cross * factor[:, None, None],
            self.scatter_a * factor,
            self.scatter_b * factor,
            self.size,
        )

    def __add__(self, other):
        """Statistics of the unions of the groups of ``self`` and ``other``, row by row."""
        count = self.count + other.count
        share = np.divide(other.count, count, out=np.zeros_like(count), where=count > 0)
        da = other.mean_a - self.mean_a
        db = other.mean_b - self.mean_b
        # Parallel-axis terms: the groups' centroids are apart.
        between = self.count * share
        return Moments(
            count,
            self.mean_a + share[:, None] * da,
            self.mean_b + share[:, None] * db,
            self.cross + other.cross + between[:, None, None] * da[:, :, None] * db[:, None, :],
            self.scatter_a + other.scatter_a + between * np.einsum("ij,ij->i", da, da),
            self.scatter_b + other.scatter_b + between * np.einsum("ij,ij->i", db, db),
            self.size + other.size,
        )

    def fit(self):
        """Least-squares motion of every group: ``(rotations, translations)``."""
        rotations = rotations_from_cross(self.cross)
        translations = self.mean_b - np.einsum("kij,kj->ki", rotations, self.mean_a)
        return rotations, translations

    def squared_error(self, rotations, translations):
        """``sum w ||b - R a - t||^2`` over each group's rows, under the motion given for it."""
        turned = np.einsum("kij,kji->k", rotations, self.cross)
        offset = self.mean_b - np.einsum("kij,kj->ki", rotations, self.mean_a) - translations
        error = self.scatter_b + self.scatter_a - 2.0 * turned
        error += self.count * np.einsum("ij,ij->i", offset, offset)
        return np.maximum(error, 0.0)


def group_moments(a, b, labels, n_groups, weights=None):
    """:class:`Moments` of every group; rows with negative labels are left out.

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
    labels : ndarray of shape (n,)
    n_groups : int
    weights : ndarray of shape (n,), default=None
        Positive weight of each row (the inverse variance of its noise); None: all 1.

    Returns
    -------
    Moments
        Arrays of length ``n_groups``; empty groups have zero count and statistics.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.moments import group_moments
    >>> a = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> m = group_moments(a, a + [1.0, 2.0, 3.0], np.zeros(4, int), 1)
    >>> rotations, translations = m.fit()
    >>> np.round(translations, 6) + 0.0
    array([[1., 2., 3.]])
    >>> float(m.squared_error(rotations, translations)[0]) < 1e-9
    True
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    labels = np.asarray(labels, dtype=np.intp)
    w = np.ones(len(labels)) if weights is None else np.asarray(weights, dtype=float)
    # The rows left out are summed into one extra group, dropped: each group's sums add
    # the same values in the same order as over its rows alone, without copying the rows.
    labels = np.where(labels >= 0, labels, n_groups)
    d = a.shape[1]
    size = np.bincount(labels, minlength=n_groups + 1)[:n_groups]

    def sums(column):
        return np.bincount(labels, weights=column, minlength=n_groups + 1)[:n_groups]

    count = sums(w)
    safe = np.where(count > 0, count, 1.0)
    mean_a = np.column_stack([sums(w * a[:, k]) for k in range(d)]) / safe[:, None]
    mean_b = np.column_stack([sums(w * b[:, k]) for k in range(d)]) / safe[:, None]
    # Centred first: raw second moments cancel badly far from the origin.
    ca = a - np.take(np.vstack([mean_a, np.zeros(d)]), labels, axis=0)
    cb = b - np.take(np.vstack([mean_b, np.zeros(d)]), labels, axis=0)
    wa = ca * w[:, None]
    cross = np.empty((n_groups, d, d))
    for p in range(d):
        for q in range(d):
            cross[:, p, q] = sums(wa[:, p] * cb[:, q])
    scatter_a = sums(np.einsum("ij,ij->i", wa, ca))
    scatter_b = sums(w * np.einsum("ij,ij->i", cb, cb))
    return Moments(count, mean_a, mean_b, cross, scatter_a, scatter_b, size)
