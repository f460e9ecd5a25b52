"""The neighbour structure of the a-points: radius graphs and tau-connected components.

A set of points is *tau-connected* (Section IV) when any two of them are joined by a
chain of points with consecutive gaps of at most ``tau``: exactly when the radius graph
with edges ``||p - q|| <= tau`` is connected. These helpers are shared by the Euclidean
initialiser and the tests; :mod:`mmreg._array.connectivity` finds tau-connected pieces without
listing the pairs, for the large ``tau`` of the gate.
"""

import numpy as np
from joblib import cpu_count
from scipy import sparse
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree
from scipy.spatial import cKDTree

from mmreg._array.geometry import column_bounds

__all__ = [
    "NeighbourTable",
    "connected_labels",
    "lookup_tree",
    "minimum_spanning_forest",
    "nearest_in_other_component",
    "query_workers",
    "radius_graph",
    "shortest_edges_between_components",
    "touching_groups",
]

# Bounding boxes prune the searches between components up to this many components; each
# costs a pass over the points.
_BOX_PRUNING_MAX_COMPONENTS = 64


class NeighbourTable:
    """The ``k`` nearest neighbours of every point, computed once and widened on demand.

    Loops that ask the same points about their neighbourhood every iteration (with
    labels that change) query this table instead of building k-d trees anew.

    Parameters
    ----------
    points : ndarray of shape (n, d)
    k : int, default=16
        Neighbours kept for every point (itself included, first).
    workers : int, default=1
        Threads for the k-d tree queries (see :func:`query_workers`).
    tree : callable, default=cKDTree
        Builds the k-d tree of the points and of the subsets :meth:`nearest_among`
        asks about; :class:`~mmreg._array.point_tree.PointTree` halves the table's time
        on a LiDAR sweep (its distances scipy's to rounding).
    """

    def __init__(self, points, k=16, workers=1, tree=cKDTree):
        self.points = np.asarray(points, dtype=float)
        self._make_tree = tree
        self.tree = tree(self.points)
        self.workers = workers
        self.k = min(k, len(self.points))
        if self.k:
            distance, index = self.tree.query(self.points, k=self.k, workers=workers)
            self.distance = distance.reshape(len(self.points), self.k)
            self.index = index.reshape(len(self.points), self.k)
        else:
            self.distance = np.empty((0, 0))
            self.index = np.empty((0, 0), dtype=np.intp)

    def __len__(self):
        return len(self.points)

    def nearest(self, rows, k):
        """Distances and indices of the ``k`` nearest neighbours of ``rows``, sorted."""
        k = min(k, len(self.points))
        if k <= self.k:
            return self.distance[rows, :k], self.index[rows, :k]
        distance, index = self.tree.query(self.points[rows], k=k, workers=self.workers)
        return distance.reshape(len(rows), k), index.reshape(len(rows), k)

    def nearest_among(self, rows, among):
        """Distance from each of ``rows`` to its nearest other point where ``among``.

        Read off the table where one of a row's ``k`` neighbours qualifies (the first
        that does is the nearest: the table is exact and sorted); a KD-tree of the
        qualifying points answers the rest. The distances are those a KD-tree of the
        qualifying points alone would give. ``inf`` where no other point qualifies.

        Parameters
        ----------
        rows : ndarray of int
        among : ndarray of bool of shape (n,)
        """
        rows = np.asarray(rows, dtype=np.intp)
        out = np.full(len(rows), np.inf)
        if not len(rows):
            return out
        index = self.index[rows]
        listed = among[index] & (index != rows[:, None])
        first = np.argmax(listed, axis=1)
        found = listed[np.arange(len(rows)), first]
        out[found] = self.distance[rows[found], first[found]]
        rest = rows[~found]
        pool = np.flatnonzero(among)
        if len(rest) and len(pool):
            k = min(2, len(pool))
            subset = self.points[pool]
            pool_tree = (
                lookup_tree(subset) if self._make_tree is cKDTree else self._make_tree(subset)
            )
            distance, index = pool_tree.query(self.points[rest], k=k, workers=self.workers)
            distance = distance.reshape(len(rest), k)
            other = pool[index.reshape(len(rest), k)] != rest[:, None]
            first = np.argmax(other, axis=1)
            hit = other[np.arange(len(rest)), first]
            out[np.flatnonzero(~found)[hit]] = distance[hit, first[hit]]
        return out


