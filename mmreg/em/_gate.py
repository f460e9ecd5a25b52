"""The distance gate of eq. (7): is cluster ``j`` within ``tau`` of a query point?

The gate admits cluster ``j`` for a query point ``a`` when
``d_cluster(H_j, a) = min_{a' in H_j} ||a' - a|| <= tau``. Eq. (7) writes ``< tau``, but
Definitions 1 and 2 call points at most ``tau`` apart ``tau``-connected; with a strict gate,
pieces of an object exactly ``tau`` apart would never meet, against Theorem 1 (see
``tests/test_theory_counterexamples.py``). Testing every (point, cluster)
pair exactly would need ``n * K`` nearest-neighbour queries per EM iteration. The
classification step (:func:`mmreg.em._likelihood.classify`) asks only about the few pairs
where a cluster scores better than the point's own one, and three tests, cheapest first,
settle almost all of those:

* a bounding ball per cluster (centroid ``c_j``, radius ``rho_j``) closes the gate when
  ``||a - c_j|| > rho_j + tau``;
* a few representative members per cluster (the one nearest the centroid, the first and
  the last) open it when one of them is within ``tau``;
* the exact nearest-member distance decides the rest: by brute force for a handful of
  queries, else with a KD-tree of the cluster built once per gate.
"""

import numpy as np

from mmreg._array.grouping import unique_sorted
from mmreg._array.neighbors import lookup_tree

__all__ = ["ClusterGate", "gated_argmax"]

# Brute force beats building a KD-tree below this many (query, member) distance pairs.
_BRUTE_FORCE_PAIRS = 2**17


