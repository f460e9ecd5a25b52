"""T-Linkage (Magri and Fusiello, CVPR 2014) for multi-model rigid registration.

Every correspondence gets a preference vector over a set of motion hypotheses; clusters
are merged greedily by the Tanimoto distance of their preference vectors until no two
clusters share a hypothesis. The agglomeration starts from the initial clusters rather
than from single correspondences (see :class:`TLinkage`, Notes).
"""

from numbers import Integral, Real

import numpy as np
from sklearn.base import _fit_context
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import check_is_fitted

from mmreg._array.geometry import degenerate_groups, fit_rigid_grouped, squared_residuals_all
from mmreg._validation import compact_labels
from mmreg.em._hypotheses import (
    fit_minimal_samples,
    minimal_sample_size,
    nearest_model,
)
from mmreg.em._likelihood import single_threaded_blas
from mmreg.em._paper import _relabel_by_size
from mmreg.estimators._base import BaseRegistration
from mmreg.init._resolve import INIT_CONSTRAINT, initial_labels

__all__ = ["TLinkage", "preference", "t_linkage", "tanimoto_linkage"]

# psi vanishes beyond this many tau_t (eq. 8 of Jin et al.).
CUTOFF = 5.0
# Cells per block of the (n x hypotheses) residual table, about 32 MiB: each block holds
# every row, so wide blocks spread the cost of each call's per-row features.
BLOCK_CELLS = 2**22


def preference(distance, tau_t):
    """The preference of a point for a hypothesis at residual ``distance`` (eq. 8).

    ``psi = exp(-distance / tau_t)`` if ``distance <= 5 tau_t``, else ``0``.

    Examples
    --------
    >>> from mmreg.baselines._t_linkage import preference
    >>> preference([0.0, 0.2, 0.6, 1.4], tau_t=0.2).round(4)
    array([1.    , 0.3679, 0.0498, 0.    ])
    """
    distance = np.asarray(distance, dtype=float)
    return np.where(distance <= CUTOFF * tau_t, np.exp(-distance / tau_t), 0.0)


def _local_samples(rng, units, n_units, n_samples, size):
    """Minimal samples whose points share the initial cluster of their first point.

    T-Linkage samples minimal sets locally, since a set spread over several objects
    gives a hypothesis that points of several objects prefer a little, which links
    them. Here locality is the initial cluster: the first point is uniform among the
    points of units with at least ``size`` points, the others uniform in its unit. If no
    unit is that large (every point its own unit), samples are uniform over all points.
    """
    n = len(units)
    order = np.argsort(units, kind="stable")
    counts = np.bincount(units, minlength=n_units)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    pool = order[counts[units[order]] >= size]
    if len(pool) == 0:
        return rng.randint(n, size=(n_samples, size))
    first = pool[rng.randint(len(pool), size=n_samples)]
    unit = units[first]
    offsets = (rng.random_sample((n_samples, size - 1)) * counts[unit][:, None]).astype(np.intp)
    others = order[starts[unit][:, None] + np.minimum(offsets, counts[unit][:, None] - 1)]
    return np.column_stack([first, others])


