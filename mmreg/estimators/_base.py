"""What every registration estimator shares: input checks, fitted layout and ``predict``."""

from numbers import Real

import numpy as np
from sklearn.base import BaseEstimator, ClusterMixin
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import check_is_fitted, validate_data

from mmreg._array.flow import rigid_flow
from mmreg._array.geometry import degenerate_groups
from mmreg._array.neighbors import query_workers
from mmreg._validation import invalid_rows, split_correspondences
from mmreg._warnings import warn
from mmreg.em._gate import ClusterGate
from mmreg.em._likelihood import classify
from mmreg.em._mixture import mixture_log_likelihood
from mmreg.em._paper import default_sigma_floor, fit_cluster_models
from mmreg.em._steps import log_uniform_density

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
      clusters' a-points (``tau=None``: no gate);
    * :meth:`score_samples` and :meth:`score`, the log-likelihood of correspondences
      under the fitted mixture (see :meth:`score_samples`).

    Warning: This class should not be used directly. Use derived classes instead.
    """

    # Advice appended to the warning raised when no cluster survives a fit.
    _no_cluster_hint = ""

    _parameter_constraints: dict = {
        "sigma_floor": [Interval(Real, 0, None, closed="neither"), None],
    }

    def _validate_correspondences(self, X, *, reset, allow_nan=False):
        """Check ``X``; return it with its a- and b-points. ``allow_nan``: rows with NaN
        pass (see :func:`~mmreg._validation.invalid_rows`), infinity does not."""
        X = validate_data(
            self,
            X,
            reset=reset,
            dtype=np.float64,
            ensure_min_samples=MIN_CORRESPONDENCES if reset else 1,
            ensure_all_finite="allow-nan" if allow_nan else True,
        )
        return (X, *split_correspondences(X))

    def _per_valid_row(self, X, a, b, function, fill):
        """``function(a, b)`` on the valid rows of ``X``; ``fill`` on the invalid ones."""
        invalid = invalid_rows(X) if self.__sklearn_tags__().input_tags.allow_nan else None
        if invalid is None or not invalid.any():
            return function(a, b)
        valid = ~invalid
        values = function(a[valid], b[valid])
        out = np.full(len(X), fill, dtype=values.dtype)
        out[valid] = values
        return out

    def _fitted_labels(self):
        """The labels of the fitted rows, which the gate of :meth:`predict` measures from
        (``labels_`` less the invalid rows that the fit left out)."""
        return getattr(self, "_cluster_labels", self.labels_)

    def _store_labels(self, a, b, labels, sigma_floor=None):
        """Set the fitted attributes from final labels, fitting each cluster's motion."""
        if sigma_floor is None:
            sigma_floor = default_sigma_floor(b)
        n_clusters = int(labels.max()) + 1 if labels.size and labels.max() >= 0 else 0
        rotations, translations, sigmas, weights, _ = fit_cluster_models(
            a, b, labels, n_clusters, sigma_floor
        )
        return self._store_clusters(a, b, labels, rotations, translations, sigmas, weights)

    def _store_clusters(self, a, b, labels, rotations, translations, sigmas, weights):
        """Set the fitted attributes shared by every registration estimator."""
        self.labels_ = labels
        self.rotations_ = rotations
        self.translations_ = translations
        self.sigmas_ = sigmas
        self.weights_ = weights
        self.n_clusters_ = len(rotations)
        self.flow_ = rigid_flow(a, labels, rotations, translations, workers=self._workers())
        # predict() and score() measure their gate against these a-points.
        self._cluster_points = a.copy()
        # score(): the uniform density of the outlier component, over the displacements.
        self._log_volume_density = log_uniform_density(a, b)
        self._warn_if_degenerate(a, labels, self.n_clusters_)
        return self

    def _warn_if_degenerate(self, a, labels, n_clusters):
        if n_clusters == 0:
            warn(
                "No cluster survived: every correspondence is labelled -1 (outlier). "
                + self._no_cluster_hint,
                DegenerateInputWarning,
            )
            return
        degenerate = np.flatnonzero(degenerate_groups(a, labels, n_clusters))
        if len(degenerate):
            warn(
                f"The a-points of cluster(s) {degenerate.tolist()} are coincident or "
                "collinear, so their rotation is one of many that fit equally well.",
                DegenerateInputWarning,
            )

    def _gate_radius(self):
        """The distance gate used by :meth:`predict`; None means no gate."""
        return getattr(self, "tau", None)

    def _workers(self):
        """Threads of the KD-tree queries: the estimator's ``n_jobs``, if it has one."""
        return query_workers(getattr(self, "n_jobs", None))

    def _fitted_gate(self):
        """The gate of eq. (7) around the fitted clusters, for new correspondences."""
        return ClusterGate(
            self._cluster_points,
            self._fitted_labels(),
            self.n_clusters_,
            self._gate_radius(),
            workers=self._workers(),
        )

    def _noise_scale(self, a):
        """Each correspondence's relative noise scale ``g_i`` (None: all 1)."""
        return None

    def _log_outlier_density(self):
        """``log(pi_0 / V)`` of the outlier component that completes the fitted mixture.

        ``pi_0`` is the share of the correspondences labelled -1 in the fit (at least
        ``1 / n``), so that with the clusters' weights ``pi_j = |H_j| / n`` it sums to
        one; ``V`` is the volume of the bounding box of the fitted displacements
        ``b - a`` (:func:`~mmreg.em._steps.log_uniform_density`).
        """
        labels = self._fitted_labels()
        n = len(labels)
        share = max(float(np.mean(labels < 0)), 1.0 / max(n, 1))
        return float(np.log(share)) + self._log_volume_density

    def score_samples(self, X):
        """Log-likelihood of each correspondence under the fitted mixture.

        The fitted model of ``b`` given ``a``: cluster ``j`` with weight ``pi_j``
        (``weights_``) moves ``a`` to ``R_j a + t_j`` with isotropic Gaussian noise
        ``sigma_j`` (``sigmas_``), and a uniform outlier component of weight ``pi_0``
        (the share of ``labels_ == -1``, at least ``1 / n``) spreads ``b - a`` over the
        bounding box (volume ``V``) of the fitted displacements. So

        ``log p(b | a) = log(sum_{j admitted} pi_j N(b; R_j a + t_j, sigma_j^2 I) + pi_0 / V)``

        where a cluster is *admitted* as the E-step of eq. (7) admits it: when one of
        its fitted a-points lies within ``tau`` of ``a`` (every cluster if the estimator
        has no ``tau`` or ``tau=None``). A correspondence far from every cluster is
        explained by the outlier component alone; a row that holds no measurement
        (NaN, where the estimator accepts it) gets NaN. The density is per unit volume of
        ``b``, in the units of the points, as :meth:`GaussianMixture.score_samples
        <sklearn.mixture.GaussianMixture.score_samples>` returns it.

        Parameters
        ----------
        X : array-like of shape (n_samples, 2 * d)
            Stacked correspondences ``[a | b]``, fitted or new.

        Returns
        -------
        log_likelihood : ndarray of shape (n_samples,)
        """
        check_is_fitted(self, "labels_")
        allow_nan = self.__sklearn_tags__().input_tags.allow_nan
        X, a, b = self._validate_correspondences(X, reset=False, allow_nan=allow_nan)
        return self._per_valid_row(X, a, b, self._log_likelihood, fill=np.nan)

    def _log_likelihood(self, a, b):
        """:meth:`score_samples` on valid rows."""
        return mixture_log_likelihood(
            a,
            b,
            self.rotations_,
            self.translations_,
            self.sigmas_,
            self.weights_,
            self._fitted_gate(),
            self._log_outlier_density(),
            self._noise_scale(a),
        )

    def score(self, X, y=None):
        """Mean log-likelihood per correspondence under the fitted mixture.

        The mean of :meth:`score_samples` over the rows that hold a measurement, as
        :meth:`GaussianMixture.score <sklearn.mixture.GaussianMixture.score>`: larger is
        better, so that
        :class:`~sklearn.model_selection.GridSearchCV` can choose parameters without
        labels. Scores of one scene are comparable between estimators and parameters;
        scores of scenes in other units are not (a density per unit volume).

        Parameters
        ----------
        X : array-like of shape (n_samples, 2 * d)
            Stacked correspondences ``[a | b]``, fitted or new (held out).
        y : Ignored
            Not used, present for API consistency.

        Returns
        -------
        log_likelihood : float
        """
        return float(np.nanmean(self.score_samples(X)))

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
        allow_nan = self.__sklearn_tags__().input_tags.allow_nan
        X, a, b = self._validate_correspondences(X, reset=False, allow_nan=allow_nan)
        return self._per_valid_row(X, a, b, self._classify, fill=-1)

    def _classify(self, a, b):
        """:meth:`predict` by eq. (7) on valid rows."""
        return classify(
            a,
            b,
            self.rotations_,
            self.translations_,
            self.sigmas_,
            self.weights_,
            self._fitted_gate(),
        )

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = False
        return tags
