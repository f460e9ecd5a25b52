"""Euclidean cluster extraction: connected components of the radius graph of the a-points.

With ``radius`` given this is PCL's Euclidean cluster extraction. Otherwise the radius is
chosen so that about ``n_clusters`` components have ``min_cluster_size`` points or more.
The components at every radius are read off a minimum spanning forest (single linkage)
of a k-nearest-neighbour graph, which is then made exact up to the chosen radius: a
radius-graph edge missing from the k-NN graph can only join two points that both have
all their ``k`` nearest neighbours within the radius ("saturated" points), so only those
are searched for edges between different components; any found are added to the forest
and the radius is chosen again. When the k-NN graph falls apart into more pieces than
the count asked for (far-apart objects, few clusters wanted), its trees are first joined
by the minimum spanning tree between them on the true distances (what Boruvka steps
would add), up to the length that the choice of the radius can need; when every tree is
whole at the chosen radius, that completion alone makes the forest exact there and no
search for missing edges is needed (:func:`_no_missing_edges`).

The searches between components, exact to the last bit of every distance, run on a grid
pyramid (:class:`_GridPyramid`): the points sorted by component and Z-order, one node per
component and cell at every scale, and pairs of nodes refined a level at a time while
their bounding boxes can still hold an answer - a dual-tree search on arrays, with no
loop over points and no list of all the pairs within a radius."""

import functools
import warnings
from numbers import Integral, Real

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree
from scipy.spatial import cKDTree
from sklearn.base import _fit_context
from sklearn.utils._param_validation import Interval

from mmreg._array.connectivity import tau_components
from mmreg._array.neighbors import (
    connected_labels,
    minimum_spanning_forest,
    nearest_in_other_component,
    query_workers,
)
from mmreg._warnings import user_stacklevel
from mmreg.init._partition import PartitionInitializer, number_by_first_point

__all__ = ["EuclideanClustering", "euclidean_clustering"]

# Listing the close pairs of the saturated points is faster than the per-bit KD-tree
# search of `nearest_in_other_component` until there are about this many per point.
_PAIRS_PER_POINT = 64
# Above this dimension the grid pyramid's 2**d children per cell cost too much, and a
# KD-tree sums squared distances in another order: the KD-tree searches are used instead.
_MAX_PYRAMID_DIM = 6
# The searches between groups refine their pairs of cells level by level; when there are
# more than this many pairs of cells per pair of groups, they first tighten their bounds
# (the radius that suffices, the pairs that cannot be in the spanning forest).
_PAIRS_BEFORE_PRUNING = 4


def _components(n_points, edges):
    """Component of every node, numbered in order of its first node."""
    # Float weights in CSR, the form csgraph works on: no conversion inside it.
    graph = sparse.csr_matrix(
        (np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n_points, n_points)
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


def _knn_forest(points, tree, n_neighbors, workers, neighbours=None):
    """Minimum spanning forest of the k-NN graph (by length) and each point's reach.

    The same forest as :func:`minimum_spanning_forest` of :func:`_knn_edges`, with the
    graph handed to the spanning-tree algorithm row by row as the query returns it
    rather than sorted from a list of edges. ``neighbours``: a :class:`NeighbourTable`
    of ``points`` with at least ``n_neighbors + 1`` columns, read instead of querying
    (equidistant neighbours may be listed apart from the query's: the single linkage,
    and the radius chosen from it, are the same).
    """
    n = len(points)
    k = min(n_neighbors + 1, n)
    rows = np.arange(n)
    if neighbours is not None and neighbours.k >= k:
        # Read in the table's own order: there is no query to run in the tree's order.
        order, neighbour = rows, neighbours.index[:, :k]
        dist = neighbours.distance[:, :k]
    else:
        order = tree.indices
        # Queries in the tree's own order touch memory in order: much faster for large n.
        dist, idx = tree.query(points[order], k=k, workers=workers)
        dist, idx = dist.reshape(n, k), idx.reshape(n, k)
        # Nodes are the rows (points in the tree's order); each row lists its neighbours.
        row_of = np.empty(n, dtype=np.intp)
        row_of[order] = rows
        neighbour = row_of[idx]
    reach = np.full(n, np.inf)
    if k < n:
        reach[order] = dist[:, -1]
    # A neighbour closer than the farthest one it lists itself lists this row too, at the
    # same length (the squared differences are summed in the same order either way): the
    # edge is given once, from the lower row. The spanning-tree algorithm sorts every edge
    # it is given, so a third fewer of them saves a third of its time.
    listed = (neighbour != rows[:, None]) & (
        (neighbour > rows[:, None]) | (dist >= np.take(dist[:, -1], neighbour))
    )
    # The entries row by row, as np.flatnonzero lists them (np.take is faster than
    # boolean masks here).
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.count_nonzero(listed, axis=1), out=indptr[1:])
    listed = np.flatnonzero(listed)
    # csgraph reads a stored zero as "no edge": coincident points travel as the tiniest.
    tiny = np.finfo(float).tiny
    graph = sparse.csr_matrix(
        (np.maximum(np.take(dist, listed), tiny), np.take(neighbour, listed), indptr),
        shape=(n, n),
    )
    spanning = sparse.coo_matrix(minimum_spanning_tree(graph))
    # Edges of equal length may come in any order: only the lengths and the components
    # below each length are read off the forest (both the same for every order).
    by_length = np.argsort(spanning.data)
    lengths = spanning.data[by_length]
    forest = order[np.column_stack([spanning.row[by_length], spanning.col[by_length]])]
    return forest, np.where(lengths <= tiny, 0.0, lengths), reach


