"""Turn the ``init`` parameter of a registration estimator into initial labels."""

import numpy as np
from sklearn.base import clone
from sklearn.utils._param_validation import HasMethods, StrOptions

from mmreg._validation import check_labels
from mmreg.init._base import BaseInitializer

__all__ = ["INIT_CONSTRAINT", "INIT_SHORTCUTS", "initial_labels", "is_label_array"]


def _shortcuts(tau=None):
    # Imported here so that a shortcut's module loads only when it is used.
    from mmreg.init import DBSCANClustering, EuclideanClustering

    return {
        "euclidean": lambda: EuclideanClustering(n_clusters=100, max_radius=tau),
        "dbscan": DBSCANClustering,
    }


INIT_SHORTCUTS = ("euclidean", "dbscan")

# The `_parameter_constraints` entry of every estimator that takes an `init`.
INIT_CONSTRAINT = [StrOptions(set(INIT_SHORTCUTS)), HasMethods(["fit_predict"]), "array-like"]


def is_label_array(init):
    """Whether ``init`` gives precomputed labels (not a shortcut nor a clusterer)."""
    if isinstance(init, str) or hasattr(init, "fit_predict"):
        return False
    return isinstance(init, (list, tuple, np.ndarray)) or hasattr(init, "__array__")


def initial_labels(init, X, *, random_state=None, n_jobs=None, tau=None, neighbours=None):
    """Initial clusters of the correspondences ``X = [a | b]``.

    Parameters
    ----------
    init : str, clusterer or array-like of shape (n,)
        ``"euclidean"`` (:class:`~mmreg.init.EuclideanClustering` with 100 clusters and
        its radius capped at ``tau``) or
        ``"dbscan"`` (:class:`~mmreg.init.DBSCANClustering`); an mmreg initialiser, fitted
        on ``X``; any other object with ``fit_predict`` (every scikit-learn clusterer),
        fitted on the a-points ``X[:, :d]``; or precomputed labels, one per row of ``X``
        (negative: in no cluster). Estimators are cloned, never fitted in place.
    X : ndarray of shape (n, 2 * d)
    random_state : int, RandomState instance or None
        Given to a cloned clusterer whose own ``random_state`` is None, so that the
        registration estimator's seed makes the whole fit reproducible.
    n_jobs : int or None, default=None
        Given, likewise, to a cloned clusterer whose own ``n_jobs`` is None (the
        shortcuts included): the registration estimator's threads for its neighbour
        queries.
    tau : float or None, default=None
        The registration's gate: the ``"euclidean"`` shortcut's radius never exceeds
        it, so that every initial cluster is ``tau``-connected (Definition 2). None: no
        cap. Clusterers given as objects are used as they are.
    neighbours : NeighbourTable or None, default=None
        The a-points' nearest neighbours, when the caller has them: the ``"euclidean"``
        shortcut reads them instead of querying them again.

    Returns
    -------
    labels : ndarray of shape (n,)
    """
    n, n_columns = X.shape
    if isinstance(init, str):
        makers = _shortcuts(tau)
        if init not in makers:
            raise ValueError(
                f"init={init!r} is not a known shortcut; use one of {sorted(makers)}, "
                "a clusterer with fit_predict, or an array of initial labels."
            )
        init = makers[init]()
        from mmreg.init import EuclideanClustering
        from mmreg.init._euclidean import euclidean_labels

        if isinstance(init, EuclideanClustering):
            # The same clusters as its fit, from the neighbours the caller may have listed.
            # The shortcut's 100 clusters are an upper bound the user never asked for: a
            # small scene that holds fewer is clustered as finely as it allows, unwarned.
            params = init.get_params() | {"n_jobs": n_jobs}
            labels, _, _ = euclidean_labels(X[:, : n_columns // 2], **params, neighbours=neighbours)
            return check_labels(labels, n, name="labels from init")
    if hasattr(init, "fit_predict"):
        if isinstance(init, type):
            raise TypeError(f"init must be an instance, not the class {init.__name__}.")
        clusterer = clone(init)
        params = clusterer.get_params(deep=False) if hasattr(clusterer, "get_params") else {}
        inherited = {"random_state": random_state, "n_jobs": n_jobs}
        inherited = {
            name: value
            for name, value in inherited.items()
            if value is not None and name in params and params[name] is None
        }
        if inherited:
            clusterer.set_params(**inherited)
        data = X if isinstance(clusterer, BaseInitializer) else X[:, : n_columns // 2]
        return check_labels(clusterer.fit_predict(data), n, name="labels from init")
    if is_label_array(init):
        return check_labels(init, n, name="init labels")
    raise TypeError(
        "init must be a shortcut string, a clusterer with fit_predict, or an array of "
        f"initial labels; got {type(init).__name__}."
    )
