"""Algorithm 1 of Jin et al. (ICRA 2024): Classification-EM for multi-model registration.

A pure function on arrays; :class:`~mmreg.MultiModelRegistration` is a thin estimator on
top of it. Line numbers in the comments refer to Algorithm 1 of the paper.
"""

from dataclasses import dataclass

import numpy as np

from mmreg._array.geometry import fit_rigid_rows
from mmreg._validation import compact_labels
from mmreg.em._gate import ClusterGate
from mmreg.em._likelihood import CorrespondenceBlocks, classify, single_threaded_blas

__all__ = ["EMResult", "default_sigma_floor", "multi_model_em"]


@dataclass
class EMResult:
    """What :func:`multi_model_em` returns; arrays are indexed by the final clusters."""

    labels: np.ndarray
    rotations: np.ndarray
    translations: np.ndarray
    sigmas: np.ndarray
    weights: np.ndarray
    n_iter: int
    converged: bool


def default_sigma_floor(b):
    """``1e-6`` times the RMS spread of the b-points (``1e-6`` if they all coincide).

    On noiseless data the residual scatter of a cluster is pure rounding (``~1e-15``), and
    ratios of such sigmas would decide assignments at random. The floor makes clusters of
    exact fits equally sharp, so the weights ``pi_j`` decide, as Theorem 1 assumes.
    """
    if len(b) == 0:
        return 1e-6
    centred = b - b.mean(axis=0)
    # Column by column: the same sums as summing each short row, several times faster.
    squared = centred[:, 0] ** 2
    for column in range(1, centred.shape[1]):
        squared += centred[:, column] ** 2
    spread = float(np.sqrt(np.mean(squared)))
    return 1e-6 * spread if spread > 0 else 1e-6


def _size_rank(labels, n_clusters):
    """New number of each cluster so that 0 is the largest; ties keep their order.

    Returns ``rank`` of length ``n_clusters + 1`` with ``rank[-1] == -1``, so that
    ``rank[labels]`` also maps the unclustered points.
    """
    counts = np.bincount(labels + 1, minlength=n_clusters + 1)[1:]
    order = np.argsort(-counts, kind="stable")
    rank = np.full(n_clusters + 1, -1, dtype=np.intp)
    rank[order] = np.arange(n_clusters)
    return rank


def _relabel_by_size(labels, n_clusters):
    """Renumber clusters so that 0 is the largest; ties keep their previous order."""
    return _size_rank(labels, n_clusters)[labels]


def fit_cluster_models(a, b, labels, n_clusters, sigma_floor):
    """Pose, weight and noise scale of every cluster (Algorithm 1, lines 3-6)."""
    a_rows = np.ascontiguousarray(np.asarray(a, dtype=float).T)
    b_rows = np.ascontiguousarray(np.asarray(b, dtype=float).T)
    return _fit_clusters(a_rows, b_rows, labels, n_clusters, sigma_floor).models


