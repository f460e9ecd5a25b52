"""Whether the second sweep explains a point of the first, in its sampling spacings.

Raw sweeps are sampled ever more sparsely with range, so a distance to the second sweep
says nothing until it is compared with the sweep's spacing there (the distance from its
nearest point to that point's own nearest neighbour). The slow movers' seeds and tests
(:mod:`mmreg.sweeps._slow_movers`), the new places of a cluster's motion
(:mod:`mmreg.sweeps._new_places`) and the parts of a moving island that its motion
tears off (``SweepRegistration``) all ask this one question, by these rules.
"""

import numpy as np

__all__ = [
    "EXPLAINED_SPACINGS",
    "MIN_FLATNESS",
    "OFF_PLANE_SCALES",
    "across_rings",
    "spacing_ratio",
    "unexplained_at",
    "unexplained_mask",
]

# A point is unexplained beyond this many spacings from the second sweep.
EXPLAINED_SPACINGS = 2.0
# ... or, where the sweep is a surface, beyond one spacing from its nearest point and
# this many robust residual scales of the ego motion off its plane.
OFF_PLANE_SCALES = 3.0
# Neighbourhoods of the second sweep flatter than this are lines (no plane).
MIN_FLATNESS = 0.2
# A line neighbourhood's gap to the next scan ring is looked for among this many times
# its own neighbours.
_RING_NEIGHBOURS = 3
# A scan ring of a z-up spinning sensor runs level: a line within 30 degrees of level
# (its direction's vertical part under this) is one; a steeper line is a thin upright
# thing (a pole, a walker), whose neighbours across it are no next ring.
_RING_RISE = 0.5


def spacing_ratio(points, tree, sweep, normals=None):
    """Distance of each point to the sweep in units of the sweep's spacing there.

    Also returns the index of the nearest sweep point and the spacing. ``normals``: the
    sweep's :class:`mmreg.sweeps._icp.SurfaceNormals`, which keeps every spacing it finds
    (these tests ask about the same sweep points again and again).
    """
    distance, nearest = tree.query(points)
    if normals is not None:
        spacing = normals.spacing(nearest)
    else:
        # Many points share their nearest sweep point: its spacing is found once.
        unique, inverse = np.unique(nearest, return_inverse=True)
        spacing = tree.query(sweep[unique], k=2)[0][:, 1][inverse.ravel()]
    spacing = np.maximum(spacing, np.finfo(float).tiny)
    # Where the sweep repeats a point (spacing 0), any distance is infinitely many
    # spacings: the overflow to inf is the answer, not a fault.
    with np.errstate(over="ignore"):
        return distance / spacing, nearest, spacing


def unexplained_mask(points, tree, sweep, normals, scale):
    """Whether the second sweep leaves each point unexplained, and the distance ratio.

    Unexplained: more than ``EXPLAINED_SPACINGS`` spacings from the nearest point of the
    sweep and, where the sweep's neighbourhood there is a surface, more than one
    spacing off its plane (a point of a surface the other sweep saw elsewhere, e.g.
    behind a moving object, lies on the plane but far from its points); or, where the
    sweep is a surface, more than one spacing from its nearest point and more than
    ``OFF_PLANE_SCALES`` robust residual scales (``scale``, the ego ICP's point-to-plane
    noise) off its plane. The second rule sees a body that moves less than two
    spacings towards or away from its surface's normal (a pedestrian walking 0.1 m
    where the sweep samples every 6 cm): the nearest point is still close, but the
    surface is displaced by many times the noise. Within one spacing of a point of the
    sweep, a point is explained whatever the plane says (edges, curved surfaces).

    Parameters
    ----------
    points : ndarray of shape (n, 3)
        Points of the first sweep, where a motion puts them in the second's frame.
    tree : cKDTree of ``sweep``
    sweep : ndarray of shape (m, 3)
    normals : SurfaceNormals of ``sweep``
    scale : float
        The ego ICP's robust point-to-plane residual scale.

    Returns
    -------
    unexplained : ndarray of bool, shape (n,)
    ratio : ndarray of shape (n,)
        Distance to the nearest point of ``sweep`` in its spacings there.

    Examples
    --------
    A floor sampled every 5 cm; points on it, 2 cm above it (past 3 residual scales of
    5 mm, but within one spacing of a point) and 30 cm above it:

    >>> import numpy as np
    >>> from scipy.spatial import cKDTree
    >>> from mmreg.sweeps._icp import SurfaceNormals
    >>> from mmreg.sweeps._explained import unexplained_mask
    >>> g = np.arange(0.0, 2.0, 0.05)
    >>> floor = np.stack(np.meshgrid(g, g, [0.0], indexing="ij"), -1).reshape(-1, 3)
    >>> tree = cKDTree(floor)
    >>> points = np.array([[1.025, 1.025, 0.0], [1.0, 1.0, 0.02], [1.0, 1.0, 0.3]])
    >>> mask, ratio = unexplained_mask(points, tree, floor, SurfaceNormals(floor, tree, 10), 0.005)
    >>> mask.tolist()
    [False, False, True]
    """
    ratio, nearest, spacing = spacing_ratio(points, tree, sweep, normals)
    return unexplained_at(points, (ratio, nearest, spacing), sweep, normals, scale), ratio