class ClusterGate:
    """Exact test of ``min_{a' in H_j} ||a' - a|| <= radius`` for clusters ``H_j``.

    Parameters
    ----------
    points : ndarray of shape (n, d)
        The a-points of the clustered correspondences.
    labels : ndarray of shape (n,)
        Cluster of each point in ``0..n_clusters-1``; negative labels belong to no cluster.
    n_clusters : int
    radius : float or None
        The gate distance ``tau``; None admits every cluster everywhere.
    centers : ndarray of shape (n_clusters, d), default=None
        Centroid of each cluster's points, if already known.
    spread : ndarray of shape (n,), default=None
        Distance of each clustered point to its cluster's centroid, if already known.
    ungated : array-like of int, default=()
        Clusters admitted everywhere, however far (the static world, which is one
        object however far apart its visible pieces lie).
    workers : int, default=1
        Threads of the KD-tree queries of the exact test (``-1``: every core).
    """

    def __init__(
        self,
        points,
        labels,
        n_clusters,
        radius,
        *,
        centers=None,
        spread=None,
        ungated=(),
        workers=1,
    ):
        self.radius = radius
        self.workers = workers
        self.n_clusters = n_clusters
        self._ungated = np.zeros(n_clusters, dtype=bool)
        self._ungated[np.asarray(ungated, dtype=np.intp)] = True
        if radius is None:
            return
        points = np.asarray(points, dtype=float)
        labels = np.asarray(labels, dtype=np.intp)
        # Points in no cluster go to an extra group n_clusters, so that every per-cluster
        # reduction below runs over all points without first copying out a subset.
        if len(labels) and labels.min() < 0:
            labels = np.where(labels < 0, n_clusters, labels)
        self._points = points
        self._labels = labels
        self._members = None
        self._trees = {}
        if centers is None:
            counts = np.bincount(labels, minlength=n_clusters + 1)[: n_clusters + 1]
            centers = np.empty((n_clusters + 1, points.shape[1]))
            for axis in range(points.shape[1]):
                centers[:, axis] = np.bincount(
                    labels, weights=points[:, axis], minlength=n_clusters + 1
                )[: n_clusters + 1]
            centers /= np.maximum(counts, 1)[:, None]
            centers = centers[:n_clusters]
        self._centers = np.asarray(centers, dtype=float).reshape(n_clusters, points.shape[1])
        if spread is None:
            centred = points - np.vstack([self._centers, np.zeros(points.shape[1])])[labels]
            spread = np.sqrt(np.einsum("ij,ij->i", centred, centred))
        ball_radius = np.full(n_clusters + 1, -np.inf)
        np.maximum.at(ball_radius, labels, spread)
        self._ball_radius = ball_radius[:n_clusters]
        self._spread = spread
        self._representatives = None

    def reach_box(self, low, high):
        """Clusters whose bounding ball comes within ``radius`` of the box ``[low, high]``.

        Returns the sorted cluster indices; a superset of every cluster the gate admits
        for a query point inside the box.
        """
        return np.flatnonzero(self.reach_boxes(low[None], high[None])[0])

    def reach_boxes(self, low, high):
        """Boolean ``(m, K)``: may cluster ``j`` be admitted anywhere in box ``i``?

        ``low`` and ``high`` of shape ``(m, d)`` are the corners of ``m`` boxes. False
        means that the bounding ball of the cluster, grown by ``radius``, misses the box.
        """
        if self.radius is None:
            return np.ones((len(low), self.n_clusters), dtype=bool)
        centers = self._centers[None]
        gap = np.maximum(np.maximum(low[:, None] - centers, centers - high[:, None]), 0.0)
        sq = np.einsum("mkj,mkj->mk", gap, gap)
        reach = self._ball_radius + self.radius
        # A relative slack keeps rounding from closing an open gate; the exact test
        # decides every pair that survives.
        slack = 1e-9 * (1.0 + reach**2)
        return ((reach >= 0) & (sq < reach**2 + slack)) | self._ungated

    def _ball_open(self, query, clusters):
        """False where the bounding ball proves the gate of ``clusters`` closed."""
        diff = query - self._centers[clusters]
        sq = np.sum(diff * diff, axis=-1)
        reach = self._ball_radius[clusters] + self.radius
        slack = 1e-9 * (1.0 + reach**2)
        return ((reach >= 0) & (sq < reach**2 + slack)) | self._ungated[clusters]

    def admits(self, query, clusters):
        """Exact gate of each query point against the cluster given for it; boolean (m,).

        Parameters
        ----------
        query : ndarray of shape (m, d)
        clusters : ndarray of shape (m,)
            The cluster to test for each query point.
        """
        if self.radius is None:
            return np.ones(len(query), dtype=bool)
        result = self._ungated[clusters]
        open_ = np.flatnonzero(~result & self._ball_open(query, clusters))
        if len(open_) == 0:
            return result
        if self._representatives is None:
            self._representatives = self._find_representatives()
        reps = self._representatives[clusters[open_]]
        diff = query[open_, None, :] - self._points[reps]
        # Same arithmetic as a KD-tree distance: square root of the sum of squares.
        dist = np.sqrt(np.sum(diff * diff, axis=-1)).min(axis=1)
        near = dist <= self.radius
        result[open_[near]] = True
        undecided = open_[~near]
        if len(undecided):
            order = np.argsort(clusters[undecided], kind="stable")
            undecided = undecided[order]
            targets, starts = unique_sorted(clusters[undecided])
            for cluster, part in zip(targets, np.split(undecided, starts[1:]), strict=True):
                result[part] = self.within(query[part], cluster)
        return result

    def _find_representatives(self):
        """A few members per cluster: the one nearest the centroid, the first and the last.

        Returns point indices of shape ``(n_clusters, 3)``; an empty cluster's row points
        at a member of no particular cluster, whose test its closed ball overrides.
        """
        k, labels, spread = self.n_clusters, self._labels, self._spread
        n = len(labels)
        representatives = np.zeros((k + 1, 3), dtype=np.intp)
        nearest = np.full(k + 1, np.inf)
        np.minimum.at(nearest, labels, spread)
        hit = np.flatnonzero(spread == nearest[labels])
        representatives[labels[hit], 0] = hit
        # Fancy assignment keeps the last write: the last and the first member.
        representatives[labels, 1] = np.arange(n)
        representatives[labels[::-1], 2] = np.arange(n)[::-1]
        return representatives[:k]

    def within(self, query, cluster):
        """Exact gate of ``query`` points (m, d) against one cluster; boolean (m,)."""
        if self.radius is None or self._ungated[cluster]:
            return np.ones(len(query), dtype=bool)
        members = self._cluster_points(cluster)
        if len(members) == 0:
            return np.zeros(len(query), dtype=bool)
        tree = self._trees.get(cluster)
        if tree is None and len(query) * len(members) <= _BRUTE_FORCE_PAIRS:
            dist = np.empty(len(query))
            step = max(1, _BRUTE_FORCE_PAIRS // (8 * len(members)))
            for start in range(0, len(query), step):
                diff = query[start : start + step, None, :] - members[None, :, :]
                dist[start : start + step] = np.sqrt(np.sum(diff * diff, axis=-1)).min(axis=1)
            return dist <= self.radius
        if tree is None:
            tree = self._trees[cluster] = lookup_tree(members)
        # The tree reports only distances below the bound; one ulp more keeps "== radius".
        bound = np.nextafter(self.radius, np.inf)
        dist, _ = tree.query(query, k=1, distance_upper_bound=bound, workers=self.workers)
        return dist <= self.radius

    def _cluster_points(self, cluster):
        if self._members is None:
            # Group the points by cluster once, on the first exact test that needs it.
            k = self.n_clusters
            small = self._labels.astype(np.uint16) if k < 2**16 else self._labels
            order = np.argsort(small, kind="stable")
            counts = np.bincount(self._labels, minlength=k + 1)
            self._members = (self._points[order], np.concatenate([[0], np.cumsum(counts)]))
        points, bounds = self._members
        return points[bounds[cluster] : bounds[cluster + 1]]


def gated_argmax(scores, query, gate, own=None, *, columns=None, tolerance=None, refine=None):
    """Row-wise arg-max of ``scores`` over the clusters the gate admits.

    Parameters
    ----------
    scores : ndarray of shape (m, k)
        Log weighted likelihoods; ``-inf`` marks clusters that may not be chosen.
        Modified in place.
    query : ndarray of shape (m, d)
        The a-point of each row.
    gate : ClusterGate
    own : ndarray of shape (m,), default=None
        Current cluster of each row (``-1`` for none). A point's own cluster is always
        admitted by the gate, and wins ties, so points do not move between equally
        likely clusters; other ties go to the lowest cluster index.
    columns : ndarray of shape (k,), default=None
        The cluster of each column, increasing, and containing every ``own`` cluster;
        None means ``0..k-1``.
    tolerance : ndarray of shape (k,), default=None
        Bound on the rounding error of each column of ``scores``. A row in which another
        column comes within the tolerance of the best one is recomputed with ``refine``
        before it is decided, so that near-ties are decided on accurate scores.
    refine : callable, default=None
        ``refine(rows)`` returns accurate scores of shape ``(len(rows), k)``.

    Returns
    -------
    labels : ndarray of shape (m,)
        Chosen cluster, ``-1`` where every cluster is gated out.
    """
    m, k = scores.shape
    labels = np.full(m, -1, dtype=np.intp)
    if k == 0 or m == 0:
        return labels
    if columns is None:
        columns = np.arange(k)
    rows = np.arange(m)
    candidate = np.argmax(scores, axis=1)
    refined = None
    if refine is not None:
        refined = np.zeros(m, dtype=bool)
        _refine_near_ties(scores, rows, candidate, tolerance, refine, refined)
    best = scores[rows, candidate]
    own_score = np.full(m, -np.inf)
    own_column = np.full(m, -1, dtype=np.intp)
    if own is not None:
        has_own = np.flatnonzero(own >= 0)
        own_column[has_own] = np.searchsorted(columns, own[has_own])
        own_score[has_own] = scores[has_own, own_column[has_own]]
        # By default a row stays where it is: in its own cluster, or in none.
        labels[has_own] = own[has_own]
    # Rows with a cluster strictly better than their own one (or any finite one if they
    # have none) move there if the gate admits it; ties keep the own cluster.
    pending = np.flatnonzero(best > own_score)
    if gate.radius is None:
        labels[pending] = columns[candidate[pending]]
        return labels
    rounds = 0
    while len(pending):
        admitted = gate.admits(query[pending], columns[candidate[pending]])
        labels[pending[admitted]] = columns[candidate[pending[admitted]]]
        pending = pending[~admitted]
        if len(pending) == 0:
            break
        scores[pending, candidate[pending]] = -np.inf
        rounds += 1
        if rounds == 2:
            # Rows still undecided tend to face many closed gates (say, far objects with
            # the same motion): rule out at once every cluster whose ball is out of reach.
            closed = ~gate._ball_open(query[pending, None, :], columns[None, :])
            sub = scores[pending]
            sub[closed] = -np.inf
            scores[pending] = sub
        candidate[pending] = np.argmax(scores[pending], axis=1)
        if refine is not None:
            redone = _refine_near_ties(scores, pending, candidate, tolerance, refine, refined)
            # Compare accurate scores with accurate scores.
            redone = redone[own_column[redone] >= 0]
            own_score[redone] = scores[redone, own_column[redone]]
        pending = pending[scores[pending, candidate[pending]] > own_score[pending]]
    return labels


def _refine_near_ties(scores, rows, candidate, tolerance, refine, refined):
    """Recompute the rows whose best column is not clearly ahead of every other one.

    ``rows`` are the rows to check, ``candidate`` the arg-max of every row of ``scores``
    (updated in place for the recomputed rows), ``refined`` marks the rows recomputed so
    far (updated in place). Returns the rows recomputed now.
    """
    none = np.zeros(0, dtype=np.intp)
    rows = rows[~refined[rows]]
    if len(rows) == 0:
        return none
    whole = len(rows) == len(scores)
    table = scores if whole else scores[rows]
    best = scores[rows, candidate[rows]]
    # A cheap test with the largest tolerance first, the exact one on the survivors.
    threshold = best - 2 * tolerance.max()
    k = len(tolerance)
    if k <= 16:
        # Short rows: a near-tie if the first and the last column within reach of the
        # best one differ (two arg-max calls, much faster than counting along a short
        # axis).
        near = table >= threshold[:, None]
        first = np.argmax(near, axis=1)
        last = np.argmax(near[:, ::-1], axis=1)
        maybe = np.flatnonzero(first + last != k - 1)
    else:
        # Long rows: the best of the other columns, with the best one masked out.
        local = np.arange(len(rows))
        table[local, candidate[rows]] = -np.inf
        runner_up = table.max(axis=1)
        table[local, candidate[rows]] = best
        maybe = np.flatnonzero(runner_up >= threshold)
    if len(maybe) == 0:
        return none
    floor = best[maybe] - tolerance[candidate[rows[maybe]]]
    near = table[maybe] + tolerance >= floor[:, None]
    ambiguous = rows[maybe[np.count_nonzero(near, axis=1) > 1]]
    if len(ambiguous) == 0:
        return none
    accurate = refine(ambiguous)
    # Keep the clusters already ruled out by the gate ruled out.
    accurate[np.isneginf(scores[ambiguous])] = -np.inf
    scores[ambiguous] = accurate
    refined[ambiguous] = True
    candidate[ambiguous] = np.argmax(accurate, axis=1)
    return ambiguous
