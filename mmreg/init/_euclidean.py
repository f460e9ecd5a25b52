"""Euclidean cluster extraction: connected components of the radius graph of the a-points.

With ``radius`` given this is PCL's Euclidean cluster extraction. Otherwise the radius is
chosen so that about ``n_clusters`` components have ``min_cluster_size`` points or more.
The components at every radius are read off a minimum spanning forest (single linkage)
of a k-nearest-neighbour graph, which is then made exact up to the chosen radius: a
radius-graph edge missing from the k-NN graph can only join two points that both have
all their ``k`` nearest neighbours within the radius ("saturated" points), so only those
are searched for edges between different components; any found are added to the forest
and the radius is chosen again. When the k-NN graph falls apart into more pieces than
the count asked for (far-apart objects, few clusters wanted), Boruvka steps on the true
distances first join its trees."""

import warnings
from numbers import Integral, Real

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from sklearn.base import _fit_context
from sklearn.utils._param_validation import Interval

from mmreg._neighbors import (
    connected_labels,
    minimum_spanning_forest,
    nearest_in_other_component,
    shortest_edges_between_components,
)
from mmreg.init._partition import PartitionInitializer, number_by_first_point

__all__ = ["EuclideanClustering", "euclidean_clustering"]

# Listing the close pairs of the saturated points is faster than the per-bit KD-tree
# search of `nearest_in_other_component` until there are about this many per point.
_PAIRS_PER_POINT = 64


def _components(n_points, edges):
    graph = sparse.coo_matrix(
        (np.ones(len(edges), dtype=bool), (edges[:, 0], edges[:, 1])), shape=(n_points, n_points)
    )
    return connected_components(graph, directed=False)[1]


def _merge(sizes, edges):
    """Join nodes of the given sizes along edges: component of each node, component sizes."""
    components = _components(len(sizes), edges)
    return components, np.bincount(components, weights=sizes).astype(np.int64)


def _knn_edges(points, tree, n_neighbors, workers):
    """Edges of the k-NN graph and each point's reach: its farthest listed neighbour."""
    n = len(points)
    k = min(n_neighbors + 1, n)
    # Queries in the tree's own order touch memory in order: much faster for large n.
    order = tree.indices
    dist, idx = tree.query(points[order], k=k, workers=workers)
    dist, idx = dist.reshape(n, k), idx.reshape(n, k)
    edges = np.column_stack([np.repeat(order, k), idx.ravel()])
    # When every point is listed, no radius can add a neighbour that is not.
    reach = np.full(n, np.inf)
    if k < n:
        reach[order] = dist[:, -1]
    return edges, dist.ravel(), reach


def _radius_between(thresholds, k):
    """A radius whose radius graph includes the forest edges ``<= thresholds[k]`` only."""
    if k < 0:
        return thresholds[0] / 2
    if k + 1 < len(thresholds):
        # Midway, so that rounding in other distance computations cannot cross it.
        return (thresholds[k] + thresholds[k + 1]) / 2
    return 2 * thresholds[k] if thresholds[k] > 0 else 1.0


