"""The robust default: Algorithm 1 with an outlier model, merging and re-proposal around it.

The loop is the paper's (fit every cluster, drop the small ones, reassign each
correspondence to its most likely cluster within the gate); the named steps of
:mod:`mmreg.estimators._robust_steps` sit between its lines:

1. M-step on inliers (:func:`trimmed_fit`) instead of Horn on every member;
2. merging of adjacent clusters that share a motion (:func:`merge_adjacent`);
3. dissolving layers of flow that bled along a boundary (:func:`boundary_layers`);
4. removal of small clusters (Algorithm 1, lines 10-13);
5. the E-step and classification of eq. (7) (:func:`assign_correspondences`), with each
   correspondence's noise scale ``sigma_j g_i`` growing with its range when the data say
   so (:func:`estimate_range_growth`);
6. the outlier component (:func:`reject_outliers`);
7. new clusters from what no cluster explains (:func:`propose_clusters`): this is also
   how a cluster holding two motions splits, since the trimmed M-step fits the majority
   and leaves the other motion's correspondences unexplained.
"""

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree
from sklearn.utils import check_random_state

from mmreg._gate import ClusterGate
from mmreg._likelihood import morton_order, single_threaded_blas
from mmreg.estimators._em import EMResult, _compact_initial, _size_rank, default_sigma_floor
from mmreg.estimators._robust_steps import (
    adjacent_pairs,
    assign_correspondences,
    boundary_layers,
    drop_small_clusters,
    estimate_range_growth,
    log_uniform_density,
    merge_adjacent,
    propose_clusters,
    range_noise_scale,
    reject_outliers,
    squared_residuals,
    trimmed_fit,
)

__all__ = ["RobustEMResult", "robust_multi_model_em"]


@dataclass
class RobustEMResult(EMResult):
    """:class:`EMResult` and what the robust steps did, iteration by iteration."""

    history: list = field(default_factory=list)
    log_outlier_density: float = 0.0
    """``log(pi_0 / V)``: the outlier component's log-density at the end."""
    noise_growth: float = 0.0
    """``c`` of the noise scale ``sigma_j (1 + c ||a||^2)``; 0 for equal noise."""


def _range_noise(a, b, labels, models, sigma_floor):
    """The growth of the noise with range, and each correspondence's noise scale."""
    clustered = np.where(labels < len(models.sigmas), labels, -1)
    squared = squared_residuals(a, b, clustered, models.rotations, models.translations)
    growth = estimate_range_growth(a, squared, clustered, len(models.sigmas), sigma_floor)
    return growth, (range_noise_scale(a, growth) if growth > 0 else None)


def _sampling_spacing(points, k=6):
    """The local sampling spacing at each point: the median nearest-neighbour distance
    of its ``k`` nearest points (itself included).

    Smoothed so that a few points that happen to lie close together (random subsampling
    makes such clumps) are not read as a surface of their own, denser than the one
    around them.
    """
    n = len(points)
    if n < 2:
        return np.zeros(n)
    distance, index = cKDTree(points).query(points, k=min(k, n), workers=-1)
    return np.median(distance[:, 1][index], axis=1)


def _weights(counts, n):
    return np.asarray(counts, dtype=float) / max(n, 1)


