"""DBSCAN on the a-points, by scikit-learn or Open3D, with one rule for border points."""

import importlib.util
from numbers import Integral, Real

import numpy as np
from scipy.spatial import cKDTree
from sklearn.base import _fit_context
from sklearn.cluster import DBSCAN
from sklearn.utils._param_validation import Interval, StrOptions

from mmreg.init._partition import PartitionInitializer, number_by_first_point

__all__ = ["DBSCANClustering"]


def _open3d_available():
    # Looking the module up does not import it (importing Open3D takes over a second).
    return importlib.util.find_spec("open3d") is not None


def _open3d_dbscan(points, eps, min_samples):
    """Open3D's DBSCAN: labels and core-point mask (neighbours strictly within ``eps``)."""
    # Imported here: Open3D is large and only this backend needs it.
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    labels = np.asarray(cloud.cluster_dbscan(eps, min_samples, print_progress=False))
    # Open3D does not report its core points; they are the points with min_samples
    # points (themselves included) at distance < eps, as Open3D counts them.
    k = min(min_samples, len(points))
    dist, _ = cKDTree(points).query(points, k=k, distance_upper_bound=eps)
    core = np.isfinite(dist.reshape(len(points), k)[:, -1]) & (k == min_samples)
    return labels.astype(np.intp), core


def _sklearn_dbscan(points, eps, min_samples, n_jobs):
    model = DBSCAN(eps=eps, min_samples=min_samples, n_jobs=n_jobs).fit(points)
    core = np.zeros(len(points), dtype=bool)
    core[model.core_sample_indices_] = True
    return model.labels_.astype(np.intp), core


