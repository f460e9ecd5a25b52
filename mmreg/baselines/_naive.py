"""The Naive baseline: Horn's method on each initial cluster, nothing else."""

from scipy.spatial import cKDTree
from sklearn.base import _fit_context
from sklearn.utils.validation import check_is_fitted

from mmreg.em._paper import multi_model_em
from mmreg.estimators._base import BaseRegistration
from mmreg.init._resolve import INIT_CONSTRAINT, initial_labels

__all__ = ["NaiveRegistration"]


class NaiveRegistration(BaseRegistration):
    """Naive multi-model registration: one rigid motion per initial cluster.

    The paper's "Naive" baseline (Section V-A): the initial clusters are the objects,
    and Horn's method gives each its motion. It shows how good the initial clustering
    is on its own, and is exactly :class:`~mmreg.MultiModelRegistration` with
    ``max_iter=0``.

    Parameters
    ----------
    init : {"euclidean", "dbscan"}, clusterer or array-like of shape (n,), \
            default="euclidean"
        Initial clusters, resolved as in :class:`~mmreg.MultiModelRegistration`:
        ``"euclidean"`` (:class:`~mmreg.init.EuclideanClustering` with 100 clusters),
        ``"dbscan"``, an mmreg initialiser (fitted on ``X``), any scikit-learn
        clusterer (fitted on the a-points ``X[:, :d]``), or precomputed labels
        (negative: in no cluster).
    sigma_floor : float or None, default=None
        Smallest value of ``sigmas_``; None uses ``1e-6`` times the RMS spread of the
        b-points.
    random_state : int, RandomState instance or None, default=None
        Seed given to a clusterer ``init`` whose own ``random_state`` is None.

    Attributes
    ----------
    labels_ : ndarray of shape (n_samples,)
        The initial clusters renumbered ``0..n_clusters_-1`` by decreasing size; ``-1``
        where the initial label was negative.
    rotations_ : ndarray of shape (n_clusters_, d, d)
        Rotation of each cluster (Horn's method).
    translations_ : ndarray of shape (n_clusters_, d)
        Translation of each cluster: ``b ~ rotations_[j] @ a + translations_[j]``.
    sigmas_ : ndarray of shape (n_clusters_,)
        Isotropic noise scale of each cluster's residuals.
    weights_ : ndarray of shape (n_clusters_,)
        Fraction of all correspondences in each cluster.
    n_clusters_ : int
        Number of initial clusters.
    init_labels_ : ndarray of shape (n_samples,)
        The initial clusters as given by ``init``.
    n_features_in_ : int
        Number of columns of ``X`` (``2 * d``).

    See Also
    --------
    mmreg.MultiModelRegistration : The EM that refines these clusters.
    TLinkage : Merges the initial clusters by their preferred motions.

    Notes
    -----
    The clusters come from where the a-points are, not from the motions, so
    :meth:`predict` does the same: a new correspondence takes the label of the nearest
    fitted a-point (``-1`` if that point had none). On the training data it returns
    ``labels_``.

    References
    ----------
    D. Jin, S. Karmalkar, H. Zhang and L. Carlone, "Multi-Model 3D Registration: Finding
    Multiple Moving Objects in Cluttered Point Clouds", ICRA 2024, Section V-A.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.baselines import NaiveRegistration
    >>> rng = np.random.default_rng(0)
    >>> a = np.vstack([rng.uniform(0, 1, (50, 3)), rng.uniform(5, 6, (50, 3))])
    >>> b = a.copy()
    >>> b[:50] += [1.0, 0.0, 0.0]                 # the first object moves, the second not
    >>> X = np.hstack([a, b])
    >>> est = NaiveRegistration(init=np.repeat([0, 1, 2, 3], 25)).fit(X)
    >>> est.n_clusters_                           # the initial clusters, unchanged
    4
    >>> np.round(est.translations_[est.labels_[0]], 6) + 0.0
    array([1., 0., 0.])
    """

    _no_cluster_hint = "The initial clustering left every correspondence unassigned."

    _parameter_constraints: dict = {
        **BaseRegistration._parameter_constraints,
        "init": INIT_CONSTRAINT,
        "random_state": ["random_state"],
    }

    def __init__(self, *, init="euclidean", sigma_floor=None, random_state=None):
        self.init = init
        self.sigma_floor = sigma_floor
        self.random_state = random_state

    @_fit_context(prefer_skip_nested_validation=False)
    def fit(self, X, y=None):
        """Fit one rigid motion to each initial cluster.

        Parameters
        ----------
        X : array-like of shape (n_samples, 2 * d)
            Stacked correspondences ``[a | b]``; ``d = 3`` for point clouds.
        y : Ignored
            Not used, present for API consistency.

        Returns
        -------
        self : NaiveRegistration
            The fitted estimator.
        """
        X, a, b = self._validate_correspondences(X, reset=True)
        self.init_labels_ = initial_labels(self.init, X, random_state=self.random_state)
        # Zero EM iterations: the initial clusters, renumbered, with their Horn fits.
        result = multi_model_em(a, b, self.init_labels_, max_iter=0, sigma_floor=self.sigma_floor)
        return self._store_clusters(
            a,
            b,
            result.labels,
            result.rotations,
            result.translations,
            result.sigmas,
            result.weights,
        )

    def predict(self, X):
        """Label each correspondence like the nearest fitted a-point.

        Parameters
        ----------
        X : array-like of shape (n_samples, 2 * d)
            Stacked correspondences ``[a | b]``; only the a-points are used.

        Returns
        -------
        labels : ndarray of shape (n_samples,)
        """
        check_is_fitted(self, "labels_")
        _, a, _ = self._validate_correspondences(X, reset=False)
        _, nearest = cKDTree(self._cluster_points).query(a, k=1)
        return self.labels_[nearest]
