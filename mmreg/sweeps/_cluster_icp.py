"""The clusters' motions refined on the second sweep: one multi-body ICP, deskewed with
the points' capture times (:mod:`mmreg.sweeps._deskew`)."""

import numpy as np
from scipy.spatial import cKDTree

from mmreg._array.grouping import group_bounds
from mmreg.sweeps._deskew import deskew, relative_motions
from mmreg.sweeps._icp import SurfaceNormals, multi_body_icp, subsample_groups

__all__ = ["refine_clusters"]


def _group_sums_3(values, groups, n_groups):
    """Sums of the rows of ``values`` (n, 3) within each group."""
    return np.stack(
        [np.bincount(groups, weights=values[:, i], minlength=n_groups) for i in range(3)], axis=1
    )


def _in_boxes(points, low, high):
    """Whether each point lies in any of the axis-aligned boxes ``[low_k, high_k]``."""
    inside = (points[:, None, :] >= low) & (points[:, None, :] <= high)
    return inside.all(axis=2).any(axis=1)


def refine_clusters(a, labels, motions, refine, target, static, settings, rng, timing, rounds):
    """ICP of the clusters flagged ``refine`` on the sweep; the others keep their motion.

    ``a``: the first sweep's points; ``labels``: their clusters; ``motions``: the
    clusters' ``(rotations, translations)``; ``target``: ``(sweep, tree, normals)``;
    ``static``: the static world's cluster (-1: none); ``settings``: a
    :class:`~mmreg.sweeps._settings.PairSettings`. With capture times (``timing``:
    ``(times, sweep_times, interval)``, else None), ``rounds`` of deskewing and ICP.
    Returns the rotations, translations and robust residual scales (NaN where not
    refined).
    """
    rotations, translations = motions
    sweep, tree, normals = target
    rotations, translations = rotations.copy(), translations.copy()
    scales = np.full(len(rotations), np.nan)
    chosen = np.flatnonzero(refine)
    if not len(chosen) or settings.max_icp_iter == 0:
        return rotations, translations, scales
    index = -np.ones(len(rotations) + 1, dtype=np.intp)
    index[chosen] = np.arange(len(chosen))
    sub = np.where(labels >= 0, index[labels], -1)
    keep = subsample_groups(sub, settings.max_points, rng)
    mask = np.full(len(a), -1, dtype=np.intp)
    mask[keep] = sub[keep]
    # With capture times the static world is refined as without (it needs no
    # deskewing: the sweeps are compensated for the ego motion), then the others.
    parts = [chosen] if timing is None else [chosen[chosen == static], chosen[chosen != static]]
    for part in parts:
        if not len(part):
            continue
        index[:] = -1
        index[part] = np.arange(len(part))
        group = np.where(mask >= 0, index[chosen[np.maximum(mask, 0)]], -1)
        if part is chosen or part[0] == static:
            result = _icp(
                a, group, rotations[part], translations[part], (sweep, tree, normals), settings
            )
        else:
            result = _deskewed_icp(
                a,
                labels,
                group,
                part,
                (rotations, translations),
                static,
                sweep,
                timing,
                rounds,
                settings,
            )
        rotations[part] = result.rotations
        translations[part] = result.translations
        scales[part] = result.scales
    return rotations, translations, scales


def _icp(a, group, rotations, translations, target, settings):
    sweep, tree, normals = target
    return multi_body_icp(
        a,
        group,
        rotations,
        translations,
        sweep,
        tree=tree,
        normals=normals,
        max_distance=settings.max_distance,
        max_iter=settings.max_icp_iter,
        tol=settings.tol,
        workers=settings.workers,
    )


def _deskewed_icp(a, labels, group, part, motions, static, sweep, timing, rounds, settings):
    """Rounds of deskewing (with the last motions) and ICP of the clusters ``part``.

    The a-points of every cluster of ``part``, and the points of the second sweep
    nearer to that cluster's moved points than to any other cluster's, are moved to
    their sweep's reference time along the cluster's motion relative to the static
    world (:mod:`mmreg.sweeps._deskew`); the ICP aligns the deskewed sets. ``group`` numbers
    the ICP's points by their cluster's place in ``part``.
    """
    rotations, translations = motions
    times, sweep_times, interval = timing
    world = (rotations[static], translations[static]) if static >= 0 else (np.eye(3), np.zeros(3))
    member = np.flatnonzero(group >= 0)
    g = group[member]
    n_part = len(part)
    counts = np.maximum(np.bincount(g, minlength=n_part), 1)
    centres = _group_sums_3(a[member], g, n_part) / counts[:, None]
    R, t = rotations[part], translations[part]
    # Only the second sweep's points near the clusters can be matched or deskewed:
    # those in the clusters' moved bounding boxes grown by twice the ICP's reach
    # (the rounds move them far less).
    moved = np.einsum("nij,nj->ni", R[g], a[member]) + t[g]
    margin = 2 * settings.max_distance
    low, high = group_bounds(moved, g, n_part)
    local = np.flatnonzero(_in_boxes(sweep, low - margin, high + margin))
    if not len(local):  # nothing to match: the ICP leaves the motions as they are
        return multi_body_icp(a, group, R, t, sweep, max_distance=settings.max_distance, max_iter=0)
    # A point nearer to another cluster (the static world's points all take part)
    # stays as it is.
    rest = np.flatnonzero((labels >= 0) & ~np.isin(labels, part))
    others = np.einsum("nij,nj->ni", rotations[labels[rest]], a[rest])
    others += translations[labels[rest]]
    others = others[_in_boxes(others, low - 2 * margin, high + 2 * margin)]
    other = np.full(len(local), np.inf)
    if len(others) and len(local):
        other, _ = cKDTree(others).query(sweep[local])
    fractions = sweep_times[local] / interval
    fractions1 = times[member] / interval
    result = None
    for _ in range(rounds):
        first, second = relative_motions(R, t, world)
        points = a.copy()
        points[member] = deskew(a[member], g, fractions1, *first, centres, turn=False)
        moved = np.einsum("nij,nj->ni", R[g], points[member]) + t[g]
        # Each of these sweep points belongs to the cluster of its nearest moved point.
        distance, nearest = cKDTree(moved).query(sweep[local])
        owner = np.where(distance < other, g[nearest], -1)
        # The second sweep's centres: where the clusters' centroids moved.
        centres2 = np.einsum("kij,kj->ki", R, centres) + t
        target = deskew(sweep[local], owner, fractions, *second, centres2, turn=False)
        target_tree = cKDTree(target)
        normals = SurfaceNormals(target, target_tree, 10, settings.workers)
        result = _icp(points, group, R, t, (target, target_tree, normals), settings)
        R, t = result.rotations, result.translations
    return result