def _choose_radius(n_points, forest, forest_lengths, n_clusters, min_cluster_size):
    """Radius at which the forest has about ``n_clusters`` components of the minimum size.

    Index ``k`` stands for the forest's edges of length ``<= thresholds[k]`` (``-1``: no
    edge). An upward pass evaluates the ``k`` at which about ``n_clusters * 2**j``
    components remain, contracting the components found so far so that each pass costs
    only as much as the components left; a bisection between the last of them with at
    least ``n_clusters`` large components and the next one finishes.

    Returns
    -------
    None when even the longest forest edge leaves at least ``n_clusters`` large
    components among several trees (the forest must be completed first); otherwise
    ``(radius, components, reached)``.
    """
    # The lengths are sorted: their distinct values are where they change.
    changes = np.flatnonzero(np.diff(forest_lengths)) + 1
    thresholds = (
        forest_lengths[np.concatenate([[0], changes])] if len(forest_lengths) else forest_lengths
    )
    n_edges = np.searchsorted(forest_lengths, thresholds, side="right")
    last = len(thresholds) - 1
    # A forest with e edges has n - e components, and at most that many large ones.
    total = n_points - n_edges
    caps = [n_clusters - 1]
    while caps[-1] < n_points:
        caps.append(max(n_clusters, 2 * caps[-1]))
    candidates = np.searchsorted(-total, -np.array(caps), side="left")
    candidates = np.unique(np.append(candidates[candidates <= last], last))

    point_node, sizes = np.arange(n_points), np.ones(n_points, dtype=np.int64)
    counts = {}
    if len(thresholds) == 0 or thresholds[0] > 0:
        # A radius of 0 still joins coincident points, so "no edge" exists only without them.
        counts[-1] = int(np.count_nonzero(sizes >= min_cluster_size))
    lo = -1 if counts.get(-1, 0) >= n_clusters else None
    lo_state = point_node, sizes
    done = 0
    for k in candidates:
        components, sizes = _merge(sizes, point_node[forest[done : n_edges[k]]])
        point_node, done = components[point_node], n_edges[k]
        counts[k] = int(np.count_nonzero(sizes >= min_cluster_size))
        if counts[k] >= n_clusters:
            lo, lo_state = k, (point_node, sizes)
    if len(thresholds) == 0:
        return 0.0, point_node, n_points >= n_clusters
    if counts[last] >= n_clusters:
        if total[last] > 1:
            return None
        return _radius_between(thresholds, last), point_node, True
    if lo is None:
        # No radius tried reaches n_clusters: take the one with the most large components.
        best = max(counts, key=lambda k: (counts[k], k))
        stop = n_edges[best] if best >= 0 else 0
        return _radius_between(thresholds, best), _components(n_points, forest[:stop]), False

    # Bisection on the components at lo: n_large(lo) >= n_clusters > n_large(hi).
    hi = int(candidates[np.searchsorted(candidates, lo, side="right")])
    point_node, sizes = lo_state
    base = n_edges[lo] if lo >= 0 else 0
    bracket = point_node[forest[base : n_edges[hi]]]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        take = n_edges[mid] - base
        components, merged = _merge(sizes, bracket[:take])
        counts[mid] = int(np.count_nonzero(merged >= min_cluster_size))
        if counts[mid] >= n_clusters:
            lo, sizes, base = mid, merged, n_edges[mid]
            point_node, bracket = components[point_node], components[bracket[take:]]
        else:
            hi, bracket = mid, bracket[:take]
    if n_clusters - counts[hi] < counts[lo] - n_clusters:
        lo, point_node = hi, _merge(sizes, bracket)[0][point_node]
    return _radius_between(thresholds, lo), point_node, True


