"""Raw sweeps: whether a cluster's motion shows it somewhere the static world was not.

A moving body leaves its old place and arrives at a new one: some of its points, which
the ego motion leaves unexplained, land under its own motion on points of the second
sweep that the first sweep, moved by the ego motion, does not explain either (its
front face in free space, its back face where its interior hid the view). A static
structure that an ICP slid along itself or onto a neighbouring surface (a pole or a
wall moved up or down by a ring gap, a building's edge seen from another place) lands
on surfaces the first sweep held already: however well its new motion fits, it shows
no new place. Both "explained" tests are the slow movers' rule
(:func:`mmreg.sweeps._explained.unexplained_mask`: in units of the sweep's sampling
spacing and of the ego ICP's robust residual scale), so nothing here is a length.
"""

import numpy as np
from scipy.spatial import cKDTree

from mmreg.sweeps._explained import EXPLAINED_SPACINGS, spacing_ratio, unexplained_mask
from mmreg.sweeps._icp import SurfaceNormals
from mmreg.sweeps._island_motions import _MIN_EXPLAINED

__all__ = ["MIN_NEW_PLACE", "new_place_shares"]

# A moving cluster shows at least this share of its points at a new place: the tenth
# that an island's own motion must explain beyond the ego motion
# (:mod:`mmreg.sweeps._island_motions`).
MIN_NEW_PLACE = _MIN_EXPLAINED

# Points of the neighbourhoods whose PCA gives the first sweep's normals (as the ICP's).
_NORMAL_POINTS = 10


def new_place_shares(
    a, labels, motions, static, scale, target, *, reach=None, whole=None, own=None
):
    """Share of each cluster's points that its motion shows at a new place.

    A point counts when the static world's motion leaves it unexplained by the second
    sweep, its cluster's motion puts it within two spacings of a point of the second
    sweep (or within ``reach``), and that point of the second sweep (the nearest) is
    itself unexplained by the first sweep moved by the static world's motion.

    Parameters
    ----------
    a : ndarray of shape (n, 3)
        The first sweep.
    labels : ndarray of shape (n,)
        Cluster of every point, ``-1`` for none.
    motions : tuple of ndarray
        ``(rotations, translations)``, one per cluster.
    static : int
        The static world's cluster.
    scale : float
        The ego ICP's robust point-to-plane residual scale.
    target : tuple
        ``(sweep, tree, normals)``: the second sweep, its cKDTree and its
        :class:`mmreg.sweeps._icp.SurfaceNormals`.
    reach : float or None, default=None
        Largest distance from a moved point to its landing place; None: two of the
        second sweep's spacings there. Motions fitted to deskewed points (capture
        times) take the ICP's gate: a body scanned by a spinning sensor is skewed by
        its own motion over the sweep (copies 0.4 m apart at 8 m/s on Argoverse 2),
        and its motion between the sweeps' reference times puts its raw points near,
        not on, its second view.
    whole : tuple or None
        ``(first, second)``: the first sweep and the second, each as ``target`` is
        (points, tree, normals), with the ground that ``a`` and ``target`` leave out.
        Whether the static world's motion explains a point, and whether the first sweep
        explains a landing place, is then asked of the whole sweeps: the two masks of
        the ground differ at objects' feet, and a surface left in one sweep only would
        read as new. None: ``a`` and ``target`` are whole.
    own : SurfaceNormals or None, default=None
        Where ``whole`` is None, the normals of ``a`` (10 neighbours, with its tree)
        where the caller keeps them; None: built here.

    Returns
    -------
    shares : ndarray of shape (n_clusters,)
        The share for every cluster (1 for the static world).

    Examples
    --------
    A block moved by 0.5 m beside a wall; the wall's own "motion" slides it along
    itself by the same step.

    >>> import numpy as np
    >>> from scipy.spatial import cKDTree
    >>> from mmreg.sweeps._icp import SurfaceNormals
    >>> from mmreg.sweeps._new_places import new_place_shares
    >>> g = np.arange(0, 4, 0.04)
    >>> wall = np.stack(np.meshgrid(g, [0.0], g, indexing="ij"), -1).reshape(-1, 3)
    >>> s = np.arange(0, 1, 0.04)
    >>> face = np.stack(np.meshgrid(s, [0.0], s, indexing="ij"), -1).reshape(-1, 3)
    >>> block = np.vstack([face, face[:, [1, 0, 2]], face[:, [0, 2, 1]]]) + [1, 0.5, 0]
    >>> a = np.vstack([wall, block])
    >>> sweep = np.vstack([wall, block + [0.5, 0.0, 0.0]])
    >>> tree = cKDTree(sweep)
    >>> labels = np.r_[np.zeros(len(wall), int), np.ones(len(block), int)]
    >>> motions = (np.stack([np.eye(3)] * 2), np.array([[0.0, 0, 0], [0.5, 0, 0]]))
    >>> shares = new_place_shares(
    ...     a, labels, motions, 0, 0.005, (sweep, tree, SurfaceNormals(sweep, tree, 10)))
    >>> bool(shares[1] > 0.2)
    True
    >>> labels[: len(wall)][wall[:, 0] > 3] = 2  # a strip of the wall, slid along it
    >>> motions = (np.stack([np.eye(3)] * 3), np.array([[0.0, 0, 0], [0.5, 0, 0], [0, 0, 0.4]]))
    >>> shares = new_place_shares(
    ...     a, labels, motions, 0, 0.005, (sweep, tree, SurfaceNormals(sweep, tree, 10)))
    >>> float(shares[2])
    0.0
    """
    rotations, translations = motions
    n_clusters = len(rotations)
    shares = np.ones(n_clusters)
    members = np.flatnonzero((labels >= 0) & (labels != static))
    if not len(members):
        return shares
    sweep, tree, normals = target
    if whole is None:
        if own is None:
            own = SurfaceNormals(a, cKDTree(a), _NORMAL_POINTS)
        whole = ((a, own.tree, own), target)
    (first, first_tree, first_normals), (whole_sweep, whole_tree, whole_normals) = whole
    counts = np.bincount(labels[members], minlength=n_clusters)
    rest = rotations[static], translations[static]
    unexplained, _ = unexplained_mask(
        a[members] @ rest[0].T + rest[1], whole_tree, whole_sweep, whole_normals, scale
    )
    rows = members[unexplained]
    group = labels[rows]
    moved = np.einsum("nij,nj->ni", rotations[group], a[rows]) + translations[group]
    if reach is None:
        ratio, landing, _ = spacing_ratio(moved, tree, sweep, normals)
        arrived = ratio <= EXPLAINED_SPACINGS
    else:
        distance, landing = tree.query(moved, distance_upper_bound=reach)
        arrived = np.isfinite(distance)
    rows, group, landing = rows[arrived], group[arrived], landing[arrived]
    new = np.zeros(len(rows), dtype=bool)
    if len(rows):
        places, inverse = np.unique(landing, return_inverse=True)
        # Whether the first sweep, moved by the static world's motion, explains a place:
        # asked in the first sweep's own frame (distances and the normals' planes do not
        # change under a rigid motion), of its tree and normals, which its state keeps.
        back = (sweep[places] - rest[1]) @ rest[0]
        new_place, _ = unexplained_mask(back, first_tree, first, first_normals, scale)
        new = new_place[inverse.ravel()]
    shown = np.bincount(group, weights=new, minlength=n_clusters)
    present = counts > 0
    shares[present] = shown[present] / counts[present]
    return shares