def lookup_tree(points):
    """A k-d tree of ``points`` built for a few queries.

    scipy's sliding-midpoint build (``balanced_tree=False, compact_nodes=False``) costs
    half its default one on LiDAR sweeps, and its queries find the same distances; only
    which of several equidistant points a query lists first may differ. Trees queried
    by every point (:class:`NeighbourTable`) keep the default build, whose queries are
    faster.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.neighbors import lookup_tree
    >>> lookup_tree(np.array([[0.0, 0], [3, 4]])).query([[3.0, 3.0]])[0]
    array([1.])
    """
    return cKDTree(points, balanced_tree=False, compact_nodes=False)


def query_workers(n_jobs):
    """scipy's ``workers`` for k-d tree queries, from scikit-learn's ``n_jobs``.

    None means one thread (mmreg never takes every core unasked: the caller may already
    run several fits at once), -1 every core, ``-k`` all but ``k - 1`` of them (scipy
    itself accepts only -1 and positive counts).

    Examples
    --------
    >>> from mmreg._array.neighbors import query_workers
    >>> query_workers(None), query_workers(3)
    (1, 3)
    """
    if n_jobs is None:
        return 1
    n_jobs = int(n_jobs)
    if n_jobs == 0:
        raise ValueError(
            "n_jobs=0 means no thread at all; use None or 1 for one, -1 for every core."
        )
    if n_jobs < 0:
        return max(1, cpu_count() + 1 + n_jobs)
    return n_jobs


def radius_graph(points, radius, *, tree=None):
    """Symmetric sparse adjacency of the pairs at distance ``<= radius``.

    Parameters
    ----------
    points : ndarray of shape (n, d)
    radius : float
    tree : scipy.spatial.cKDTree, default=None
        A tree already built on ``points``, to reuse.

    Returns
    -------
    graph : scipy.sparse.csr_matrix of shape (n, n)
        Boolean adjacency without self-loops. Coincident points are adjacent (a sparse
        distance matrix would drop their zero distances).
    """
    points = np.asarray(points, dtype=float)
    n = len(points)
    if tree is None:
        tree = cKDTree(points)
    pairs = tree.query_pairs(radius, output_type="ndarray")
    data = np.ones(len(pairs), dtype=bool)
    graph = sparse.coo_matrix((data, (pairs[:, 0], pairs[:, 1])), shape=(n, n)).tocsr()
    return (graph + graph.T).tocsr()


def connected_labels(points, radius, *, tree=None):
    """Connected components of the radius graph: Euclidean cluster extraction.

    Returns
    -------
    n_components : int
    labels : ndarray of shape (n,)
        Component of each point; two points share a component iff a chain of points
        with gaps ``<= radius`` joins them.
    """
    graph = radius_graph(points, radius, tree=tree)
    return connected_components(graph, directed=False)


def minimum_spanning_forest(n_points, edges, lengths):
    """Minimum spanning forest of an undirected graph given as a list of weighted edges.

    Its edges of length ``<= r`` join exactly the points that the graph's edges of length
    ``<= r`` join, for every ``r``: single linkage on the graph.

    Parameters
    ----------
    n_points : int
    edges : ndarray of shape (m, 2)
        Point indices; direction, repeats and self-loops are allowed and ignored.
    lengths : ndarray of shape (m,)
        Non-negative edge lengths; zero (coincident points) is a real edge.

    Returns
    -------
    edges : ndarray of shape (n_points - n_components, 2)
    lengths : ndarray of shape (n_points - n_components,)
        Sorted by increasing length.
    """
    edges = np.asarray(edges, dtype=np.intp).reshape(-1, 2)
    lengths = np.asarray(lengths, dtype=float)
    keep = edges[:, 0] != edges[:, 1]
    edges, lengths = edges[keep], lengths[keep]
    # csgraph reads a stored zero as "no edge", so zero lengths travel as the tiniest float.
    tiny = np.finfo(float).tiny
    weights = np.maximum(lengths, tiny)
    shape = (n_points, n_points)
    graph = sparse.csr_matrix((weights, (edges[:, 0], edges[:, 1])), shape=shape)
    if graph.nnz < len(edges):
        # The same (row, column) listed twice was summed; keep the shortest copy instead.
        order = np.lexsort((weights, edges[:, 1], edges[:, 0]))
        edges, weights = edges[order], weights[order]
        first = np.ones(len(edges), dtype=bool)
        first[1:] = np.any(edges[1:] != edges[:-1], axis=1)
        graph = sparse.csr_matrix((weights[first], tuple(edges[first].T)), shape=shape)
    tree = sparse.coo_matrix(minimum_spanning_tree(graph))
    order = np.argsort(tree.data, kind="stable")
    tree_lengths = np.where(tree.data[order] <= tiny, 0.0, tree.data[order])
    return np.column_stack([tree.row[order], tree.col[order]]).astype(np.intp), tree_lengths