class _MissingEdges:
    """Radius-graph edges that join two components of the forest, found without the forest.

    An edge ``(p, q)`` of length ``<= r`` that the k-NN graph lacks needs both ``p`` and
    ``q`` saturated: each has its ``k`` listed neighbours within ``r``, else the other would
    be listed. The saturated points' neighbours within ``r`` are listed (more nearest
    neighbours, bounded by ``r``, until every list ends before ``r``) and kept, so a later
    check at a radius no larger only filters them. When that would list too many pairs,
    each saturated point's nearest neighbour in another component is searched instead.
    """

    def __init__(self, points, tree, reach, n_neighbors, workers):
        self.points = points
        self.tree = tree
        self.reach = reach
        self.n_neighbors = n_neighbors
        self.workers = workers
        self.listed_radius = -np.inf

    def _list_pairs(self, saturated, radius):
        n = len(self.points)
        bound = np.nextafter(radius, np.inf)
        sources, targets, lengths = [], [], []
        # In the tree's order, consecutive queries touch the same nodes: much faster.
        position = np.empty(n, dtype=np.intp)
        position[self.tree.indices] = np.arange(n)
        todo = saturated[np.argsort(position[saturated])]
        k = min(2 * (self.n_neighbors + 1), n)
        while len(todo):
            dist, idx = self.tree.query(
                self.points[todo], k=k, distance_upper_bound=bound, workers=self.workers
            )
            dist, idx = dist.reshape(len(todo), k), idx.reshape(len(todo), k)
            # Lists that reach the radius may miss neighbours: ask again for twice as many.
            full = np.isfinite(dist[:, -1]) & (k < n)
            row, col = np.nonzero(np.isfinite(dist) & ~full[:, None])
            # Only pairs of saturated points can be missing from the k-NN graph; each pair
            # is listed from both ends, so keep one.
            other = idx[row, col]
            keep = (self.reach[other] <= radius) & (todo[row] < other)
            sources.append(todo[row[keep]])
            targets.append(idx[row[keep], col[keep]])
            lengths.append(dist[row[keep], col[keep]])
            todo, k = todo[full], min(2 * k, n)
        self.pairs = np.column_stack([np.concatenate(sources), np.concatenate(targets)])
        # The query found these within the bound; keep that rounding from crossing radius.
        self.lengths = np.minimum(np.concatenate(lengths), radius)
        self.listed_radius = radius

    def __call__(self, components, radius):
        empty = np.zeros((0, 2), dtype=np.intp), np.zeros(0)
        if radius > self.listed_radius:
            saturated = np.flatnonzero(self.reach <= radius)
            if len(np.unique(components[saturated])) < 2:
                return empty
            with np.errstate(divide="ignore"):
                ratio = radius / self.reach[saturated]
            expected_pairs = np.sum((self.n_neighbors + 1) * ratio ** self.points.shape[1])
            if expected_pairs > _PAIRS_PER_POINT * len(self.points):
                source, target, lengths = nearest_in_other_component(
                    self.points[saturated],
                    components[saturated],
                    max_distance=radius,
                    workers=self.workers,
                )
                return saturated[np.column_stack([source, target])], np.minimum(lengths, radius)
            self._list_pairs(saturated, radius)
        close = self.lengths <= radius
        pairs, lengths = self.pairs[close], self.lengths[close]
        across = components[pairs[:, 0]] != components[pairs[:, 1]]
        return pairs[across], lengths[across]


def _complete_forest(points, forest, forest_lengths, workers):
    """Join the trees of the forest into one by Boruvka steps on the true distances."""
    n = len(points)
    while True:
        trees = _components(n, forest)
        if trees.max() == 0:
            return forest, forest_lengths
        edges, lengths = shortest_edges_between_components(points, trees, workers=workers)
        forest, forest_lengths = minimum_spanning_forest(
            n, np.vstack([forest, edges]), np.concatenate([forest_lengths, lengths])
        )


def _radius_for_count(points, n_clusters, min_cluster_size, n_neighbors, workers):
    n = len(points)
    tree = cKDTree(points)
    edges, lengths, reach = _knn_edges(points, tree, n_neighbors, workers)
    forest, forest_lengths = minimum_spanning_forest(n, edges, lengths)
    missing_edges = _MissingEdges(points, tree, reach, n_neighbors, workers)
    while True:
        choice = _choose_radius(n, forest, forest_lengths, n_clusters, min_cluster_size)
        if choice is None:
            forest, forest_lengths = _complete_forest(points, forest, forest_lengths, workers)
            continue
        radius, components, reached = choice
        missing, missing_lengths = missing_edges(components, radius)
        if not len(missing):
            return radius, components, reached
        forest, forest_lengths = minimum_spanning_forest(
            n, np.vstack([forest, missing]), np.concatenate([forest_lengths, missing_lengths])
        )


