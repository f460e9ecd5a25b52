"""Split a cluster that holds two touching objects whose flows jump where they touch.

An initial cluster larger than an object (the Euclidean initialisation's clusters span up
to ``tau``) may hold two touching objects that move alike: two boxes on one pallet, one
slipping 10 cm as both move 1 m. Fitted as one, its motion lies between theirs, and a
noise scale of its own (``variant="sweep"``) keeps both objects' points: nothing is left
unexplained for the proposals to find either object in. The step below tries, in each
moving cluster, the two-motion split of a two-means on rigid fits (from the pieces that
neighbours' flows fall apart into, the motions at the cluster's two ends, or the signs of
the residuals; the one of least squared residuals), smooths the
halves into regions, and keeps the split when the halves' flows jump at their contact by
more than ``min_motion`` (:func:`~mmreg.em._steps._flow_jumps_at_contact`,
the test that keeps :func:`~mmreg.em._steps.join_moving_pieces` from
joining them again). A network's flow that bends across one object meets itself at the
contact of the halves, and noise gives halves whose motions differ by less than
``min_motion``: neither splits.
"""

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from mmreg.em._steps import (
    _flow_jumps_at_contact,
    _motion_from,
    _rms,
    fit_clusters,
    motion_gap,
)

__all__ = ["split_mixed_clusters"]

# Rounds of the two-means on rigid fits (fit each half, give each member to the half
# whose motion explains it better); from the objects' own regions it settles in one or two.
_ROUNDS = 4


def _residuals(a, b, rotations, translations, labels):
    """``b - (R_j a + t_j)`` for each row's cluster ``j``."""
    return b - np.einsum("nij,nj->ni", rotations[labels], a) - translations[labels]


def _residual_halves(a, b, labels, n_clusters, sigma_floor, noise_scale):
    """Each row's half (0 or 1): the sign of its residual along the main direction of its
    cluster's residuals (a mixture's residuals point two opposite ways)."""
    models = fit_clusters(a, b, labels, n_clusters, sigma_floor, noise_scale)
    r = _residuals(a, b, models.rotations, models.translations, labels)
    d = a.shape[1]
    scatter = np.zeros((n_clusters, d, d))
    np.add.at(scatter, labels, r[:, :, None] * r[:, None, :])
    direction = np.linalg.eigh(scatter)[1][:, :, -1]
    return (np.sum(r * direction[labels], axis=1) > 0).astype(np.intp)


