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
    "OFF_PLANE_SCALES",
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
_MIN_FLATNESS = 0.2


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
        line = flatness < _MIN_FLATNESS
        beyond = ratio[far] > EXPLAINED_SPACINGS
        off_plane = ~line & (along > OFF_PLANE_SCALES * scale)
        unexplained[far] = (beyond & (line | (along > spacing[far]))) | off_plane
    return unexplained
