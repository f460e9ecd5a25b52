"""The steps the robust estimator adds around Algorithm 1, each a pure function on arrays.

* :func:`trimmed_fit`: the M-step on each cluster's inliers only (a residual test against
  a robust, median-based noise scale), so wrong correspondences do not bend the motions.
* :func:`merge_adjacent`: adjacent clusters whose motions explain each other's
  correspondences within their own noise are merged, by a likelihood-ratio test with the
  BIC's price for a rigid motion; many rounds per iteration, so a large over-segmented
  surface merges at once instead of growing by ``tau`` per iteration.
* :func:`reject_outliers`: the uniform outlier component: a correspondence whose
  cluster explains it less well than a uniform density over the scene is labelled -1.
* :func:`propose_clusters`: RANSAC hypotheses drawn inside tau-connected groups of
  unexplained correspondences; a hypothesis becomes a cluster only if it pays for itself
  under the same BIC, so scattered wrong correspondences never form one.
* :func:`drop_small_clusters`: clusters below ``min_cluster_size`` are dissolved.
"""

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from scipy.special import gamma
from scipy.stats import binom, chi2

from mmreg._array.connectivity import tau_components
from mmreg._array.geometry import column_bounds, own_residuals, residual_table
from mmreg._array.grouping import middle_values, unique_sorted
from mmreg._array.moments import Moments, group_moments
from mmreg._array.neighbors import NeighbourTable, touching_groups
from mmreg.em._hypotheses import fit_minimal_samples, minimal_sample_size
from mmreg.em._likelihood import morton_order
from mmreg.em._static_world import agrees_with_ego_motion, spanning_union, widest_cluster

__all__ = [
    "ClusterModels",
    "adjacent_pairs",
    "assign_correspondences",
    "boundary_layers",
    "drop_small_clusters",
    "estimate_range_growth",
    "fit_clusters",
    "judge_correspondences",
    "log_uniform_density",
    "join_moving_pieces",
    "merge_adjacent",
    "merge_static_world",
    "motion_gap",
    "moves_slowly",
    "pool_sigmas",
    "propose_clusters",
    "range_noise_scale",
    "reject_outliers",
    "squared_residuals",
    "trimmed_fit",
]

_LOG_2PI = np.log(2.0 * np.pi)
# Correspondences per spatial run of the E-step.
_RUN = 2048


def motion_parameters(d):
    """Free parameters of a rigid motion in ``d`` dimensions (6 in 3-D)."""
    return d * (d + 1) // 2


@dataclass
class ClusterModels:
    """Motions, noise scales and statistics of the clusters ``0..K-1``."""

    rotations: np.ndarray
    translations: np.ndarray
    sigmas: np.ndarray
    moments: Moments
    squared_error: np.ndarray
    """Weighted sum of squared residuals of each cluster's members under its own motion."""

    @property
    def counts(self):
        return self.moments.size

    def take(self, index):
        return ClusterModels(
            self.rotations[index],
            self.translations[index],
            self.sigmas[index],
            self.moments.take(index),
            self.squared_error[index],
        )

    def put(self, index, other):
        """Overwrite the entries ``index`` with ``other``'s, in place."""
        for name in ("rotations", "translations", "sigmas", "squared_error"):
            getattr(self, name)[index] = getattr(other, name)
        for name, value in vars(other.moments).items():
            getattr(self.moments, name)[index] = value


def _merge_into(models, target, group, d, sigma_floor):
    """Refit ``models[target]`` on the union of the clusters ``group``, in place.

    The union's noise scale pools the members' scales by size (each was measured on its
    own residuals; the joint motion's residuals would also count how the motions differ).
    """
    merged = models.moments.take(group[:1])
    for member in group[1:]:
        merged = merged + models.moments.take([member])
    refit = _models_from_moments(merged, d, sigma_floor)
    sizes = models.moments.size[group].astype(float)
    refit.sigmas = np.sqrt(np.sum(sizes * models.sigmas[group] ** 2) / max(sizes.sum(), 1))[None]
    models.put(target, refit.take(0))


def _models_from_moments(moments, d, sigma_floor):
    rotations, translations = moments.fit()
    error = moments.squared_error(rotations, translations)
    # Unbiased: the motion's parameters were fitted to the same residuals.
    dof = d * moments.size - motion_parameters(d)
    with np.errstate(divide="ignore", invalid="ignore"):
        sigmas = np.sqrt(error / dof)
    sigmas[~(dof > 0) | ~np.isfinite(sigmas)] = sigma_floor
    sigmas = np.maximum(sigmas, sigma_floor)
    return ClusterModels(rotations, translations, sigmas, moments, error)


def fit_clusters(a, b, labels, n_clusters, sigma_floor, noise_scale=None):
    """Motion (weighted Horn), unbiased noise scale and moments of every cluster.

    With ``noise_scale`` ``g_i``, correspondence ``i`` has noise ``sigma_j g_i``: rows
    are weighted by ``1 / g_i^2`` and ``sigma_j`` is the scale of the normalised
    residuals ``r_i / g_i``.
    """
    weights = None if noise_scale is None else noise_scale**-2
    moments = group_moments(a, b, labels, n_clusters, weights)
    return _models_from_moments(moments, a.shape[1], sigma_floor)


def squared_residuals(a, b, labels, rotations, translations):
    """``||b - R_j a - t_j||^2`` under each correspondence's own cluster ``j`` (inf for -1)."""
    out = np.full(len(a), np.inf)
    rows = np.flatnonzero(labels >= 0)
    if len(rows):
        out[rows] = own_residuals(rotations, translations, labels[rows], a[rows].T, b[rows].T)
    return out


def range_noise_scale(a, growth):
    """Relative noise scale ``g_i = 1 + growth * ||a_i||^2`` of each correspondence.

    Depth from stereo or structured light, and scene flow computed from it, errs by an
    amount that grows with the square of the range (``dz ~ z^2 d_disp / (f B)``), the
    sensor being at the origin of the a-points' frame. ``growth = 0``: equal noise.
    """
    return 1.0 + growth * np.einsum("ij,ij->i", a, a)


_GROWTH_SAMPLE = 16384


