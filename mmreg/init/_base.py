"""What every mmreg initialiser shares: it clusters the a-points of stacked correspondences."""

from sklearn.base import BaseEstimator, ClusterMixin, TransformerMixin

__all__ = ["BaseInitializer"]


class BaseInitializer(ClusterMixin, TransformerMixin, BaseEstimator):
    """Base class of the initialisers in :mod:`mmreg.init`.

    An initialiser takes the stacked correspondences ``X = [a | b]`` of shape
    ``(n, 2 * d)`` (not only the a-points, unlike a plain scikit-learn clusterer), and
    ``fit(X)`` sets ``labels_``: the initial partition, ``-1`` for correspondences it
    leaves out. :func:`mmreg.init.initial_labels` passes ``X`` whole to subclasses of
    this class and only the a-points to any other clusterer.
    """
