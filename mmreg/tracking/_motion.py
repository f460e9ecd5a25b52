"""Rigid motions over time: 4 x 4 transforms, and the constant twist of a moving object.

A track moves by a constant twist about its centre: over ``dt`` its points turn by the
rotation vector ``omega * dt`` about the centre ``c`` and the centre moves by
``velocity * dt``, ``x -> R(omega dt) (x - c) + c + velocity dt``. On a road this is the
constant velocity and turn rate model (CTRV) of multi-object trackers, written without
assuming which axis is up. A motion measured between two frames gives the twist back
exactly (:func:`twist_of`), so a prediction over the same interval is that motion.
"""

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ["compose", "inverse", "predicted_motion", "to_matrix", "transform", "twist_of"]


def to_matrix(rotation, translation):
    """The 4 x 4 homogeneous matrix of ``x -> rotation @ x + translation``.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.tracking._motion import to_matrix
    >>> to_matrix(np.eye(3), [1.0, 2.0, 3.0])[:3, 3].tolist()
    [1.0, 2.0, 3.0]
    """
    matrix = np.eye(4)
    matrix[:3, :3] = rotation
    matrix[:3, 3] = translation
    return matrix


def inverse(matrix):
    """The inverse of a rigid 4 x 4 transform (no general matrix inverse)."""
    rotation, translation = matrix[:3, :3], matrix[:3, 3]
    return to_matrix(rotation.T, -rotation.T @ translation)


def compose(*matrices):
    """The product of 4 x 4 transforms, the rightmost applied first."""
    out = np.eye(4)
    for matrix in matrices:
        out = out @ matrix
    return out


def transform(matrix, points):
    """``points`` (n, 3) moved by the 4 x 4 ``matrix``."""
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def twist_of(motion, centre, dt):
    """The constant twist ``(omega, velocity)`` that makes ``motion`` over ``dt``.

    ``motion`` (4 x 4) moves points of an object whose centre is ``centre``; ``omega`` is
    its rotation vector per unit time and ``velocity`` the centre's displacement per unit
    time, so that ``predicted_motion(omega, velocity, centre, dt)`` is ``motion`` again.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.tracking._motion import predicted_motion, to_matrix, twist_of
    >>> c, s = np.cos(0.1), np.sin(0.1)
    >>> motion = to_matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]], [1.0, 0.5, 0.0])
    >>> centre = np.array([10.0, 2.0, 0.5])
    >>> omega, velocity = twist_of(motion, centre, 0.5)
    >>> np.round(omega, 6).tolist()
    [0.0, 0.0, 0.2]
    >>> bool(np.allclose(predicted_motion(omega, velocity, centre, 0.5), motion))
    True
    """
    rotation, translation = motion[:3, :3], motion[:3, 3]
    omega = Rotation.from_matrix(rotation).as_rotvec() / dt
    velocity = (rotation @ centre + translation - centre) / dt
    return omega, velocity


def predicted_motion(omega, velocity, centre, dt):
    """The 4 x 4 motion of an object moving by the twist ``(omega, velocity)`` for ``dt``.

    Its points turn by ``omega * dt`` about ``centre`` while the centre moves by
    ``velocity * dt``.
    """
    rotation = Rotation.from_rotvec(np.asarray(omega, dtype=float) * dt).as_matrix()
    centre = np.asarray(centre, dtype=float)
    return to_matrix(rotation, centre + np.asarray(velocity) * dt - rotation @ centre)
