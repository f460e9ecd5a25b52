"""Islands of a sweep: its pieces connected through occupied voxels, found without pairs.

A LiDAR sweep without its ground falls apart into islands: cars, poles, walls, bushes.
Listing every pair of points within a radius (a radius graph) costs seconds at 100k
points; the islands need not be that exact. The points are binned into cubic voxels of
side ``cell``, and two occupied voxels are joined when they touch (share a face, an edge
or a corner). Points within ``cell`` of each other always lie in touching voxels, so an
island is at least as large as a component of the radius graph at ``cell``; points in
touching voxels are at most ``2 sqrt(3) cell`` apart, so it is at most as large as one at
that radius.

The cost is a sort of the voxel keys and 13 searches among the occupied voxels (one per
half of the 26 neighbour offsets), all vectorised.
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
    occupied, voxel = np.unique(keys, return_inverse=True)
    voxel = voxel.ravel()
    centre = np.empty((len(occupied), 3), dtype=np.int64)
    centre[voxel] = cells
    # Half of the 26 neighbour offsets: every touching pair is found once.
    steps = np.array(
        [(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)], dtype=np.int64
    )
    steps = steps[[tuple(s) > (0, 0, 0) for s in steps]]
    rows, cols = [], []
    for step in steps:  # 13 vectorised searches
        wanted = _keys(centre + step)
        at = np.minimum(np.searchsorted(occupied, wanted), len(occupied) - 1)
        found = occupied[at] == wanted
        rows.append(np.flatnonzero(found))
        cols.append(at[found])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    graph = sparse.coo_matrix(
        (np.ones(len(rows), dtype=bool), (rows, cols)), shape=(len(occupied),) * 2
    )
    component = connected_components(graph, directed=False)[1][voxel]
    sizes = np.bincount(component)
    component = np.where(sizes[component] >= min_size, component, -1)
    # Number the islands by their first point, so the labels do not depend on the keys.
    kept = component >= 0
    _, first = np.unique(component[kept], return_index=True)
    order = np.argsort(first)
    remap = np.empty(len(first), dtype=np.intp)
    remap[order] = np.arange(len(first))
    labels = np.full(n, -1, dtype=np.intp)
    if kept.any():
        labels[kept] = remap[np.unique(component[kept], return_inverse=True)[1].ravel()]
    return labels, len(first)
