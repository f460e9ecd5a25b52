"""The robust default: Algorithm 1 with an outlier model, merging and re-proposal around it.

The loop is the paper's (fit every cluster, drop the small ones, reassign each
correspondence to its most likely cluster within the gate); the named steps of
:mod:`mmreg.estimators._robust_steps` sit between its lines:

1. M-step on inliers (:func:`trimmed_fit`) instead of Horn on every member;
2. merging of adjacent clusters that share a motion (:func:`merge_adjacent`);
3. removal of small clusters (Algorithm 1, lines 10-13);
4. the paper's E-step and classification (:func:`~mmreg._likelihood.classify`), unchanged;
5. the outlier component (:func:`reject_outliers`);
6. new clusters from what no cluster explains (:func:`propose_clusters`).
"""

from dataclasses import dataclass, field

import numpy as np
from sklearn.utils import check_random_state

from mmreg._gate import ClusterGate
from mmreg._likelihood import CorrespondenceBlocks, classify, single_threaded_blas
from mmreg.estimators._em import EMResult, _compact_initial, _size_rank, default_sigma_floor
from mmreg.estimators._robust_steps import (
    adjacent_pairs,
    drop_small_clusters,
    log_uniform_density,
    merge_adjacent,
    propose_clusters,
    reject_outliers,
    trimmed_fit,
)

__all__ = ["RobustEMResult", "robust_multi_model_em"]


@dataclass
class RobustEMResult(EMResult):
    """:class:`EMResult` and what the robust steps did, iteration by iteration."""

    history: list = field(default_factory=list)
    log_outlier_density: float = 0.0
    """``log(pi_0 / V)``: the outlier component's log-density at the end."""


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
    log_volume_density = log_uniform_density(b)
    blocks = CorrespondenceBlocks(a, b) if max_iter > 0 else None
    history = []
    converged = False
    n_iter = 0
    outlier_share = None
    with single_threaded_blas():
        for _ in range(max_iter):
            if n_clusters == 0:
                # Nothing left to fit, merge or assign to; proposals found nothing either.
                converged = True
                break
            n_iter += 1
            # 1. M-step on inliers.
            inliers, models = trimmed_fit(
                a, b, labels, n_clusters, sigma_floor, confidence=confidence
            )
            if outlier_share is None:
                outlier_share = np.mean(inliers < 0)
            # 2. Merge adjacent clusters that share a motion.
            pairs = adjacent_pairs(a, inliers, n_clusters, tau)
            root, models, n_merges = merge_adjacent(models, pairs, d, sigma_floor)
            # 3. Drop clusters below m_min (lines 10-13); merged-away ones have no members.
            counts = np.bincount(root[labels[labels >= 0]], minlength=n_clusters)
            own, kept = drop_small_clusters(
                np.where(labels >= 0, root[np.maximum(labels, 0)], -1), counts, min_cluster_size
            )
            models = models.take(kept)
            weights = _weights(counts[kept], n)
            # 4. The paper's E-step and classification, gated by tau.
            gate = ClusterGate(a, own, len(kept), tau)
            new = classify(
                a,
                b,
                models.rotations,
                models.translations,
                models.sigmas,
                weights,
                gate,
                own,
                blocks=blocks,
                limit_blas=False,
            )
            # 5. The outlier component.
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
            )
            outlier_share = np.mean(new < 0)
            # 6. New clusters from the unexplained correspondences.
            scale = float(np.median(models.sigmas)) if len(kept) else sigma_floor
            found = propose_clusters(
                a,
                b,
                new < 0,
                tau if tau is not None else np.inf,
                scale,
                log_outlier,
                n,
                rng,
                min_cluster_size=min_cluster_size,
                n_hypotheses=n_hypotheses,
                confidence=confidence,
            )
            for members in found:
                new[members] = len(kept)
                kept = np.append(kept, -1)
            step = {
                "iteration": n_iter,
                "clusters": int(len(kept)),
                "merges": int(n_merges),
                "dropped": int(np.count_nonzero(counts[counts > 0] < min_cluster_size)),
                "outliers": int(np.count_nonzero(new < 0)),
                "proposed": len(found),
            }
            history.append(step)
            if verbose:
                print(", ".join(f"{key} {value}" for key, value in step.items()))
            new, n_clusters = _compact_initial(new)
            unchanged = len(labels) == len(new) and np.array_equal(new, labels)
            labels = new
            if unchanged and not n_merges and not found:
                converged = True
                break
    # Final clean-up: no cluster below m_min; clusters numbered by size.
    counts = np.bincount(labels[labels >= 0], minlength=n_clusters)
    labels, kept = drop_small_clusters(labels, counts, min_cluster_size)
    n_clusters = len(kept)
    rank = _size_rank(labels, n_clusters)
    labels = rank[labels]
    _, models = trimmed_fit(a, b, labels, n_clusters, sigma_floor, confidence=confidence)
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
    )
