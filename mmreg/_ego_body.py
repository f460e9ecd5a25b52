"""Returns from the sensor's own vehicle: near the sensor and fixed in its frame.

A roof-mounted LiDAR sees its own car (nuScenes: a quarter of a sweep within 2.5 m of the
sensor). Those points move with the sensor: in the sensor's frame they sit where they sat
in the last sweep, while the ego motion carries everything static away. They would pull
the ego motion towards the identity and make one "object" that moves exactly as the ego
vehicle does; they are found from the data, in two steps:

1. candidates (:func:`fixed_candidates`): points near the sensor's origin whose nearest
   point of the other sweep, in the same sensor coordinates, is within the matching
   distance;
2. confirmation (:func:`confirm_body`): the ego motion, found without the candidates,
   moves them by more than the matching distance and leaves them off the second
   sweep, so the identity, not the ego motion, explains them. When the sensor stands
   still nothing is confirmed (the body then looks like the static world, and is).

Every length is the caller's, in the points' units (``SweepRegistration`` gives them in
units of its ``tau``).
"""

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["confirm_body", "fixed_candidates"]


def fixed_candidates(points, sweep, *, reach, match, exclude=None, sweep_exclude=None):
    """Points of each sweep near the sensor that the other sweep holds at the same place.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
        The first sweep, in its sensor's frame (the sensor at the origin).
    sweep : ndarray of shape (m, 3)
        The second sweep, in its own sensor's frame.
    reach : float
        Only points closer than this to the sensor's origin are candidates.
    match : float
        A candidate's nearest point of the other sweep, same coordinates, is this close.
    exclude, sweep_exclude : ndarray of bool or None
        Points that are never candidates (the ground: on a flat road its range rings
        stay fixed in the sensor's frame too).

    Returns
    -------
    candidates : ndarray of shape (n,), bool
    sweep_candidates : ndarray of shape (m,), bool

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._ego_body import fixed_candidates
    >>> body = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    >>> far = np.array([[20.0, 0.0, 0.0]])
    >>> c, s = fixed_candidates(np.vstack([body, far]), np.vstack([body, far + 1]),
    ...                         reach=3.0, match=0.1)
    >>> c.tolist(), s.tolist()
    ([True, True, False], [True, True, False])
    """
    near = np.linalg.norm(points, axis=1) < reach
    sweep_near = np.linalg.norm(sweep, axis=1) < reach
    if exclude is not None:
        near &= ~exclude
    if sweep_exclude is not None:
        sweep_near &= ~sweep_exclude
    candidates = np.zeros(len(points), dtype=bool)
    sweep_candidates = np.zeros(len(sweep), dtype=bool)
    if not near.any() or not sweep_near.any():
        return candidates, sweep_candidates
    first, second = np.flatnonzero(near), np.flatnonzero(sweep_near)
    distance, _ = cKDTree(sweep[second]).query(points[first], distance_upper_bound=match)
    candidates[first[distance <= match]] = True
    distance, _ = cKDTree(points[first]).query(sweep[second], distance_upper_bound=match)
    sweep_candidates[second[distance <= match]] = True
    return candidates, sweep_candidates


def confirm_body(points, sweep, candidates, sweep_candidates, ego, *, match):
    """The candidates that move with the sensor: the ego motion does not explain them.

    A candidate is confirmed when the ego motion ``(R, t)`` moves it by more than three
    times ``match`` and puts it farther than ``match`` from every point of ``sweep``
    that is not a candidate (a wall beside the car also matches itself in the sensor's
    frame, as it slides along itself, but the ego motion keeps it on the wall). A point
    of ``sweep`` is confirmed when it is a candidate within ``match`` of a confirmed
    point of ``points``, same coordinates.

    Returns
    -------
    body : ndarray of shape (n,), bool
    sweep_body : ndarray of shape (m,), bool

    Examples
    --------
    A point fixed in the sensor's frame while the sensor drives 1 m on:

    >>> import numpy as np
    >>> from mmreg._ego_body import confirm_body
    >>> points = np.array([[1.0, 0.0, 0.0], [5.0, 5.0, 0.0]])
    >>> sweep = np.array([[1.0, 0.0, 0.0], [4.0, 5.0, 0.0]])
    >>> ego = (np.eye(3), np.array([-1.0, 0.0, 0.0]))
    >>> body, sweep_body = confirm_body(points, sweep, np.array([True, False]),
    ...                                 np.array([True, False]), ego, match=0.1)
    >>> body.tolist(), sweep_body.tolist()
    ([True, False], [True, False])
    """
    body = np.zeros(len(points), dtype=bool)
    sweep_body = np.zeros(len(sweep), dtype=bool)
    first = np.flatnonzero(candidates)
    rest = sweep[~sweep_candidates]
    if not len(first) or not sweep_candidates.any():
        return body, sweep_body
    rotation, translation = ego
    moved = points[first] @ rotation.T + translation
    carried = np.linalg.norm(moved - points[first], axis=1) > 3 * match
    if len(rest):
        distance, _ = cKDTree(rest).query(moved, distance_upper_bound=match)
        carried &= distance > match
    body[first[carried]] = True
    if body.any():
        second = np.flatnonzero(sweep_candidates)
        distance, _ = cKDTree(points[body]).query(sweep[second], distance_upper_bound=match)
        sweep_body[second[distance <= match]] = True
    return body, sweep_body
