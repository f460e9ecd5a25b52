"""The paper's estimator: Classification-EM multi-model registration."""

from numbers import Integral, Real

from sklearn.base import _fit_context
from sklearn.utils._param_validation import Interval

from mmreg.estimators._base import BaseRegistration
from mmreg.estimators._em import multi_model_em
from mmreg.init._resolve import INIT_CONSTRAINT, initial_labels

__all__ = ["MultiModelRegistration"]


class MultiModelRegistration(BaseRegistration):
    """Multi-model registration by Classification-EM (Jin et al., ICRA 2024, Algorithm 1).

    Given putative correspondences ``(a_i, b_i)`` between two point clouds of a scene in
    which several objects move rigidly, finds the objects (clusters of correspondences),
    the motion ``b = R_j a + t_j`` of each, and the outliers. Starting from an initial
    over-segmentation, every iteration fits a pose, weight ``pi_j = |H_j| / n`` and noise
    scale ``sigma_j`` per cluster, drops clusters smaller than ``min_cluster_size``, and
    moves each correspondence to the cluster of largest weighted likelihood among those
    whose a-points come within ``tau`` of its own a-point (eq. 7).

    Parameters
    ----------
    tau : float or None, default=1.5
        Distance gate of eq. (7), in the units of the points: a correspondence may join
        cluster ``H_j`` only if ``min_{a' in H_j} ||a' - a_i|| <= tau`` (eq. 7 writes ``<``;
        ``<=`` matches the paper's tau-connectedness, so Theorem 1 holds also for gaps of
        exactly ``tau``). Two objects farther apart than ``tau`` stay apart even when they
        move alike. None turns the gate off (the paper's "Ours (Vanilla)").
    min_cluster_size : int, default=4
        ``m_min``: clusters with fewer correspondences are removed before each M-step.
    max_iter : int, default=10
        ``T``, the largest number of EM iterations; iteration stops as soon as an M-step
        leaves every assignment unchanged. ``max_iter=0`` returns the initial clusters
        with their fitted motions (the paper's "Naive" baseline).
    init : {"euclidean", "dbscan"}, clusterer or array-like of shape (n,), \
            default="euclidean"
        Initial clusters. ``"euclidean"``: :class:`~mmreg.init.EuclideanClustering` with
        100 clusters, as in the paper; ``"dbscan"``: :class:`~mmreg.init.DBSCANClustering`.
        An mmreg initialiser is fitted on ``X``; any other object with ``fit_predict``
        (every scikit-learn clusterer) is fitted on the a-points ``X[:, :d]``. An array
        gives precomputed labels (e.g. from SAM masks), negative for none.
    sigma_floor : float or None, default=None
        Smallest noise scale ``sigma_j``. None uses ``1e-6`` times the RMS spread of the
        b-points, which keeps noiseless data well posed (see Notes).
    random_state : int, RandomState instance or None, default=None
        Seed given to a clusterer ``init`` whose own ``random_state`` is None. The EM
        iterations themselves are deterministic.

    Attributes
    ----------
    labels_ : ndarray of shape (n_samples,)
        Cluster of each correspondence in ``0..n_clusters_-1``, numbered by decreasing
        size; ``-1`` for correspondences that the gate keeps out of every cluster.
    rotations_ : ndarray of shape (n_clusters_, d, d)
        Proper rotation of each cluster (determinant ``+1``).
    translations_ : ndarray of shape (n_clusters_, d)
        Translation of each cluster: ``b ~ rotations_[j] @ a + translations_[j]``.
    sigmas_ : ndarray of shape (n_clusters_,)
        Isotropic noise scale of each cluster's residuals.
    weights_ : ndarray of shape (n_clusters_,)
        ``pi_j``: the fraction of all correspondences in each cluster.
    n_clusters_ : int
        Number of clusters found.
    init_labels_ : ndarray of shape (n_samples,)
        The initial clusters as given by ``init``.
    n_iter_ : int
        Number of EM iterations run.
    converged_ : bool
        Whether the last iteration left every assignment unchanged.
    n_features_in_ : int
        Number of columns of ``X`` (``2 * d``).

    See Also
    --------
    mmreg.init.EuclideanClustering : The default initial clustering.

    Notes
    -----
    Choices the paper leaves open:

    * **Ties** in the M-step keep a correspondence in its current cluster; among other
      clusters the lowest index wins.
    * **sigma** is ``sqrt(tr(cov(E_j)) / d)`` with the sample covariance (``ddof=1``),
      never below ``sigma_floor``; one-point clusters get ``sigma_floor``. Without a floor
      the sigmas of exact fits are rounding noise and would decide assignments at random.
    * **Points no cluster may take** (their own cluster was removed and no other is
      within ``tau``) are labelled ``-1``. They are not in any cluster, so they do not
      move the poses, but every M-step offers them to the clusters again.
    * **Initial labels below 0** mark correspondences in no cluster, handled as above.
    * The returned poses, sigmas and weights are refitted on the final clusters (when the
      iterations converged, they equal the last iteration's).

    Each iteration costs one batched SVD for the poses of the clusters that changed and
    scores each spatial block of correspondences only against the clusters whose
    bounding ball, grown by ``tau``, reaches it and which could beat the block's own
    clusters; the gate itself is tested with KD-trees only for correspondences whose
    best cluster is not their own. Memory stays linear in ``n``; time is about linear
    in ``n`` and sub-linear in the number of initial clusters (see ``benchmarks/``).

    References
    ----------
    D. Jin, S. Karmalkar, H. Zhang and L. Carlone, "Multi-Model 3D Registration: Finding
    Multiple Moving Objects in Cluttered Point Clouds", ICRA 2024.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg import MultiModelRegistration
    >>> rng = np.random.default_rng(0)
    >>> a = np.vstack([rng.uniform(0, 1, (50, 3)), rng.uniform(5, 6, (50, 3))])
    >>> b = a.copy()
    >>> b[:50] += [1.0, 0.0, 0.0]                 # the first object moves, the second not
    >>> X = np.hstack([a, b])
    >>> init = np.repeat([0, 1, 2, 3], [30, 20, 30, 20])  # two clusters per object
    >>> est = MultiModelRegistration(init=init).fit(X)
    >>> est.n_clusters_
    2
    >>> np.round(est.translations_[est.labels_[0]], 6) + 0.0
    array([1., 0., 0.])
    """

    _no_cluster_hint = "Lower min_cluster_size, raise tau, or use a coarser initial clustering."

    _parameter_constraints: dict = {
        **BaseRegistration._parameter_constraints,
        "tau": [Interval(Real, 0, None, closed="neither"), None],
        "min_cluster_size": [Interval(Integral, 1, None, closed="left")],
        "max_iter": [Interval(Integral, 0, None, closed="left")],
        "init": INIT_CONSTRAINT,
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        *,
        tau=1.5,
        min_cluster_size=4,
        max_iter=10,
        init="euclidean",
        sigma_floor=None,
        random_state=None,
    ):
        self.tau = tau
        self.min_cluster_size = min_cluster_size
        self.max_iter = max_iter
        self.init = init
        self.sigma_floor = sigma_floor
        self.random_state = random_state

    @_fit_context(prefer_skip_nested_validation=False)
    def fit(self, X, y=None):
        """Find the moving objects, their motions and the outliers.

        Parameters
        ----------
        X : array-like of shape (n_samples, 2 * d)
            Stacked correspondences ``[a | b]``; ``d = 3`` for point clouds.
        y : Ignored
            Not used, present for API consistency.

        Returns
        -------
        self : MultiModelRegistration
            The fitted estimator.
        """
        X, a, b = self._validate_correspondences(X, reset=True)
        self.init_labels_ = initial_labels(self.init, X, random_state=self.random_state)
        result = multi_model_em(
            a,
            b,
            self.init_labels_,
            tau=self.tau,
            min_cluster_size=self.min_cluster_size,
            max_iter=self.max_iter,
            sigma_floor=self.sigma_floor,
        )
        self._store_clusters(
            a, result.labels, result.rotations, result.translations, result.sigmas, result.weights
        )
        self.n_iter_ = result.n_iter
        self.converged_ = result.converged
        return self