def robust_multi_model_em(
    a,
    b,
    init_labels,
    *,
    tau=1.5,
    min_cluster_size=4,
    max_iter=10,
    sigma_floor=None,
    confidence=0.999,
    n_hypotheses=32,
    noise_model="range",
    tol=1e-3,
    random_state=None,
    verbose=0,
):
    """Classification-EM with outliers, merging and re-proposal (the robust default).

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
    init_labels : ndarray of shape (n,)
        Initial clusters; negative labels mark correspondences in no cluster.
    tau : float or None, default=1.5
        The gate of eq. (7); also the reach of merging and of proposals.
    min_cluster_size : int, default=4
    max_iter : int, default=10
    sigma_floor : float, default=None
    confidence : float, default=0.999
        Inlier quantile of the residual tests of the trimmed M-step and of proposals.
    n_hypotheses : int, default=32
        Minimal samples drawn in each group of unexplained correspondences.
    noise_model : {"range", "constant"}, default="range"
        ``"range"``: correspondence ``i`` of cluster ``j`` has noise ``sigma_j (1 + c
        ||a_i||^2)``, with ``c >= 0`` estimated by maximum likelihood every iteration (0
        when the noise does not grow with range); ``"constant"``: ``sigma_j``.
    tol : float, default=1e-3
        Converged when an iteration merges and proposes nothing and changes the label of
        at most this fraction of the correspondences (0: of none, as Algorithm 1).
    random_state : int, RandomState instance or None, default=None
        Seeds the proposals' samples.
    verbose : int, default=0
        Print one line per iteration.

    Returns
    -------
    RobustEMResult
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    n, d = a.shape
    rng = check_random_state(random_state)
    if sigma_floor is None:
        sigma_floor = default_sigma_floor(b)
    labels, n_clusters = _compact_initial(init_labels)
    log_volume_density = log_uniform_density(a, b)
    order = morton_order(np.ascontiguousarray(a.T))
    spacing = _sampling_spacing(a)
    history = []
    converged = False
    n_iter = 0
    outlier_share = None
    noise_scale = None
    with single_threaded_blas():
        for _ in range(max_iter):
            if n_clusters == 0:
                # Nothing left to fit, merge or assign to.
                converged = True
                break
            n_iter += 1
            # 1. M-step on inliers. The noise's growth with range comes from the last
            # iteration's clusters; the first estimates it from the initial ones.
            inliers, models = trimmed_fit(
                a, b, labels, n_clusters, sigma_floor, noise_scale, confidence=confidence
            )
            if noise_model == "range" and n_iter == 1:
                growth, noise_scale = _range_noise(a, b, inliers, models, sigma_floor)
                if noise_scale is not None:
                    inliers, models = trimmed_fit(
                        a, b, labels, n_clusters, sigma_floor, noise_scale, confidence=confidence
                    )
            if outlier_share is None:
                outlier_share = np.mean(inliers < 0)
            # 2. Merge adjacent clusters that share a motion.
            pairs = adjacent_pairs(a, inliers, n_clusters, tau)
            root, models, n_merges = merge_adjacent(models, pairs, d, sigma_floor)
            members = np.where(labels >= 0, root[np.maximum(labels, 0)], -1)
            # 3. Dissolve layers of flow that bled along another cluster's boundary.
            bled = boundary_layers(a, members, n_clusters, spacing)
            members[np.isin(members, bled)] = -1
            # 4. Drop clusters below m_min (lines 10-13); merged-away ones have no members.
            counts = np.bincount(members[members >= 0], minlength=n_clusters)
            own, kept = drop_small_clusters(members, counts, min_cluster_size)
            models = models.take(kept)
            weights = _weights(counts[kept], n)
            # 5. E-step and classification of eq. (7), gated by tau.
            gate = ClusterGate(a, own, len(kept), tau)
            new = assign_correspondences(
                a,
                b,
                models.rotations,
                models.translations,
                models.sigmas,
                weights,
                gate,
                own,
                order,
                noise_scale,
            )
            # 6. The outlier component.
            log_outlier = np.log(max(outlier_share, 1.0 / n)) + log_volume_density
            new = reject_outliers(
                a,
                b,
                new,
                models.rotations,
                models.translations,
                models.sigmas,
                weights,
                log_outlier,
                noise_scale,
            )
            outlier_share = np.mean(new < 0)
            # 7. New clusters from the unexplained correspondences.
            scale = float(models.sigmas[0]) if len(kept) else sigma_floor
            found = propose_clusters(
                a,
                b,
                new < 0,
                tau if tau is not None else np.inf,
                scale,
                log_outlier,
                n,
                rng,
                log_volume_density=log_volume_density,
                models=models,
                min_cluster_size=min_cluster_size,
                sigma_floor=sigma_floor,
                noise_scale=noise_scale,
                n_hypotheses=n_hypotheses,
                confidence=confidence,
            )
            for members in found:
                new[members] = len(kept)
                kept = np.append(kept, -1)
            # A proposal along another cluster's boundary is bled flow too.
            layers = boundary_layers(a, new, len(kept), spacing)
            found = [f for k, f in enumerate(found) if len(models.sigmas) + k not in layers]
            new[np.isin(new, layers[layers >= len(models.sigmas)])] = -1
            step = {
                "iteration": n_iter,
                "clusters": int(len(kept)),
                "merges": int(n_merges),
                "bled": len(bled),
                "dropped": int(np.count_nonzero((counts > 0) & (counts < min_cluster_size))),
                "outliers": int(np.count_nonzero(new < 0)),
                "proposed": len(found),
                "noise_growth": 0.0 if noise_scale is None else float(growth),
            }
            history.append(step)
            if noise_model == "range" and len(models.sigmas):
                growth, noise_scale = _range_noise(a, b, new, models, sigma_floor)
            new, n_clusters = _compact_initial(new)
            n_changed = int(np.count_nonzero(new != labels)) if len(new) == len(labels) else n
            step["changed"] = n_changed
            if verbose:
                print(", ".join(f"{key} {value:g}" for key, value in step.items()))
            labels = new
            if n_changed <= tol * n and not n_merges and not found:
                converged = True
                break
    # Final clean-up: no boundary layer and no cluster below m_min; numbered by size.
    # With max_iter=0 the initial clusters are returned as given (the paper's contract).
    if n_iter and n_clusters:
        # The last E-step can leave a few correspondences of a shrunk cluster behind, in a
        # cluster of their own with their neighbour's motion: one more merge pass.
        inliers, models = trimmed_fit(
            a, b, labels, n_clusters, sigma_floor, noise_scale, confidence=confidence
        )
        pairs = adjacent_pairs(a, inliers, n_clusters, tau)
        root, _, _ = merge_adjacent(models, pairs, d, sigma_floor)
        labels, n_clusters = _compact_initial(
            np.where(labels >= 0, root[np.maximum(labels, 0)], -1)
        )
        bled = boundary_layers(a, labels, n_clusters, spacing)
        labels = np.where(np.isin(labels, bled), -1, labels)
    counts = np.bincount(labels[labels >= 0], minlength=n_clusters)
    labels, kept = drop_small_clusters(labels, counts, min_cluster_size)
    n_clusters = len(kept)
    rank = _size_rank(labels, n_clusters)
    labels = rank[labels]
    _, models = trimmed_fit(
        a, b, labels, n_clusters, sigma_floor, noise_scale, confidence=confidence
    )
    weights = _weights(np.bincount(labels[labels >= 0], minlength=n_clusters), n)
    return RobustEMResult(
        labels,
        models.rotations,
        models.translations,
        models.sigmas,
        weights,
        n_iter,
        converged,
        history,
        float(np.log(max(np.mean(labels < 0), 1.0 / max(n, 1))) + log_volume_density),
        0.0 if noise_scale is None else float(growth),
    )
