"""A k-d tree of 3-D points whose nearest-neighbour queries run on small_gicp's k-d tree.

A pair's registration and a log's tracks ask one sweep's tree for the nearest points of
hundreds of thousands of moved points a frame (ICP, surface normals, the explained
tests). small_gicp's tree (nanoflann) answers those queries about twice as fast as
scipy's ``cKDTree`` on one thread (k = 1: 13 against 25 ms for 35k points of a nuScenes
sweep; k = 10: 29 against 52 ms). Its distances are scipy's to rounding (small_gicp
sums the squares in another order: an ulp apart in one of eight). :class:`PointTree`
speaks ``cKDTree``'s language, so that the code that reads a tree stays as it is: its
``query`` is served by small_gicp where small_gicp is installed, and everything else
(``query_ball_point``, ``sparse_distance_matrix``, ...) by a ``cKDTree`` built when
first asked for.
"""

import importlib.util
import os

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["PointTree"]


class PointTree:
    """A k-d tree of 3-D points with ``cKDTree``'s interface and faster nearest queries.

    Parameters
    ----------
    points : array-like of shape (n, 3)

    Attributes
    ----------
    data : ndarray of shape (n, 3), float64
        The points.
    n : int
        Their number (the index of "no neighbour" in :meth:`query`'s answers).

    Notes
    -----
    Where several points are as near, which one a query lists may differ from
    ``cKDTree``'s, and a distance may differ from scipy's in its last bit: where
    exact equality with scipy matters (the robust EM's neighbour table), use
    ``cKDTree``. A tree pickles (its engine is rebuilt
    when it is next queried).

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.point_tree import PointTree
    >>> tree = PointTree(np.array([[0.0, 0, 0], [1, 0, 0], [5, 0, 0]]))
    >>> distance, index = tree.query([[0.9, 0, 0], [9.0, 0, 0]], distance_upper_bound=2.0)
    >>> distance.round(6).tolist(), index.tolist()
    ([0.1, inf], [1, 3])
    >>> tree.query_ball_point([0.0, 0, 0], r=1.5)  # served by scipy's cKDTree
    [0, 1]
    """

    def __init__(self, points):
        self.data = np.ascontiguousarray(points, dtype=np.float64)
        if self.data.ndim != 2:
            raise ValueError(f"points must be 2-D (n, d); got shape {self.data.shape}.")
        self.n, self.m = self.data.shape
        self._engine = None
        self._scipy = None

    # ---------------------------------------------------------------- the engines
    def _small_gicp(self):
        """small_gicp's tree of the points, or None where it cannot serve them."""
        if self._engine is None:
            self._engine = False
            if self.n and self.m == 3 and _HAS_SMALL_GICP:
                import small_gicp

                self._engine = small_gicp.KdTree(self.data, num_threads=1)
        return self._engine or None

    @property
    def scipy_tree(self):
        """scipy's ``cKDTree`` of the points, built when first asked for."""
        if self._scipy is None:
            self._scipy = cKDTree(self.data)
        return self._scipy

    def __getstate__(self):
        return {"data": self.data}

    def __setstate__(self, state):
        self.__init__(state["data"])

    def __getattr__(self, name):
        # Everything but ``query`` is scipy's; a PointTree passed to it (the ``other``
        # of sparse_distance_matrix) stands for its cKDTree.
        if name.startswith("_"):
            raise AttributeError(name)
        attribute = getattr(self.scipy_tree, name)
        if not callable(attribute):
            return attribute

        def call(*args, **kwargs):
            args = [_scipy_of(a) for a in args]
            kwargs = {key: _scipy_of(value) for key, value in kwargs.items()}
            return attribute(*args, **kwargs)

        return call

    def __len__(self):
        return self.n

    # --------------------------------------------------------------------- query
    def query(self, x, k=1, eps=0, p=2, distance_upper_bound=np.inf, workers=1):
        """``cKDTree.query``: distances and indices of the ``k`` nearest points of ``x``.

        Where no point lies nearer than ``distance_upper_bound`` the distance is ``inf``
        and the index ``n``. Integer ``k`` on ``(m, 3)`` queries with ``eps=0`` and
        ``p=2`` run on small_gicp's tree (``workers``: its threads, -1 every core);
        any other query on scipy's.
        """
        x = np.asarray(x, dtype=np.float64)
        plain = isinstance(k, (int, np.integer)) and k >= 1 and eps == 0 and p == 2
        plain = plain and x.ndim == 2 and x.shape[1] == 3 and len(x) > 0
        engine = self._small_gicp() if plain else None
        if engine is None:
            return self.scipy_tree.query(
                x, k=k, eps=eps, p=p, distance_upper_bound=distance_upper_bound, workers=workers
            )
        x = np.ascontiguousarray(x)
        threads = (os.cpu_count() or 1) if workers == -1 else max(int(workers), 1)
        found = min(int(k), self.n)
        # The k-NN search also serves k = 1: its answers are arrays, where the nearest
        # neighbour search's are Python lists (their conversion cost a sixth of a query).
        index, squared = engine.batch_knn_search(x, found, num_threads=threads)
        index = np.asarray(index).astype(np.intp).reshape(len(x), found)
        distance = np.sqrt(np.asarray(squared, dtype=np.float64).reshape(len(x), found))
        if found < k:  # fewer points than asked for: the rest are "none", as scipy's
            index = np.hstack([index, np.full((len(x), k - found), self.n, dtype=np.intp)])
            distance = np.hstack([distance, np.full((len(x), k - found), np.inf)])
        if distance_upper_bound < np.inf:
            beyond = ~(distance < distance_upper_bound)
            distance[beyond] = np.inf
            index[beyond] = self.n
        if k == 1:
            return distance[:, 0], index[:, 0]
        return distance, index


def _scipy_of(value):
    return value.scipy_tree if isinstance(value, PointTree) else value


# Intel macOS has no small_gicp wheel: there, scipy's tree answers every query.
_HAS_SMALL_GICP = importlib.util.find_spec("small_gicp") is not None