def estimate_range_growth(
    a,
    squared,
    labels,
    n_clusters,
    sigma_floor,
    *,
    n_grid=25,
    robust=False,
    confidence=0.999,
):
    """Maximum-likelihood ``growth`` of :func:`range_noise_scale` for the clusters given.

    ``growth`` is the sensor's, estimated with one noise scale ``sigma`` for all the
    clustered correspondences: with a scale of its own, each cluster at its own range
    could take the growth up in its scale, and a static world at one range (a backdrop)
    would say nothing of it. The likelihood of the residuals ``squared`` (``r_i^2``, of
    the correspondences with ``labels >= 0``) is maximised over 0 and a logarithmic grid
    of ``n_grid`` values around ``1 / median(||a||^2)``, ``sigma`` profiled out in
    closed form; a growth above 0 must raise it by more than the BIC price of one
    parameter. ``robust``: ``sigma`` from the median of the normalised residuals and
    each residual's cost truncated at the ``confidence`` quantile, so that the wrong
    correspondences the clusters still hold do not decide how the noise grows.
    """
    rows = np.flatnonzero((labels >= 0) & np.isfinite(squared))
    if len(rows) < 2 or n_clusters == 0:
        return 0.0
    if robust and len(rows) > _GROWTH_SAMPLE:
        # One parameter: an even sample of the rows pins it down as well as all of them.
        rows = rows[:: -(-len(rows) // _GROWTH_SAMPLE)]
    d = a.shape[1]
    range2 = np.einsum("ij,ij->i", a[rows], a[rows])
    typical = float(np.median(range2))
    if typical <= 0:
        return 0.0
    grid = np.concatenate([[0.0], np.logspace(-3, 3, n_grid) / typical])
    n = len(rows)
    floor2 = sigma_floor**2
    if robust:
        log_like = _robust_growth_likelihood(squared[rows], range2, grid, d, floor2, confidence)
    else:
        log_like = np.empty(len(grid))
        for k, growth in enumerate(grid):
            g2 = (1.0 + growth * range2) ** 2
            normalised = squared[rows] / g2
            # bincount's sequential sum, as the per-cluster version summed: same floats.
            total = np.bincount(np.zeros(n, dtype=np.intp), weights=normalised)[0]
            sigma2 = max(float(total) / (d * n), floor2)
            log_like[k] = -0.5 * d * (n * np.log(sigma2)) - 0.5 * d * np.sum(np.log(g2))
    best = int(np.argmax(log_like))
    # BIC: the growth is one more parameter, worth log(n) / 2 of likelihood.
    if log_like[best] - log_like[0] <= 0.5 * np.log(n):
        return 0.0
    return float(grid[best])


def _robust_growth_likelihood(squared, range2, grid, d, floor2, confidence):
    """The robust log-likelihood of every growth of ``grid`` (rows: the grid's values),
    :func:`estimate_range_growth`'s ``robust`` branch for the whole grid at once.

    In place on two ``(len(grid), n)`` arrays, and each row's median from one partition
    (the largest of the lower half is the other middle value): the same floats as
    ``np.median`` and the plain expressions, in a third of the time.
    """
    g2 = 1.0 + grid[:, None] * range2
    np.square(g2, out=g2)
    normalised = squared / g2
    n = normalised.shape[1]
    half = n // 2
    part = np.partition(normalised, half, axis=1)
    median = part[:, half] if n % 2 else (part[:, :half].max(axis=1) + part[:, half]) / 2
    sigma2 = np.maximum(median / chi2.ppf(0.5, d), floor2)
    cost = g2
    cost *= sigma2[:, None]
    np.log(cost, out=cost)
    cost *= d
    normalised /= sigma2[:, None]
    cost += normalised
    # A wrong correspondence costs the same under every growth: truncating its residual
    # alone would still credit it the log-density of a small scale, and a growth that
    # shrinks the scale of the nearest points would pay for itself by calling them all
    # wrong. Equal noise (the grid's first value, 0) puts the inlier quantile here.
    outlier_cost = d * np.log(sigma2[0]) + chi2.ppf(confidence, d)
    np.minimum(cost, outlier_cost, out=cost)
    return -0.5 * np.sum(cost, axis=1)


def pool_sigmas(models, d, sigma_floor):
    """Give every cluster the pooled noise scale of all of them, in place; return it.

    The noise of scene flow is the sensor's and the flow network's, not the object's: one
    scale ``sigma`` (times each correspondence's ``g_i``) for all clusters, estimated
    without bias from all their residuals. A cluster of wrong correspondences cannot
    pass itself off as an object with a large noise of its own.
    """
    sizes = models.moments.size
    dof = d * np.sum(sizes) - motion_parameters(d) * np.count_nonzero(sizes)
    sigma = float(np.sqrt(np.sum(models.squared_error) / dof)) if dof > 0 else sigma_floor
    sigma = max(sigma, sigma_floor) if np.isfinite(sigma) else sigma_floor
    models.sigmas = np.full(len(sizes), sigma)
    return sigma


def group_median(values, labels, n_groups):
    """Median of ``values`` over each group ``0..n_groups-1`` (NaN for an empty group).

    The lower median for an even count; rows with a negative label are ignored.
    """
    rows = np.flatnonzero(labels >= 0)
    low, _ = middle_values(values[rows], labels[rows], n_groups)
    return low


def robust_scales(squared, labels, n_clusters, d):
    """Each cluster's robust noise scale, and the scene's: ``sqrt(median(r^2) / median(chi2_d))``.

    Unharmed by up to half of a cluster's correspondences being wrong. The scene's scale
    (over every clustered correspondence) is the sensor's noise; no object's noise is
    taken to be smaller, so a cluster's scale never falls below it.

    Returns
    -------
    scales : ndarray of shape (n_clusters,)
    scene_scale : float
    """
    median_chi2 = chi2.ppf(0.5, d)
    member = labels >= 0
    scene = float(np.sqrt(np.median(squared[member]) / median_chi2)) if member.any() else 0.0
    scales = np.sqrt(group_median(squared, labels, n_clusters) / median_chi2)
    scales = np.where(np.isfinite(scales), np.maximum(scales, scene), scene)
    return scales, scene


def trimmed_fit(
    a,
    b,
    labels,
    n_clusters,
    sigma_floor,
    noise_scale=None,
    *,
    confidence=0.999,
    rounds=1,
    per_cluster=True,
    max_noise_ratio=None,
    reference=None,
):
    """M-step on inliers: fit, drop residuals beyond each cluster's robust scale, refit.

    Each round fits every cluster's motion on its current inliers, estimates each
    cluster's noise scale robustly from all its members (:func:`robust_scales`) and keeps
    as inliers the members whose normalised squared residual is within the
    ``confidence`` quantile of ``sigma_j^2 chi2_d``. One round is enough when the E-step
    runs in between: it has already left out the wrong correspondences of the last
    iteration. Each cluster keeps a noise scale of its own, as in Algorithm 1: a scene
    flow network errs by a few millimetres on the static world and by centimetres on a
    moving car (its error grows with the motion), and one shared scale would make every
    flow of the car an outlier. The scales are floored at the scene's own.
    ``per_cluster=False``: one scale for all clusters, robust for the trimming and pooled
    without bias afterwards (:func:`pool_sigmas`), so that a cluster of wrong
    correspondences cannot pass itself off as an object with a large noise of its own.

    ``max_noise_ratio``: a cluster's scale is capped at this fraction of how far its
    motion carries its points relative to the ``reference`` motion ``(R, t)`` (standing
    still if None), the prior of :func:`propose_clusters`: a flow network errs in
    proportion to the motion. An initial cluster that holds two objects (a moving car
    and a parked one, joined by the initialiser) otherwise fits a motion between them
    with a noise scale large enough to keep both; capped, its members fall out, and the
    proposals find each object's own motion.

    Returns
    -------
    inliers : ndarray of shape (n,)
        ``labels`` with the trimmed correspondences set to -1.
    models : ClusterModels
        Fitted on the inliers, with ``sigmas`` the unbiased scale of each cluster's
        inliers (at least the scene's scale and ``sigma_floor``).
    """
    d = a.shape[1]
    limit = chi2.ppf(confidence, d)
    g2 = 1.0 if noise_scale is None else noise_scale**2
    member = labels >= 0
    inliers = labels
    scene = sigma_floor
    for _ in range(rounds):
        models = fit_clusters(a, b, inliers, n_clusters, sigma_floor, noise_scale)
        sq = squared_residuals(a, b, labels, models.rotations, models.translations) / g2
        if per_cluster:
            scales, scene = robust_scales(sq, labels, n_clusters, d)
            if max_noise_ratio is not None:
                moved = _motion_from(models, reference)
                scales = np.minimum(scales, np.maximum(scene, max_noise_ratio * moved))
            scales = np.append(np.maximum(scales, sigma_floor), 0.0)  # labels -1 read the 0
            keep = member & (sq <= limit * scales[labels] ** 2)
        else:
            scale2 = np.median(sq[member]) / chi2.ppf(0.5, d) if member.any() else 0.0
            keep = member & (sq <= limit * max(scale2, sigma_floor**2))
        inliers = np.where(keep, labels, -1)
    models = fit_clusters(a, b, inliers, n_clusters, sigma_floor, noise_scale)
    if not per_cluster:
        pool_sigmas(models, d, sigma_floor)
        return inliers, models
    models.sigmas = np.maximum(models.sigmas, max(scene, sigma_floor))
    return inliers, models


def _rms(squared_sum, moments):
    """Root mean of each cluster's summed squares over its (weighted) count."""
    return np.sqrt(np.maximum(squared_sum, 0.0) / np.maximum(moments.count, 1e-300))


def _motion_from(models, reference):
    """How far each cluster's motion carries its members (RMS) from ``reference``'s
    ``(R, t)``, or from standing still if None."""
    k, d = models.translations.shape
    rotation, translation = (np.eye(d), np.zeros(d)) if reference is None else reference
    away = models.moments.squared_error(
        np.broadcast_to(rotation, (k, d, d)), np.broadcast_to(translation, (k, d))
    )
    return _rms(away - models.squared_error, models.moments)


def log_uniform_density(a, b):
    """``-log V`` of a uniform density of the displacements ``b - a`` over their bounding box.

    A wrong correspondence (a wrong match, a wrong scene flow) displaces its a-point by
    something in the range of the displacements the scene shows, not to anywhere in the
    scene: measured on scene-flow errors, this outlier model is several nats per point
    stronger than one uniform over the b-points, which is what keeps a patch of smoothly
    wrong flow from paying for a motion of its own. Degenerate extents (every point
    displaced alike, along an axis or a plane) are floored at ``1e-3`` of the scene's
    largest extent, so the volume is never zero and stays in the scene's units.
    """
    if not len(b):
        return 0.0
    (low_a, high_a), (low_b, high_b) = column_bounds(a), column_bounds(b)
    scene = float(np.max(np.maximum(high_a, high_b) - np.minimum(low_a, low_b)))
    if scene <= 0:
        return 0.0
    low, high = column_bounds(b - a)
    extent = np.maximum(high - low, 1e-3 * scene)
    return -float(np.sum(np.log(extent)))


def reject_outliers(
    a,
    b,
    labels,
    rotations,
    translations,
    sigmas,
    weights,
    log_outlier,
    noise_scale=None,
    *,
    false_alarms=None,
):
    """Label -1 the correspondences the uniform outlier component explains better.

    Correspondence ``i`` of cluster ``j`` stays iff
    ``pi_j N(b_i - R_j a_i - t_j; 0, (sigma_j g_i)^2 I) >= pi_0 / V`` with ``log_outlier``
    the right-hand side's logarithm: a residual test at about 5-7 ``sigma_j g_i``, farther
    the more weight the cluster has and the larger the scene.

    ``false_alarms``: also keep every correspondence whose residual is no larger than
    the cluster's noise shows with probability ``false_alarms / n`` (n correspondences
    judged), so that at most that many correspondences of a scene without outliers are
    expected to be called wrong. Without it, classification-EM settles where the
    outlier weight is the share that its own test rejects: the Gaussian tail beyond
    about 4 sigma, a few in ten thousand, stays labelled -1 for ever.
    """
    d = a.shape[1]
    sq = squared_residuals(a, b, labels, rotations, translations)
    rows = np.flatnonzero(labels >= 0)
    j = labels[rows]
    sigma = sigmas[j] if noise_scale is None else sigmas[j] * noise_scale[rows]
    with np.errstate(divide="ignore"):
        score = np.log(weights[j]) - d * np.log(sigma) - 0.5 * d * _LOG_2PI
    normalised = sq[rows] / sigma**2
    score -= 0.5 * normalised
    wrong = score < log_outlier
    if false_alarms is not None and len(a):
        wrong &= normalised > chi2.isf(false_alarms / len(a), d)
    out = labels.copy()
    out[rows[wrong]] = -1
    return out


def assign_correspondences(
    a, b, rotations, translations, sigmas, weights, gate, own, order, noise_scale=None
):
    """E-step and classification of eq. (7), each correspondence with its own noise scale.

    Correspondence ``i`` goes to the cluster of largest ``pi_j N(r_ij; 0, (sigma_j g_i)^2 I)``
    among those the gate admits; its own cluster wins ties (and keeps it when no other is
    admitted). The common factor ``g_i^-d`` does not change the winner, so scores are
    ``log pi_j - d log sigma_j - r_ij^2 / (2 sigma_j^2 g_i^2)``. Correspondences are taken
    in spatial runs (``order``, e.g. Morton order) of 2048, each scored only against the
    clusters whose bounding ball, grown by ``tau``, reaches the run.
    """
    n, d = a.shape
    labels = own.copy()
    k = len(rotations)
    if k == 0:
        return labels
    with np.errstate(divide="ignore"):
        log_prior = np.log(weights) - d * np.log(sigmas)
    half_precision = 0.5 / sigmas**2
    g2 = np.ones(n) if noise_scale is None else noise_scale**2
    if n == 0:
        return labels
    # The points in run order, once; every run's bounding box and the clusters that may
    # reach it, at once.
    ordered = a[order]
    a_rows, b_rows = np.ascontiguousarray(ordered.T), np.ascontiguousarray(b[order].T)
    starts = np.arange(0, n, _RUN)
    reach = gate.reach_boxes(
        np.minimum.reduceat(ordered, starts, axis=0), np.maximum.reduceat(ordered, starts, axis=0)
    )
    for run, start in enumerate(starts):
        rows = order[start : start + _RUN]
        pa = ordered[start : start + _RUN]
        candidates = np.flatnonzero(reach[run])
        if not len(candidates):
            continue
        sq = residual_table(
            rotations[candidates],
            translations[candidates],
            a_rows[:, start : start + _RUN],
            b_rows[:, start : start + _RUN],
        )
        sq /= g2[rows]
        sq *= half_precision[candidates, None]
        # One row per candidate cluster, one column per correspondence.
        score = log_prior[candidates, None] - sq
        column = np.full(k + 1, -1, dtype=np.intp)
        column[candidates] = np.arange(len(candidates))
        own_column = column[own[rows]]
        has_own = own_column >= 0
        own_score = np.full(len(rows), -np.inf)
        own_score[has_own] = score[own_column[has_own], np.flatnonzero(has_own)]
        challenger = score > own_score
        while True:
            live = np.flatnonzero(np.logical_or.reduce(challenger, axis=0))
            if not len(live):
                break
            best = np.argmax(np.where(challenger[:, live], score[:, live], -np.inf), axis=0)
            admitted = gate.admits(pa[live], candidates[best])
            labels[rows[live[admitted]]] = candidates[best[admitted]]
            challenger[:, live[admitted]] = False
            challenger[best[~admitted], live[~admitted]] = False
    return labels


def judge_correspondences(
    a,
    b,
    rotations,
    translations,
    sigmas,
    weights,
    gate,
    log_outlier,
    noise_scale=None,
    *,
    false_alarms=None,
):
    """Correspondences in no cluster yet, judged by fitted clusters: each to its most
    likely admitted cluster (:func:`assign_correspondences`), or -1 where the outlier
    component explains it better (:func:`reject_outliers`)."""
    parameters = (rotations, translations, sigmas, weights)
    labels = assign_correspondences(
        a,
        b,
        *parameters,
        gate,
        np.full(len(a), -1, dtype=np.intp),
        morton_order(np.ascontiguousarray(a.T)),
        noise_scale,
    )
    return reject_outliers(
        a, b, labels, *parameters, log_outlier, noise_scale, false_alarms=false_alarms
    )


def adjacent_pairs(points, labels, n_clusters, tau):
    """Pairs of clusters ``(i, j)``, ``i < j``, with points in one cell of side ``tau/sqrt(d)``.

    Two points in one such cell are at most ``tau`` apart, so every pair returned is
    within the gate of eq. (7); clusters that touch share cells. ``tau=None`` (no gate)
    pairs every two clusters.
    """
    if n_clusters < 2:
        return np.empty((0, 2), dtype=np.intp)
    if tau is None:
        i, j = np.triu_indices(n_clusters, k=1)
        return np.column_stack([i, j])
    keep = labels >= 0
    if not keep.any():
        return np.empty((0, 2), dtype=np.intp)
    points, labels = points[keep], labels[keep]
    d = points.shape[1]
    low, high = column_bounds(points)
    side = tau / np.sqrt(d)
    cells = np.floor((points - low) / side).astype(np.int64)
    dims = np.floor((high - low) / side).astype(np.int64) + 1
    if np.prod(dims.astype(float)) * n_clusters < 2.0**62:
        key = np.ravel_multi_index(tuple(cells.T), tuple(dims)) * n_clusters + labels
        key = unique_sorted(key)[0]
        cell_of, label_of = np.divmod(key, n_clusters)
    else:
        rows = np.unique(np.column_stack([cells, labels]), axis=0)
        _, cell_of = np.unique(rows[:, :d], axis=0, return_inverse=True)
        cell_of, label_of = cell_of.ravel(), rows[:, d]
    pairs = []
    offset = 1
    while offset < len(cell_of):
        same = np.flatnonzero(cell_of[offset:] == cell_of[:-offset])
        if not len(same):
            break
        pairs.append(np.column_stack([label_of[same], label_of[same + offset]]))
        offset += 1
    if not pairs:
        return np.empty((0, 2), dtype=np.intp)
    pairs = np.sort(np.vstack(pairs), axis=1).astype(np.intp)
    # As integer codes: np.unique(axis=0) costs a hundred times a sort of them.
    code, _ = unique_sorted(pairs[:, 0] * n_clusters + pairs[:, 1])
    return np.column_stack(np.divmod(code, n_clusters))


def _merge_ratio(models, pairs, d):
    """Likelihood-ratio statistic of "one motion" over its BIC price, for each pair.

    The joint motion is fitted with each cluster weighted by ``1 / sigma^2`` (each keeps
    its own noise scale: a far, noisier part of the background must not look like another
    motion). The statistic is ``sum_k (RSS_k(joint) - RSS_k(own)) / sigma_k^2``, which is
    ``chi2`` with ``d (d + 1) / 2`` degrees of freedom when the motions agree; the BIC
    price of the second motion is ``d (d + 1) / 2 * log(n_i + n_j)``. Below 1: merge.
    """
    i, j = pairs[:, 0], pairs[:, 1]
    inv_i = 1.0 / models.sigmas[i] ** 2
    inv_j = 1.0 / models.sigmas[j] ** 2
    mi, mj = models.moments.take(i), models.moments.take(j)
    rotations, translations = (mi.scaled(inv_i) + mj.scaled(inv_j)).fit()
    excess = (mi.squared_error(rotations, translations) - models.squared_error[i]) * inv_i
    excess += (mj.squared_error(rotations, translations) - models.squared_error[j]) * inv_j
    price = motion_parameters(d) * np.log(np.maximum(mi.size + mj.size, 2))
    return np.maximum(excess, 0.0) / price


def merge_adjacent(models, pairs, d, sigma_floor):
    """Merge adjacent clusters whose motions agree within their noise, round by round.

    Each round computes the statistic of :func:`_merge_ratio` for every adjacent pair and
    merges the pairs below 1 that are each other's best partner (so a cluster joins at
    most one other per round, and the strongest agreements go first); the merged
    clusters are refitted from their summed moments and the next round tests them again.

    Returns
    -------
    root : ndarray of shape (K,)
        The cluster each cluster was merged into (itself if none).
    models : ClusterModels
        Indexed like the old clusters; only the entries of roots are meaningful.
    n_merges : int
    """
    k = len(models.sigmas)
    parent = np.arange(k)
    n_merges = 0
    models = models.take(np.arange(k))  # a copy: entries are overwritten below
    # A pair's statistic depends on its two clusters alone: after a round only the pairs
    # of merged clusters (NaN) are tested again, which gives the same rounds as testing
    # every pair every round.
    ratio = np.full(len(pairs), np.nan)
    while len(pairs):
        stale = np.isnan(ratio)
        ratio[stale] = _merge_ratio(models, pairs[stale], d)
        good = ratio < 1.0
        if not good.any():
            break
        pairs, ratio = pairs[good], ratio[good]
        # Mutual best partners; ties to the first pair in order.
        order = np.argsort(ratio, kind="stable")
        pairs, ratio = pairs[order], ratio[order]
        first = np.full(k, len(ratio))
        np.minimum.at(first, pairs[:, 0], np.arange(len(ratio)))
        np.minimum.at(first, pairs[:, 1], np.arange(len(ratio)))
        index = np.arange(len(ratio))
        chosen = (first[pairs[:, 0]] == index) & (first[pairs[:, 1]] == index)
        keep, gone = pairs[chosen, 0], pairs[chosen, 1]
        merged = models.moments.take(keep) + models.moments.take(gone)
        refit = _models_from_moments(merged, d, sigma_floor)
        # The merged cluster's noise: the two scales pooled by size.
        size_keep, size_gone = models.moments.size[keep], models.moments.size[gone]
        refit.sigmas = np.sqrt(
            (size_keep * models.sigmas[keep] ** 2 + size_gone * models.sigmas[gone] ** 2)
            / np.maximum(size_keep + size_gone, 1)
        )
        models.put(keep, refit)
        parent[gone] = keep
        n_merges += len(keep)
        remap = np.arange(k)
        remap[gone] = keep
        pairs = np.sort(remap[pairs], axis=1)
        changed = np.zeros(k, dtype=bool)
        changed[keep] = True
        stale = changed[pairs].any(axis=1)
        # Pairs as integer codes: np.unique(axis=0) costs a hundred times a sort of them.
        code = pairs[:, 0] * k + pairs[:, 1]
        retested, _ = unique_sorted(code[stale & (pairs[:, 0] != pairs[:, 1])])
        code = np.concatenate([code[~stale], retested])
        ratio = np.concatenate([ratio[~stale], np.full(len(retested), np.nan)])
        # Ascending pairs, as np.unique gives them: the tie-break above reads this order.
        order = np.argsort(code, kind="stable")
        code, ratio = code[order], ratio[order]
        pairs = np.column_stack(np.divmod(code, k))
    root = parent
    while True:
        nxt = root[root]
        if np.array_equal(nxt, root):
            break
        root = nxt
    return root, models, n_merges


def motion_gap(models, reference, clusters):
    """RMS distance between where each cluster's motion and ``reference``'s carry its points.

    From the sufficient statistics: by Pythagoras, the squared error of cluster ``j``
    under the reference motion exceeds that under its own by (about, the rotations not
    being a linear family) the summed squared distance between the two motions' images
    of its points. ``reference`` is one cluster, or one per entry of ``clusters``.
    """
    clusters = np.asarray(clusters, dtype=np.intp)
    reference = np.broadcast_to(np.asarray(reference, dtype=np.intp), clusters.shape)
    moments = models.moments.take(clusters)
    excess = (
        moments.squared_error(models.rotations[reference], models.translations[reference])
        - models.squared_error[clusters]
    )
    return _rms(excess, moments)


def motion_beyond_scatter(models, reference, clusters):
    """:func:`motion_gap` less each cluster's own scatter (the RMS of its residuals).

    How far a cluster's motion carries its points from where ``reference``'s carries
    them, beyond what the cluster's own flow errs by. A scene-flow network's error on
    the static world is a few millimetres near the sensor and centimetres in coherent
    patches far from it (ZeroFlow: a wall 36 m away shifted by 6 cm, scattered by 2 cm);
    such a patch fits a motion of its own, but not one that its own scatter could not
    reach from the static world's.
    """
    clusters = np.asarray(clusters, dtype=np.intp)
    scatter = _rms(models.squared_error[clusters], models.moments.take(clusters))
    return motion_gap(models, reference, clusters) - scatter


def moves_slowly(a, b, groups, reference, sigma_floor, min_motion, noise_scale=None):
    """Which groups of correspondences move less than ``min_motion`` beyond their own
    scatter (:func:`motion_beyond_scatter`) relative to the ``reference`` motion ``(R,
    t)``: fitted as clusters, :func:`merge_static_world` would call them slow."""
    if not len(groups):
        return np.zeros(0, dtype=bool)
    rows = np.concatenate(groups)
    labels = np.repeat(np.arange(len(groups)), [len(g) for g in groups])
    scale = None if noise_scale is None else noise_scale[rows]
    models = fit_clusters(a[rows], b[rows], labels, len(groups), sigma_floor, scale)
    scatter = _rms(models.squared_error, models.moments)
    return _motion_from(models, reference) - scatter < min_motion


def motion_size(models, clusters, static):
    """How far each cluster's motion carries its points (RMS) relative to the static
    world's motion, or, without a static world (-1), relative to standing still."""
    clusters = np.asarray(clusters, dtype=np.intp)
    if static >= 0:
        return motion_gap(models, static, clusters)
    return _motion_from(models.take(clusters), None)


def join_moving_pieces(
    points,
    labels,
    models,
    static,
    d,
    sigma_floor,
    *,
    tolerance=0.2,
    neighbours=None,
    workers=1,
    targets=None,
    min_jump=0.0,
):
    """Merge touching moving clusters whose motions agree within ``tolerance`` of the motion.

    A scene-flow network errs on a moving object in proportion to its motion, and not
    rigidly: ZeroFlow's flow on a car 1.1 m into its motion bends by 10-30 cm from front
    to back. Each part of the car then fits a rigid motion of its own, and the test of
    :func:`merge_adjacent`, which trusts the residuals, keeps them apart. Two moving
    clusters (not the ``static`` world) are one object when they touch (points within
    three typical spacings of the moving points) and each one's motion carries the
    other's points, RMS, within ``tolerance`` times the smaller of their motions
    relative to the static world (to standing still when there is none: a camera's
    background split in pieces moves alike too). Cars in one lane move alike too, but
    do not touch. Two objects that touch and move alike within ``tolerance`` (two boxes
    on one pallet, one slipping 10 cm as both move 1 m) are told apart by ``targets``,
    the b-points: a network's error bends the flow of one object continuously, so the
    flows meet where its pieces touch, while two objects' flows jump there by the
    difference of their motions (:func:`_flow_jumps_at_contact`); pieces whose flows
    jump there by more than ``min_jump`` (``min_motion``: motions closer than this are
    one motion, as the static world's slow pieces are; FlyingThings3D's objects are
    rigid to a few millimetres) are never joined. Without ``targets`` the contact is
    not looked at.
    ``neighbours``: a :class:`NeighbourTable` of ``points``, which saves the query of
    the spacings.

    Returns
    -------
    root : ndarray of shape (K,)
        The cluster each cluster was merged into (itself if none).
    models : ClusterModels
        Indexed like the input; the entries of merged roots refitted.
    n_merges : int
    """
    k = len(models.sigmas)
    root = np.arange(k)
    if k < 2 + (static >= 0):
        return root, models, 0
    rows = np.flatnonzero((labels >= 0) & (labels != static))
    if len(rows) < 2:
        return root, models, 0
    if not _some_motions_agree(models, np.unique(labels[rows]), static, tolerance):
        # Joining needs agreeing motions and touching points: without the first, the
        # neighbour queries of the second are not needed.
        return root, models, 0
    pts, own = points[rows], labels[rows]
    if neighbours is None:
        spacing = cKDTree(pts).query(pts, k=2, workers=workers)[0][:, 1]
    else:
        moving = np.zeros(len(points), dtype=bool)
        moving[rows] = True
        spacing = neighbours.nearest_among(rows, moving)
    radius = 3.0 * float(np.median(spacing))
    pairs = touching_groups(pts, own, radius)
    if not len(pairs):
        return root, models, 0
    pairs = pairs[_motions_agree(models, pairs[:, 0], pairs[:, 1], static, tolerance)]
    if len(pairs) and targets is not None:
        jumps = _flow_jumps_at_contact(
            pts, targets[rows], own, models, pairs, radius, min_jump=min_jump
        )
        pairs = pairs[~jumps]
    if not len(pairs):
        return root, models, 0
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(k, k))
    _, component = connected_components(graph, directed=False)
    first = np.full(k, k, dtype=np.intp)
    np.minimum.at(first, component, np.arange(k))
    root = first[component]
    models = models.take(np.arange(k))  # a copy: merged roots are overwritten
    for target in np.unique(root[root != np.arange(k)]):
        _merge_into(models, target, np.flatnonzero(root == target), d, sigma_floor)
    return root, models, int(np.count_nonzero(root != np.arange(k)))


def _flow_jumps_at_contact(points, targets, labels, models, pairs, radius, *, min_jump=0.0):
    """Whether the flow jumps where the clusters of each pair ``(i, j)`` touch.

    Two hypotheses about a touching pair whose motions differ by a gap ``g`` (where one
    motion carries a point, less where the other carries it): two objects, whose flows
    jump by ``g`` at the contact, so that each side's contact points sit on their own
    motion; or one object whose flow bends continuously (a network's error), cut in two
    by rigid fits, so that the flows meet at the contact, halfway between the two
    motions. For every contact point (within ``radius`` of the other cluster) the
    position of its b-point along ``g`` is ``s = (b - own(a)) . g / |g|^2``: 0 on its own
    motion, 1/2 halfway. The flow jumps when the median ``s`` of the pair's contact
    points on both sides is nearer 0 than 1/2, and the median ``|g|`` there exceeds
    ``min_jump``. The median keeps wrong correspondences (up to half of the contact)
    from deciding, and noise moves ``s`` symmetrically about its mean.
    """
    jumps = np.zeros(len(pairs), dtype=bool)
    trees = {}

    def tree_of(cluster):
        if cluster not in trees:
            trees[cluster] = cKDTree(points[labels == cluster])
        return trees[cluster]

    for index, (i, j) in enumerate(pairs):
        positions, sizes = [], []
        for own, other in ((i, j), (j, i)):
            mine = np.flatnonzero(labels == own)
            dist, _ = tree_of(other).query(points[mine], distance_upper_bound=radius)
            contact = mine[np.isfinite(dist)]
            a, b = points[contact], targets[contact]
            here = a @ models.rotations[own].T + models.translations[own]
            gap = a @ models.rotations[other].T + models.translations[other] - here
            size2 = np.sum(gap * gap, axis=1)
            valid = size2 > 0
            positions.append(np.sum((b - here) * gap, axis=1)[valid] / size2[valid])
            sizes.append(np.sqrt(size2[valid]))
        positions, sizes = np.concatenate(positions), np.concatenate(sizes)
        jumps[index] = (
            len(positions) > 0 and np.median(positions) < 0.25 and np.median(sizes) > min_jump
        )
    return jumps


# Above this many pairs of moving clusters, join_moving_pieces tests only touching ones.
_MAX_PAIRS_TESTED_AHEAD = 1 << 15


def _motions_agree(models, i, j, static, tolerance):
    """The motion test of :func:`join_moving_pieces` for the pairs of clusters ``(i, j)``:
    each one's motion carries the other's points, RMS, within ``tolerance`` times the
    smaller of their motions relative to the ``static`` world."""
    motion = np.minimum(motion_size(models, i, static), motion_size(models, j, static))
    gap = np.maximum(motion_gap(models, i, j), motion_gap(models, j, i))
    return gap <= tolerance * motion


def _some_motions_agree(models, clusters, static, tolerance):
    """Whether any two of ``clusters`` pass :func:`_motions_agree` (True, untested, when
    there are too many pairs to test them all ahead)."""
    if len(clusters) * (len(clusters) - 1) // 2 > _MAX_PAIRS_TESTED_AHEAD:
        return True
    i, j = np.triu_indices(len(clusters), k=1)
    return bool(np.any(_motions_agree(models, clusters[i], clusters[j], static, tolerance)))


def _with(models, other):
    """``models`` followed by ``other``'s clusters."""
    return ClusterModels(
        *(
            np.concatenate([getattr(models, name), getattr(other, name)])
            for name in ("rotations", "translations", "sigmas")
        ),
        _concatenate_moments(models.moments, other.moments),
        np.concatenate([models.squared_error, other.squared_error]),
    )


# Pairs of clusters whose bounds gathered_by_each reads at once (memory: 25 floats each).
_PAIRS_PER_BLOCK = 1 << 18


def _pairs_that_may_gather(models, d, min_motion, present):
    """The pairs ``(i, j)`` of ``present`` clusters, ``i != j``, that lower bounds on
    :func:`_merge_ratio` and :func:`motion_beyond_scatter` cannot rule out.

    Both tests read a cluster's squared error under another motion, which is at least its
    least squared error plus its count times the distance by which that motion misplaces
    its centroid (Pythagoras, from the sufficient statistics). So a joint motion
    leaves an excess of at least ``h (|mb_i - mb_j| - |ma_i - ma_j|)^2`` (``h`` the two
    weights ``count / sigma^2`` in series: no rigid motion changes how far apart the
    centroids are), and ``i``'s motion carries ``j``'s points at least as far from where
    ``j``'s does as it carries ``j``'s centroid, less what each cluster's own motion
    errs above its least squared error (zero for fitted motions). Pairs with a bound
    twice beyond its test's threshold (and a margin for rounding) cannot pass it; the
    rest are tested exactly.
    """
    moments = models.moments.take(present)
    sigma2 = models.sigmas[present] ** 2
    count, size = moments.count, moments.size
    least = moments.squared_error(*moments.fit())
    slack = np.maximum(models.squared_error[present] - least, 0.0)
    # The size of the terms that the tests add and subtract, for a margin of rounding.
    magnitude = moments.scatter_a + moments.scatter_b
    magnitude = magnitude + count * (
        np.einsum("ij,ij->i", moments.mean_a, moments.mean_a)
        + np.einsum("ij,ij->i", moments.mean_b, moments.mean_b)
    )
    weight = count / sigma2
    merge_slack = (slack + 1e-9 * magnitude) / sigma2
    scatter = np.sqrt(np.maximum(models.squared_error[present], 0.0) / np.maximum(count, 1e-300))
    reach = count * 4.0 * np.maximum(min_motion + scatter, 0.0) ** 2 + slack + 1e-9 * magnitude
    rotations, translations = models.rotations[present], models.translations[present]
    n = len(present)
    step = max(1, _PAIRS_PER_BLOCK // max(n, 1))
    found = []
    for start in range(0, n, step):
        i = np.arange(start, min(start + step, n))
        apart_a = np.linalg.norm(moments.mean_a[i, None] - moments.mean_a[None], axis=2)
        apart_b = np.linalg.norm(moments.mean_b[i, None] - moments.mean_b[None], axis=2)
        series = weight[i, None] * weight[None] / (weight[i, None] + weight[None])
        price = motion_parameters(d) * np.log(np.maximum(size[i, None] + size[None], 2))
        may_merge = (
            series * (apart_b - apart_a) ** 2 - merge_slack[i, None] - merge_slack[None]
            <= 2.0 * price
        )
        # Where i's motion puts j's a-centroid, against j's b-centroid.
        carried = np.einsum("iab,jb->ija", rotations[i], moments.mean_a) + translations[i, None]
        off = carried - moments.mean_b[None]
        may_be_slow = count[None] * np.einsum("ija,ija->ij", off, off) <= reach[None]
        may = may_merge | may_be_slow
        may[np.arange(len(i)), i] = False
        row, column = np.nonzero(may)
        found.append(np.column_stack([present[i[row]], present[column]]))
    return np.vstack(found) if found else np.empty((0, 2), dtype=np.intp)


def gathered_by_each(models, d, min_motion):
    """What the static world would gather with it, were each cluster the static world.

    Row ``j`` marks ``j`` and every cluster whose motion agrees with ``j``'s
    (:func:`_merge_ratio` below 1) or moves less than ``min_motion`` relative to it beyond
    its own scatter (:func:`motion_beyond_scatter`): what :func:`merge_static_world`
    gathers. Only the pairs that bounds on both tests leave open are tested
    (:func:`_pairs_that_may_gather`), so that a thousand far-apart objects do not cost a
    million rigid fits; the result is that of testing every pair.

    Returns
    -------
    members : ndarray of shape (K, K), dtype bool
    """
    k = len(models.sigmas)
    members = np.eye(k, dtype=bool)
    present = np.flatnonzero(models.moments.size > 0)
    pairs = _pairs_that_may_gather(models, d, min_motion, present)
    if len(pairs):
        i, j = pairs[:, 0], pairs[:, 1]
        with_it = _merge_ratio(models, pairs, d) < 1.0
        with_it |= motion_beyond_scatter(models, i, j) < min_motion
        members[i[with_it], j[with_it]] = True
    return members


def merge_static_world(
    models, d, sigma_floor, *, share=0.5, min_motion=0.0, ego_motion=None, geometry=None
):
    """Find the static world and gather its pieces, however far apart.

    The static world is the dominant motion (the ego motion of the sensor, for a scene
    seen from a moving vehicle): the largest cluster, with every cluster that shares its
    motion (the likelihood-ratio test of :func:`merge_adjacent`, without the distance
    gate) or moves less than ``min_motion`` relative to it beyond its own scatter
    (:func:`motion_beyond_scatter`), if together they hold at least ``share`` of the
    clustered correspondences. In a crowded scene no motion does: the static world is
    then the cluster that spans the scene, whatever its share
    (:func:`~mmreg.em._static_world.widest_cluster`: the background reaches
    across the view, an object does not), or, when the background lies in pieces none of
    which spans it alone, the cluster whose union with the pieces it would gather spans it
    from behind the others (:func:`~mmreg.em._static_world.spanning_union`), or none;
    a cluster that spans the scene also wins over a majority that does not (an object
    filling half of a camera's view).
    With ``ego_motion`` ``(R, t)`` given, it is the largest cluster that moves with it
    (within ``min_motion`` beyond its scatter), whatever its share or spread, or none.
    ``geometry``: the clusters' a-points' :class:`~mmreg._array.moments.Moments`, every row
    weighted 1, for the spread (the models' moments weigh far rows less when the noise
    grows with range); None: the models'.

    Clusters that share its motion merge into it. Those that
    only move less than ``min_motion`` (a parked car whose flow carries a centimetre of
    annotation jitter) are *slow*: they keep their own motion, so that their
    correspondences are not outliers of the static world's, and are reported as part of
    it. Anything that moves alike but is not the static world keeps the gate of eq. (7):
    two far-apart objects with one motion stay two objects (the paper's Exp. 3).

    Returns
    -------
    static : int
        The static world's cluster, or -1 if there is none.
    root : ndarray of shape (K,)
        The cluster each cluster was merged into (itself if none).
    models : ClusterModels
        Indexed like the input; the static world's entry refitted.
    n_merges : int
    slow : ndarray of int
        The slow clusters.
    """
    k = len(models.sigmas)
    root = np.arange(k)
    none = (-1, root, models, 0, np.empty(0, dtype=np.intp))
    sizes = models.moments.size
    if k == 0 or sizes.sum() == 0:
        return none

    def gathered(static):
        others = np.flatnonzero((np.arange(k) != static) & (sizes > 0))
        agree = slow = np.zeros(len(others), dtype=bool)
        if len(others):
            pairs = np.column_stack([np.full(len(others), static), others])
            agree = _merge_ratio(models, pairs, d) < 1.0
            slow = ~agree & (motion_beyond_scatter(models, static, others) < min_motion)
        return others[agree], others[slow]

    if ego_motion is not None:
        present = np.flatnonzero(sizes > 0)
        gap = _motion_from(models.take(present), ego_motion)
        gap -= _rms(models.squared_error[present], models.moments.take(present))
        moving_with = present[agrees_with_ego_motion(gap, min_motion)]
        if not len(moving_with):
            return none
        static = int(moving_with[np.argmax(sizes[moving_with])])
        joined, slow = gathered(static)
    else:
        static = int(np.argmax(sizes))
        joined, slow = gathered(static)
        majority = share is not None and (
            sizes[static] + sizes[joined].sum() + sizes[slow].sum() >= share * sizes.sum()
        )
        # The cluster that spans the scene, if one does: the static world without a
        # majority, and instead of a majority that does not span it (an object filling
        # half of a camera's view in front of the background).
        spans = widest_cluster(
            models.moments if geometry is None else geometry, np.flatnonzero(sizes > 0)
        )
        if not majority or (spans >= 0 and spans not in {static, *joined, *slow}):
            if spans < 0:
                # A background in pieces, none spanning the scene alone.
                spans = spanning_union(
                    models.moments if geometry is None else geometry,
                    lambda: gathered_by_each(models, d, min_motion),
                )
            if spans < 0:
                return none
            static = spans
            joined, slow = gathered(static)
    if not len(joined):
        return static, root, models, 0, slow
    models = models.take(np.arange(k))  # a copy: the static world's entry is overwritten
    _merge_into(models, static, np.concatenate([[static], joined]), d, sigma_floor)
    root[joined] = static
    return static, root, models, len(joined), slow


def _local_samples(points, n_samples, size, rng, *, tree):
    """Minimal samples: a random seed and ``size - 1`` of its nearest neighbours.

    Nearby correspondences are the likeliest to share a motion, so local samples find
    a small object's motion among many others' far more often than uniform ones.
    ``tree``: a k-d tree of ``points``.
    """
    k_near = min(len(points), 9)
    seeds = rng.randint(len(points), size=n_samples)
    _, near = tree.query(points[seeds], k=k_near)
    near = np.asarray(near).reshape(n_samples, k_near)
    # Column 0 is the seed itself.
    picks = np.take_along_axis(
        near, 1 + rng.randint(max(k_near - 1, 1), size=(n_samples, size - 1)), axis=1
    )
    return np.column_stack([seeds, picks])


def _local_translations(points, targets, n_samples, reference, rng, *, tree, k=9):
    """Hypotheses that turn like ``reference`` and shift by a neighbourhood's mean.

    Over the 0.1 s between two sweeps a pedestrian or a car turns little relative to the
    static world: the static world's rotation and the mean of ``b - R a`` over a random
    seed's ``k`` nearest neighbours is a motion hypothesis whose noise is averaged over
    ``k`` correspondences, where a three-point sample on a small object amplifies it.
    ``tree``: a k-d tree of ``points``.
    """
    d = points.shape[1]
    rotation = np.eye(d) if reference is None else reference[0]
    k = min(k, len(points))
    seeds = rng.randint(len(points), size=n_samples)
    _, near = tree.query(points[seeds], k=k)
    near = np.asarray(near).reshape(n_samples, k)
    shifts = (targets[near] - points[near] @ rotation.T).mean(axis=1)
    return np.repeat(rotation[None], n_samples, axis=0), shifts


def _sample_every_group(a, b, members_of, n_hypotheses, size, rng, reference, turned):
    """The hypotheses of each group of :func:`propose_clusters`: its minimal samples'
    motions, then (if ``turned``) its :func:`_local_translations`.

    Every group draws from ``rng`` in turn; the minimal samples of all the groups are
    then fitted in one batched solve (a sample's motion does not depend on the others
    fitted with it), which saves a solve's fixed cost per group.

    Returns
    -------
    list of (rotations, translations), one per group
    """
    drawn, shifts = [], []
    for members in members_of:
        pa = a[members]
        tree = cKDTree(pa)
        drawn.append(members[_local_samples(pa, n_hypotheses, size, rng, tree=tree)])
        if turned:
            shifts.append(
                _local_translations(pa, b[members], n_hypotheses, reference, rng, tree=tree)
            )
    if not drawn:
        return []
    rotations, translations, valid = fit_minimal_samples(a, b, np.concatenate(drawn))
    ends = np.cumsum(np.count_nonzero(valid.reshape(len(drawn), -1), axis=1))
    out = []
    for i, (start, end) in enumerate(zip(np.concatenate([[0], ends[:-1]]), ends, strict=True)):
        turns, moves = rotations[start:end], translations[start:end]
        if turned:
            turns = np.concatenate([turns, shifts[i][0]])
            moves = np.concatenate([moves, shifts[i][1]])
        out.append((turns, moves))
    return out


def _explains_its_surroundings(points, inliers):
    """Whether ``inliers`` are most of the unexplained ``points`` around them.

    Around means within twice the median spacing of the inliers. A new motion of an
    object explains most of the unexplained correspondences where the object is; wrong
    flows that a few correspondences happen to share leave most of those around them
    unexplained.
    """
    tree = cKDTree(points[inliers])
    spacing, _ = tree.query(points[inliers], k=2)
    radius = 2.0 * float(np.median(spacing[:, 1]))
    distance, _ = tree.query(points, k=1, distance_upper_bound=np.nextafter(radius, np.inf))
    return 2 * len(inliers) > np.count_nonzero(distance <= radius)


def _concatenate_moments(first, second):
    return Moments(
        *(
            np.concatenate([x, y])
            for x, y in zip(vars(first).values(), vars(second).values(), strict=True)
        )
    )


# Rows per block of the passes over every point's neighbours (boundary_layers,
# scattered_clusters): n x 16 arrays at once cost hundreds of MB at a million points.
_BLOCK_ROWS = 1 << 16


def boundary_layers(
    points,
    labels,
    n_clusters,
    spacing,
    *,
    thickness=3.0,
    exempt=-1,
    neighbours=None,
    ignore_strays=False,
):
    """Clusters that are all boundary: a layer along another cluster, no interior.

    Scene-flow networks smear the flow of one surface over the pixels next to it, so
    along every silhouette a band of correspondences a pixel or two wide takes the motion
    of whatever lies beside it in the image (metres away in depth), and so do the blobs
    of wrong flow inside a surface. Either forms a cluster whose points lie within a few
    sampling spacings of another cluster's points: its median distance to the nearest
    point of another cluster is at most ``thickness`` times its median ``spacing`` (the
    distance from each point to its nearest neighbour). An object, however small or
    thin, has most of its points away from what it touches.

    Parameters
    ----------
    points : ndarray of shape (n, d)
    labels : ndarray of shape (n,)
    n_clusters : int
    spacing : ndarray of shape (n,)
        Distance from each point to its nearest neighbour among all points.
    thickness : float, default=3.0
    exempt : int or array-like of int, default=-1
        Clusters that are never layers (the static world); their points are not
        queried. Negative values name none.
    neighbours : NeighbourTable, default=None
        The nearest neighbours of ``points``; built here if None. A loop that calls this
        every iteration builds it once.
    ignore_strays : bool, default=False
        Whether points of other clusters that are strays (fewer than half of their
        nearest neighbours in their own cluster) are left out of the gaps. A few
        members of the static world inside a small object (a pedestrian whose noisy
        flow fits the static motion at a few points) otherwise make the object look like
        a layer along them; a layer lies along the body of another cluster.
    Returns
    -------
    clusters : ndarray
        Indices of the clusters that are boundary layers.

    Notes
    -----
    The median test only needs to know, for each point, whether a point of another
    cluster lies within its cluster's limit ``thickness * typical spacing``. The nearest
    ``k`` neighbours settle that for most points: a foreign one among them within the
    limit says yes; none, with the ``k``-th beyond the limit, says no. Only clusters that
    the settled points leave undecided widen ``k`` for their unsettled points, so the
    answer is exact without a k-d tree per call.
    """
    rows = np.flatnonzero(labels >= 0)
    if n_clusters < 2 or not len(rows):
        return np.empty(0, dtype=np.intp)
    if neighbours is None:
        neighbours = NeighbourTable(points)
    own = labels[rows]
    counts = np.bincount(own, minlength=n_clusters)
    limit = thickness * np.nan_to_num(group_median(spacing, labels, n_clusters))
    # A cluster is a layer when its median gap is within its limit: when at least this
    # many of its points have a foreign point within the limit.
    needed = (counts - 1) // 2 + 1
    candidate = counts > 0
    candidate[_clusters_named(exempt)] = False
    counted = labels.copy()
    if ignore_strays:
        alone = np.zeros(len(labels), dtype=bool)
        # In blocks: the neighbours' labels of every point at once are n x 15 integers.
        for start in range(0, len(labels), _BLOCK_ROWS):
            block = slice(start, start + _BLOCK_ROWS)
            others = labels[neighbours.index[block, 1:]]
            same = np.count_nonzero(others == labels[block, None], axis=1)
            alone[block] = 2 * same < others.shape[1]
        counted[alone] = -1
    near = np.zeros(n_clusters, dtype=np.intp)
    pending = rows[candidate[own]]
    k = neighbours.k
    while len(pending):
        # Most points pending (no static world exempt): every point is scanned with the
        # table read in place, cheaper than copying the pending points' entries.
        dense = k <= neighbours.k and 4 * len(pending) >= 3 * len(labels)
        scanned = np.arange(len(labels)) if dense else pending
        cluster = labels[scanned]
        reach = limit[cluster]
        settled_near = np.zeros(len(scanned), dtype=bool)
        reaches = np.zeros(len(scanned), dtype=bool)  # the k-th neighbour within reach
        for start in range(0, len(scanned), _BLOCK_ROWS):
            block = slice(start, start + _BLOCK_ROWS)
            if dense:
                distance, index = neighbours.distance[block, :k], neighbours.index[block, :k]
            else:
                distance, index = neighbours.nearest(scanned[block], k)
            others = counted[index]
            within = distance <= reach[block, None]
            foreign = (others >= 0) & (others != cluster[block, None]) & within
            settled_near[block] = foreign.any(axis=1)
            reaches[block] = within[:, -1]
        if dense:
            cluster, settled_near, reaches = (x[pending] for x in (cluster, settled_near, reaches))
        open_ = ~settled_near & reaches & (k < len(neighbours))
        near += np.bincount(cluster[settled_near], minlength=n_clusters)
        still_open = np.bincount(cluster[open_], minlength=n_clusters)
        undecided = (near < needed) & (near + still_open >= needed)
        pending = pending[open_ & undecided[cluster]]
        k *= 4
    layers = candidate & (near >= needed)
    return np.flatnonzero(layers)


def scattered_clusters(labels, n_clusters, neighbours, *, exempt=-1):
    """Clusters without a body of their own: most of their members are strays.

    A member is a stray when fewer than a quarter of its nearest neighbours (the ``k -
    1`` that ``neighbours`` lists, or as many as its cluster has other members if fewer)
    belong to its cluster. An object, however small, is a body of points nearer each
    other than the points around it: even with wrong flows and bled flows on it and
    around it, its members have many of their own among their neighbours.
    Correspondences that only share a motion while scattered among other points are
    not: a few of a blob of wrong flows that agree within a noise that grows with range,
    spread over metres of the static world. Not applied to the ``exempt`` clusters (the
    static world; an int or array-like, negative values naming none).

    Returns
    -------
    clusters : ndarray
        Indices of the clusters more than half of whose members are strays.
    """
    judged = np.ones(n_clusters + 1, dtype=bool)
    judged[-1] = False  # label -1
    judged[_clusters_named(exempt)] = False
    rows = np.flatnonzero(judged[labels])
    if not len(rows):
        return np.empty(0, dtype=np.intp)
    own = labels[rows]
    size = np.bincount(own, minlength=n_clusters)
    depth = np.minimum(neighbours.k - 1, size[own] - 1)
    stray = np.zeros(len(rows), dtype=bool)
    whole = len(rows) == len(labels)  # nothing exempt: the table is read in place
    # In blocks: a row's neighbours' labels and their running count stay small in memory.
    for start in range(0, len(rows), _BLOCK_ROWS):
        block = slice(start, start + _BLOCK_ROWS)
        listed = labels[neighbours.index[block if whole else rows[block], 1:]]
        stray[block] = stray_members(own[block], listed, depth[block])
    n_strays = np.bincount(own[stray], minlength=n_clusters)
    return np.flatnonzero(2 * n_strays > size)


def stray_members(own, listed, depth):
    """Rows fewer than a quarter of whose first ``depth`` listed neighbours share their
    label ``own`` (:func:`scattered_clusters`); ``listed``: the neighbours' labels,
    nearest first, the row itself left out. A row with ``depth`` 0 is no stray."""
    same = listed == own[:, None]
    mine = np.count_nonzero(same, axis=1)  # rows that look at every listed neighbour
    # Members of small clusters look at fewer: they count along the row to their depth.
    short = np.flatnonzero((depth > 0) & (depth < listed.shape[1]))
    if len(short):
        running = np.cumsum(same[short], axis=1, dtype=np.int16)
        mine[short] = running[np.arange(len(short)), depth[short] - 1]
    stray = np.zeros(len(own), dtype=bool)
    looked = depth > 0
    stray[looked] = 4 * mine[looked] < depth[looked]
    return stray


def _clusters_named(clusters):
    """The non-negative entries of an int or array-like of cluster indices."""
    clusters = np.atleast_1d(np.asarray(clusters, dtype=np.intp))
    return clusters[clusters >= 0]


def drop_small_clusters(labels, counts, min_cluster_size):
    """Labels with the clusters below ``min_cluster_size`` dissolved (-1), renumbered."""
    kept = counts >= min_cluster_size
    position = np.full(len(counts) + 1, -1, dtype=np.intp)
    position[:-1][kept] = np.arange(np.count_nonzero(kept))
    return position[labels], np.flatnonzero(kept)


# Scales below the grid that a proposal may fall back on (a factor 2 each).
_FINER_SCALES = 3


def _best_hypothesis(
    sq, grid, allowed, d, chi2_limit, log_g, n_total, log_outlier, meaningful=None, finer=()
):
    """The (hypothesis, noise scale) whose inliers gain most over the outlier component.

    ``sq`` (h, m) are squared residuals normalised by each correspondence's ``g_i``; the
    gain of scale ``s`` is ``sum_inliers [log N(r_i; 0, (s g_i)^2 I) + log(k / n) -
    log_outlier]`` over the ``k`` inliers ``sq <= chi2_limit s^2``, and ``allowed`` (h, S)
    says which scales of ``grid`` each hypothesis may take. ``meaningful(counts, s)``,
    if given, says which counts of inliers at scale ``s`` are not to be expected by
    chance. When the best of all is not one of them, the best among those wins, on the
    grid and on the ``finer`` scales below it: a scale too wide (the clusters' smallest
    is inflated when the initial clusters mix motions) gathers other motions' points as
    inliers, as any motion would. Returns the hypothesis' index and its scale.
    """
    best = _most_gain(sq, grid, allowed, d, chi2_limit, log_g, n_total, log_outlier)
    if meaningful is None or best[0] == -np.inf or meaningful(np.array([best[3]]), best[2])[0]:
        return best[1], best[2]
    finer = np.asarray(finer, dtype=float)
    wide = np.concatenate([finer, grid])
    wide_allowed = np.hstack([np.ones((len(sq), len(finer)), dtype=bool), allowed])
    found = _most_gain(
        sq, wide, wide_allowed, d, chi2_limit, log_g, n_total, log_outlier, meaningful
    )
    return (found[1], found[2]) if found[0] > -np.inf else (best[1], best[2])


def _most_gain(sq, grid, allowed, d, chi2_limit, log_g, n_total, log_outlier, meaningful=None):
    """``(gain, hypothesis, scale, inliers)`` of :func:`_best_hypothesis`."""
    best_gain, best, best_scale, best_count = -np.inf, 0, grid[0], 0
    for k, sigma in enumerate(grid):
        if not allowed[:, k].any():
            continue
        inlier = sq <= chi2_limit * sigma**2
        count = inlier.sum(axis=1)
        gain = (
            -0.5 * np.where(inlier, sq, 0.0).sum(axis=1) / sigma**2
            - d * np.where(inlier, log_g[None], 0.0).sum(axis=1)
            - count * d * (np.log(sigma) + 0.5 * _LOG_2PI)
            + count * (np.log(np.maximum(count, 1) / n_total) - log_outlier)
        )
        keep = allowed[:, k] & (count > 0)
        if meaningful is not None:
            keep &= meaningful(count, sigma)
        gain = np.where(keep, gain, -np.inf)
        h = int(np.argmax(gain))
        if gain[h] > best_gain:
            best_gain, best, best_scale, best_count = gain[h], h, sigma, count[h]
    return best_gain, best, float(best_scale), int(best_count)


def _shares_a_motion(models, proposal, d):
    """The merge test of :func:`merge_adjacent` between the proposal and every cluster."""
    both = _with(models, proposal)
    k = len(models.sigmas)
    pairs = np.column_stack([np.arange(k), np.full(k, k)])
    return bool(np.any(_merge_ratio(both, pairs, d) < 1.0))


def _has_its_motion(models, proposal, d):
    """Whether a current cluster's motion explains the proposal's inliers as well as its own.

    Judged on the proposal's own noise scale: its inliers' squared error under cluster
    ``j``'s motion may exceed that under their own by at most the BIC price of a motion.
    (A two-sided merge test would let a cluster with a large noise scale of its own claim
    any proposal.)
    """
    k = len(models.sigmas)
    moments = proposal.moments.take(np.zeros(k, dtype=np.intp))
    excess = moments.squared_error(models.rotations, models.translations)
    excess = (excess - proposal.squared_error[0]) / proposal.sigmas[0] ** 2
    price = motion_parameters(d) * np.log(max(int(proposal.moments.size[0]), 2))
    return bool(np.any(excess < price))


def propose_clusters(
    a,
    b,
    unexplained,
    radius,
    scale,
    log_outlier,
    n_total,
    rng,
    *,
    log_volume_density,
    models,
    min_cluster_size,
    sigma_floor,
    noise_scale=None,
    n_hypotheses=32,
    confidence=0.999,
    reference=None,
    max_noise_ratio=0.1,
    n_scales=7,
    per_cluster=True,
    max_scale=None,
):
    """New clusters from groups of unexplained correspondences that share a motion.

    The unexplained correspondences (labelled -1) are split into ``radius``-connected
    groups of their a-points; in every group of at least ``min_cluster_size``, minimal
    samples are drawn locally (a random seed and two of its nearest unexplained
    neighbours). Each hypothesis is scored at every noise scale ``sigma`` of the grid
    ``scale * 2^k``, ``k < n_scales``, up to ``max_noise_ratio`` times how far it moves
    the points relative to the ``reference`` motion (the static world's; the identity if
    None): a flow network errs in proportion to the motion, so a moving object's flow is
    noisier than the static world's, but never by more than a fraction of its motion.
    Nor beyond ``max_scale``, the widest scale the next M-step lets a new cluster keep
    (the clusters' shared scale when they have none of their own): a proposal must be a
    motion its members follow at the scale they will be judged by. Found at a wider one,
    say one object's wrong correspondences (scattered a metre about its motion) taken
    for an object of their own, the M-step trims every member of it, its motion is
    fitted on nothing, and the proposals bring it back at every iteration.
    The (hypothesis, scale) whose inliers (residual within the ``confidence`` quantile
    of ``(sigma g_i)^2 chi2_d``) gain most log-likelihood over the outlier component
    wins (the noise scale is searched, as MAGSAC marginalises it) and is refitted on
    them; if so many inliers would be expected by chance (below), the best one that
    passes that test wins instead, on three finer scales too (as AC-RANSAC picks the
    most meaningful threshold). It becomes a cluster only if its inliers' log-likelihood
    under it beats that under the outlier density by more than the BIC price of a motion
    and a noise scale, and if so many inliers are not to be expected by chance: with
    ``p`` the share of the scene's volume ``V`` within the inlier radius of a point's
    predicted position, the number of false alarms
    ``N_tests P(Binomial(m - 3, p) >= k - 3)`` of ``k`` inliers among ``m`` must stay
    below 1, ``N_tests`` counting every hypothesis drawn (the a-contrario test of
    AC-RANSAC, Moisan and Stival 2004). Wrong correspondences that agree on no motion
    never form a cluster. Nor does a motion that one of the ``models`` (the current
    clusters) already has, by the merge test of :func:`merge_adjacent`: a proposal must
    bring a new motion. Points that move like a
    cluster beyond the gate are flow that bled across an object's silhouette far more
    often than another object: separate objects that move alike come from the initial
    clusters, as eq. (7) intends.

    Returns
    -------
    groups : list of ndarray
        The indices (into ``a``) of the members of each accepted new cluster.
    """
    d = a.shape[1]
    size = minimal_sample_size(d)
    if noise_scale is None:
        noise_scale = np.ones(len(a))
    rows = np.flatnonzero(unexplained)
    if len(rows) < max(min_cluster_size, size + 1):
        return []
    _, component = tau_components(a[rows], radius)
    counts = np.bincount(component)
    chi2_limit = chi2.ppf(confidence, d)
    price = 0.5 * (motion_parameters(d) + 1) * np.log(n_total)
    grid = scale * 2.0 ** np.arange(n_scales)
    widest = np.inf if max_scale is None else max(max_scale, scale)
    groups = np.flatnonzero(counts >= max(min_cluster_size, size + 1))
    n_tests = max(len(groups) * n_hypotheses, 1)
    # Volume of a d-ball of radius 1.
    unit_ball = np.pi ** (d / 2) / gamma(d / 2 + 1)
    accepted = []
    members_of = [rows[component == c] for c in groups]
    sampled = _sample_every_group(a, b, members_of, n_hypotheses, size, rng, reference, per_cluster)
    for members, (rotations, translations) in zip(members_of, sampled, strict=True):
        pa, pb, g = a[members], b[members], noise_scale[members]
        if not len(rotations):
            continue
        a_rows, b_rows = np.ascontiguousarray(pa.T), np.ascontiguousarray(pb.T)
        if not per_cluster:  # the shared scale: the hypothesis with most inliers wins
            sq = residual_table(rotations, translations, a_rows, b_rows)
            sq /= g**2
            sigma = scale
            best = int(np.argmax((sq <= chi2_limit * sigma**2).sum(axis=1)))
        else:
            base = pa if reference is None else pa @ reference[0].T + reference[1]
            sq, moved_by = residual_table(
                rotations, translations, a_rows, b_rows, origins=np.ascontiguousarray(base.T)
            )
            sq /= g**2
            motion = np.median(moved_by, axis=1)
            # The a-contrario test below, with the members' median noise scale.
            spread, m = float(np.median(g)), len(members)

            def meaningful(counts, sigma, spread=spread, m=m):
                reach = np.sqrt(chi2_limit) * sigma * spread
                chance = min(1.0, unit_ball * reach**d * np.exp(log_volume_density))
                return n_tests * binom.sf(counts - size - 1, m - size, chance) < 1.0

            best, sigma = _best_hypothesis(
                sq,
                grid,
                grid <= np.minimum(np.maximum(scale, max_noise_ratio * motion), widest)[:, None],
                d,
                chi2_limit,
                np.log(g),
                n_total,
                log_outlier,
                meaningful,
                finer=scale * 2.0 ** -np.arange(_FINER_SCALES, 0, -1),
            )
        limit = chi2_limit * sigma**2
        inliers = np.flatnonzero(sq[best] <= limit)
        if len(inliers) < min_cluster_size or not _explains_its_surroundings(pa, inliers):
            continue
        one = np.zeros(len(inliers), dtype=np.intp)
        model = fit_clusters(pa[inliers], pb[inliers], one, 1, sigma_floor, g[inliers])
        model.sigmas[:] = sigma
        log_like = -0.5 * model.squared_error[0] / sigma**2 - d * np.sum(
            np.log(sigma * g[inliers]) + 0.5 * _LOG_2PI
        )
        weight = np.log(len(inliers) / n_total)
        if log_like + len(inliers) * weight - len(inliers) * log_outlier <= price:
            continue
        radius = np.sqrt(limit) * float(np.median(g[inliers]))
        chance = min(1.0, unit_ball * radius**d * np.exp(log_volume_density))
        tail = binom.sf(len(inliers) - size - 1, len(members) - size, chance)
        if n_tests * tail >= 1.0:
            continue
        if len(models.sigmas) and (
            _has_its_motion(models, model, d) if per_cluster else _shares_a_motion(models, model, d)
        ):
            continue
        accepted.append(members[inliers])
    return accepted