def _radius_between(thresholds, k):
    """A radius whose radius graph includes the forest edges ``<= thresholds[k]`` only."""
    if k < 0:
        return thresholds[0] / 2
    if k + 1 < len(thresholds):
        # Midway, so that rounding in other distance computations cannot cross it; but
        # no float lies between two adjacent ones (the same gap rounded two ways, as
        # 0.3 - 0.1 and 0.5 - 0.3), and the midpoint would round up to the next length.
        middle = (thresholds[k] + thresholds[k + 1]) / 2
        return middle if middle < thresholds[k + 1] else thresholds[k]
    return 2 * thresholds[k] if thresholds[k] > 0 else 1.0


def _choose_radius(n_points, forest, forest_lengths, n_clusters, min_cluster_size, states=None):
    """Radius at which the forest has about ``n_clusters`` components of the minimum size.

    Index ``k`` stands for the forest's edges of length ``<= thresholds[k]`` (``-1``: no
    edge). An upward pass evaluates the ``k`` at which about ``n_clusters * 2**j``
    components remain, contracting the components found so far so that each pass costs
    only as much as the components left; a bisection between the last of them with at
    least ``n_clusters`` large components and the next one finishes.

    ``states``: a dict from a length ``t`` to the components (of the points, then their
    sizes) of the forest's edges ``<= t``, read where the upward pass stops at ``t`` and
    filled where it computes them. The components are numbered in order of their first
    point whatever the contractions that found them, so a state is valid for as long as
    the forest's edges up to ``t`` stay the same.

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
        known = None if states is None else states.get(float(thresholds[k]))
        if known is None:
            components, sizes = _merge(sizes, point_node[forest[done : n_edges[k]]])
            point_node = components[point_node]
            if states is not None:
                states[float(thresholds[k])] = point_node, sizes
        else:
            point_node, sizes = known
        done = n_edges[k]
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


# The helpers below take coordinates axis by axis (shape ``(d, N)``) and the indices of
# the pairs: gathering one axis at a time is several times faster than gathering the
# columns of a (d, N) array, and the sums are the same, axis after axis.


def _squared_distances(x, a, y, b):
    """Squared distances of the points ``x[:, a]`` and ``y[:, b]``, summed over the axes
    in order: the sum a KD-tree query computes, so that the lengths (and the radius chosen
    from them) are the ones the tree would give, to the last bit."""
    diff = x[0][a] - y[0][b]
    total = diff * diff
    for axis in range(1, len(x)):
        diff = x[axis][a] - y[axis][b]
        total += diff * diff
    return total


def _squared_box_gaps(lo, hi, a, b):
    """Squared gaps between the boxes ``a`` and ``b`` (corners ``lo`` and ``hi``): never
    more than the squared distance of two of their points as :func:`_squared_distances`
    rounds it."""
    total = np.zeros(len(a))
    for axis in range(len(lo)):
        low, high = lo[axis], hi[axis]
        gap = np.maximum(low[b] - high[a], low[a] - high[b])
        np.maximum(gap, 0, out=gap)
        total += gap * gap
    return total


def _squared_box_reaches(lo, hi, a, x, b):
    """Squared distances from the points ``x[:, b]`` to the farthest corners of the boxes
    ``a``: never less than the squared distance of a point of the box to the point."""
    total = np.zeros(len(a))
    for axis in range(len(lo)):
        point = x[axis][b]
        far = np.maximum(np.abs(point - lo[axis][a]), np.abs(point - hi[axis][a]))
        total += far * far
    return total


def _morton_codes(cells, bits):
    """Interleave the bits of the non-negative integer cell coordinates (Z-order);
    ``cells`` has shape ``(d, n)``, each below ``2**bits``."""
    d = len(cells)
    spread = np.zeros(256, dtype=np.int64)
    for bit in range(8):
        spread |= ((np.arange(256, dtype=np.int64) >> bit) & 1) << (bit * d)
    codes = np.zeros(cells.shape[1], dtype=np.int64)
    for byte in range((bits + 7) // 8):
        for axis in range(d):
            codes |= spread[(cells[axis] >> (8 * byte)) & 255] << (8 * byte * d + axis)
    return codes


def _ragged_product(start_a, count_a, start_b, count_b):
    """Every ``(i, j)`` with ``i`` in ``start_a[k] + range(count_a[k])`` and ``j`` likewise
    from ``b``, for every ``k``: returns ``k``, ``i`` and ``j``."""
    per = count_a * count_b
    owner = np.repeat(np.arange(len(per)), per)
    offset = np.arange(len(owner)) - np.repeat(np.cumsum(per) - per, per)
    width = count_b[owner]
    return owner, start_a[owner] + offset // width, start_b[owner] + offset % width


def _first_per_key(keys, values):
    """Index of the smallest value for each distinct key (ties: the first)."""
    order = np.lexsort((values, keys))
    first = np.ones(len(order), dtype=bool)
    first[1:] = keys[order[1:]] != keys[order[:-1]]
    return order[first]


class _ZOrder:
    """Points axis by axis, their grid cells of side ``cell``, the cells' Z-order codes
    and the points' order by code: computed once, shared by the pyramids of any subset
    of the points."""

    def __init__(self, points, cell):
        self.coords = np.ascontiguousarray(points.T)
        d = len(self.coords)
        low = self.coords.min(axis=1)
        extent = float(np.max(self.coords.max(axis=1) - low)) if self.coords.size else 0.0
        bits = 62 // d
        self.cell = max(cell, extent / 2 ** (bits - 1), np.finfo(float).tiny)
        cells = np.floor((self.coords - low[:, None]) / self.cell).astype(np.int64)
        np.minimum(cells, 2**bits - 1, out=cells)
        self.bits = max(int(cells.max()).bit_length(), 1) if cells.size else 1
        self.codes = _morton_codes(cells, self.bits)
        self.by_code = np.argsort(self.codes, kind="stable")

    def sort(self, groups, subset=None):
        """Order of the points of ``subset`` (all by default) by group, then code:
        positions in ``subset``."""
        if subset is None:
            by_code = self.by_code
        else:
            position = np.full(len(self.codes), -1, dtype=np.intp)
            position[subset] = np.arange(len(subset))
            by_code = position[self.by_code]
            by_code = by_code[by_code >= 0]
        # A stable sort by group of the points in code order; on 16-bit keys numpy sorts
        # stably in linear time (radix sort).
        key = groups[by_code]
        if len(key) and int(key.max()) < 2**16:
            key = key.astype(np.uint16)
        return by_code[np.argsort(key, kind="stable")]


class _GridPyramid:
    """Grid cells of the points at every scale, each cell split by group.

    The points (``subset`` of those of ``zorder``) are sorted by group, then by the
    Z-order of their cell. Level 0 holds the points themselves; a node of level
    ``l >= 1`` is the set of points of one group in one cell of side
    ``zorder.cell * 2**(l - 1)``: a run of the sorted points, whose children are the
    nodes of level ``l - 1`` in that run. Levels stop at the first whose side reaches
    ``top_side`` (or when every group is one node). Coordinates are stored axis by axis,
    shape ``(d, n_nodes)``; ``order`` maps the sorted points back to ``subset``.

    Two nodes' bounding boxes bound the distances of their points from below; the
    distance of two of their points (``rep``: the middle one of each run) from above.
    Searches start from the pairs of nodes of one level and descend, splitting the pairs
    and dropping those that cannot hold an answer: a dual-tree search, one level at a
    time, on arrays.
    """

    def __init__(self, zorder, groups, top_side=np.inf, subset=None):
        groups = np.asarray(groups, dtype=np.int64)
        self.order = zorder.sort(groups, subset)
        index = self.order if subset is None else subset[self.order]
        keys = zorder.codes[index]
        self.groups = groups[self.order]
        # np.take gathers columns several times faster than fancy indexing.
        self.coords = np.take(zorder.coords, index, axis=1)
        d, n = self.coords.shape
        bits = zorder.bits
        # The highest bit in which consecutive sorted points differ: a node boundary at
        # every level below it; a change of group is a boundary at every level.
        differ = keys[1:] ^ keys[:-1]
        group_change = self.groups[1:] != self.groups[:-1]
        n_groups = int(np.count_nonzero(group_change)) + 1
        self.side = [0.0]
        self.starts = [np.arange(n)]
        self.first_child = [None]
        self.n_children = [None]
        self.lo = [self.coords]
        self.hi = [self.coords]
        self.rep = [self.coords]
        level = 1
        while True:
            shift = d * (level - 1)
            change = (differ >> shift) != 0
            change |= group_change
            starts = np.concatenate([[0], np.flatnonzero(change) + 1])
            first_child = np.searchsorted(self.starts[-1], starts)
            ends = np.append(starts[1:], n)
            self.side.append(zorder.cell * 2.0 ** (level - 1))
            self.starts.append(starts)
            self.first_child.append(first_child)
            self.n_children.append(np.diff(np.append(first_child, len(self.starts[-2]))))
            self.lo.append(np.minimum.reduceat(self.lo[-1], first_child, axis=1))
            self.hi.append(np.maximum.reduceat(self.hi[-1], first_child, axis=1))
            self.rep.append(np.take(self.coords, (starts + ends) // 2, axis=1))
            if len(starts) == n_groups or self.side[-1] >= top_side or shift >= bits * d:
                break
            level += 1
        self.top = level

    def level_for(self, radius):
        """The finest level whose cells are at least ``radius`` wide (or the top)."""
        return next((lv for lv in range(1, self.top + 1) if self.side[lv] >= radius), self.top)

    def node_groups(self, level):
        return self.groups[self.starts[level]]

    def close_pairs(self, level, radius):
        """Pairs of nodes of ``level``, of different groups, whose boxes are within
        ``radius`` (squared gap at most ``radius**2``)."""
        lo, hi = self.lo[level], self.hi[level]
        if lo.shape[1] < 2:
            return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
        centre = ((lo + hi) / 2).T
        half = np.sqrt(np.max(np.sum(((hi - lo) / 2) ** 2, axis=0)))
        pairs = cKDTree(centre).query_pairs(
            (radius + 2 * half) * (1 + 1e-9) + 1e-300, output_type="ndarray"
        )
        a, b = pairs[:, 0].astype(np.intp), pairs[:, 1].astype(np.intp)
        groups = self.node_groups(level)
        keep = groups[a] != groups[b]
        a, b = a[keep], b[keep]
        keep = _squared_box_gaps(lo, hi, a, b) <= radius * radius
        return a[keep], b[keep]

    def split(self, level, a, b):
        """The pairs of children of the node pairs ``(a, b)`` of ``level``: returns the
        pair each comes from and the two children (nodes of ``level - 1``)."""
        first, count = self.first_child[level], self.n_children[level]
        return _ragged_product(first[a], count[a], first[b], count[b])


def _squared_lower_bounds(pyramid, level, a, b):
    """Squared box gaps of the node pairs ``(a, b)`` of ``level``; at level 0, where the
    boxes are points, their squared distances (the same numbers, found faster)."""
    if not level:
        return _squared_distances(pyramid.coords, a, pyramid.coords, b)
    lo, hi = pyramid.lo[level], pyramid.hi[level]
    return _squared_box_gaps(lo, hi, a, b)


def _connected_below(group_a, group_b, lower, upper, n_groups, n_thresholds=4):
    """Which group pairs are joined, below some threshold ``t <= lower``, by pairs with
    ``upper < t``: such a pair is the longest edge of a cycle, in no minimum spanning
    forest of the groups."""
    joined = np.zeros(len(lower), dtype=bool)
    finite = lower[np.isfinite(lower)]
    if not len(finite):
        return joined
    for threshold in np.unique(np.quantile(finite, np.linspace(0, 1, n_thresholds + 1)[1:])):
        below = upper < threshold
        if not below.any():
            continue
        graph = sparse.coo_matrix(
            (np.ones(np.count_nonzero(below), dtype=bool), (group_a[below], group_b[below])),
            shape=(n_groups, n_groups),
        )
        labels = connected_components(graph, directed=False)[1]
        joined |= (lower >= threshold) & (labels[group_a] == labels[group_b])
    return joined


def _group_pair_minima(pyramid, radius, n_groups, sufficient_radius=None):
    """Closest pair of points of the group pairs within ``radius``, exactly.

    Returns the two groups, the two points (original indices) and their distance, for a
    set of group pairs within ``radius`` that holds every edge up to ``radius`` of the
    minimum spanning forest of the groups (the single linkage between groups): pairs of
    groups the bounds show to be joined by shorter pairs are dropped on the way.
    ``sufficient_radius(group_a, group_b, upper)``, given upper bounds of group pairs'
    distances, may lower ``radius`` on the way; the returned pairs then hold the edges up
    to the last radius it gave. Returns that radius last.
    """
    empty = np.zeros(0, dtype=np.intp)
    # A little over radius, so that no pair within it is lost to rounding.
    squared_radius = radius * radius * (1 + 1e-12)
    top = pyramid.level_for(radius)
    a, b = pyramid.close_pairs(top, np.sqrt(squared_radius))
    if not len(a):
        return empty, empty, empty, empty, np.zeros(0), radius
    groups = pyramid.node_groups(top)
    low, high = np.minimum(groups[a], groups[b]), np.maximum(groups[a], groups[b])
    keys, pair = np.unique(low * n_groups + high, return_inverse=True)
    pair = pair.ravel()
    pair_a, pair_b = keys // n_groups, keys % n_groups
    best = np.full(len(keys), np.inf)
    for level in range(top, 0, -1):
        owner, a, b = pyramid.split(level, a, b)
        pair = pair[owner]
        child = level - 1
        lower = _squared_lower_bounds(pyramid, child, a, b)
        if child:
            rep = pyramid.rep[child]
            # The representatives are points: the best pair so far bounds the minimum.
            np.minimum.at(best, pair, _squared_distances(rep, a, rep, b))
        else:
            np.minimum.at(best, pair, lower)
        if child and sufficient_radius is not None and len(a) > _PAIRS_BEFORE_PRUNING * len(keys):
            known = np.isfinite(best)
            radius = min(radius, sufficient_radius(pair_a[known], pair_b[known], best[known]))
            squared_radius = radius * radius * (1 + 1e-12)
        keep = lower <= np.minimum(best[pair], squared_radius)
        a, b, pair, lower = a[keep], b[keep], pair[keep], lower[keep]
        if child and len(a) > _PAIRS_BEFORE_PRUNING * len(keys):
            least = np.full(len(keys), np.inf)
            np.minimum.at(least, pair, lower)
            dead = _connected_below(pair_a, pair_b, least, best, n_groups)
            keep = ~dead[pair]
            a, b, pair, lower = a[keep], b[keep], pair[keep], lower[keep]
    # Level 0: the lower bounds are the squared distances themselves.
    first = _first_per_key(pair, lower)
    return (
        pair_a[pair[first]],
        pair_b[pair[first]],
        pyramid.order[a[first]],
        pyramid.order[b[first]],
        np.sqrt(lower[first]),
        radius,
    )


def _close_point_pairs(pyramid, radius, *, nearest_only=False):
    """Pairs of points (pyramid indices) of different groups closer than ``radius``,
    with their squared distances, by descending the pyramid a level at a time.

    Closer means what a KD-tree query bounded by the next float above ``radius`` finds
    (squared distance below that bound's square). ``nearest_only``: pairs that cannot
    be a point's nearest in another group are pruned on the way down.
    """
    bound = np.nextafter(radius, np.inf)
    squared_bound = bound * bound
    top = pyramid.level_for(bound)
    a, b = pyramid.close_pairs(top, bound)
    for level in range(top, 0, -1):
        _, a, b = pyramid.split(level, a, b)
        child = level - 1
        lower = _squared_lower_bounds(pyramid, child, a, b)
        keep = lower < squared_bound
        a, b, lower = a[keep], b[keep], lower[keep]
        if not (nearest_only and child):
            continue  # child 0 is the points themselves: lower holds their distances
        lo, hi, rep = pyramid.lo[child], pyramid.hi[child], pyramid.rep[child]
        # Every point of node a has a point of another group within reach[a] of it.
        reach = np.full(lo.shape[1], np.inf)
        np.minimum.at(reach, a, _squared_box_reaches(lo, hi, a, rep, b))
        np.minimum.at(reach, b, _squared_box_reaches(lo, hi, b, rep, a))
        keep = (lower <= reach[a]) | (lower <= reach[b])
        a, b, lower = a[keep], b[keep], lower[keep]
    return a, b, lower


def _nearest_in_other_group(pyramid, radius):
    """Each point's nearest point of another group closer than ``radius``, exactly.

    What a KD-tree query bounded by the next float above ``radius`` finds (squared
    distance below that bound's square). Returns source and target (original indices)
    and their distance.
    """
    a, b, lower = _close_point_pairs(pyramid, radius, nearest_only=True)
    if not len(a):
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty, np.zeros(0)
    # Each point's smallest squared distance, then one pair that attains it.
    nearest = np.full(len(pyramid.groups), np.inf)
    np.minimum.at(nearest, a, lower)
    np.minimum.at(nearest, b, lower)
    target = np.full(len(nearest), -1, dtype=np.intp)
    for source, other in ((a, b), (b, a)):
        attains = lower == nearest[source]
        target[source[attains]] = other[attains]
    source = np.flatnonzero(target >= 0)
    return pyramid.order[source], pyramid.order[target[source]], np.sqrt(nearest[source])


def _pairs_across_groups(pyramid, radius):
    """Every pair of points of different groups closer than ``radius``, once, exactly.

    What KD-tree queries bounded by the next float above ``radius`` list (squared
    distance below that bound's square). Returns the two points (original indices) and
    their distance.
    """
    a, b, lower = _close_point_pairs(pyramid, radius)
    return pyramid.order[a], pyramid.order[b], np.sqrt(lower)


def _pyramid_cell(reach):
    """Finest cell side of the pyramids: the typical distance to the k-th neighbour."""
    finite = reach[np.isfinite(reach) & (reach > 0)]
    return float(np.median(finite)) if len(finite) else 0.0


class _MissingEdges:
    """Radius-graph edges that join two components of the forest, found without the forest.

    An edge ``(p, q)`` of length ``<= r`` that the k-NN graph lacks needs both ``p`` and
    ``q`` saturated: each has its ``k`` listed neighbours within ``r``, else the other would
    be listed. The pairs of saturated points within ``r`` in different components are
    searched on a grid pyramid; when there would be too many pairs within ``r`` (more
    than ``_PAIRS_PER_POINT`` per point expected), each saturated point's nearest
    neighbour in another component instead. Above ``_MAX_PYRAMID_DIM`` dimensions, KD-tree
    queries list the saturated points' neighbours within ``r`` (more nearest neighbours,
    bounded by ``r``, until every list ends before ``r``) and keep them, so that a later
    check at a radius no larger only filters them.
    """

    def __init__(self, points, tree, reach, n_neighbors, workers, zorder):
        self.zorder = zorder
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

    def _across_on_grid(self, components, radius):
        """The same edges, found on a grid pyramid without listing every pair."""
        empty = np.zeros((0, 2), dtype=np.intp), np.zeros(0)
        saturated = np.flatnonzero(self.reach <= radius)
        groups = np.unique(components[saturated], return_inverse=True)[1].ravel()
        if not len(groups) or groups.max() < 1:
            return empty
        pyramid = _GridPyramid(
            self.zorder(), groups, np.nextafter(radius, np.inf), subset=saturated
        )
        if radius <= self.listed_radius:
            # As filtering the pairs listed at the larger listed_radius would: lengths
            # clipped to that radius, kept when no longer than this one.
            source, target, lengths = _pairs_across_groups(pyramid, radius)
            lengths = np.minimum(lengths, self.listed_radius)
            close = lengths <= radius
            return saturated[np.column_stack([source[close], target[close]])], lengths[close]
        with np.errstate(divide="ignore"):
            ratio = radius / self.reach[saturated]
        expected_pairs = np.sum((self.n_neighbors + 1) * ratio ** self.points.shape[1])
        if expected_pairs > _PAIRS_PER_POINT * len(self.points):
            source, target, lengths = _nearest_in_other_group(pyramid, radius)
        else:
            source, target, lengths = _pairs_across_groups(pyramid, radius)
            self.listed_radius = radius
        return saturated[np.column_stack([source, target])], np.minimum(lengths, radius)

    def __call__(self, components, radius):
        if self.points.shape[1] <= _MAX_PYRAMID_DIM:
            return self._across_on_grid(components, radius)
        empty = np.zeros((0, 2), dtype=np.intp), np.zeros(0)
        if radius > self.listed_radius:
            saturated = np.flatnonzero(self.reach <= radius)
            groups = np.unique(components[saturated], return_inverse=True)[1].ravel()
            if not len(groups) or groups.max() < 1:
                return empty
            with np.errstate(divide="ignore"):
                ratio = radius / self.reach[saturated]
            expected_pairs = np.sum((self.n_neighbors + 1) * ratio ** self.points.shape[1])
            if expected_pairs > _PAIRS_PER_POINT * len(self.points):
                source, target, lengths = nearest_in_other_component(
                    self.points[saturated], groups, max_distance=radius, workers=self.workers
                )
                return saturated[np.column_stack([source, target])], np.minimum(lengths, radius)
            self._list_pairs(saturated, radius)
        close = self.lengths <= radius
        pairs, lengths = self.pairs[close], self.lengths[close]
        across = components[pairs[:, 0]] != components[pairs[:, 1]]
        return pairs[across], lengths[across]


def _group_forest(group_a, group_b, lengths, n_groups):
    """Minimum spanning forest of the groups joined by the given pairs: the index of the
    pairs it keeps, and the tree of every group."""
    # The shortest pair of each two groups, the only one the forest can keep: given
    # alone, the spanning-forest algorithm has no repeats to sort out.
    keys = np.minimum(group_a, group_b) * n_groups + np.maximum(group_a, group_b)
    first = _first_per_key(keys, lengths)
    forest, _ = minimum_spanning_forest(
        n_groups, np.column_stack([group_a[first], group_b[first]]), lengths[first]
    )
    # Map the forest's group edges back to the pairs given.
    forest_keys = np.minimum(forest[:, 0], forest[:, 1]) * n_groups + np.maximum(
        forest[:, 0], forest[:, 1]
    )
    chosen = first[np.searchsorted(keys[first], forest_keys)]
    return chosen, _components(n_groups, forest)


def _boruvka_step(points, components, workers):
    """Each component's shortest edge to another one, on the true distances.

    :func:`~mmreg._array.neighbors.shortest_edges_between_components` prunes with bounding
    boxes whose rounding can drop the closest pair when it is the boxes' own gap (points
    on a line), so this asks every point for its nearest point in another component.
    """
    source, target, lengths = nearest_in_other_component(points, components, workers=workers)
    first = _first_per_key(components[source], lengths)
    return np.column_stack([source[first], target[first]]), lengths[first]


def _spanning_bound(pyramid, n_groups):
    """Pairs of points joining the groups, from the k-NN graph of the representative
    points of a coarse level: their lengths bound the single linkage of the groups from
    above. Returns the groups and lengths of the pairs of its spanning forest, and the
    tree of every group (all 0 when the pairs join every group)."""
    level = next(
        (lv for lv in range(1, pyramid.top + 1) if len(pyramid.starts[lv]) <= 2 * n_groups),
        pyramid.top,
    )
    reps, groups = pyramid.rep[level].T, pyramid.node_groups(level)
    k = min(8, len(reps) - 1)
    _, neighbours = cKDTree(reps).query(reps, k=k + 1)
    a = np.repeat(np.arange(len(reps)), k + 1)
    b = neighbours.reshape(-1)
    keep = groups[a] != groups[b]
    a, b = a[keep], b[keep]
    lengths = np.sqrt(_squared_distances(pyramid.rep[level], a, pyramid.rep[level], b))
    chosen, tree_of = _group_forest(groups[a], groups[b], lengths, n_groups)
    return groups[a[chosen]], groups[b[chosen]], lengths[chosen], tree_of


def _shows_next_length(lengths, n_points, target, radius):
    """Whether a forest completed up to ``radius`` shows the choice of the radius all the
    completed one would: their lengths agree up to ``radius``, and the choice looks no
    further than the first length after the one at which ``target`` components remain.
    """
    j = n_points - target  # edges up to the length where target components remain
    if j > len(lengths):
        return False
    star = lengths[j - 1] if j >= 1 else -np.inf
    after = np.searchsorted(lengths, star, side="right")
    return after < len(lengths) and lengths[after] <= radius


def _no_missing_edges(lengths, longest_before, completed_to, radius):
    """Whether a forest just completed up to ``completed_to`` (no edge added since) is
    known to join every pair of points that the search for missing edges at ``radius``
    would find (squared distance below that of the next float above ``radius``).

    Such a pair is at most ``bound``, the next float, apart. Two points of one tree of the
    forest before completion (``longest_before``: its longest edge) are joined at
    ``radius`` when no edge of that tree is longer. Two points of different trees: the
    completed forest joins their trees by edges no longer than the pair (the single
    linkage between the trees), all of them in the forest when ``bound <=
    completed_to``; with no length of the forest in ``(radius, bound]`` they are no
    longer than ``radius`` either. The search would then find nothing.
    """
    bound = np.nextafter(radius, np.inf)
    if longest_before > radius or completed_to < bound:
        return False
    after = np.searchsorted(lengths, radius, side="right")
    return after == len(lengths) or lengths[after] > bound


def _complete_forest(points, forest, forest_lengths, zorder, target, workers, trees=None):
    """Join the trees of the forest by the minimum spanning tree between the trees (the
    single linkage of the trees on the true distances, which Boruvka steps give), as far
    as the choice of the radius needs.

    Its edges are added up to a length ``R`` past the one at which the completed forest
    has ``target`` components or fewer, so that the result and the completed forest have
    the same edges up to ``R`` (see :func:`_shows_next_length`); ``target=1`` completes
    it all. Returns the forest, its lengths, whether it is a single tree, and ``R``.
    ``trees``: the component of every point in ``forest``, if known.
    """
    n = len(points)
    trees = _components(n, forest) if trees is None else trees
    n_trees = int(trees.max()) + 1
    target = max(target, 1)
    if points.shape[1] > _MAX_PYRAMID_DIM:
        while n_trees > 1:
            edges, lengths = _boruvka_step(points, trees, workers=workers)
            forest, forest_lengths = minimum_spanning_forest(
                n, np.vstack([forest, edges]), np.concatenate([forest_lengths, lengths])
            )
            trees = _components(n, forest)
            n_trees = int(trees.max()) + 1
        return forest, forest_lengths, True, np.inf
    # Stages of Kruskal's algorithm on the trees: while the k-NN graph of representative
    # points leaves the groups in several pieces (many small trees), add every edge of
    # the minimum spanning tree up to a length that joins many of them, and go on with
    # the joined groups as the groups.
    groups, n_groups = trees, n_trees
    while True:
        pyramid = _GridPyramid(zorder(), groups)
        bound_a, bound_b, bound, pieces = _spanning_bound(pyramid, n_groups)
        if pieces.max() == 0:
            break
        # Half the pairs' length: it joins many groups, yet leaves the long pairs (to far
        # groups) to later stages, with fewer groups.
        stage = float(np.median(bound)) if len(bound) else np.inf
        found = _group_pair_minima(pyramid, stage, n_groups)
        chosen, joined = _group_forest(found[0], found[1], found[4], n_groups)
        forest = np.vstack([forest, np.column_stack([found[2][chosen], found[3][chosen]])])
        forest_lengths = np.concatenate([forest_lengths, found[4][chosen]])
        order = np.argsort(forest_lengths, kind="stable")
        forest, forest_lengths = forest[order], forest_lengths[order]
        groups, n_groups = joined[groups], int(joined.max()) + 1
        if n_groups == 1:
            return forest, forest_lengths, True, np.inf
    # Components to reach: one fewer than target, for the length after the target's
    # (enough unless several merge at once there: then lower still).
    goal = [max(target - 1, 1)]

    def sufficient_radius(group_a, group_b, squared_upper):
        # Any pairs joining groups bound the groups' single linkage from above, so with
        # them the forest has no fewer components at any length than when completed:
        # where it falls to the goal, R suffices.
        upper = np.concatenate([bound, np.sqrt(squared_upper)])
        chosen, _ = _group_forest(
            np.concatenate([bound_a, group_a]),
            np.concatenate([bound_b, group_b]),
            upper,
            n_groups,
        )
        upper = np.sort(upper[chosen])
        # With j of these edges, needed - j forest edges: R = max(both longest).
        j = np.arange(len(upper) + 1)
        from_forest = n - goal[0] - j - 1
        forest_part = np.where(
            from_forest < 0,
            -np.inf,
            forest_lengths[np.clip(from_forest, 0, len(forest_lengths) - 1)],
        )
        forest_part[from_forest >= len(forest_lengths)] = np.inf
        return float(np.min(np.maximum(np.concatenate([[-np.inf], upper]), forest_part)))

    radius = sufficient_radius(bound_a[:0], bound_b[:0], bound[:0])
    while True:
        group_a, group_b, p, q, pair_lengths, radius = _group_pair_minima(
            pyramid, radius, n_groups, sufficient_radius
        )
        chosen, _ = _group_forest(group_a, group_b, pair_lengths, n_groups)
        edges = np.vstack([forest, np.column_stack([p[chosen], q[chosen]])])
        whole = len(chosen) == n_groups - 1
        lengths = np.concatenate([forest_lengths, pair_lengths[chosen]])
        order = np.argsort(lengths, kind="stable")
        edges, lengths = edges[order], lengths[order]
        if whole or _shows_next_length(lengths, n, target, radius):
            return edges, lengths, whole, radius
        if n - np.count_nonzero(lengths <= radius) > goal[0]:
            radius = 2 * radius if radius > 0 else float(bound.max()) or 1.0  # Not expected.
            continue
        # The length after the target's is past R: reach one component fewer than there.
        star = lengths[n - target - 1]
        goal[0] = n - int(np.searchsorted(lengths, star, side="right")) - 1
        radius = sufficient_radius(group_a, group_b, pair_lengths**2)
        radius = max(radius, float(np.nextafter(star, np.inf)))


def _add_to_forest(n_points, forest, forest_lengths, edges, lengths):
    """Minimum spanning forest of a minimum spanning forest and more edges.

    The forest's edges shorter than every new edge stay (a cycle through one of them
    holds a longer new edge): their trees are contracted, and only the longer forest
    edges and the new ones are left to the spanning-forest algorithm.
    """
    kept = np.searchsorted(forest_lengths, lengths.min(), side="left")
    nodes = _components(n_points, forest[:kept])
    rest = np.vstack([forest[kept:], edges])
    rest_lengths = np.concatenate([forest_lengths[kept:], lengths])
    chosen, _ = _group_forest(nodes[rest[:, 0]], nodes[rest[:, 1]], rest_lengths, nodes.max() + 1)
    chosen = chosen[np.argsort(rest_lengths[chosen], kind="stable")]
    return (
        np.vstack([forest[:kept], rest[chosen]]),
        np.concatenate([forest_lengths[:kept], rest_lengths[chosen]]),
    )


def _radius_for_count(
    points,
    n_clusters,
    min_cluster_size,
    n_neighbors,
    workers,
    *,
    complete_all=False,
    neighbours=None,
):
    n = len(points)
    # Sliding-midpoint splits: built and queried about a fifth faster than median ones
    # here, with the same distances (ties may be listed apart; the forest is exact anyway).
    tree = cKDTree(points, balanced_tree=False) if neighbours is None else neighbours.tree
    forest, forest_lengths, reach = _knn_forest(points, tree, n_neighbors, workers, neighbours)
    # The grid cells of the points, for the searches between components: made once, if
    # any is needed.
    zorder = functools.cache(lambda: _ZOrder(points, _pyramid_cell(reach)))
    missing_edges = _MissingEdges(points, tree, reach, n_neighbors, workers, zorder)
    # The forest is completed (see below) only up to this length, or in full.
    completed_to = None
    target = 1 if complete_all else max(n_clusters - 1, 1)
    # The first choice returns None (complete the forest first) when the k-NN forest
    # has several trees, n_clusters of them large: seen from the trees alone.
    first = len(forest) and n - len(forest) >= max(n_clusters, 2)
    trees = None
    if first:
        trees = _components(n, forest)
        first = np.sum(np.bincount(trees) >= min_cluster_size) >= n_clusters
    # The longest edge of the forest that was completed, while no edge has been added
    # since (see _no_missing_edges); None otherwise.
    longest_before = None
    # The components at the lengths the choices stopped at, kept while the forest up to
    # them stays the same: a choice after edges were added starts from the last of them.
    states = {}
    while True:
        if first:
            choice, first = None, False
        else:
            choice = _choose_radius(n, forest, forest_lengths, n_clusters, min_cluster_size, states)
        if choice is None:
            if completed_to is not None:
                break
            longest_before = forest_lengths[-1] if len(forest_lengths) else -np.inf
            forest, forest_lengths, whole, completed_to = _complete_forest(
                points, forest, forest_lengths, zorder, target, workers, trees
            )
            states.clear()
            if whole:
                completed_to = np.inf
            continue
        radius, components, reached = choice
        if (
            completed_to is not None
            and np.isfinite(completed_to)
            and (not reached or not _shows_next_length(forest_lengths, n, target, completed_to))
        ):
            break
        if longest_before is not None and _no_missing_edges(
            forest_lengths, longest_before, completed_to, radius
        ):
            return radius, components, reached
        missing, missing_lengths = missing_edges(components, radius)
        if not len(missing):
            return radius, components, reached
        forest, forest_lengths = _add_to_forest(n, forest, forest_lengths, missing, missing_lengths)
        trees, longest_before = None, None
        # The forest's edges shorter than every added one stay (_add_to_forest).
        shortest = missing_lengths.min()
        states = {length: state for length, state in states.items() if length < shortest}
    # The forest was completed only up to the radii that usually matter, and this choice
    # needs the rest: start again, completing it all, as the choice would have seen it.
    if complete_all:  # pragma: no cover - a completed forest is one tree
        raise RuntimeError("the completed forest did not let the radius be chosen")
    return _radius_for_count(
        points,
        n_clusters,
        min_cluster_size,
        n_neighbors,
        workers,
        complete_all=True,
        neighbours=neighbours,
    )


def euclidean_clustering(
    points,
    *,
    n_clusters=100,
    radius=None,
    max_radius=None,
    min_cluster_size=4,
    n_neighbors=6,
    n_jobs=None,
    neighbours=None,
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
    max_radius : float or None, default=None
        Cap on the chosen radius (ignored when ``radius`` is given): where
        ``n_clusters`` would need a wider one, the clusters at ``max_radius`` are
        returned, more than ``n_clusters`` of them.
    min_cluster_size : int, default=4
        Components with fewer points are left out (label ``-1``).
    n_neighbors : int, default=6
        Neighbours per point in the k-NN graph that seeds the radius search.
    n_jobs : int or None, default=None
        Threads for the k-NN queries; None means 1, -1 all processors.
    neighbours : NeighbourTable or None, default=None
        The ``points``' nearest neighbours, already listed (at least ``n_neighbors +
        1``, as a caller that needs them anyway has them): read instead of a query.

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
    labels, radius, short = euclidean_labels(
        points,
        n_clusters=n_clusters,
        radius=radius,
        max_radius=max_radius,
        min_cluster_size=min_cluster_size,
        n_neighbors=n_neighbors,
        n_jobs=n_jobs,
        neighbours=neighbours,
    )
    if short is not None:
        warnings.warn(
            f"No radius tried gives n_clusters={n_clusters} clusters of at least "
            f"min_cluster_size={min_cluster_size} points; using the radius {radius:.6g}, "
            f"which gives the most ({short}). Lower n_clusters or min_cluster_size.",
            UserWarning,
            stacklevel=user_stacklevel(),
        )
    return labels, radius


def euclidean_labels(
    points,
    *,
    n_clusters,
    radius,
    max_radius,
    min_cluster_size,
    n_neighbors,
    n_jobs,
    neighbours=None,
):
    """:func:`euclidean_clustering` without its warning, for callers to whom
    ``n_clusters`` is an upper bound rather than a request.

    Returns
    -------
    labels : ndarray of shape (n,)
    radius : float
    short : int or None
        The number of large clusters found when no radius tried reaches ``n_clusters``
        (then ``radius`` is the one giving the most); None when one does.
    """
    points = np.asarray(points, dtype=float)
    n = len(points)
    short = None
    if radius is not None:
        _, components = connected_labels(points, radius)
    elif n <= 1:
        radius, components = 0.0, np.zeros(n, dtype=np.intp)
    else:
        workers = query_workers(n_jobs)
        radius, components, reached = _radius_for_count(
            points, n_clusters, min_cluster_size, n_neighbors, workers, neighbours=neighbours
        )
        if max_radius is not None and radius > max_radius:
            # Far-apart objects: joining them into n_clusters would need gaps wider than
            # the cap allows; more clusters, each max_radius-connected, instead.
            radius, reached = max_radius, True
            components = tau_components(points, max_radius)[1]
        if not reached:
            short = int(np.count_nonzero(np.bincount(components) >= min_cluster_size))
    sizes = np.bincount(components, minlength=1)
    components = np.where(sizes[components] >= min_cluster_size, components, -1)
    return number_by_first_point(components)[0], float(radius), short


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
    max_radius : float or None, default=None
        Cap on the automatic radius. Where ``n_clusters`` clusters would need a wider
        one (objects farther apart than the cap, fewer than ``n_clusters`` clusters
        within it), the clusters at ``max_radius`` are returned instead, more than
        ``n_clusters`` of them: with the registration's ``tau`` as the cap, every
        initial cluster is ``tau``-connected, as Definition 2 of the paper asks, and
        single linkage does not join hundreds of far-apart objects into one cluster.
        Ignored when ``radius`` is given. None: no cap.
    min_cluster_size : int, default=4
        Components with fewer points get label ``-1``: no initial cluster. The EM does not
        fit poses to them but offers them to every cluster within ``tau`` at once. The
        default is the EM's own ``min_cluster_size``, below which it drops a cluster.
    n_neighbors : int, default=6
        Neighbours per point in the k-nearest-neighbour graph from which the single
        linkage is built. The clusters are exact whatever its value; it trades the cost
        of the k-NN graph against that of the edges the graph misses.
    n_jobs : int or None, default=None
        Threads for the k-NN queries; None means 1, -1 every core and ``-k`` all but
        ``k - 1`` of them.

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
    the radius (``O(n)`` in all), and a search for the pairs within the radius that join
    two components, among the points whose ``k`` nearest neighbours all lie within it.
    When the k-NN graph falls apart into more far-apart groups than clusters are asked
    for, the single linkage between those groups is added, as far as the choice of the
    radius needs. Both searches run on a grid pyramid (one sort, then ``O(n)`` array
    passes per level and the pairs of cells that face each other across the gaps). On
    this project's 2-core machine (``benchmarks/init_speed.py``): 0.09 s for
    ``make_scene(random_state=0)`` (22,395 points), 0.5 s for 1,000 objects of 100
    points 6 m apart and for an 82,000-point Argoverse 2 LiDAR sweep, 5.5 s for
    1,000,000 points; 2.3 to 3.3 times one KD-tree build and ``k=8`` query on the same
    points. With an explicit ``radius`` the cost is that of the radius graph, which
    grows with the number of pairs within ``radius``.

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
        "max_radius": [Interval(Real, 0, None, closed="neither"), None],
        "min_cluster_size": [Interval(Integral, 1, None, closed="left")],
        "n_neighbors": [Interval(Integral, 1, None, closed="left")],
        "n_jobs": [Integral, None],
    }

    def __init__(
        self,
        n_clusters=100,
        *,
        radius=None,
        max_radius=None,
        min_cluster_size=4,
        n_neighbors=6,
        n_jobs=None,
    ):
        self.n_clusters = n_clusters
        self.radius = radius
        self.max_radius = max_radius
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
            max_radius=self.max_radius,
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
        bound = np.nextafter(self.radius_, np.inf)
        dist, idx = tree.query(
            points, k=1, distance_upper_bound=bound, workers=query_workers(self.n_jobs)
        )
        near = np.isfinite(dist)
        out[near] = self.labels_[self.labels_ >= 0][idx[near]]
        return out