def unit_preferences(a, b, units, n_units, rotations, translations, tau_t):
    """Preference vector of each unit: the elementwise minimum over its points.

    Since ``psi`` decreases with the residual, the minimum over a unit's points is
    ``psi`` of the unit's largest residual, so only the ``(n_units, H)`` table of largest
    residuals is kept; the ``(n, H)`` residuals are built in blocks of hypotheses.

    Returns
    -------
    preferences : ndarray of shape (n_units, H)
    """
    order = np.argsort(units, kind="stable")
    a, b = a[order], b[order]
    starts = np.searchsorted(units[order], np.arange(n_units))
    n_hyp = len(rotations)
    largest = np.empty((n_units, n_hyp))
    step = max(1, BLOCK_CELLS // max(len(a), 1))
    for lo in range(0, n_hyp, step):
        cols = slice(lo, min(lo + step, n_hyp))
        sq = squared_residuals_all(a, b, rotations[cols], translations[cols])
        largest[:, cols] = np.maximum.reduceat(sq, starts, axis=0)
    return preference(np.sqrt(largest), tau_t)


def _tanimoto_distances(inner, norm, norms):
    """Tanimoto distance ``1 - <p,q> / (|p|^2 + |q|^2 - <p,q>)``; inf where ``<p,q> = 0``.

    Disjoint preferences are at distance exactly 1, which T-Linkage never merges, so
    they are stored as inf and the search for the closest pair ends at the first inf.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        dist = 1.0 - inner / (norm + norms - inner)
    return np.where(inner > 0, dist, np.inf)


def tanimoto_linkage(preferences):
    """Agglomerate units by the Tanimoto distance of their preference vectors.

    Repeatedly merges the closest pair of clusters; a merged cluster's preference is the
    elementwise minimum of its parts'. Stops when every pair is at distance 1 (no
    hypothesis preferred by both).

    Parameters
    ----------
    preferences : ndarray of shape (n_units, H)
        Non-negative preference vector of each unit.

    Returns
    -------
    clusters : ndarray of shape (n_units,)
        Final cluster of each unit, named by its lowest unit index.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.baselines._t_linkage import tanimoto_linkage
    >>> P = np.array([[1.0, 0.5, 0.0], [0.9, 0.0, 0.0], [0.0, 0.0, 1.0]])
    >>> tanimoto_linkage(P)
    array([0, 0, 2])
    """
    # Hypotheses x units, so that the rows of the hypotheses a cluster prefers are
    # contiguous: a merge then reads only those rows, a small part of the matrix.
    by_hyp = np.array(np.asarray(preferences, dtype=float).T, order="C")
    n_units = by_hyp.shape[1]
    owner = np.arange(n_units)
    active = np.ones(n_units, dtype=bool)
    norms = np.einsum("ij,ij->j", by_hyp, by_hyp)
    dist = _tanimoto_distances(by_hyp.T @ by_hyp, norms[:, None], norms[None, :])
    np.fill_diagonal(dist, np.inf)
    # Each unit keeps its nearest other unit, so the closest pair is one arg-min over
    # units. A merge can move a unit's nearest distance up; such a row is only marked
    # stale, its old distance a lower bound, and recomputed when it comes up as closest.
    nearest = np.argmin(dist, axis=1) if n_units else np.zeros(0, dtype=np.intp)
    bound = dist[np.arange(n_units), nearest]
    stale = np.zeros(n_units, dtype=bool)
    while n_units:
        first = int(np.argmin(bound))
        if not np.isfinite(bound[first]):
            break
        if stale[first]:
            nearest[first] = np.argmin(dist[first])
            bound[first] = dist[first, nearest[first]]
            stale[first] = False
            continue
        keep, gone = sorted((first, int(nearest[first])))
        merged = np.minimum(by_hyp[:, keep], by_hyp[:, gone])
        by_hyp[:, keep] = merged
        norms[keep] = merged @ merged
        active[gone] = False
        owner[owner == gone] = keep
        support = np.flatnonzero(merged)
        row = _tanimoto_distances(merged[support] @ by_hyp[support], norms[keep], norms)
        row[~active] = np.inf
        row[keep] = np.inf
        dist[keep], dist[:, keep] = row, row
        dist[gone], dist[:, gone] = np.inf, np.inf
        bound[gone] = np.inf
        # The merged cluster is nearer than any other unit to these rows: exact again.
        closer = row < bound
        lost = ~closer & ~stale & active & ((nearest == keep) | (nearest == gone))
        nearest[closer] = keep
        bound[closer] = row[closer]
        stale[closer] = False
        stale[lost] = True
        nearest[keep] = np.argmin(row)
        bound[keep] = row[nearest[keep]]
        stale[keep] = False
    return owner


def t_linkage(
    a,
    b,
    init_labels,
    *,
    tau_t=0.2,
    n_hypotheses=0,
    min_cluster_size=4,
    random_state=None,
):
    """T-Linkage on correspondences, starting from initial clusters.

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
        Corresponding points.
    init_labels : ndarray of shape (n,)
        Initial clusters, the units of the agglomeration; every correspondence with a
        negative label is a unit of its own.
    tau_t : float, default=0.2
        Scale of the preference function (eq. 8).
    n_hypotheses : int, default=0
        Random minimal-sample hypotheses added to the one Horn fit per initial cluster.
        Each sample is drawn inside the initial cluster of its first point.
    min_cluster_size : int, default=4
        Final clusters with fewer correspondences are outliers.
    random_state : int, RandomState instance or None, default=None
        Draws the random hypotheses.

    Returns
    -------
    labels : ndarray of shape (n,)
        Final clusters in ``0..K-1``, numbered by decreasing size; ``-1`` for outliers:
        correspondences in small clusters or in units that prefer no hypothesis.
    """
    rng = check_random_state(random_state)
    n, d = a.shape
    clusters, n_init = compact_labels(init_labels)
    units = clusters.copy()
    loose = np.flatnonzero(units < 0)
    units[loose] = n_init + np.arange(len(loose))
    n_units = n_init + len(loose)

    rotations, translations, _ = fit_rigid_grouped(a, b, clusters, n_init)
    fixed = ~degenerate_groups(a, clusters, n_init)
    rotations, translations = rotations[fixed], translations[fixed]
    if n_hypotheses:
        samples = _local_samples(rng, units, n_units, n_hypotheses, minimal_sample_size(d))
        extra_r, extra_t, _ = fit_minimal_samples(a, b, samples)
        rotations = np.concatenate([rotations, extra_r])
        translations = np.concatenate([translations, extra_t])

    # Thin products and matrix-vector products: one BLAS thread is faster, above all
    # when the cores are busy.
    with single_threaded_blas():
        pref = unit_preferences(a, b, units, n_units, rotations, translations, tau_t)
        owner = tanimoto_linkage(pref)
    # A unit that prefers no hypothesis is explained by no model: an outlier.
    owner[~np.any(pref > 0, axis=1)] = -1
    labels = owner[units]
    sizes = np.bincount(labels[labels >= 0], minlength=n_units)
    labels[(labels >= 0) & (sizes[np.maximum(labels, 0)] < min_cluster_size)] = -1
    labels, n_clusters = compact_labels(labels)
    return _relabel_by_size(labels, n_clusters)


class TLinkage(BaseRegistration):
    """T-Linkage baseline for multi-model registration (Magri and Fusiello, 2014).

    Each correspondence prefers each motion hypothesis by
    ``psi = exp(-d / tau_t)`` if its residual ``d = ||b - R a - t|| <= 5 tau_t``, else 0
    (eq. 8 of Jin et al.). Clusters are merged greedily, closest pair first, by the
    Tanimoto distance between their preference vectors, a merged cluster preferring what
    all its members prefer (the elementwise minimum), until no two clusters share a
    hypothesis. Clusters smaller than ``min_cluster_size`` are outliers. Each final
    cluster's motion is fitted by Horn's method.

    Parameters
    ----------
    tau_t : float, default=0.2
        Scale of the preference function, in the units of the points (the paper uses
        0.2 m on PASCAL3D+ and 1 m on FlyingThings3D).
    init : {"euclidean", "dbscan"}, clusterer or array-like of shape (n,), \
            default="euclidean"
        Initial clusters, resolved as in :class:`~mmreg.MultiModelRegistration`. They
        are the units the agglomeration starts from and each gives one hypothesis (its
        Horn fit). Correspondences with a negative initial label start as single units.
    n_hypotheses : int, default=0
        Random minimal-sample hypotheses added to those of the initial clusters; each
        sample lies inside one initial cluster (T-Linkage samples locally). Three noisy
        points extrapolate poorly, and with the cutoff ``5 tau_t`` a poor hypothesis can
        be preferred by parts of two objects, which then merge; so by default only the
        initial clusters' fits are used.
    min_cluster_size : int, default=4
        Final clusters with fewer correspondences are labelled ``-1``.
    sigma_floor : float or None, default=None
        Smallest value of ``sigmas_``; None uses ``1e-6`` times the RMS spread of the
        b-points.
    random_state : int, RandomState instance or None, default=None
        Draws the random hypotheses, and seeds a clusterer ``init`` whose own
        ``random_state`` is None. A fixed value gives identical results.

    Attributes
    ----------
    labels_ : ndarray of shape (n_samples,)
        Cluster of each correspondence, numbered by decreasing size; ``-1`` for outliers.
    rotations_ : ndarray of shape (n_clusters_, d, d)
        Rotation of each cluster (Horn's method on the cluster).
    translations_ : ndarray of shape (n_clusters_, d)
        Translation of each cluster: ``b ~ rotations_[j] @ a + translations_[j]``.
    sigmas_ : ndarray of shape (n_clusters_,)
        Isotropic noise scale of each cluster's residuals.
    weights_ : ndarray of shape (n_clusters_,)
        Fraction of all correspondences in each cluster.
    n_clusters_ : int
        Number of clusters found.
    init_labels_ : ndarray of shape (n_samples,)
        The initial clusters as given by ``init``.
    n_features_in_ : int
        Number of columns of ``X`` (``2 * d``).

    See Also
    --------
    mmreg.MultiModelRegistration : The paper's Classification-EM.
    NaiveRegistration : Horn's method on each initial cluster.
    SequentialRANSAC : One motion at a time by RANSAC.

    Notes
    -----
    **Units.** The original T-Linkage starts from single points: ``n - 1`` merges over
    an ``n x n`` distance matrix (4 GB for ``n = 22,395``). Here the agglomeration starts
    from the initial clusters (the paper initialises T-Linkage with the same clusters as
    the EM), each with the preference of its members' elementwise minimum, exactly what
    T-Linkage would give the cluster had it merged those points first. An initial
    labelling with every point in its own cluster is the original algorithm.

    **Hypotheses.** One Horn fit per initial cluster (clusters with coincident or
    collinear a-points give none), plus ``n_hypotheses`` minimal samples.

    **Outliers.** Units that prefer no hypothesis and final clusters smaller than
    ``min_cluster_size`` are labelled ``-1``.

    **Cost.** Residuals of all ``n`` points under all ``H`` hypotheses, in blocks of
    bounded memory; a dense ``U x U`` distance matrix over the ``U`` units; each merge
    reads the rows of the hypotheses the merged cluster prefers, ``O(U H)`` at worst.
    With 100 initial clusters (plus a thousand unclustered points) a 22k-correspondence
    scene takes about 0.1 s with ``n_hypotheses=0`` and 0.5 s with 1000.

    :meth:`predict` gives each correspondence to the cluster whose motion has the
    smallest residual, if that residual is at most ``5 tau_t`` (where the preference
    vanishes), else ``-1``.

    References
    ----------
    L. Magri and A. Fusiello, "T-Linkage: A continuous relaxation of J-Linkage for
    multi-model fitting", CVPR 2014.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.baselines import TLinkage
    >>> rng = np.random.default_rng(0)
    >>> a = np.vstack([rng.uniform(0, 1, (60, 3)), rng.uniform(5, 6, (40, 3))])
    >>> b = a.copy()
    >>> b[:60] += [3.0, 0.0, 0.0]                 # the first object moves, the second not
    >>> X = np.hstack([a, b])
    >>> init = np.repeat([0, 1, 2, 3], [30, 30, 20, 20])   # two pieces per object
    >>> est = TLinkage(init=init).fit(X)
    >>> est.n_clusters_
    2
    >>> np.bincount(est.labels_)
    array([60, 40])
    """

    _no_cluster_hint = "Raise tau_t, lower min_cluster_size, or use a coarser initial clustering."

    _parameter_constraints: dict = {
        **BaseRegistration._parameter_constraints,
        "tau_t": [Interval(Real, 0, None, closed="neither")],
        "init": INIT_CONSTRAINT,
        "n_hypotheses": [Interval(Integral, 0, None, closed="left")],
        "min_cluster_size": [Interval(Integral, 1, None, closed="left")],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        *,
        tau_t=0.2,
        init="euclidean",
        n_hypotheses=0,
        min_cluster_size=4,
        sigma_floor=None,
        random_state=None,
    ):
        self.tau_t = tau_t
        self.init = init
        self.n_hypotheses = n_hypotheses
        self.min_cluster_size = min_cluster_size
        self.sigma_floor = sigma_floor
        self.random_state = random_state

    @_fit_context(prefer_skip_nested_validation=False)
    def fit(self, X, y=None):
        """Merge the initial clusters by preference and fit each final cluster's motion.

        Parameters
        ----------
        X : array-like of shape (n_samples, 2 * d)
            Stacked correspondences ``[a | b]``; ``d = 3`` for point clouds.
        y : Ignored
            Not used, present for API consistency.

        Returns
        -------
        self : TLinkage
            The fitted estimator.
        """
        X, a, b = self._validate_correspondences(X, reset=True)
        # The same seed gives the same initial clusters as MultiModelRegistration's.
        self.init_labels_ = initial_labels(self.init, X, random_state=self.random_state)
        labels = t_linkage(
            a,
            b,
            self.init_labels_,
            tau_t=self.tau_t,
            n_hypotheses=self.n_hypotheses,
            min_cluster_size=self.min_cluster_size,
            random_state=self.random_state,
        )
        return self._store_labels(a, b, labels, self.sigma_floor)

    def predict(self, X):
        """Assign correspondences to the motion of smallest residual.

        A correspondence goes to the cluster whose motion moves its a-point closest to
        its b-point, if that residual is at most ``5 tau_t``; else ``-1``.

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
        return nearest_model(a, b, self.rotations_, self.translations_, CUTOFF * self.tau_t)
