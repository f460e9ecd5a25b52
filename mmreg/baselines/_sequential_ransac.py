"""Sequential RANSAC (Torr 1998): find one motion by RANSAC, remove its inliers, repeat."""

from numbers import Integral, Real

import numpy as np
from sklearn.base import _fit_context
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import check_is_fitted

from mmreg._array.geometry import fit_rigid, squared_residuals_all
from mmreg.em._hypotheses import (
    count_inliers,
    draw_minimal_samples,
    fit_minimal_samples,
    minimal_sample_size,
    nearest_model,
)
from mmreg.estimators._base import BaseRegistration

__all__ = ["SequentialRANSAC", "sequential_ransac"]


def _inliers(a, b, rotation, translation, threshold):
    sq = squared_residuals_all(a, b, rotation[None], translation[None])[:, 0]
    return sq <= threshold**2


def sequential_ransac(
    a,
    b,
    *,
    residual_threshold,
    max_trials=1000,
    min_inliers=10,
    max_models=None,
    random_state=None,
):
    """Sequential RANSAC for multi-model rigid registration.

    Each round draws ``max_trials`` minimal samples from the correspondences not yet
    explained, fits all of them with one batched Horn/Kabsch solve, counts the inliers of
    every hypothesis (residual ``<= residual_threshold``) with blocked matrix products,
    takes the hypothesis with most inliers, refits it on its inliers, takes the inliers of
    the refitted motion as the new model's correspondences and removes them. Rounds stop
    when the best model has fewer than ``min_inliers`` inliers, when ``max_models``
    models are found, or when no sample is left that is not degenerate.

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
        Corresponding points.
    residual_threshold : float
        Largest residual ``||b_i - R a_i - t||`` of an inlier.
    max_trials : int, default=1000
        Minimal samples drawn per round. Degenerate samples (coincident or collinear
        a-points) are drawn but skipped.
    min_inliers : int, default=10
        Smallest number of inliers of a model.
    max_models : int or None, default=None
        Largest number of models; None for no limit.
    random_state : int, RandomState instance or None, default=None

    Returns
    -------
    labels : ndarray of shape (n,)
        Model of each correspondence in the order the models were found (``0``: the
        largest consensus of the first round); ``-1`` for correspondences left over.
    """
    rng = check_random_state(random_state)
    n, d = a.shape
    size = minimal_sample_size(d)
    labels = np.full(n, -1, dtype=np.intp)
    remaining = np.arange(n)
    n_models = 0
    while (max_models is None or n_models < max_models) and len(remaining) >= max(
        size, min_inliers
    ):
        rest_a, rest_b = a[remaining], b[remaining]
        samples = draw_minimal_samples(rng, len(remaining), max_trials, size)
        rotations, translations, _ = fit_minimal_samples(rest_a, rest_b, samples)
        if len(rotations) == 0:
            break
        counts = count_inliers(rest_a, rest_b, rotations, translations, residual_threshold)
        best = int(np.argmax(counts))
        if counts[best] < min_inliers:
            break
        inliers = _inliers(rest_a, rest_b, rotations[best], translations[best], residual_threshold)
        # The minimal sample's motion carries the noise of three points; the least-squares
        # motion of its whole consensus set decides which correspondences the model keeps.
        rotation, translation = fit_rigid(rest_a[inliers], rest_b[inliers])
        inliers = _inliers(rest_a, rest_b, rotation, translation, residual_threshold)
        if np.count_nonzero(inliers) < min_inliers:
            break
        labels[remaining[inliers]] = n_models
        n_models += 1
        remaining = remaining[~inliers]
    return labels


