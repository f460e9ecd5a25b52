"""The neighbour structure of the a-points: radius graphs and tau-connected components.

A set of points is *tau-connected* (Section IV) when any two of them are joined by a
chain of points with consecutive gaps of at most ``tau``: exactly when the radius graph
with edges ``||p - q|| <= tau`` is connected. These helpers are shared by the Euclidean
initialiser, the partition diagnostics and the checks of Definitions 1 and 2.
"""

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

__all__ = ["connected_labels", "cluster_components", "radius_graph"]


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


def cluster_components(points, labels, radius, *, graph=None):
    """How many ``radius``-connected pieces each cluster falls into.

    Parameters
    ----------
    points : ndarray of shape (n, d)
    labels : ndarray of shape (n,)
        Cluster of each point; negative labels are ignored.
    radius : float
    graph : sparse matrix, default=None
        The radius graph of ``points`` if already built.

    Returns
    -------
    pieces : ndarray of shape (n_clusters,)
        ``pieces[j] == 1`` iff cluster ``j`` is ``radius``-connected (0 for empty
        clusters). ``n_clusters`` is ``labels.max() + 1``.
    """
    labels = np.asarray(labels)
    n_clusters = int(labels.max()) + 1 if labels.size and labels.max() >= 0 else 0
    if graph is None:
        graph = radius_graph(points, radius)
    coo = sparse.coo_matrix(graph)
    # Keep only the edges inside one cluster: the components of what remains are the
    # connected pieces of each cluster.
    same = (labels[coo.row] == labels[coo.col]) & (labels[coo.row] >= 0)
    inner = sparse.coo_matrix(
        (np.ones(int(same.sum()), dtype=bool), (coo.row[same], coo.col[same])), shape=graph.shape
    )
    _, comp = connected_components(inner, directed=False)
    keep = labels >= 0
    if not keep.any():
        return np.zeros(n_clusters, dtype=np.intp)
    distinct = np.unique(np.column_stack([labels[keep], comp[keep]]), axis=0)
    return np.bincount(distinct[:, 0], minlength=n_clusters)
