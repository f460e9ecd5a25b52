"""Split a cluster that holds two touching objects whose flows jump where they touch.

An initial cluster larger than an object (the Euclidean initialisation's clusters span up
to ``tau``) may hold two touching objects that move alike: two boxes on one pallet, one
slipping 10 cm as both move 1 m. Fitted as one, its motion lies between theirs, and a
noise scale of its own (``variant="sweep"``) keeps both objects' points: nothing is left
unexplained for the proposals to find either object in. The step below tries, in each
cluster, the two-motion split that a two-means on the rigid fits gives, and keeps it when
the two halves' flows jump at their contact by more than ``min_motion``
(:func:`~mmreg.estimators._robust_steps._flow_jumps_at_contact`, the test that keeps
:func:`~mmreg.estimators._robust_steps.join_moving_pieces` from joining them again). A
network's flow that bends across one object meets itself at the contact of the halves,
and noise gives halves whose motions differ by less than ``min_motion``: neither splits.
"""

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from mmreg.estimators._robust_steps import (
    _flow_jumps_at_contact,
    fit_clusters,
    motion_gap,
)

__all__ = ["split_mixed_clusters"]

# Rounds of the two-means on rigid fits (fit each half, give each member to the half
# whose motion explains it better); a mixture of two rigid motions settles in one or two.
_ROUNDS = 4


def _residuals(a, b, rotations, translations, labels):
    """``b - (R_j a + t_j)`` for each row's cluster ``j``."""
    return b - np.einsum("nij,nj->ni", rotations[labels], a) - translations[labels]


def _residual_halves(a, b, labels, n_clusters, sigma_floor, noise_scale):
    """Each member's half (0 or 1): the sign of its residual along the main direction of
    its cluster's residuals (a mixture's residuals point two opposite ways)."""
    models = fit_clusters(a, b, labels, n_clusters, sigma_floor, noise_scale)
    r = _residuals(a, b, models.rotations, models.translations, labels)
    d = a.shape[1]
    scatter = np.zeros((n_clusters, d, d))
    np.add.at(scatter, labels, r[:, :, None] * r[:, None, :])
    direction = np.linalg.eigh(scatter)[1][:, :, -1]
    return (np.sum(r * direction[labels], axis=1) > 0).astype(np.intp)


def _first_halves(a, b, labels, n_clusters, sigma_floor, noise_scale, min_jump, min_size):
    """Each member's half (0 or 1) to start the two-means from.

    Neighbours (8 nearest) of one cluster whose flows differ by at most ``min_jump`` are
    linked; a cluster whose links fall apart into pieces, where two objects' flows jump
    by more, starts from its largest piece against the rest: the objects' own regions,
    from which the two-means on rigid fits settles on them. (A least-squares motion of
    two objects turns to explain part of their difference, so the signs of its residuals
    cut both objects.) Other clusters start from :func:`_residual_halves`.
    """
    half = _residual_halves(a, b, labels, n_clusters, sigma_floor, noise_scale)
    n = len(a)
    k = min(9, n)
    index = cKDTree(a).query(a, k=k)[1][:, 1:]
    source = np.repeat(np.arange(n), k - 1)
    target = index.ravel()
    flow = b - a
    linked = (labels[source] == labels[target]) & (
        np.linalg.norm(flow[source] - flow[target], axis=1) <= min_jump
    )
    graph = coo_matrix(
        (np.ones(np.count_nonzero(linked)), (source[linked], target[linked])), shape=(n, n)
    )
    _, piece = connected_components(graph, directed=False)
    # Each cluster's largest piece.
    sizes = np.bincount(piece)
    largest = np.full(n_clusters, -1)
    order = np.argsort(sizes[piece], kind="stable")
    largest[labels[order]] = piece[order]  # the last write per cluster is its largest
    in_largest = piece == largest[labels]
    rest = np.bincount(labels[~in_largest], minlength=n_clusters)
    held = np.bincount(labels[in_largest], minlength=n_clusters)
    apart = (rest >= min_size) & (held >= min_size)
    return np.where(apart[labels], (~in_largest).astype(np.intp), half)


def split_mixed_clusters(
    a, b, labels, n_clusters, sigma_floor, *, min_jump, min_size=4, noise_scale=None, exempt=-1
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
    exempt : int, default=-1
        A cluster never split (the static world), -1 for none.

    Returns
    -------
    labels : ndarray of shape (n,)
        The split clusters' second halves numbered from ``n_clusters`` on.
    n_clusters : int
    """
    rows = np.flatnonzero(labels >= 0)
    if n_clusters == 0 or len(rows) < 2 * min_size:
        return labels, n_clusters
    pa, pb, own = a[rows], b[rows], labels[rows]
    scale = None if noise_scale is None else noise_scale[rows]
    half = _first_halves(pa, pb, own, n_clusters, sigma_floor, scale, min_jump, min_size)
    for _ in range(_ROUNDS):
        models = fit_clusters(pa, pb, 2 * own + half, 2 * n_clusters, sigma_floor, scale)
        first = _residuals(pa, pb, models.rotations, models.translations, 2 * own)
        second = _residuals(pa, pb, models.rotations, models.translations, 2 * own + 1)
        nearer = (np.sum(second**2, axis=1) < np.sum(first**2, axis=1)).astype(np.intp)
        if np.array_equal(nearer, half):
            break
        half = nearer
    models = fit_clusters(pa, pb, 2 * own + half, 2 * n_clusters, sigma_floor, scale)
    sizes = np.bincount(2 * own + half, minlength=2 * n_clusters).reshape(-1, 2)
    candidates = np.flatnonzero(sizes.min(axis=1) >= min_size)
    candidates = candidates[candidates != exempt]
    if not len(candidates):
        return labels, n_clusters
    # Motions that differ by less than min_jump anywhere cannot jump by more at the contact.
    gap = np.maximum(
        motion_gap(models, 2 * candidates, 2 * candidates + 1),
        motion_gap(models, 2 * candidates + 1, 2 * candidates),
    )
    labels = labels.copy()
    next_label = n_clusters
    for cluster in candidates[gap > min_jump]:
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
            labels[rows[mine & (half == 1)]] = next_label
            next_label += 1
    return labels, next_label