def euclidean_clustering(
    points, *, n_clusters=100, radius=None, min_cluster_size=4, n_neighbors=6, n_jobs=None
):
    """Euclidean cluster extraction on points, with a given or an automatic radius.

    Read more in :class:`EuclideanClustering`.

    Parameters
    ----------
    points : ndarray of shape (n, d)
    n_clusters : int, default=100
        Number of clusters of at least ``min_cluster_size`` points to aim for; used only
        when ``radius`` is None.
    radius : float or None, default=None
        Largest gap within a cluster. None chooses it from ``n_clusters``.
    min_cluster_size : int, default=4
        Components with fewer points are left out (label ``-1``).
    n_neighbors : int, default=6
        Neighbours per point in the k-NN graph that seeds the radius search.
    n_jobs : int or None, default=None
        Threads for the k-NN queries; None means 1, -1 all processors.

    Returns
    -------
    labels : ndarray of shape (n,)
        Component of each point in ``0..K-1``, in order of their first point; ``-1`` for
        points in components smaller than ``min_cluster_size``.
    radius : float
        The radius used.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.init import euclidean_clustering
    >>> points = np.array([[0.0, 0], [0.1, 0], [0.2, 0], [5, 0], [5.1, 0], [9, 9]])
    >>> labels, radius = euclidean_clustering(points, n_clusters=2, min_cluster_size=2)
    >>> labels
    array([ 0,  0,  0,  1,  1, -1])
    """
    points = np.asarray(points, dtype=float)
    n = len(points)
    if radius is not None:
        _, components = connected_labels(points, radius)
    elif n <= 1:
        radius, components = 0.0, np.zeros(n, dtype=np.intp)
    else:
        workers = 1 if n_jobs is None else n_jobs
        radius, components, reached = _radius_for_count(
            points, n_clusters, min_cluster_size, n_neighbors, workers
        )
        if not reached:
            found = int(np.count_nonzero(np.bincount(components) >= min_cluster_size))
            warnings.warn(
                f"No radius tried gives n_clusters={n_clusters} clusters of at least "
                f"min_cluster_size={min_cluster_size} points; using the radius {radius:.6g}, "
                f"which gives the most ({found}). Lower n_clusters or min_cluster_size.",
                UserWarning,
                stacklevel=2,
            )
    sizes = np.bincount(components, minlength=1)
    components = np.where(sizes[components] >= min_cluster_size, components, -1)
    return number_by_first_point(components)[0], float(radius)


