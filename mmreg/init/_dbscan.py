"""DBSCAN on the a-points, by scikit-learn or Open3D, with one rule for border points."""

import importlib.util
import warnings
from numbers import Integral, Real

import numpy as np
from scipy.spatial import cKDTree
from sklearn.base import _fit_context
from sklearn.utils._param_validation import Interval, StrOptions

from mmreg._array.neighbors import query_workers
from mmreg._warnings import user_stacklevel
from mmreg.init._partition import PartitionInitializer, number_by_first_point

__all__ = ["AllOutliersWarning", "DBSCANClustering", "default_eps"]

# eps=None: this many times the median distance from an a-point to its nearest neighbour.
EPS_SPACING_FACTOR = 4.0
# The median is estimated on at most this many a-points (evenly strided).
_SPACING_SAMPLE = 20_000


def default_eps(points, factor=EPS_SPACING_FACTOR):
    """``factor`` times the median nearest-neighbour distance of ``points`` (the spacing).

    Duplicate points (distance 0) are left out of the median; ``1.0`` when every point
    is the same. The median is taken over at most 20,000 evenly strided points, each
    against all the others.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.init._dbscan import default_eps
    >>> grid = np.stack(np.meshgrid(np.arange(10.0), np.arange(10.0), [0.0]), -1).reshape(-1, 3)
    >>> round(default_eps(0.2 * grid), 6)  # 4 times the spacing, 0.2
    0.8
    """
    points = np.asarray(points, dtype=float)
    if len(points) < 2:
        return 1.0
    step = max(1, len(points) // _SPACING_SAMPLE)
    dist, _ = cKDTree(points).query(points[::step], k=2)
    spacing = dist[:, 1][dist[:, 1] > 0]
    if not len(spacing):
        return 1.0
    return factor * float(np.median(spacing))


class AllOutliersWarning(UserWarning):
    """DBSCAN found no cluster: every a-point is noise (``eps`` too small for the data)."""


def _open3d_available():
    # Looking the module up does not import it (importing Open3D takes over a second).
    return importlib.util.find_spec("open3d") is not None


def _open3d_dbscan(points, eps, min_samples, workers=1):
    """Open3D's DBSCAN: labels and core-point mask (neighbours strictly within ``eps``)."""
    # Imported here: Open3D is large and only this backend needs it.
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    labels = np.asarray(cloud.cluster_dbscan(eps, min_samples, print_progress=False))
    # Open3D does not report its core points; they are the points with min_samples
    # points (themselves included) at distance < eps, as Open3D counts them.
    k = min(min_samples, len(points))
    dist, _ = cKDTree(points).query(points, k=k, distance_upper_bound=eps, workers=workers)
    core = np.isfinite(dist.reshape(len(points), k)[:, -1]) & (k == min_samples)
    return labels.astype(np.intp), core


def _sklearn_dbscan(points, eps, min_samples, n_jobs):
    from sklearn.cluster import DBSCAN  # imported when used: sklearn.cluster costs start-up

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
    eps : float or None, default=None
        Neighbourhood radius, in the units of the points (e.g. 0.05: 5 cm for point
        clouds in metres). None adapts it to the data: 4 times the median distance from
        an a-point to its nearest neighbour (:func:`default_eps`), so the same default
        suits data in millimetres and in kilometres, dense and sparse (the fixed 0.05 of
        earlier versions put every point of a scene in millimetres into noise). On the
        generated scenes 4 times gave over-segmentations from which the registration
        recovered the objects best (3 times left many points as noise, FlyingThings3D-like
        IoU 0.78-0.79 against 0.92). Clusters are
        ``eps``-connected, so ``eps < tau`` keeps them within Definition 2 of the paper.
        When no cluster is found (every point noise), an :class:`AllOutliersWarning` says
        so and names the ``eps`` used.
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
        Threads of the neighbour searches (the scikit-learn backend's, and the k-d tree
        queries around either backend); None means 1, -1 every core. Open3D's own
        clustering uses its own threads.

    Attributes
    ----------
    eps_ : float
        The neighbourhood radius used: ``eps``, or the one chosen from the data.
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
        "eps": [Interval(Real, 0, None, closed="neither"), None],
        "min_samples": [Interval(Integral, 1, None, closed="left")],
        "backend": [StrOptions({"auto", "open3d", "sklearn"})],
        "n_jobs": [Integral, None],
    }

    def __init__(self, eps=None, *, min_samples=5, backend="auto", n_jobs=None):
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
        self.eps_ = float(self.eps) if self.eps is not None else default_eps(points)
        if not np.isfinite(self.eps_) or self.eps_ <= 0:  # e.g. an overflowing spacing
            raise ValueError(f"eps must be a finite positive number; got {self.eps_}.")
        if self.backend_ == "open3d":
            labels, core = _open3d_dbscan(
                points, self.eps_, self.min_samples, query_workers(self.n_jobs)
            )
        else:
            labels, core = _sklearn_dbscan(points, self.eps_, self.min_samples, self.n_jobs)
        # Every point the backend clustered is a core point or within eps of one.
        core &= labels >= 0
        self.core_sample_indices_ = np.flatnonzero(core)
        self._core_points = points[core]
        self._core_labels = labels[core]
        border = np.flatnonzero((labels >= 0) & ~core)
        if len(border):
            _, nearest = cKDTree(self._core_points).query(
                points[border], k=1, workers=query_workers(self.n_jobs)
            )
            labels[border] = self._core_labels[nearest]
        self.labels_, self.n_clusters_ = number_by_first_point(labels)
        self._core_labels = self.labels_[core]
        if self.n_clusters_ == 0:
            warnings.warn(
                f"DBSCAN found no cluster: all {len(points):,} a-points are noise with "
                f"eps={self.eps_:.4g} and min_samples={self.min_samples} (the median spacing "
                f"of the points is {default_eps(points, 1.0):.4g}); raise eps.",
                AllOutliersWarning,
                stacklevel=user_stacklevel(),
            )
        return self

    def _assign(self, points):
        out = np.full(len(points), -1, dtype=np.intp)
        if not len(self._core_points):
            return out
        tree = cKDTree(self._core_points)
        bound = np.nextafter(self.eps_, np.inf)
        dist, idx = tree.query(
            points, k=1, distance_upper_bound=bound, workers=query_workers(self.n_jobs)
        )
        near = np.isfinite(dist)
        out[near] = self._core_labels[idx[near]]
        return out
