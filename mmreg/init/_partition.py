"""What mmreg's initialisers share: input checks, the fitted layout and ``transform``."""

import numpy as np
from scipy import sparse
from sklearn.utils.validation import check_is_fitted, validate_data

from mmreg._validation import split_correspondences
from mmreg.init._base import BaseInitializer

__all__ = ["PartitionInitializer", "membership_matrix", "number_by_first_point"]


def membership_matrix(labels, n_clusters):
    """Sparse one-hot matrix of a partition.

    Parameters
    ----------
    labels : ndarray of shape (n,)
        Cluster of each row in ``0..n_clusters-1``; negative for none.
    n_clusters : int

    Returns
    -------
    membership : scipy.sparse.csr_matrix of shape (n, n_clusters), dtype float64
        ``membership[i, j] == 1`` iff row ``i`` is in cluster ``j``; rows in no cluster
        are all zero.
    """
    labels = np.asarray(labels)
    rows = np.flatnonzero(labels >= 0)
    data = np.ones(len(rows))
    return sparse.csr_matrix((data, (rows, labels[rows])), shape=(len(labels), n_clusters))


def number_by_first_point(labels):
    """Renumber the non-negative labels ``0..K-1`` in order of their first row; negatives -1.

    Makes the numbering a function of the partition alone, whatever order a backend
    discovered its clusters in.

    Returns
    -------
    labels : ndarray of shape (n,)
    n_clusters : int
    """
    labels = np.asarray(labels)
    out = np.full(labels.shape, -1, dtype=np.intp)
    keep = np.flatnonzero(labels >= 0)
    uniques, first, inverse = np.unique(labels[keep], return_index=True, return_inverse=True)
    rank = np.empty(len(uniques), dtype=np.intp)
    rank[np.argsort(first)] = np.arange(len(uniques))
    out[keep] = rank[inverse]
    return out, len(uniques)


class PartitionInitializer(BaseInitializer):
    """Private base of mmreg's initialisers: a fitted partition and its one-hot transform.

    A subclass implements ``fit`` (which calls :meth:`_validate_points` and sets
    ``labels_`` and ``n_clusters_``) and ``_assign(points)``, the cluster of new a-points
    (``-1`` for none). ``transform`` returns the sparse one-hot membership matrix of
    :func:`membership_matrix`.
    """

    def _validate_points(self, X, *, reset):
        """Check the stacked correspondences ``X``; return their a-points."""
        X = validate_data(self, X, reset=reset, dtype=np.float64)
        return split_correspondences(X)[0]

    def fit_transform(self, X, y=None):
        """Fit, then return the one-hot membership of the fitted partition.

        Parameters
        ----------
        X : array-like of shape (n_samples, 2 * d)
            Stacked correspondences ``[a | b]``.
        y : Ignored
            Not used, present for API consistency.

        Returns
        -------
        membership : scipy.sparse.csr_matrix of shape (n_samples, n_clusters_)
            One in the column of each row's cluster; rows in no cluster are zero.
        """
        self.fit(X)
        return membership_matrix(self.labels_, self.n_clusters_)

    def transform(self, X):
        """One-hot membership of the correspondences ``X`` in the fitted clusters.

        Parameters
        ----------
        X : array-like of shape (n_samples, 2 * d)
            Stacked correspondences ``[a | b]``.

        Returns
        -------
        membership : scipy.sparse.csr_matrix of shape (n_samples, n_clusters_)
            One in the column of each row's cluster (see the class's Notes for how new
            rows are assigned); rows in no cluster are zero.
        """
        check_is_fitted(self, "labels_")
        points = self._validate_points(X, reset=False)
        return membership_matrix(self._assign(points), self.n_clusters_)

    def _assign(self, points):
        raise NotImplementedError

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = False
        return tags