def _near_other_box(points, components, n_components, reach):
    """Whether each point lies within ``reach`` (per axis) of another component's box.

    ``reach`` is one distance or one per point. A per-axis (Chebyshev) test: it keeps
    every point within ``reach`` of another component's bounding box, and a few more
    near the boxes' corners, which the exact query that follows discards.
    """
    order = np.argsort(components, kind="stable")
    starts = np.searchsorted(components[order], np.arange(n_components))
    reach = np.asarray(reach, dtype=float)
    if reach.ndim:
        reach = reach[:, None]
    low = np.minimum.reduceat(points[order], starts, axis=0)
    high = np.maximum.reduceat(points[order], starts, axis=0)
    near = np.zeros(len(points), dtype=bool)
    for c in range(n_components):
        inside = np.all((points >= low[c] - reach) & (points <= high[c] + reach), axis=1)
        inside &= components != c
        near |= inside
    return near


def nearest_in_other_component(points, components, *, max_distance=np.inf, sources=None, workers=1):
    """Each point's nearest neighbour among the points of the other components.

    Parameters
    ----------
    points : ndarray of shape (n, d)
    components : ndarray of shape (n,)
        Non-negative component of each point.
    max_distance : float, default=inf
        Neighbours farther than this are not reported.
    sources : ndarray of shape (m,), default=None
        Indices of the points to find neighbours for; None means all. Neighbours are
        always sought among all points.
    workers : int, default=1
        Threads for the KD-tree queries (-1: all processors).

    Returns
    -------
    source, target : ndarray of shape (m,)
        ``target[i]`` is the nearest point to ``source[i]`` outside its component, for
        every source point that has one within ``max_distance`` (inclusive).
    distance : ndarray of shape (m,)

    Notes
    -----
    Two different components differ in some bit of their (compacted) index, so querying,
    for every bit, the points whose bit is 1 against a KD-tree of those whose bit is 0
    (and vice versa) finds every point's nearest foreign neighbour: ``2 log2(c)`` trees
    for ``c`` components, ``O(n log n log c)`` in all, never a list of all close pairs.
    With a finite ``max_distance`` and at most 64 components, points farther than it
    from every other component's bounding box are skipped.
    """
    points = np.asarray(points, dtype=float)
    _, components = np.unique(components, return_inverse=True)
    n = len(points)
    n_components = int(components.max()) + 1 if n else 0
    sources = np.arange(n) if sources is None else np.asarray(sources, dtype=np.intp)
    if np.isfinite(max_distance) and 1 < n_components <= _BOX_PRUNING_MAX_COMPONENTS:
        sources = sources[_near_other_box(points, components, n_components, max_distance)[sources]]
    best = np.full(n, np.inf)
    target = np.full(n, -1, dtype=np.intp)
    # cKDTree's bound is strict; the next float up makes it inclusive.
    bound = np.nextafter(max_distance, np.inf)
    for bit in range(max(n_components - 1, 0).bit_length()):
        side = ((components >> bit) & 1).astype(bool)
        for mine in (side, ~side):
            src = sources[mine[sources]]
            if not len(src):
                continue
            dst = np.flatnonzero(~mine)
            dist, idx = cKDTree(points[dst]).query(
                points[src], k=1, distance_upper_bound=bound, workers=workers
            )
            better = dist < best[src]
            best[src[better]] = dist[better]
            target[src[better]] = dst[idx[better]]
    found = np.flatnonzero(target >= 0)
    return found, target[found], best[found]


