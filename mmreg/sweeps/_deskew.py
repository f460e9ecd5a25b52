"""Motion compensation of moving objects within a sweep ("deskewing").

A spinning LiDAR captures the points of one sweep over its whole period (Argoverse 2:
0-106 ms, its two heads about 50 ms apart at the same azimuth). Sweeps come compensated
for the ego motion, so the static world is where it was at the sweep's reference time,
but a moving object is where it was when each point was captured: a car moving 8 m/s
relative to the world appears twice, its two copies 0.4 m apart. Given the object's
rigid motion ``M`` over the interval ``dt`` between two sweeps, relative to the static
world, a point captured ``tau`` after the reference time is moved back to where it was
at the reference time along ``M`` interpolated at ``s = tau / dt``:

    M^s (x) = exp(s [w]_x) (x - c) + c + s d,    x_ref = (M^s)^-1 (x),

``w`` the rotation vector of ``M``, ``c`` a centre (the object's centroid) and ``d = M(c) -
c``: the centre moves on a straight line and the body turns by the same share of its
angle, a constant-velocity model; the same for ``s < 0`` (points captured before the
reference time).
"""

import numpy as np
from scipy.spatial.transform import Rotation

from mmreg.sweeps._icp import rotation_vectors_to_matrices

__all__ = ["deskew", "relative_motions"]


def relative_motions(rotations, translations, world):
    """The motions of clusters relative to the static world, in both sweeps' frames.

    A cluster's motion ``M_k`` maps the first sweep's frame to the second's and the
    static world's ``E`` does the same for the resting points, so the motion of the body
    itself over the interval is ``E^-1 M_k`` in the first sweep's frame and
    ``M_k E^-1`` in the second's.

    Parameters
    ----------
    rotations : ndarray of shape (K, 3, 3)
    translations : ndarray of shape (K, 3)
        The clusters' motions from the first sweep to the second.
    world : tuple of ndarray
        ``(R, t)``, the static world's motion.

    Returns
    -------
    first, second : tuple of (ndarray of shape (K, 3, 3), ndarray of shape (K, 3))
        The relative motions in the first sweep's frame and in the second's.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.sweeps._deskew import relative_motions
    >>> world = (np.eye(3), np.array([1.0, 0.0, 0.0]))
    >>> first, second = relative_motions(np.eye(3)[None], np.array([[3.0, 0.0, 0.0]]), world)
    >>> first[1].tolist(), second[1].tolist()
    ([[2.0, 0.0, 0.0]], [[2.0, 0.0, 0.0]])
    """
    R_world, t_world = (np.asarray(x, dtype=float) for x in world)
    rotations = np.asarray(rotations, dtype=float)
    translations = np.asarray(translations, dtype=float)
    first = (R_world.T @ rotations, (translations - t_world) @ R_world)
    second_rotations = rotations @ R_world.T
    second = (second_rotations, translations - second_rotations @ t_world)
    return first, second


def deskew(points, groups, fractions, rotations, translations, centres, *, turn=True):
    """Move every point back to its group's pose at the reference time.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
    groups : ndarray of shape (n,)
        The group of each point in ``0..K-1``; points with a negative group are returned
        unchanged.
    fractions : ndarray of shape (n,)
        ``tau / dt`` of each point: its capture time after the reference time, as a share
        of the interval over which the groups' motions are given.
    rotations : ndarray of shape (K, 3, 3)
    translations : ndarray of shape (K, 3)
        Each group's motion over the interval, relative to the static world, in the
        points' frame.
    centres : ndarray of shape (K, 3)
        The centre of each group's interpolation (its centroid): the centre moves on a
        straight line.
    turn : bool, default=True
        Whether the groups turn by their share of the rotation; False: every point of a
        group moves as its centre does (the rotation only sets where the centre goes).

    Returns
    -------
    points : ndarray of shape (n, 3)
        A new array.

    Examples
    --------
    A body moving 1 m along x per interval; a point captured half an interval late is
    moved back by 0.5 m, one captured a quarter early forward by 0.25 m.

    >>> import numpy as np
    >>> from mmreg.sweeps._deskew import deskew
    >>> out = deskew(np.zeros((2, 3)), np.array([0, 0]), np.array([0.5, -0.25]),
    ...              np.eye(3)[None], np.array([[1.0, 0.0, 0.0]]), np.zeros((1, 3)))
    >>> out[:, 0].tolist()
    [-0.5, 0.25]
    """
    points = np.array(points, dtype=float)
    groups = np.asarray(groups, dtype=np.intp)
    rotations = np.asarray(rotations, dtype=float)
    translations = np.asarray(translations, dtype=float)
    centres = np.asarray(centres, dtype=float)
    rows = np.flatnonzero(groups >= 0)
    if not len(rows) or not len(rotations):
        return points
    shift = np.einsum("kij,kj->ki", rotations, centres) + translations - centres
    g, s = groups[rows], np.asarray(fractions, dtype=float)[rows]
    if not turn:
        points[rows] -= s[:, None] * shift[g]
        return points
    angle = Rotation.from_matrix(rotations).as_rotvec()
    back = rotation_vectors_to_matrices(-s[:, None] * angle[g])
    local = points[rows] - centres[g] - s[:, None] * shift[g]
    points[rows] = np.einsum("nij,nj->ni", back, local) + centres[g]
    return points