class DBSCANClustering(PartitionInitializer):
    """DBSCAN on the a-points: clusters of densely packed points, sparse points left out.

    A point is a *core* point when at least ``min_samples`` points (itself included) lie
    within ``eps``; core points within ``eps`` of each other share a cluster; a non-core
    point within ``eps`` of a core point is a *border* point and joins the cluster of its
    nearest core point; all others are noise, label ``-1`` (no initial cluster: the EM
    offers them to every cluster within ``tau``).

    Parameters
    ----------
    eps : float, default=0.05
        Neighbourhood radius, in the units of the points (0.05: 5 cm for point clouds in
        metres). Clusters are ``eps``-connected, so ``eps < tau`` keeps them within
        Definition 2 of the paper.
    min_samples : int, default=5
        Points within ``eps`` (the point itself included) that make a core point.
    backend : {"auto", "open3d", "sklearn"}, default="auto"
        Who finds the clusters. ``"open3d"``: Open3D's ``cluster_dbscan`` (3-D points
        only; neighbours at exactly ``eps`` do not count); ``"sklearn"``:
        :class:`sklearn.cluster.DBSCAN` (any dimension; neighbours at ``eps`` count).
        ``"auto"`` uses Open3D for 3-D points when it is installed, else scikit-learn:
        Open3D was about twice as fast on the paper-sized scenes (see Notes). Open3D is
        imported on first use, which takes about a second once per process.
    n_jobs : int or None, default=None
        Parallel jobs for the scikit-learn backend's neighbour search; Open3D uses its
        own threads.

    Attributes
    ----------
    labels_ : ndarray of shape (n_samples,)
        Cluster of each correspondence in ``0..n_clusters_-1``, numbered in order of their
        first correspondence (whatever the backend); ``-1`` for noise.
    n_clusters_ : int
        Number of clusters found.
    core_sample_indices_ : ndarray of shape (n_core_samples,)
        Indices of the core points, increasing.
    backend_ : str
        The backend used, ``"open3d"`` or ``"sklearn"``.
    n_features_in_ : int
        Number of columns of ``X`` (``2 * d``).

    See Also
    --------
    EuclideanClustering : Components of the radius graph, tuned to a number of clusters.
    sklearn.cluster.DBSCAN : The scikit-learn backend.

    Notes
    -----
    Border points within ``eps`` of core points of two clusters go to the nearest core
    point here; both backends assign them to whichever cluster reaches them first, which
    depends on the order of the points. With this rule the two backends return the same
    labels up to points at exactly ``eps``.

    ``transform`` returns the sparse one-hot membership matrix ``(n_samples,
    n_clusters_)``; a new correspondence joins the cluster of its nearest core point if
    that is within ``eps``, like a border point.

    Timings on this project's 2-core machine (best of 3, ``make_scene(noise=0.03)``,
    Open3D 0.20, scikit-learn 1.9; both gave identical labels): 22,395 points,
    ``eps=0.05``: Open3D 0.06 s, scikit-learn 0.13 s; ``eps=0.1, min_samples=10``:
    0.11 s and 0.17 s; 100,000 points, ``eps=0.03``: 0.35 s and 0.73 s. With an ``eps``
    covering whole objects (``eps=0.5``, thousands of neighbours per point)
    scikit-learn is faster: 0.78 s against 1.6 s. Importing Open3D takes about 1 s,
    once per process.

    References
    ----------
    M. Ester, H.-P. Kriegel, J. Sander and X. Xu, "A Density-Based Algorithm for
    Discovering Clusters in Large Spatial Databases with Noise", KDD 1996.

    Examples
    --------
    >>> from mmreg.datasets import make_scene
    >>> from mmreg.init import DBSCANClustering
    >>> X = make_scene(n_objects=3, n_points=600, random_state=0).X
    >>> init = DBSCANClustering(eps=0.3, min_samples=5).fit(X)
    >>> init.n_clusters_
    3
    """

    _parameter_constraints: dict = {
        "eps": [Interval(Real, 0, None, closed="neither")],
        "min_samples": [Interval(Integral, 1, None, closed="left")],
        "backend": [StrOptions({"auto", "open3d", "sklearn"})],
        "n_jobs": [Integral, None],
    }

    def __init__(self, eps=0.05, *, min_samples=5, backend="auto", n_jobs=None):
        self.eps = eps
        self.min_samples = min_samples
        self.backend = backend
        self.n_jobs = n_jobs

    def _resolve_backend(self, n_dims):
        if self.backend == "sklearn":
            return "sklearn"
        if self.backend == "open3d":
            if n_dims != 3:
                raise ValueError(
                    f"backend='open3d' clusters 3-D points only; these a-points have {n_dims} "
                    "dimensions. Use backend='sklearn'."
                )
            if not _open3d_available():
                raise ImportError("backend='open3d' needs Open3D: pip install open3d.")
            return "open3d"
        return "open3d" if n_dims == 3 and _open3d_available() else "sklearn"

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
        self : DBSCANClustering
            The fitted initialiser.
        """
        points = self._validate_points(X, reset=True)
        self.backend_ = self._resolve_backend(points.shape[1])
        if self.backend_ == "open3d":
            labels, core = _open3d_dbscan(points, self.eps, self.min_samples)
        else:
            labels, core = _sklearn_dbscan(points, self.eps, self.min_samples, self.n_jobs)
        # Every point the backend clustered is a core point or within eps of one.
        core &= labels >= 0
        self.core_sample_indices_ = np.flatnonzero(core)
        self._core_points = points[core]
        self._core_labels = labels[core]
        border = np.flatnonzero((labels >= 0) & ~core)
        if len(border):
            _, nearest = cKDTree(self._core_points).query(points[border], k=1)
            labels[border] = self._core_labels[nearest]
        self.labels_, self.n_clusters_ = number_by_first_point(labels)
        self._core_labels = self.labels_[core]
        return self

    def _assign(self, points):
        out = np.full(len(points), -1, dtype=np.intp)
        if not len(self._core_points):
            return out
        tree = cKDTree(self._core_points)
        dist, idx = tree.query(points, k=1, distance_upper_bound=np.nextafter(self.eps, np.inf))
        near = np.isfinite(dist)
        out[near] = self._core_labels[idx[near]]
        return out