class SequentialRANSAC(BaseRegistration):
    """Sequential RANSAC baseline for multi-model registration (Torr, 1998).

    Finds the objects one at a time: RANSAC on minimal samples of three correspondences
    finds the motion with the largest consensus set among the correspondences not yet
    explained, the motion is refitted on its inliers, and its inliers are removed. Stops
    when the best motion has fewer than ``min_inliers`` inliers. Needs no initial
    clustering.

    Parameters
    ----------
    residual_threshold : float, default=0.5
        Largest residual ``||b_i - R a_i - t||`` of an inlier, in the units of the points.
        The paper uses 0.01 on noiseless data and 0.5 with noise of standard deviation
        0.03.
    max_trials : int, default=1000
        Minimal samples (hypotheses) per RANSAC round; the paper uses 1000.
    min_inliers : int, default=10
        A model needs at least this many inliers; a minimal sample always has three, so
        values below 4 would never stop before every correspondence is explained.
    max_models : int or None, default=None
        Largest number of models (rounds); None for no limit.
    sigma_floor : float or None, default=None
        Smallest value of ``sigmas_``; None uses ``1e-6`` times the RMS spread of the
        b-points.
    random_state : int, RandomState instance or None, default=None
        Draws the minimal samples. A fixed value gives identical results.

    Attributes
    ----------
    labels_ : ndarray of shape (n_samples,)
        Model of each correspondence, in the order the models were found; ``-1`` for
        correspondences no model explains.
    rotations_ : ndarray of shape (n_clusters_, d, d)
        Rotation of each model, refitted on its inliers.
    translations_ : ndarray of shape (n_clusters_, d)
        Translation of each model: ``b ~ rotations_[j] @ a + translations_[j]``.
    sigmas_ : ndarray of shape (n_clusters_,)
        Isotropic noise scale of each model's residuals.
    weights_ : ndarray of shape (n_clusters_,)
        Fraction of all correspondences in each cluster.
    n_clusters_ : int
        Number of models found.
    n_features_in_ : int
        Number of columns of ``X`` (``2 * d``).

    See Also
    --------
    mmreg.MultiModelRegistration : The paper's Classification-EM.
    TLinkage : Preference-based agglomerative clustering of the correspondences.

    Notes
    -----
    Every round draws all ``max_trials`` samples at once, fits them with one batched
    Horn/Kabsch solve, and counts inliers for all hypotheses and correspondences as
    blocked matrix products: ``O(max_trials * m)`` work and bounded memory for ``m``
    remaining correspondences. There is no adaptive early stop; every round uses
    ``max_trials`` samples, as in the paper.

    A correspondence belongs to the first model that claims it, so the order in which
    the models are found matters. :meth:`predict`, which has no order to go by, gives
    each correspondence to the model of smallest residual if that residual is within
    ``residual_threshold``, else ``-1``; on the training data it can differ from
    ``labels_`` where two models both explain a correspondence.

    References
    ----------
    P. H. S. Torr, "Geometric motion segmentation and model selection", Philosophical
    Transactions of the Royal Society A, 1998.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.baselines import SequentialRANSAC
    >>> rng = np.random.default_rng(0)
    >>> a = np.vstack([rng.uniform(0, 1, (60, 3)), rng.uniform(5, 6, (40, 3))])
    >>> b = a.copy()
    >>> b[:60] += [1.0, 0.0, 0.0]                 # the first object moves, the second not
    >>> X = np.hstack([a, b])
    >>> est = SequentialRANSAC(residual_threshold=0.01, random_state=0).fit(X)
    >>> est.n_clusters_
    2
    >>> np.bincount(est.labels_)
    array([60, 40])
    >>> np.round(est.translations_[0], 6) + 0.0
    array([1., 0., 0.])
    """

    _no_cluster_hint = "Raise residual_threshold or lower min_inliers."

    _parameter_constraints: dict = {
        **BaseRegistration._parameter_constraints,
        "residual_threshold": [Interval(Real, 0, None, closed="neither")],
        "max_trials": [Interval(Integral, 1, None, closed="left")],
        "min_inliers": [Interval(Integral, 4, None, closed="left")],
        "max_models": [Interval(Integral, 1, None, closed="left"), None],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        *,
        residual_threshold=0.5,
        max_trials=1000,
        min_inliers=10,
        max_models=None,
        sigma_floor=None,
        random_state=None,
    ):
        self.residual_threshold = residual_threshold
        self.max_trials = max_trials
        self.min_inliers = min_inliers
        self.max_models = max_models
        self.sigma_floor = sigma_floor
        self.random_state = random_state

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, X, y=None):
        """Find the motions one at a time and label each correspondence by its model.

        Parameters
        ----------
        X : array-like of shape (n_samples, 2 * d)
            Stacked correspondences ``[a | b]``; ``d = 3`` for point clouds.
        y : Ignored
            Not used, present for API consistency.

        Returns
        -------
        self : SequentialRANSAC
            The fitted estimator.
        """
        X, a, b = self._validate_correspondences(X, reset=True)
        labels = sequential_ransac(
            a,
            b,
            residual_threshold=self.residual_threshold,
            max_trials=self.max_trials,
            min_inliers=self.min_inliers,
            max_models=self.max_models,
            random_state=self.random_state,
        )
        return self._store_labels(a, b, labels, self.sigma_floor)

    def predict(self, X):
        """Assign correspondences to the motion of smallest residual.

        A correspondence goes to the model whose motion moves its a-point closest to its
        b-point, if that residual is within ``residual_threshold``; else ``-1``.

        Parameters
        ----------
        X : array-like of shape (n_samples, 2 * d)
            Stacked correspondences ``[a | b]``.

        Returns
        -------
        labels : ndarray of shape (n_samples,)
        """
        check_is_fitted(self, "labels_")
        _, a, b = self._validate_correspondences(X, reset=False)
        return nearest_model(a, b, self.rotations_, self.translations_, self.residual_threshold)
