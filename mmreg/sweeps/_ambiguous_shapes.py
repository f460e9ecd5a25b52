"""Raw sweeps: islands whose shape cannot tell a far motion from another match.

A flat island (a patch of road, a wall) fits its second view wherever that view
continues in the plane: a motion within the plane is not evidence that it moved. A
flat piece of a moving object still counts when its motion has a clear component
across the plane (the rear of a car driving away). A thin line of points (a pole, a
post) fits any other pole of a street as well as its own second view, and a line slid
along itself (a scan ring across a wall) its own.
"""

import numpy as np

from mmreg._array.geometry import departures
from mmreg._array.moments import group_moments

__all__ = ["ACROSS", "is_line", "shapes", "slides_along_line", "slides_in_plane"]

# Flat: the smallest spread (variance) of the island's points under this share of the
# middle one; a line: the middle one under this share of the largest.
_FLATNESS = 0.05
# Along the plane: the motion's component across it is under this share of its length.
ACROSS = 0.5


def slides_in_plane(points, groups, n_groups, motions, ego):
    """Whether each group is flat and its motion, relative to the ego motion, lies in it.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
    groups : ndarray of shape (n,)
        Group of every point in ``0..n_groups-1`` (negative: none).
    n_groups : int
    motions : tuple of ndarray
        ``(rotations, translations)``, one per group.
    ego : tuple of ndarray
        ``(R, t)`` of the ego motion.

    Returns
    -------
    slides : ndarray of bool, shape (n_groups,)

    Examples
    --------
    A flat patch moved 3 m within its plane slides; moved across it, it does not.

    >>> import numpy as np
    >>> from mmreg.sweeps._ambiguous_shapes import slides_in_plane
    >>> rng = np.random.default_rng(0)
    >>> patch = np.c_[rng.uniform(0, 2, (100, 2)), np.zeros(100)]
    >>> rotations = np.stack([np.eye(3)] * 2)
    >>> translations = np.array([[3.0, 0, 0], [0, 0, 3.0]])
    >>> groups = np.r_[np.zeros(100, int), np.ones(100, int)]
    >>> ego = (np.eye(3), np.zeros(3))
    >>> slides_in_plane(np.vstack([patch, patch]), groups, 2, (rotations, translations), ego)
    array([ True, False])
    """
    spread, normal, displacement = _turned_axis(points, groups, n_groups, motions, ego, 0)
    across = np.abs(np.einsum("ki,ki->k", displacement, normal))
    return _flat(spread) & (across < ACROSS * np.linalg.norm(displacement, axis=1))


def slides_along_line(points, groups, n_groups, motions, ego):
    """Whether each group lies along a line and its motion, relative to the ego motion,
    runs along it.

    A line slid along itself fits its second view wherever that view continues (the
    aperture problem): one scan ring's cone crosses a wall along a curve that travels
    with the sensor, and where the rings lie far apart (2 degrees) none above or below
    shows the wall's surface, so the curve seems to move with the sensor from sweep to
    sweep. The motion is ambiguous where its component across the line is under
    ``ACROSS`` of its length. Parameters and result as :func:`slides_in_plane`'s.

    Examples
    --------
    A thin strip 6 m long moved 2 m along itself slides; moved 2 m across it, or a
    square patch moved alike, does not.

    >>> import numpy as np
    >>> from mmreg.sweeps._ambiguous_shapes import slides_along_line
    >>> rng = np.random.default_rng(0)
    >>> strip = np.c_[rng.uniform(0, 6, 100), rng.normal(0, 0.02, (100, 2))]
    >>> patch = np.c_[rng.uniform(0, 2, (100, 2)), np.zeros(100)]
    >>> points = np.vstack([strip, strip, patch])
    >>> groups = np.repeat([0, 1, 2], 100)
    >>> motions = (np.stack([np.eye(3)] * 3), np.array([[2.0, 0, 0], [0, 2.0, 0], [2.0, 0, 0]]))
    >>> ego = (np.eye(3), np.zeros(3))
    >>> slides_along_line(points, groups, 3, motions, ego)
    array([ True, False, False])
    """
    spread, axis, displacement = _turned_axis(points, groups, n_groups, motions, ego, 2)
    along = np.einsum("ki,ki->k", displacement, axis)
    across = np.linalg.norm(displacement - along[:, None] * axis, axis=1)
    return _line(spread) & (across < ACROSS * np.linalg.norm(displacement, axis=1))


def shapes(points, groups, n_groups):
    """Whether each group's points lie in a plane, and whether along a line.

    Flat: the smallest spread (variance) is under a twentieth of the middle one; a line:
    the middle one under a twentieth of the largest. One pass over the groups' moments.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
    groups : ndarray of shape (n,)
        Group of every point in ``0..n_groups-1`` (negative: none).
    n_groups : int

    Returns
    -------
    flat, line : ndarray of bool, shape (n_groups,)

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.sweeps._ambiguous_shapes import shapes
    >>> rng = np.random.default_rng(0)
    >>> wall = np.c_[rng.uniform(0, 3, (50, 2)), rng.normal(0, 0.01, 50)]
    >>> pole = np.c_[rng.normal(0, 0.03, (50, 2)), rng.uniform(0, 4, 50)]
    >>> box = rng.uniform(0, 1, (50, 3))
    >>> flat, line = shapes(np.vstack([wall, pole, box]), np.repeat([0, 1, 2], 50), 3)
    >>> flat.tolist(), line.tolist()
    ([True, False, False], [False, True, False])
    """
    _, spread, _ = _principal_axes(points, groups, n_groups)
    return _flat(spread), _line(spread)


def is_line(points, groups, n_groups):
    """Whether each group's points lie along a line: the second answer of :func:`shapes`.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.sweeps._ambiguous_shapes import is_line
    >>> rng = np.random.default_rng(0)
    >>> pole = np.c_[rng.normal(0, 0.03, (50, 2)), rng.uniform(0, 4, 50)]
    >>> box = rng.uniform(0, 1, (50, 3))
    >>> is_line(np.vstack([pole, box]), np.repeat([0, 1], 50), 2)
    array([ True, False])
    """
    return shapes(points, groups, n_groups)[1]


def _flat(spread):
    """Whether the smallest of each row of ascending spreads is small beside the middle."""
    return spread[:, 0] < _FLATNESS * spread[:, 1]


def _line(spread):
    """Whether the middle of each row of ascending spreads is small beside the largest."""
    return spread[:, 1] < _FLATNESS * spread[:, 2]


def _turned_axis(points, groups, n_groups, motions, ego, rank):
    """Each group's spreads (ascending), its principal axis of that ``rank`` (0: the
    least spread) where the ego motion turns it, and its centroid's departure from the
    ego motion under its own motion."""
    moments, spread, axes = _principal_axes(points, groups, n_groups)
    rotations, translations = motions
    displacement = departures(moments.mean_a, rotations, translations, ego)
    return spread, axes[:, :, rank] @ ego[0].T, displacement


def _principal_axes(points, groups, n_groups):
    """Each group's moments, and the spreads (ascending) and axes of its points."""
    moments = group_moments(points, points, groups, n_groups)
    spread, axes = np.linalg.eigh(moments.cross)
    return moments, spread, axes
