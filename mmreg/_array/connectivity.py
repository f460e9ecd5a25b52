"""Tau-connected components and gaps between groups of points, for any ``tau``.

The radius graph of :mod:`mmreg._array.neighbors` lists every pair within ``tau``; when ``tau``
is large compared to the sampling gap (the paper's ``tau = 1.5`` m on dense objects) that
is billions of edges. Connectivity needs far fewer, so :func:`tau_components` works on a
grid instead:

* cells of side ``tau / sqrt(d)`` have diameter below ``tau``, so the points of one cell
  are all joined to each other and a cell can stand for its points;
* two cells can only be joined if their index offset is at most ``ceil(sqrt(d))`` per
  axis; a pair of such cells is joined at once when their most central points are within
  ``tau`` of each other (a witness pair), rejected at once when their bounding boxes are
  farther than ``tau`` apart, and otherwise decided exactly from their points, but only
  while the two cells still lie in different components.

Everything but the exact fallback for large undecided cell pairs is vectorised.
"""

import math
from itertools import product

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from mmreg._array.neighbors import radius_graph

__all__ = ["cluster_components", "min_gap_between", "tau_components"]

# Largest number of point pairs compared in one vectorised block of exact checks.
_PAIR_BUDGET = 2**21
# The grid needs (2 ceil(sqrt(d)) + 1)^d neighbour offsets; beyond 4-D the radius graph is used.
_MAX_GRID_DIM = 4


def _components(n_nodes, rows, cols):
    graph = sparse.coo_matrix((np.ones(len(rows), dtype=bool), (rows, cols)), shape=(n_nodes,) * 2)
    return connected_components(graph, directed=False)


def _ragged_arange(starts, counts):
    """Concatenation of ``arange(s, s + c)`` for every ``(s, c)``."""
    total = int(counts.sum())
    shift = np.repeat(starts - np.cumsum(counts) + counts, counts)
    return np.arange(total) + shift


def _radius_graph_components(points, tau, groups):
    graph = sparse.coo_matrix(radius_graph(points, tau))
    same = groups[graph.row] == groups[graph.col]
    return _components(len(points), graph.row[same], graph.col[same])


def _half_offsets(d, side, tau):
    """Grid offsets ``o > 0`` (lexicographically) whose cells can hold points within tau."""
    reach = math.ceil(math.sqrt(d))
    offsets = np.array(list(product(range(-reach, reach + 1), repeat=d)), dtype=np.int64)
    first = np.argmax(offsets != 0, axis=1)
    positive = offsets[np.arange(len(offsets)), first] > 0
    gap = side * np.sqrt(np.sum(np.maximum(np.abs(offsets) - 1, 0) ** 2, axis=1))
    return offsets[positive & (gap <= tau)], reach


def _exact_pairs(points, starts, counts, c1, c2, tau):
    """Which cell pairs ``(c1[k], c2[k])`` hold two points within ``tau``, all at once."""
    n1, n2 = counts[c1], counts[c2]
    first = _ragged_arange(starts[c1], n1)
    pair_of_first = np.repeat(np.arange(len(c1)), n1)
    reps = n2[pair_of_first]
    left = np.repeat(first, reps)
    right = _ragged_arange(np.repeat(starts[c2], n1), reps)
    diff = points[left] - points[right]
    close = np.einsum("ij,ij->i", diff, diff) <= tau * tau
    pair = np.repeat(pair_of_first, reps)
    return np.bincount(pair[close], minlength=len(c1)) > 0


def _exact_pair_tree(points, starts, counts, c1, c2, tau):
    """Whether the large cells ``c1`` and ``c2`` hold two points within ``tau``."""
    small, large = (c1, c2) if counts[c1] <= counts[c2] else (c2, c1)
    tree = cKDTree(points[starts[large] : starts[large] + counts[large]])
    query = points[starts[small] : starts[small] + counts[small]]
    dist, _ = tree.query(query, k=1, distance_upper_bound=tau * (1 + 1e-9) + 1e-300)
    return bool(np.any(dist <= tau))