class EuclideanClustering(PartitionInitializer):
    """Euclidean cluster extraction on the a-points, tuned to a number of clusters.

    The clusters are the connected components of the radius graph of the a-points
    (points at distance ``<= radius_`` are joined), as in PCL's Euclidean cluster
    extraction, so every cluster is ``radius_``-connected and any two clusters are more
    than ``radius_`` apart. Unless ``radius`` is given, the radius is chosen so that about
    ``n_clusters`` components have at least ``min_cluster_size`` points: the paper tunes
    this initialisation to about 100 clusters. With ``radius_ < tau`` every cluster is
    ``tau``-connected, as Definition 2 of the paper asks of an initial clustering.

    Parameters
    ----------
    n_clusters : int or None, default=100
        Number of clusters of at least ``min_cluster_size`` points to aim for. The count
        changes by one cluster at a time as the radius grows, so it is met exactly unless
        several components merge at the same distance, or the count is out of reach: then
        the radius giving the most clusters among those tried is used, with a warning.
        Ignored when ``radius`` is given.
    radius : float or None, default=None
        Largest gap within a cluster, in the units of the points. None chooses it from
        ``n_clusters``.
    min_cluster_size : int, default=4
        Components with fewer points get label ``-1``: no initial cluster. The EM does not
        fit poses to them but offers them to every cluster within ``tau`` at once. The
        default is the EM's own ``min_cluster_size``, below which it drops a cluster.
    n_neighbors : int, default=6
        Neighbours per point in the k-nearest-neighbour graph from which the single
        linkage is built. The clusters are exact whatever its value; it trades the cost
        of the k-NN graph against that of the edges the graph misses.
    n_jobs : int or None, default=None
        Threads for the k-NN queries; None means 1 and -1 all processors.

    Attributes
    ----------
    labels_ : ndarray of shape (n_samples,)
        Cluster of each correspondence in ``0..n_clusters_-1``, numbered in order of their
        first correspondence; ``-1`` for those in components below ``min_cluster_size``.
    n_clusters_ : int
        Number of clusters found.
    radius_ : float
        The radius used. When chosen automatically it lies midway between the distances at
        which the components last merged and next merge.
    n_features_in_ : int
        Number of columns of ``X`` (``2 * d``).

    See Also
    --------
    DBSCANClustering : Density-based clusters of the a-points.
    mmreg.init.describe_partition : Sizes and tau-connectivity of a partition.

    Notes
    -----
    ``transform`` returns the sparse one-hot membership matrix ``(n_samples,
    n_clusters_)``; a new correspondence joins the cluster of its nearest clustered
    a-point if that is within ``radius_`` (a new point could bridge two clusters; it is
    not allowed to merge them).

    Cost: one k-NN query (``O(n k log n)``), one minimum spanning forest of its ``n k``
    edges, connected-component passes over ever fewer contracted components to choose
    the radius (``O(n)`` in all), and one listing of the pairs within the radius among
    the points whose ``k`` nearest neighbours all lie within it. On this project's
    2-core machine, ``make_scene(noise=0.03)`` with ``n_clusters=100`` took 0.13 s for
    22,395 points, 0.5 s for 100,000 and 9 s for 1,000,000 (where the pair listing,
    about 12 pairs per point, and the spanning forest dominate). Asking for fewer
    clusters than there are far-apart groups of points adds Boruvka steps, ``O(n log n)``
    each (22,395 points, 7 objects, ``n_clusters=5``: 0.3 to 0.9 s). With an explicit
    ``radius`` the cost is that of the radius graph, which grows with the number of
    pairs within ``radius``.

    References
    ----------
    R. B. Rusu, "Semantic 3D Object Maps for Everyday Manipulation in Human Living
    Environments", PhD thesis, TU Munich, 2009 (Euclidean cluster extraction).

    Examples
    --------
    >>> from mmreg.datasets import make_scene
    >>> from mmreg.init import EuclideanClustering
    >>> X = make_scene(n_objects=3, n_points=600, random_state=0).X
    >>> init = EuclideanClustering(n_clusters=10, min_cluster_size=5).fit(X)
    >>> init.n_clusters_
    10
    >>> init.transform(X).shape
    (600, 10)
    """

    _parameter_constraints: dict = {
        "n_clusters": [Interval(Integral, 1, None, closed="left"), None],
        "radius": [Interval(Real, 0, None, closed="left"), None],
        "min_cluster_size": [Interval(Integral, 1, None, closed="left")],
        "n_neighbors": [Interval(Integral, 1, None, closed="left")],
        "n_jobs": [Integral, None],
    }

    def __init__(
        self, n_clusters=100, *, radius=None, min_cluster_size=4, n_neighbors=6, n_jobs=None
    ):
        self.n_clusters = n_clusters
        self.radius = radius
        self.min_cluster_size = min_cluster_size
        self.n_neighbors = n_neighbors
        self.n_jobs = n_jobs

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, X, y=None):
        """Cluster the a-points of ``X``.

        Parameters
        ----------
        X : array-like of shape (n_samples, 2 * d)
            Stacked correspondences ``[a | b]``; the first ``d`` columns are clustered.
        y : Ignored
            Not used, present for API consistency.

        Returns
        -------
        self : EuclideanClustering
            The fitted initialiser.
        """
        points = self._validate_points(X, reset=True)
        if self.n_clusters is None and self.radius is None:
            raise ValueError("EuclideanClustering needs n_clusters or radius; both are None.")
        labels, self.radius_ = euclidean_clustering(
            points,
            n_clusters=self.n_clusters,
            radius=self.radius,
            min_cluster_size=self.min_cluster_size,
            n_neighbors=self.n_neighbors,
            n_jobs=self.n_jobs,
        )
        self.labels_ = labels
        self.n_clusters_ = int(labels.max()) + 1 if len(labels) else 0
        self._clustered_points = points[labels >= 0]
        return self

    def _assign(self, points):
        out = np.full(len(points), -1, dtype=np.intp)
        if not len(self._clustered_points):
            return out
        tree = cKDTree(self._clustered_points)
        dist, idx = tree.query(points, k=1, distance_upper_bound=np.nextafter(self.radius_, np.inf))
        near = np.isfinite(dist)
        out[near] = self.labels_[self.labels_ >= 0][idx[near]]
        return out