def _fit_clusters(a_rows, b_rows, labels, n_clusters, sigma_floor, n_total=None):
    """:func:`fit_cluster_models` on ``(d, n)`` coordinate rows.

    Returns a :class:`_Fitted`; its per-point arrays cover all ``n`` points (those of
    unclustered points are meaningless). ``n_total`` (default ``n``) divides the counts
    into weights, for a fit of a subset of the points.
    """
    n_total = len(labels) if n_total is None else n_total
    # Unclustered points form an extra group, so no subset of the points is ever copied;
    # the per-group sums of the real clusters are unchanged by it.
    if len(labels) and labels.min() < 0:
        labels = np.where(labels < 0, n_clusters, labels)
        n_groups = n_clusters + 1
    else:
        n_groups = n_clusters
    fit = fit_rigid_rows(a_rows, b_rows, labels, n_groups)
    counts = fit.counts[:n_clusters]
    weights = counts / n_total
    # sigma_j = sqrt(tr(cov(E_j)) / d), sample covariance (ddof=1) of the residuals.
    d = len(a_rows)
    squared = np.einsum("ij,ij->j", fit.residuals, fit.residuals)
    sums = np.stack(
        [
            np.bincount(labels, weights=row, minlength=n_groups)[:n_clusters]
            for row in (*fit.residuals, squared)
        ],
        axis=1,
    )
    mean_sq_norm = np.sum(sums[:, :d] ** 2, axis=1) / np.maximum(counts, 1)
    scatter = np.maximum(sums[:, d] - mean_sq_norm, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        sigmas = np.sqrt(scatter / (d * (counts - 1)))
    sigmas[counts < 2] = sigma_floor
    sigmas = np.maximum(sigmas, sigma_floor)
    return _Fitted(
        fit.rotations[:n_clusters],
        fit.translations[:n_clusters],
        sigmas,
        weights,
        counts,
        fit.centroids[:n_clusters],
        squared,
        np.sqrt(np.einsum("ij,ij->j", fit.centred, fit.centred)),
    )


@dataclass
class _Fitted:
    """The models of the clusters, and what the E-step needs of each point."""

    rotations: np.ndarray
    translations: np.ndarray
    sigmas: np.ndarray
    weights: np.ndarray
    counts: np.ndarray
    centroids: np.ndarray
    squared: np.ndarray
    """Each point's squared residual under its cluster's motion."""
    spread: np.ndarray
    """Each point's distance to its cluster's centroid."""

    @property
    def models(self):
        return self.rotations, self.translations, self.sigmas, self.weights, self.counts

    def renumbered(self, present):
        """The models of the clusters ``present`` (a boolean mask), in order."""
        per_cluster = (self.rotations, self.translations, self.sigmas, self.weights)
        per_cluster += (self.counts, self.centroids)
        return _Fitted(*(x[present] for x in per_cluster), self.squared, self.spread)


def _refit(fitted, a_rows, b_rows, labels, changed, sigma_floor):
    """The models after an E-step that changed the members of the clusters ``changed``.

    ``fitted`` holds the models from before the E-step, renumbered like ``labels``. A
    cluster with the same members (in the same order) would be refitted to the very same
    model, bit for bit; only the changed clusters are, on their own points.
    """
    redo = np.flatnonzero(changed)
    position = np.full(len(changed) + 1, -1, dtype=np.intp)
    position[redo] = np.arange(len(redo))
    points = np.flatnonzero(position[labels] >= 0)
    part = _fit_clusters(
        np.take(a_rows, points, axis=1),
        np.take(b_rows, points, axis=1),
        position[labels[points]],
        len(redo),
        sigma_floor,
        n_total=len(labels),
    )
    out = _Fitted(*(np.array(x) for x in vars(fitted).values()))
    for name in ("rotations", "translations", "sigmas", "weights", "counts", "centroids"):
        getattr(out, name)[redo] = getattr(part, name)
    out.squared[points] = part.squared
    out.spread[points] = part.spread
    return out


def _compact_initial(labels):
    """:func:`~mmreg._validation.compact_labels`, without sorting when labels are small."""
    labels = np.asarray(labels)
    if labels.dtype.kind not in "iu" or not len(labels) or labels.max() > 4 * len(labels):
        return compact_labels(labels)
    labels = np.maximum(labels.astype(np.intp), -1)
    compact, n_clusters, _ = _compact(labels, int(labels.max()) + 1)
    return compact, n_clusters


def _compact(labels, n_clusters):
    """:func:`~mmreg._validation.compact_labels` for labels already in ``-1..K-1``.

    Also returns which of the ``K`` clusters are present (kept, in order).
    """
    present = np.bincount(labels + 1, minlength=n_clusters + 1)[1:] > 0
    rank = np.full(n_clusters + 1, -1, dtype=np.intp)
    rank[:n_clusters][present] = np.arange(np.count_nonzero(present))
    return rank[labels], int(np.count_nonzero(present)), present


def _print_iteration(iteration, labels, n_kept, n_dropped, settled):
    """One line of ``verbose`` output, in the robust variant's format."""
    step = {
        "iteration": iteration,
        "clusters": int(np.count_nonzero(np.bincount(labels[labels >= 0], minlength=n_kept))),
        "dropped": int(n_dropped),
        "outliers": int(np.count_nonzero(labels < 0)),
        "changed": int(np.count_nonzero(~settled)),
    }
    print(", ".join(f"{key} {value:g}" for key, value in step.items()))


def multi_model_em(
    a,
    b,
    init_labels,
    *,
    tau=1.5,
    min_cluster_size=4,
    max_iter=10,
    sigma_floor=None,
    workers=1,
    verbose=0,
):
    """Classification-EM for multi-model registration (Algorithm 1).

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
        Corresponding points, ``b_i ~ R_j a_i + t_j`` for the object ``j`` of ``i``.
    init_labels : ndarray of shape (n,)
        Initial clusters; negative labels mark correspondences in no cluster.
    tau : float or None, default=1.5
        Distance gate of eq. (7); None turns it off ("Ours (Vanilla)").
    min_cluster_size : int, default=4
        ``m_min``: clusters with fewer correspondences are removed before each M-step.
    max_iter : int, default=10
        ``T``. Iteration stops early once an M-step leaves every assignment unchanged.
    sigma_floor : float, default=None
        Smallest noise scale; None uses :func:`default_sigma_floor`.
    workers : int, default=1
        Threads of the KD-tree queries of the gate (``-1``: every core).
    verbose : int, default=0
        Print one line per iteration: the clusters after it, those dropped below
        ``min_cluster_size``, the correspondences in no cluster and those that changed
        cluster (the format of the robust variant's lines).

    Returns
    -------
    EMResult
        Final labels in ``0..K-1`` (``-1``: gated out of every cluster), numbered by
        decreasing cluster size, and the pose, noise scale and weight of each cluster,
        refitted on the final clusters.

    Notes
    -----
    An iteration costs ``O(n d^2)`` for the M-step (after the first, only the clusters
    whose members changed are refitted) and, for the E-step, ``O(d^2)`` per pair of a
    correspondence and a cluster still in play: in reach of the gate and not provably
    worse than the correspondence's own cluster (see :mod:`mmreg.em._likelihood`); points
    whose surroundings did not change are not scored again. Memory is ``O(n d^2)``,
    about 450 MiB of arrays for a million correspondences. None of this changes a label:
    the result is that of the plain loop in ``benchmarks/straightforward_em.py``.
    """
    if sigma_floor is None:
        sigma_floor = default_sigma_floor(b)
    labels, n_clusters = _compact_initial(init_labels)
    a_rows = np.ascontiguousarray(np.asarray(a, dtype=float).T)
    b_rows = np.ascontiguousarray(np.asarray(b, dtype=float).T)
    # The a-points never move: their blocks and residual features serve every E-step.
    blocks = CorrespondenceBlocks(a, b) if max_iter > 0 and n_clusters > 0 else None
    n_iter = 0
    converged = False
    fitted = None
    # What the last E-step left alone: its points face the same comparisons again unless
    # a cluster near them changed, so the next E-step can skip them, and the M-step need
    # refit only the changed clusters.
    settled = changed = None
    # The products are small: one BLAS thread is faster (see single_threaded_blas).
    with single_threaded_blas():
        for _ in range(max_iter):
            if n_clusters == 0:
                # Nothing left to fit or to assign to: the labels cannot change any more.
                converged = True
                break
            n_iter += 1
            # Lines 2-7: pose, weight pi_j = |H_j| / n and sigma_j of every cluster.
            if fitted is None:
                fitted = _fit_clusters(a_rows, b_rows, labels, n_clusters, sigma_floor)
            else:
                fitted = _refit(fitted, a_rows, b_rows, labels, changed, sigma_floor)
            rotations, translations, sigmas, weights, counts = fitted.models
            # Lines 10-13: clusters below m_min leave H before the M-step; their points keep
            # no "own" cluster and must be won by another one (or become outliers).
            kept = np.flatnonzero(counts >= min_cluster_size)
            # position[-1] == -1 maps the unclustered points too.
            position = np.full(n_clusters + 1, -1, dtype=np.intp)
            position[kept] = np.arange(len(kept))
            own = position[labels]
            # Lines 8-9 and 15-18: E-step and classification M-step, gated by d_cluster <= tau
            # measured against the clusters as they were when the poses were fitted.
            gate = ClusterGate(
                a,
                own,
                len(kept),
                tau,
                centers=fitted.centroids[kept],
                spread=fitted.spread,
                workers=workers,
            )
            new = classify(
                a,
                b,
                rotations[kept],
                translations[kept],
                sigmas[kept],
                weights[kept],
                gate,
                own,
                blocks=blocks,
                own_squared_residuals=fitted.squared,
                settled=settled,
                changed=None if changed is None else changed[kept],
                limit_blas=False,
            )
            new_in_old_ids = np.append(kept, -1)[new]
            settled = new_in_old_ids == labels
            if verbose:
                _print_iteration(n_iter, new, len(kept), n_clusters - len(kept), settled)
            if settled.all():
                converged = True
                break
            # A cluster changes when a point leaves or joins it; the last slot takes -1.
            touched = np.zeros(n_clusters + 1, dtype=bool)
            touched[labels[~settled]] = True
            touched[new_in_old_ids[~settled]] = True
            labels, n_clusters, present = _compact(new_in_old_ids, n_clusters)
            changed = touched[:-1][present]
            fitted = fitted.renumbered(present)
        else:
            # max_iter reached: the last E-step's clusters were never fitted.
            fitted = None
    rank = _size_rank(labels, n_clusters)
    labels = rank[labels]
    if fitted is None:
        rotations, translations, sigmas, weights, _ = fit_cluster_models(
            a, b, labels, n_clusters, sigma_floor
        )
    else:
        # The last M-step fitted exactly these clusters: renumbering them changes neither
        # the points nor their order within a cluster, so a refit would give the same.
        order = np.argsort(rank[:n_clusters])
        rotations, translations, sigmas, weights = (x[order] for x in fitted.models[:4])
    return EMResult(labels, rotations, translations, sigmas, weights, n_iter, converged)