def tau_components(points, tau, groups=None):
    """Connected components of the graph joining points at distance ``<= tau``.

    Two points are in one component iff a chain of points, consecutive ones at most
    ``tau`` apart (and, with ``groups``, all in the same group), joins them: the
    ``tau``-connected pieces of Section IV of the paper.

    Parameters
    ----------
    points : ndarray of shape (n, d)
    tau : float
        Largest gap within a chain, ``> 0``.
    groups : ndarray of shape (n,), default=None
        If given, only points of the same group are joined, so every component lies in
        one group; the pieces of all groups are found in one pass.

    Returns
    -------
    n_components : int
    labels : ndarray of shape (n,)
        Component of each point, in ``0..n_components-1``.

    Notes
    -----
    Runs in ``O(n log n)`` time and ``O(n)`` memory whatever the density: it never lists
    the pairs within ``tau``, only about ``62`` candidate neighbour cells per grid cell in
    3-D (see the module docstring). Dimensions above 4 use the radius graph.
    """
    points = np.asarray(points, dtype=float)
    n, d = points.shape
    groups = np.zeros(n, dtype=np.int64) if groups is None else np.asarray(groups, dtype=np.int64)
    if n == 0:
        return 0, np.zeros(0, dtype=np.intp)
    if d == 0 or math.isinf(tau):
        # No gap is too wide (no gate, tau=None upstream): each group is one component.
        _, groups_compact = np.unique(groups, return_inverse=True)
        return int(groups_compact.max()) + 1, groups_compact.astype(np.intp)
    if d > _MAX_GRID_DIM:
        return _radius_graph_components(points, tau, groups)
    # Slightly under tau / sqrt(d), so that rounding cannot stretch a cell beyond tau.
    side = tau / math.sqrt(d) * (1 - 1e-9)
    offsets, reach = _half_offsets(d, side, tau)
    coords = np.floor((points - points.min(axis=0)) / side)
    _, group_index = np.unique(groups, return_inverse=True)
    spans = [int(group_index.max()) + 1] + [int(s) + 1 + 2 * reach for s in coords.max(axis=0)]
    if math.prod(spans) >= 2**62 or not np.all(np.isfinite(coords)):
        return _radius_graph_components(points, tau, groups)
    # One int64 key per cell (group first, then the shifted grid coordinates), so that a
    # neighbour cell's key is the cell's key plus a constant per offset.
    coords = coords.astype(np.int64) + reach
    strides = np.cumprod([1] + spans[:0:-1])[::-1]
    keys = group_index.astype(np.int64) * strides[0] + coords @ strides[1:]
    cell_keys, cell_of = np.unique(keys, return_inverse=True)
    n_cells = len(cell_keys)

    # Points sorted by cell, the most central point of each cell first.
    centre = (coords - reach + 0.5) * side + points.min(axis=0)
    off_centre = np.einsum("ij,ij->i", points - centre, points - centre)
    order = np.lexsort((off_centre, cell_of))
    sorted_points = points[order]
    counts = np.bincount(cell_of, minlength=n_cells)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    box_lo = np.minimum.reduceat(sorted_points, starts, axis=0)
    box_hi = np.maximum.reduceat(sorted_points, starts, axis=0)
    rep = sorted_points[starts]

    pairs = []
    for offset in offsets:
        target = cell_keys + offset @ strides[1:]
        pos = np.minimum(np.searchsorted(cell_keys, target), n_cells - 1)
        hit = np.flatnonzero(cell_keys[pos] == target)
        pairs.append(np.column_stack([hit, pos[hit]]))
    pairs = np.vstack(pairs) if pairs else np.zeros((0, 2), dtype=np.int64)
    c1, c2 = pairs[:, 0], pairs[:, 1]
    gap = np.maximum(np.maximum(box_lo[c2] - box_hi[c1], box_lo[c1] - box_hi[c2]), 0)
    possible = np.einsum("ij,ij->i", gap, gap) <= tau * tau
    c1, c2 = c1[possible], c2[possible]
    diff = rep[c1] - rep[c2]
    witnessed = np.einsum("ij,ij->i", diff, diff) <= tau * tau
    edges1, edges2 = [c1[witnessed]], [c2[witnessed]]
    c1, c2 = c1[~witnessed], c2[~witnessed]

    _, comp = _components(n_cells, edges1[0], edges2[0])
    while len(c1):
        undecided = comp[c1] != comp[c2]
        c1, c2 = c1[undecided], c2[undecided]
        if not len(c1):
            break
        # Smallest pairs first, as many as fit the budget; a single pair above the budget
        # is decided with a KD-tree.
        cost = counts[c1] * counts[c2]
        by_cost = np.argsort(cost, kind="stable")
        c1, c2, cost = c1[by_cost], c2[by_cost], cost[by_cost]
        take = max(1, int(np.searchsorted(np.cumsum(cost), _PAIR_BUDGET, side="right")))
        if cost[0] > _PAIR_BUDGET:
            joined = np.array([_exact_pair_tree(sorted_points, starts, counts, c1[0], c2[0], tau)])
        else:
            joined = _exact_pairs(sorted_points, starts, counts, c1[:take], c2[:take], tau)
        edges1.append(c1[:take][joined])
        edges2.append(c2[:take][joined])
        c1, c2 = c1[take:], c2[take:]
        if joined.any():
            _, comp = _components(n_cells, np.concatenate(edges1), np.concatenate(edges2))
    n_components, comp = _components(n_cells, np.concatenate(edges1), np.concatenate(edges2))
    return n_components, comp[cell_of].astype(np.intp)