def shortest_edges_between_components(points, components, *, workers=1):
    """Each component's shortest edge to another component: one Boruvka step.

    Parameters
    ----------
    points : ndarray of shape (n, d)
    components : ndarray of shape (n,)
        Non-negative component of each point; at least two components.
    workers : int, default=1
        Threads for the KD-tree queries (-1: all processors).

    Returns
    -------
    edges : ndarray of shape (n_components, 2)
        For each component (in increasing order), a closest pair ``(p, q)`` with ``p``
        in it and ``q`` in another component.
    lengths : ndarray of shape (n_components,)

    Notes
    -----
    With at most 64 components, a few points of each bound its shortest edge from
    above, and only the points within that bound of another component's bounding box
    are searched: for separated objects, the facing sides.
    """
    points = np.asarray(points, dtype=float)
    _, components = np.unique(components, return_inverse=True)
    n_components = int(components.max()) + 1
    if n_components > _BOX_PRUNING_MAX_COMPONENTS:
        source, target, dist = nearest_in_other_component(points, components, workers=workers)
    else:
        order = np.argsort(components, kind="stable")
        sizes = np.bincount(components, minlength=n_components)
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        # Up to 16 points of each component, spread over its indices.
        take = np.minimum(sizes, 16)
        offsets = np.arange(take.sum()) - np.repeat(np.cumsum(take) - take, take)
        samples = order[np.repeat(starts, take) + offsets * np.repeat(sizes // take, take)]
        source, _, dist = nearest_in_other_component(
            points, components, sources=samples, workers=workers
        )
        bound = np.full(n_components, np.inf)
        np.minimum.at(bound, components[source], dist)
        near = _near_other_box(points, components, n_components, bound[components])
        candidates = np.flatnonzero(near)
        source, target, dist = nearest_in_other_component(
            points, components, max_distance=bound.max(), sources=candidates, workers=workers
        )
    order = np.lexsort((dist, components[source]))
    first = np.ones(len(order), dtype=bool)
    first[1:] = components[source[order[1:]]] != components[source[order[:-1]]]
    keep = order[first]
    return np.column_stack([source[keep], target[keep]]), dist[keep]


def touching_groups(points, labels, radius):
    """Pairs of groups ``(i, j)``, ``i < j``, with a point of each within ``radius``.

    The pairs of :meth:`scipy.spatial.cKDTree.query_pairs` whose two points lie in
    different groups, without listing the pairs within a group, which are nearly all of
    them when ``radius`` spans a few sampling gaps. Two points within ``radius`` lie in
    the same or adjacent cells of a grid of that side, so only the points of cells next
    to (or holding) another group's points go to ``query_pairs``.

    Parameters
    ----------
    points : ndarray of shape (n, d)
    labels : ndarray of shape (n,)
        Non-negative group of each point.
    radius : float

    Returns
    -------
    pairs : ndarray of shape (m, 2)
        Sorted rows, each pair once.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.neighbors import touching_groups
    >>> points = np.array([[0.0, 0], [1, 0], [2, 0], [3, 0], [9, 0]])
    >>> touching_groups(points, np.array([0, 0, 1, 2, 3]), 1.0)
    array([[0, 1],
           [1, 2]])
    """
    points = np.asarray(points, dtype=float)
    labels = np.asarray(labels, dtype=np.intp)
    near = _next_to_another_group(points, labels, radius)
    rows = np.flatnonzero(near)
    pairs = cKDTree(points[rows]).query_pairs(radius, output_type="ndarray")
    pairs = labels[rows[pairs]].reshape(-1, 2)
    pairs = np.sort(pairs[pairs[:, 0] != pairs[:, 1]], axis=1)
    return np.unique(pairs, axis=0)


def _next_to_another_group(points, labels, radius):
    """Whether each point's grid cell (side just over ``radius``) or one adjacent to it
    holds a point of another group; True everywhere when the grid cannot be used."""
    n, d = points.shape
    everywhere = np.ones(n, dtype=bool)
    if n < 2 or not (0 < radius < np.inf) or d > 3:
        return everywhere
    # Cells a hair wider than the radius: rounding cannot put a pair within the radius
    # two cells apart.
    low, high = column_bounds(points)
    side = radius * (1 + 1e-6)
    cells = np.floor((points - low) / side)
    shape = np.floor((high - low) / side) + 3
    if not np.all(np.isfinite(shape)) or np.prod(shape) >= 2.0**62:
        return everywhere
    shape = shape.astype(np.int64)
    codes = np.ravel_multi_index(tuple((cells + 1).astype(np.int64).T), shape)
    cell_codes, cell_of = np.unique(codes, return_inverse=True)
    cell_of = cell_of.ravel()
    n_cells = len(cell_codes)
    low = np.full(n_cells, np.iinfo(np.intp).max)
    high = np.full(n_cells, -1)
    np.minimum.at(low, cell_of, labels)
    np.maximum.at(high, cell_of, labels)
    # A cell is next to another group unless it and every occupied neighbour hold one
    # and the same group.
    flagged = low != high
    strides = np.ravel_multi_index(np.ones(d, dtype=np.int64), shape)
    for offset in np.ndindex(*(3,) * d):
        step = np.ravel_multi_index(np.array(offset), shape) - strides
        # Adjacency is symmetric: each pair of cells is looked up once, from the cell
        # with the lower code, and flags both.
        if step <= 0:
            continue
        neighbour = np.searchsorted(cell_codes, cell_codes + step)
        neighbour = np.minimum(neighbour, n_cells - 1)
        occupied = cell_codes[neighbour] == cell_codes + step
        other = occupied & ((low[neighbour] != low) | (high[neighbour] != high))
        flagged |= other
        flagged[neighbour[other]] = True
    return flagged[cell_of]