def _end_halves(a, b, labels, n_clusters, sigma_floor, k=32):
    """Each row's half (0 or 1): which of the motions fitted at the two ends of its
    cluster (the ``k`` rows nearest each extreme along its longest axis) explains it
    better. Two objects side by side each hold one end."""
    half = np.zeros(len(a), dtype=np.intp)
    for cluster in range(n_clusters):
        rows = np.flatnonzero(labels == cluster)
        near = min(k, len(rows) // 4)
        if near < 4:
            continue
        points = a[rows]
        centred = points - points.mean(axis=0)
        along = centred @ np.linalg.svd(centred, full_matrices=False)[2][0]
        tree = cKDTree(points)
        ends = np.concatenate(
            [
                tree.query(points[np.argmin(along)], k=near)[1],
                tree.query(points[np.argmax(along)], k=near)[1],
            ]
        )
        models = fit_clusters(points[ends], b[rows][ends], np.repeat([0, 1], near), 2, sigma_floor)
        first, second = (
            _residuals(
                points, b[rows], models.rotations, models.translations, np.full(len(rows), j)
            )
            for j in (0, 1)
        )
        half[rows] = np.sum(second**2, axis=1) < np.sum(first**2, axis=1)
    return half


def _two_means(a, b, labels, n_clusters, half, sigma_floor, noise_scale):
    """Two-means on rigid fits from ``half``: fit each half, give each row to the half
    whose motion explains it better. Returns the halves, their models (cluster ``j``'s
    halves are ``2j`` and ``2j + 1``) and each cluster's summed squared residuals."""
    for _ in range(_ROUNDS):
        models = fit_clusters(a, b, 2 * labels + half, 2 * n_clusters, sigma_floor, noise_scale)
        first = _residuals(a, b, models.rotations, models.translations, 2 * labels)
        second = _residuals(a, b, models.rotations, models.translations, 2 * labels + 1)
        nearer = (np.sum(second**2, axis=1) < np.sum(first**2, axis=1)).astype(np.intp)
        if np.array_equal(nearer, half):
            break
        half = nearer
    models = fit_clusters(a, b, 2 * labels + half, 2 * n_clusters, sigma_floor, noise_scale)
    rss = models.squared_error.reshape(-1, 2).sum(axis=1)
    return half, models, rss


def _neighbours(a, k=8):
    """Each row's ``k`` nearest other rows (fewer if there are fewer)."""
    k = min(k + 1, len(a))
    return cKDTree(a).query(a, k=k)[1][:, 1:]


def _smoothed(half, labels, index, rounds=3):
    """Each row takes the half most of its neighbours of its own cluster are in (its own
    on a tie), ``rounds`` times. Two objects' halves are regions and stay as they are;
    halves that a noisy flow's residuals drew (every row nearer the motion of its own
    half, interleaved) become regions of one motion, whose fits then agree."""
    same = labels[index] == labels[:, None]
    for _ in range(rounds):
        votes = np.sum(same * (2 * half[index] - 1), axis=1)
        half = np.where(votes > 0, 1, np.where(votes < 0, 0, half))
    return half


def _pieces_apart(a, b, labels, n_clusters, min_jump, min_size, index):
    """Each row's half (0: its cluster's largest piece, 1: the rest), and whether each
    cluster falls apart.

    Neighbours (8 nearest) of one cluster whose flows differ by at most ``min_jump`` are
    linked. A cluster whose links fall apart into its largest piece and at least
    ``min_size`` other rows (two objects' flows jump by more than ``min_jump`` where they
    touch) starts the two-means from those: the objects' own regions. (A least-squares
    motion of two objects turns to explain part of their difference, and the signs of
    its residuals cut both objects; where one object turns about an axis through the
    contact, the links hold there and the signs of the residuals are the better start.)
    A flow that bends across one object stays linked.
    """
    n = len(a)
    source = np.repeat(np.arange(n), index.shape[1])
    target = index.ravel()
    flow = b - a
    linked = (labels[source] == labels[target]) & (
        np.linalg.norm(flow[source] - flow[target], axis=1) <= min_jump
    )
    graph = coo_matrix(
        (np.ones(np.count_nonzero(linked)), (source[linked], target[linked])), shape=(n, n)
    )
    _, piece = connected_components(graph, directed=False)
    sizes = np.bincount(piece)
    largest = np.full(n_clusters, -1)
    order = np.argsort(sizes[piece], kind="stable")
    largest[labels[order]] = piece[order]  # the last write per cluster is its largest
    half = (piece != largest[labels]).astype(np.intp)
    counts = np.bincount(2 * labels + half, minlength=2 * n_clusters).reshape(-1, 2)
    return half, counts.min(axis=1) >= min_size


def split_mixed_clusters(
    a,
    b,
    labels,
    n_clusters,
    sigma_floor,
    *,
    min_jump,
    min_size=4,
    noise_scale=None,
    reference=None,
):
    """Split each cluster whose two best rigid halves' flows jump where they touch.

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
    labels : ndarray of shape (n,)
        Clusters ``0..n_clusters-1``, -1 for none.
    n_clusters : int
    sigma_floor : float
    min_jump : float
        The halves split only where their motions differ at the contact by more than
        this (``min_motion``: closer motions are one).
    min_size : int, default=4
        Each half keeps at least this many members.
    noise_scale : ndarray of shape (n,) or None
        Each row's noise scale, for the fits.
    reference : tuple of ndarray or None
        The static world's motion ``(R, t)``: only clusters that move ``min_jump``
        beyond their scatter relative to it are split (not the static world nor its
        slow pieces). None: every cluster may be.

    Returns
    -------
    labels : ndarray of shape (n,)
        The split clusters' second halves numbered from ``n_clusters`` on.
    n_clusters : int
    """
    rows = np.flatnonzero(labels >= 0)
    if reference is not None and len(rows):
        # Only moving clusters: neither the static world nor its slow pieces.
        scale = None if noise_scale is None else noise_scale[rows]
        models = fit_clusters(a[rows], b[rows], labels[rows], n_clusters, sigma_floor, scale)
        beyond = _motion_from(models, reference) - _rms(models.squared_error, models.moments)
        rows = rows[beyond[labels[rows]] >= min_jump]
    if len(rows) < 2 * min_size:
        return labels, n_clusters
    clusters, own = np.unique(labels[rows], return_inverse=True)
    m = len(clusters)
    pa, pb = a[rows], b[rows]
    scale = None if noise_scale is None else noise_scale[rows]
    # Three starts, the best kept: the signs of the residuals, the motions at the
    # cluster's two ends, and the pieces the flow falls apart into.
    index = _neighbours(pa)
    pieces, apart = _pieces_apart(pa, pb, own, m, min_jump, min_size, index)
    signs = _residual_halves(pa, pb, own, m, sigma_floor, scale)
    ends = _end_halves(pa, pb, own, m, sigma_floor)
    half, models, rss = _two_means(pa, pb, own, m, signs, sigma_floor, scale)
    starts = [ends, pieces] if apart.any() else [ends]
    for start in starts:
        other, other_models, other_rss = _two_means(pa, pb, own, m, start, sigma_floor, scale)
        better = other_rss < rss
        half = np.where(better[own], other, half)
        rss = np.where(better, other_rss, rss)
        pick = np.repeat(better, 2)
        models = models.take(np.arange(2 * m))
        models.put(np.flatnonzero(pick), other_models.take(np.flatnonzero(pick)))
    # The contact test below reads halves that are regions: two-means halves are
    # drawn by the residuals, each row nearer its own half's motion by construction.
    half = _smoothed(half, own, index)
    models = fit_clusters(pa, pb, 2 * own + half, 2 * m, sigma_floor, scale)
    sizes = np.bincount(2 * own + half, minlength=2 * m).reshape(-1, 2)
    candidates = np.flatnonzero(sizes.min(axis=1) >= min_size)
    # Motions that differ by less than min_jump anywhere cannot jump by more at the contact.
    gap = np.maximum(
        motion_gap(models, 2 * candidates, 2 * candidates + 1),
        motion_gap(models, 2 * candidates + 1, 2 * candidates),
    )
    # Each half a rigid motion of its own: its rows nearer its motion (RMS) than halfway
    # to the other's. Halves of one noisy object, or a patch of coherently wrong flow
    # (errors as large as their offset) cut from its object, are not.
    scatter = _rms(models.squared_error, models.moments).reshape(-1, 2)[candidates].max(axis=1)
    rigid = scatter < 0.5 * gap
    labels = labels.copy()
    next_label = n_clusters
    for cluster in candidates[(gap > min_jump) & rigid]:
        mine = own == cluster
        points = pa[mine]
        spacing = cKDTree(points).query(points, k=2)[0][:, 1]
        pair = np.array([[2 * cluster, 2 * cluster + 1]])
        if _flow_jumps_at_contact(
            points,
            pb[mine],
            2 * cluster + half[mine],
            models,
            pair,
            3.0 * float(np.median(spacing)),
            min_jump=min_jump,
        )[0]:
            # Each row to the half whose motion explains it better.
            first = _residuals(
                pa[mine],
                pb[mine],
                models.rotations,
                models.translations,
                np.full(np.count_nonzero(mine), 2 * cluster),
            )
            second = _residuals(
                pa[mine],
                pb[mine],
                models.rotations,
                models.translations,
                np.full(np.count_nonzero(mine), 2 * cluster + 1),
            )
            nearer = np.sum(second**2, axis=1) < np.sum(first**2, axis=1)
            labels[rows[mine][nearer]] = next_label
            next_label += 1
    return labels, next_label
