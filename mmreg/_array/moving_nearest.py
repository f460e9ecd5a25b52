"""Nearest neighbours of points that move a little at a time, re-queried only where needed.

An ICP asks a k-d tree for the nearest target point of every moved point at every
iteration, yet after the first steps its points move by millimetres while its target
points lie centimetres apart. Each point keeps the position of its last query (its
anchor) and its ``k`` nearest target points there, the farthest at ``d_k``. Moved by
``s`` from its anchor, every other target point is at least ``d_k - s`` away (the
triangle inequality): when the nearest of the ``k`` is nearer than that, and nearer than
the next of them, it is the nearest of all, found without a query; only the other
points are queried again. The answers are those of
``tree.query(x, distance_upper_bound=bound)`` itself: a margin far above the rounding of
the distances keeps every decision away from a tie or a bound.
"""

import numpy as np

__all__ = ["MovingNearest"]

# Decisions within this share of the coordinates' magnitude of a tie or a bound are left
# to the k-d tree (distances computed two ways differ by a few ulps, 1e-16 of it).
_RELATIVE_MARGIN = 1e-9
# Target points kept per moving point: more survive longer moves but cost more to query
# and check (2 was the fastest of 2-8 on the ICPs of three Argoverse 2 pairs).
_CANDIDATES = 2


class MovingNearest:
    """The nearest target point of each of ``n`` moving points, within a bound.

    Parameters
    ----------
    tree : cKDTree
        The target points' tree.
    n : int
        Number of moving points; they are named by their row ``0..n-1`` in every call.
    bound : float
        As ``tree.query``'s ``distance_upper_bound``: no neighbour at or beyond it.
    workers : int, default=1
        Threads of the k-d tree queries.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.spatial import cKDTree
    >>> from mmreg._array.moving_nearest import MovingNearest
    >>> target = np.array([[0.0, 0, 0], [1, 0, 0], [5, 0, 0]])
    >>> nearest = MovingNearest(cKDTree(target), 2, bound=2.0)
    >>> x = np.array([[0.1, 0, 0], [3.0, 9.0, 0]])  # the second far from every target point
    >>> nearest(x, np.arange(2))[1].tolist()
    [0, 3]
    >>> nearest(x + 0.01, np.arange(2))[1].tolist()  # the first from its anchor, no query
    [0, 3]
    """

    def __init__(self, tree, n, bound, workers=1):
        self.tree = tree
        self.bound = float(bound)
        self.workers = workers
        data = np.asarray(tree.data, dtype=float)
        self.k = min(_CANDIDATES, len(data))
        magnitude = max(1.0, float(np.abs(data).max()) if len(data) else 1.0)
        if np.isfinite(self.bound):
            magnitude = max(magnitude, self.bound)
        self.margin = _RELATIVE_MARGIN * magnitude
        # The target points and, at ``len(data)`` (the tree's "none"), one infinitely far.
        self.padded = np.vstack([data, np.full((1, data.shape[1]), np.inf)])
        self.anchor = np.full((n, data.shape[1]), np.nan)
        self.candidates = np.full((n, self.k), len(data), dtype=np.intp)
        self.where = np.full((n, self.k, data.shape[1]), np.inf)  # the candidates' points
        # min(d_k, bound): within this of its anchor no target point but the candidates.
        self.clear = np.full(n, -np.inf)
        self.n_queried = 0

    def __call__(self, x, rows, gate=None):
        """Distances and indices of the nearest target points of ``x``, the points ``rows``.

        ``tree.query(x, distance_upper_bound=bound)``'s answer (``inf`` and
        ``len(target)`` for none within the bound), except that where a point's nearest
        target point was known without a query its distance is computed here, equal to
        the tree's to a few ulps; ``gate`` (per point, or None), the distances that the
        caller compares with ``<=``, is kept a margin away from those.
        """
        x = np.asarray(x, dtype=float)
        rows = np.asarray(rows, dtype=np.intp)
        distance = np.full(len(rows), np.inf)
        nearest = np.full(len(rows), len(self.tree.data), dtype=np.intp)
        step = x - self.anchor[rows]
        shift = np.sqrt(np.einsum("ni,ni->n", step, step))  # NaN: never queried
        known = np.flatnonzero(shift < self.clear[rows])
        if len(known):
            held = rows[known]
            gap = self.where[held] - x[known, None, :]
            squared = np.einsum("nki,nki->nk", gap, gap)  # inf where no candidate
            best = np.argmin(squared, axis=1)
            across = np.arange(len(known))
            first = np.sqrt(squared[across, best])
            squared[across, best] = np.inf
            second = np.sqrt(squared.min(axis=1))
            sure = (first + self.margin < self.clear[held] - shift[known]) & (
                first + self.margin < second
            )
            if gate is not None:  # a distance this close to its gate is the tree's to give
                sure &= np.abs(first - np.asarray(gate)[known]) > self.margin
            known = known[sure]
            distance[known] = first[sure]
            nearest[known] = self.candidates[held[sure], best[sure]]
        ask = np.ones(len(rows), dtype=bool)
        ask[known] = False
        ask = np.flatnonzero(ask)
        if len(ask) and self.k:
            distance[ask], nearest[ask] = self._query(x[ask], rows[ask])
        return distance, nearest

    def _query(self, x, rows):
        """The tree's answer for ``x``; the points' anchors and candidates renewed."""
        self.n_queried += len(x)
        k = self.k
        distance, index = self.tree.query(
            x, k=k, distance_upper_bound=self.bound, workers=self.workers
        )
        distance, index = distance.reshape(len(x), k), index.reshape(len(x), k)
        first, nearest = distance[:, 0].copy(), index[:, 0].copy()
        # Two target points (nearly) as near: which one a single query lists is the
        # tree's choice, so that query is made.
        tie = np.zeros(0, dtype=np.intp)
        if k > 1:
            with np.errstate(invalid="ignore"):  # inf - inf where none is within the bound
                tie = np.flatnonzero(np.isfinite(first) & (distance[:, 1] - first <= self.margin))
        if len(tie):
            first[tie], nearest[tie] = self.tree.query(
                x[tie], distance_upper_bound=self.bound, workers=self.workers
            )
        self.anchor[rows] = x
        self.candidates[rows] = index
        self.where[rows] = self.padded[index]
        self.clear[rows] = np.minimum(distance[:, -1], self.bound)
        return first, nearest