def unexplained_at(points, nearest_spacings, sweep, normals, scale):
    """:func:`unexplained_mask` from the points' :func:`spacing_ratio` already found
    (``(ratio, nearest, spacing)``): callers that ask of the same points under several
    motions query the tree once per motion."""
    ratio, nearest, spacing = nearest_spacings
    far = np.flatnonzero(ratio > 1.0)
    unexplained = np.zeros(len(points), dtype=bool)
    if len(far):
        normal, _, flatness = normals(nearest[far])
        along = np.abs(np.einsum("ni,ni->n", normal, points[far] - sweep[nearest[far]]))
        line = flatness < MIN_FLATNESS
        beyond = ratio[far] > EXPLAINED_SPACINGS
        off_plane = ~line & (along > OFF_PLANE_SCALES * scale)
        unexplained[far] = (beyond & (line | (along > spacing[far]))) | off_plane
    return unexplained


def across_rings(points, nearest_spacings, tree, sweep, normals, up):
    """:func:`spacing_ratio`'s answers ``(ratio, nearest, spacing)`` where the sweep is
    one scan ring at a point's nearest: the spacing there at least half the gap to the
    next ring.

    Where a sparse sensor's rings lie far apart, each ring crosses a surface along a
    curve that moves with the sensor: a point of the first sweep that lies between two
    rings of the second is no sign of motion, though it is many spacings along the ring
    from either. The nearest sweep point's neighbourhood is a line (flatness under
    ``MIN_FLATNESS``) running within 30 degrees of level (``up``, the vertical); the
    gap is the distance across that line to the nearest of its ``3 k`` neighbours that
    lies off it (beyond the line's own thickness), or to the farthest of them.

    Examples
    --------
    Two rings 0.1 m apart on a wall, sampled every centimetre, and a pole: a point
    0.04 m below the upper ring, between the two, is 4 spacings from it but within a
    half gap; 0.04 m beside the pole it is not between rings.

    >>> import numpy as np
    >>> from scipy.spatial import cKDTree
    >>> from mmreg.sweeps._icp import SurfaceNormals
    >>> from mmreg.sweeps._explained import across_rings, spacing_ratio
    >>> x = np.arange(0.0, 2.0, 0.01)
    >>> rings = np.concatenate([np.c_[x, 0 * x, 0 * x], np.c_[x, 0 * x, 0 * x + 0.1]])
    >>> pole = np.c_[0 * x + 5.0, 0 * x, x]
    >>> sweep = np.vstack([rings, pole])
    >>> tree, normals = cKDTree(sweep), SurfaceNormals(sweep, cKDTree(sweep), 10)
    >>> points = np.array([[1.005, 0.0, 0.06], [5.04, 0.0, 1.005]])
    >>> answers = spacing_ratio(points, tree, sweep, normals)
    >>> np.round(answers[0], 1)
    array([4., 4.])
    >>> ratio, _, _ = across_rings(points, answers, tree, sweep, normals, np.eye(3)[2])
    >>> np.round(ratio, 1)
    array([0.8, 4. ])
    """
    ratio, nearest, spacing = nearest_spacings
    _, _, flatness = normals(nearest)
    line = np.flatnonzero(flatness < MIN_FLATNESS)
    if not len(line):
        return nearest_spacings
    foot, where = np.unique(nearest[line], return_inverse=True)
    k = normals.k
    distance, hood = tree.query(sweep[foot], k=min(_RING_NEIGHBOURS * k, len(sweep)))
    offsets = sweep[hood] - sweep[foot][:, None, :]
    own = offsets[:, :k] - offsets[:, :k].mean(axis=1, keepdims=True)
    _, axes = np.linalg.eigh(np.einsum("nki,nkj->nij", own, own))
    direction = axes[:, :, 2]  # the line's
    along = np.einsum("nki,ni->nk", offsets, direction)
    across = np.linalg.norm(offsets - along[:, :, None] * direction[:, None, :], axis=2)
    # Off the line: beyond its own thickness (at least a millionth of its spacing, where
    # its points lie on one straight line to the rounding).
    thickness = np.fmax(across[:, :k].max(axis=1), 1e-6 * normals.spacing(foot))
    off = across > thickness[:, None]
    off[:, :k] = False
    gap = np.where(off.any(axis=1), np.where(off, across, np.inf).min(axis=1), distance[:, -1])
    ring = np.abs(direction @ up) < _RING_RISE
    half_gap = np.where(ring, 0.5 * gap, 0.0)[where.ravel()]
    spacing = spacing.copy()
    spacing[line] = np.maximum(spacing[line], half_gap)
    with np.errstate(over="ignore"):
        ratio = np.linalg.norm(points - sweep[nearest], axis=1) / spacing
    return ratio, nearest, spacing
