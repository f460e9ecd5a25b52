"""What every registration estimator shares: input checks, fitted layout and ``predict``."""

import warnings
from numbers import Real

import numpy as np
from sklearn.base import BaseEstimator, ClusterMixin
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import check_is_fitted, validate_data

from mmreg._flow import rigid_flow
from mmreg._gate import ClusterGate
from mmreg._geometry import degenerate_groups
from mmreg._likelihood import classify
from mmreg._validation import split_correspondences
from mmreg.estimators._em import default_sigma_floor, fit_cluster_models

__all__ = ["BaseRegistration", "DegenerateInputWarning"]

# Horn's method needs three non-collinear points to fix a 3-D rotation.
MIN_CORRESPONDENCES = 3


class DegenerateInputWarning(UserWarning):
    """The input is valid but does not determine the answer uniquely (e.g. collinear points)."""


class BaseRegistration(ClusterMixin, BaseEstimator):
    """Base class for multi-model registration estimators.

    Subclasses implement ``fit`` and call :meth:`_validate_correspondences` first and
    :meth:`_store_clusters` (or :meth:`_store_labels`) last. They share:

    * the input, stacked correspondences ``X = [a | b]`` of shape ``(n, 2 * d)``
      (``d = 3`` for point clouds; any ``d >= 1`` works);
    * the fitted layout: ``labels_`` (``-1`` for outliers), ``rotations_`` ``(K, d, d)``,
      ``translations_`` ``(K, d)``, ``sigmas_``, ``weights_``, ``n_clusters_``, and
      ``flow_``, the rigid scene flow ``R_j a_i + t_j - a_i`` of every correspondence
      (an outlier's a-point moves with the cluster of its nearest clustered a-point);
    * :meth:`predict`, which assigns new correspondences to the fitted motions by the
      weighted likelihood of eq. (7), gated by the distance ``tau`` to the fitted
      clusters' a-points (``tau=None``: no gate).

    Warning: This class should not be used directly. Use derived classes instead.
    """

    # Advice appended to the warning raised when no cluster survives a fit.
    _no_cluster_hint = ""

    _parameter_constraints: dict = {
        "sigma_floor": [Interval(Real, 0, None, closed="neither"), None],
    }

    def _validate_correspondences(self, X, *, reset):
        """Check ``X``; return it with its a- and b-points."""
        X = validate_data(
            self,
            X,
            reset=reset,
            dtype=np.float64,
            ensure_min_samples=MIN_CORRESPONDENCES if reset else 1,
        )
        return (X, *split_correspondences(X))

    def _store_labels(self, a, b, labels, sigma_floor=None):
        """Set the fitted attributes from final labels, fitting each cluster's motion."""
        if sigma_floor is None:
            sigma_floor = default_sigma_floor(b)
        n_clusters = int(labels.max()) + 1 if labels.size and labels.max() >= 0 else 0
        rotations, translations, sigmas, weights, _ = fit_cluster_models(
            a, b, labels, n_clusters, sigma_floor
        )
        return self._store_clusters(a, labels, rotations, translations, sigmas, weights)

    def _store_clusters(self, a, labels, rotations, translations, sigmas, weights):
        """Set the fitted attributes shared by every registration estimator."""
        self.labels_ = labels
        self.rotations_ = rotations
        self.translations_ = translations
        self.sigmas_ = sigmas
        self.weights_ = weights
        self.n_clusters_ = len(rotations)
        self.flow_ = rigid_flow(a, labels, rotations, translations)
        # predict() measures its gate against these a-points.
        self._cluster_points = a.copy()
        self._warn_if_degenerate(a, labels, self.n_clusters_)
        return self

    def _warn_if_degenerate(self, a, labels, n_clusters):
        if n_clusters == 0:
            warnings.warn(
                "No cluster survived: every correspondence is labelled -1 (outlier). "
                + self._no_cluster_hint,
                DegenerateInputWarning,
                stacklevel=3,
            )
            return
        degenerate = np.flatnonzero(degenerate_groups(a, labels, n_clusters))
        if len(degenerate):
            warnings.warn(
                f"The a-points of cluster(s) {degenerate.tolist()} are coincident or "
                "collinear, so their rotation is one of many that fit equally well.",
                DegenerateInputWarning,
                stacklevel=3,
            )

    def _gate_radius(self):
        """The distance gate used by :meth:`predict`; None means no gate."""
        return getattr(self, "tau", None)

    def predict(self, X):
        """Assign correspondences to the fitted motions.

        Each row goes to the cluster of largest weighted likelihood
        ``pi_j phi_j(b | a)`` (eq. 7) among the clusters whose fitted a-points lie within
        ``tau`` of its a-point; ``-1`` if there is none.

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
        gate = ClusterGate(
            self._cluster_points, self.labels_, self.n_clusters_, self._gate_radius()
        )
        return classify(
            a, b, self.rotations_, self.translations_, self.sigmas_, self.weights_, gate
        )

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = False
        return tags
