"""Islands of a sweep: its pieces connected through occupied voxels, found without pairs.

A LiDAR sweep without its ground falls apart into islands: cars, poles, walls, bushes.
Listing every pair of points within a radius (a radius graph) costs seconds at 100k
points; the islands need not be that exact. The points are binned into cubic voxels of
side ``cell``, and two occupied voxels are joined when they touch (share a face, an edge
or a corner). Points within ``cell`` of each other always lie in touching voxels, so an
island is at least as large as a component of the radius graph at ``cell``; points in
touching voxels are at most ``2 sqrt(3) cell`` apart, so it is at most as large as one at
that radius.

The cost is a sort of the voxel keys and 4 searches among the occupied voxels, all
vectorised: of the 26 neighbour offsets, half find every touching pair once, and the
three voxels below, level with and above a voxel's neighbour in the plane have
consecutive keys, so one search serves the three.
"""

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components

__all__ = ["voxel_islands"]

# Voxel coordinates are packed into one int64 key, 21 bits per axis.
_BITS = 21
_OFFSET = 1 << (_BITS - 1)


def _keys(cells):
    shifted = cells + _OFFSET
    return (shifted[:, 0] << (2 * _BITS)) | (shifted[:, 1] << _BITS) | shifted[:, 2]


# Key offsets of the neighbours in the plane that lie after a voxel (x, then y): with
# every coordinate kept away from its field's ends, a step adds to the key without carry.
_PLANE_STEPS = np.array(
    [(i << (2 * _BITS)) + (j << _BITS) for i, j in ((0, 1), (1, -1), (1, 0), (1, 1))],
    dtype=np.int64,
)


def voxel_islands(points, cell, min_size=1):
    """Label every point with its island: components of touching occupied voxels.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
    cell : float
        Side of the voxels.
    min_size : int, default=1
        Islands with fewer points get label ``-1``.

    Returns
    -------
    labels : ndarray of shape (n,)
        Island of every point in ``0..K-1`` (numbered by first point), ``-1`` for points
        of islands smaller than ``min_size``.
    n_islands : int
        ``K``.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.sweeps._islands import voxel_islands
    >>> points = np.array([[0.0, 0, 0], [0.4, 0, 0], [0.8, 0, 0], [5, 5, 5], [9, 0, 0]])
    >>> voxel_islands(points, 0.5, min_size=1)
    (array([0, 0, 0, 1, 2]), 3)
    >>> voxel_islands(points, 0.5, min_size=2)
    (array([ 0,  0,  0, -1, -1]), 1)
    """
    points = np.asarray(points, dtype=float)
    n = len(points)
    if n == 0:
        return np.zeros(0, dtype=np.intp), 0
    cells = np.floor((points - points.min(axis=0)) / cell).astype(np.int64)
    if cells.max() >= _OFFSET:
        raise ValueError(
            f"the points span more than {_OFFSET} voxels of side {cell:g} along an axis; "
            "use a larger cell."
        )
    cells -= _OFFSET // 2  # centred in the key's range, so neighbours never wrap
    keys = _keys(cells)
    order = np.argsort(keys, kind="stable")
    ordered = keys[order]
    starts = np.empty(n, dtype=bool)
    starts[0] = True
    np.not_equal(ordered[1:], ordered[:-1], out=starts[1:])
    occupied = ordered[starts]
    voxel = np.empty(n, dtype=np.intp)
    voxel[order] = np.cumsum(starts) - 1
    first = order[starts]  # each voxel's first point (the sort is stable)
    counts = np.diff(np.append(np.flatnonzero(starts), n))
    m = len(occupied)
    # The neighbour above (z + 1) is the next key; the three at each plane neighbour
    # (z - 1, z, z + 1) follow where one search puts the lowest of them.
    above = np.flatnonzero(occupied[1:] == occupied[:-1] + 1)
    rows, cols = [above], [above + 1]
    for step in _PLANE_STEPS:
        wanted = occupied + step
        at = np.searchsorted(occupied, wanted - 1)
        for dz in (-1, 0, 1):
            where = np.minimum(at, m - 1)
            hit = occupied[where] == wanted + dz
            found = np.flatnonzero(hit)
            rows.append(found)
            cols.append(where[found])
            at = at + hit
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    graph = sparse.coo_matrix((np.ones(len(rows), dtype=bool), (rows, cols)), shape=(m, m))
    n_components, component = connected_components(graph, directed=False)
    sizes = np.bincount(component, weights=counts, minlength=n_components)
    # Number the islands by their first point, so the labels do not depend on the keys.
    component_first = np.full(n_components, n, dtype=np.intp)
    np.minimum.at(component_first, component, first)
    kept = np.flatnonzero(sizes >= min_size)
    remap = np.full(n_components, -1, dtype=np.intp)
    remap[kept[np.argsort(component_first[kept])]] = np.arange(len(kept))
    return remap[component][voxel], len(kept)
