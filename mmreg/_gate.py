"""The distance gate of eq. (7) and the gated arg-max of the classification M-step.

The gate admits cluster ``j`` for a query point ``a`` when
``d_cluster(H_j, a) = min_{a' in H_j} ||a' - a|| < tau``. Testing every (point, cluster)
pair exactly would need ``n * K`` nearest-neighbour queries per EM iteration. Two facts
make almost all of them unnecessary:

* a point's own cluster always passes (its distance is 0), so a point needs a gate test
  only for the clusters that score *better* than its own cluster;
* a bounding ball per cluster (centroid ``c_j``, radius ``rho_j``) rejects the pair at
  once when ``||a - c_j|| >= rho_j + tau``.

So the arg-max is found by rounds: each pending point proposes its best-scoring cluster
not yet rejected; the proposals are tested with one KD-tree query per proposed cluster
(trees are built lazily, once per cluster and gate); rejected clusters are masked out and
the point proposes again. Each round is vectorised over points, and in practice one or
two rounds settle all points.
"""

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["ClusterGate", "gated_argmax"]


class ClusterGate:
    """Exact test of ``min_{a' in H_j} ||a' - a|| < radius`` for clusters ``H_j``.

    Parameters
    ----------
    points : ndarray of shape (n, d)
        The a-points of the clustered correspondences.
    labels : ndarray of shape (n,)
        Cluster of each point in ``0..n_clusters-1``; negative labels belong to no cluster.
    n_clusters : int
    radius : float or None
        The gate distance ``tau``; None admits every cluster everywhere.
    """

    def __init__(self, points, labels, n_clusters, radius):
        self.radius = radius
        self.n_clusters = n_clusters
        if radius is None:
            return
        keep = labels >= 0
        order = np.argsort(labels[keep], kind="stable")
        self._points = points[keep][order]
        counts = np.bincount(labels[keep], minlength=n_clusters)
        self._bounds = np.concatenate([[0], np.cumsum(counts)])
        self._trees = {}
        safe = np.maximum(counts, 1)[:, None]
        self._centers = np.add.reduceat(self._points, self._bounds[:-1], axis=0) / safe
        if len(self._points) == 0:
            self._centers = np.zeros((n_clusters, points.shape[1]))
        spread = np.linalg.norm(self._points - np.repeat(self._centers, counts, axis=0), axis=1)
        self._ball_radius = np.zeros(n_clusters)
        nonempty = counts > 0
        if nonempty.any():
            self._ball_radius[nonempty] = np.maximum.reduceat(spread, self._bounds[:-1][nonempty])
        self._ball_radius[~nonempty] = -np.inf

    def maybe_within(self, query):
        """Boolean ``(m, K)``: False where the bounding ball proves the gate closed."""
        if self.radius is None:
            return np.ones((len(query), self.n_clusters), dtype=bool)
        sq = (
            np.einsum("ij,ij->i", query, query)[:, None]
            - 2.0 * query @ self._centers.T
            + np.einsum("ij,ij->i", self._centers, self._centers)[None, :]
        )
        reach = self._ball_radius + self.radius
        # A small slack keeps rounding in the expansion from closing a gate that is open;
        # the exact test below decides every pair that survives.
        slack = 1e-9 * (1.0 + reach**2)
        return sq < np.where(np.isfinite(reach), reach**2, -1.0) + slack

    def within(self, query, cluster):
        """Exact gate of ``query`` points (m, d) against one cluster; boolean (m,)."""
        if self.radius is None:
            return np.ones(len(query), dtype=bool)
        tree = self._trees.get(cluster)
        if tree is None:
            lo, hi = self._bounds[cluster], self._bounds[cluster + 1]
            tree = self._trees[cluster] = cKDTree(self._points[lo:hi])
        dist, _ = tree.query(query, k=1, distance_upper_bound=self.radius)
        return dist < self.radius


def gated_argmax(scores, query, gate, own=None):
    """Row-wise arg-max of ``scores`` over the clusters the gate admits.

    Parameters
    ----------
    scores : ndarray of shape (m, K)
        Log weighted likelihoods; ``-inf`` marks clusters that may not be chosen.
        Modified in place.
    query : ndarray of shape (m, d)
        The a-point of each row.
    gate : ClusterGate
    own : ndarray of shape (m,), default=None
        Current cluster of each row (``-1`` for none). A point's own cluster is always
        admitted by the gate, and wins ties, so points do not move between equally
        likely clusters.

    Returns
    -------
    labels : ndarray of shape (m,)
        Chosen cluster, ``-1`` where every cluster is gated out.
    """
    m = len(scores)
    labels = np.full(m, -1, dtype=np.intp)
    if scores.shape[1] == 0 or m == 0:
        return labels
    rows = np.arange(m)
    own_score = np.full(m, -np.inf)
    if own is not None:
        has_own = own >= 0
        own_score[has_own] = scores[rows[has_own], own[has_own]]
    if gate.radius is not None:
        scores[~gate.maybe_within(query)] = -np.inf
    pending = rows
    while len(pending):
        candidate = np.argmax(scores[pending], axis=1)
        best = scores[pending, candidate]
        settle = (best <= own_score[pending]) | ~np.isfinite(best)
        if own is not None:
            settled = pending[settle]
            labels[settled] = np.where(np.isfinite(own_score[settled]), own[settled], -1)
        pending, candidate = pending[~settle], candidate[~settle]
        if gate.radius is None:
            labels[pending] = candidate
            break
        admitted = np.zeros(len(pending), dtype=bool)
        for cluster in np.unique(candidate):
            sel = np.flatnonzero(candidate == cluster)
            admitted[sel] = gate.within(query[pending[sel]], cluster)
        labels[pending[admitted]] = candidate[admitted]
        scores[pending[~admitted], candidate[~admitted]] = -np.inf
        pending = pending[~admitted]
    return labels