def cluster_components(points, labels, radius):
    """How many ``radius``-connected pieces each cluster falls into.

    Parameters
    ----------
    points : ndarray of shape (n, d)
    labels : ndarray of shape (n,)
        Cluster of each point; negative labels are ignored.
    radius : float

    Returns
    -------
    pieces : ndarray of shape (n_clusters,)
        ``pieces[j] == 1`` iff cluster ``j`` is ``radius``-connected (0 for empty
        clusters). ``n_clusters`` is ``labels.max() + 1``.
    """
    points = np.asarray(points, dtype=float)
    labels = np.asarray(labels)
    n_clusters = int(labels.max()) + 1 if labels.size and labels.max() >= 0 else 0
    keep = labels >= 0
    if not keep.any():
        return np.zeros(n_clusters, dtype=np.intp)
    _, pieces = tau_components(points[keep], radius, labels[keep])
    distinct = np.unique(np.column_stack([labels[keep], pieces]), axis=0)
    return np.bincount(distinct[:, 0], minlength=n_clusters)


def min_gap_between(points, labels):
    """Smallest distance between two points of different groups, and the two groups.

    Parameters
    ----------
    points : ndarray of shape (n, d)
    labels : ndarray of shape (n,)
        Group of each point; negative labels are ignored.

    Returns
    -------
    gap : float
        ``min ||p - q||`` over pairs with different non-negative labels; ``inf`` when
        fewer than two groups are present.
    groups : tuple of int or None
        The labels of the two groups that come closest, smaller first; None with ``inf``.

    Notes
    -----
    One KD-tree per group, queried only with the points of later groups whose bounding
    box is within the best gap found so far, which prunes all but the facing points.
    """
    points = np.asarray(points, dtype=float)
    labels = np.asarray(labels)
    keep = labels >= 0
    points, labels = points[keep], labels[keep]
    uniques = np.unique(labels)
    best, pair = np.inf, None
    for group in uniques[:-1]:
        own = points[labels == group]
        later_mask = labels > group
        later, later_labels = points[later_mask], labels[later_mask]
        tree = cKDTree(own)
        lo, hi = own.min(axis=0), own.max(axis=0)
        if not np.isfinite(best):
            # A few hundred probes first give a finite bound for the box filter to prune.
            step = max(1, len(later) // 256)
            dist, _ = tree.query(later[::step], k=1)
            best = float(dist.min())
            pair = (int(group), int(later_labels[::step][np.argmin(dist)]))
        gap = np.maximum(np.maximum(lo - later, later - hi), 0)
        near = np.flatnonzero(np.einsum("ij,ij->i", gap, gap) <= best * best)
        if not len(near):
            continue
        dist, _ = tree.query(later[near], k=1, distance_upper_bound=best * (1 + 1e-9))
        closest = int(np.argmin(dist))
        if dist[closest] < best:
            best = float(dist[closest])
            pair = (int(group), int(later_labels[near[closest]]))
    return best, pair
