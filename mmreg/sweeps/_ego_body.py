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
   carries a clear share of each island of them off the second sweep, so the identity,
   not the ego motion, explains them. When the sensor stands
   still nothing is confirmed (the body then looks like the static world, and is).

Every length is the caller's, in the points' units (``SweepRegistration`` gives them in
units of its ``tau``).
"""

import numpy as np

from mmreg._array.neighbors import lookup_tree
from mmreg.sweeps._ego_motion import _FINE_REACH, ego_motion
from mmreg.sweeps._islands import voxel_islands

__all__ = ["carried_body", "confirm_body", "find_ego_body", "fixed_candidates", "would_show_body"]

# An island of candidates is the body when this share of its points is carried off by
# the ego motion (a third of a car's returns face along the motion: its ends and edges).
_CARRIED_SHARE = 0.25
# ... and when this share of its points are candidates at all.
_FIXED_SHARE = 0.5
# In units of tau: candidates lie within _REACH of the sensor (3 m at tau 5; nuScenes'
# body returns lie within 2.5 m) and match the other sweep within _MATCH (5 cm) at the
# same coordinates; fewer than _MIN_POINTS confirmed points are no body.
_REACH = 0.6
_MATCH = 0.01
_MIN_POINTS = 10
# Fewest points left of each sweep for an ego motion without the candidates.
_MIN_REST = 10


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
    >>> from mmreg.sweeps._ego_body import fixed_candidates
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
    distance, _ = lookup_tree(sweep[second]).query(points[first], distance_upper_bound=match)
    candidates[first[distance <= match]] = True
    distance, _ = lookup_tree(points[first]).query(sweep[second], distance_upper_bound=match)
    sweep_candidates[second[distance <= match]] = True
    return candidates, sweep_candidates


def confirm_body(points, sweep, candidates, sweep_candidates, ego, *, match, cell, near):
    """The candidates that move with the sensor: the ego motion does not explain them.

    A candidate is carried off when the ego motion ``(R, t)`` moves it by more than three
    times ``match`` and puts it farther than ``match`` from every point of ``sweep``. A
    surface that slides along itself (a roof, a wall beside the car) is explained by
    both motions, so the points ``near`` the sensor are cut into islands (touching
    voxels of side ``cell``) and an island is the body when at least half of its points
    are candidates (the body's returns come back to the same place; a static surface
    sampled anew matches by chance only here and there) and at least a quarter of
    those are carried off (its faces across the motion are). A point of ``sweep`` is the body
    when it is a candidate within ``match`` of the body's points, same coordinates.

    Returns
    -------
    body : ndarray of shape (n,), bool
    sweep_body : ndarray of shape (m,), bool

    Examples
    --------
    A short wall across the motion, fixed in the sensor's frame while the sensor drives
    1 m on, and a long wall along the motion, static:

    >>> import numpy as np
    >>> from mmreg.sweeps._ego_body import confirm_body
    >>> across = np.c_[np.full(20, 1.0), np.linspace(-0.5, 0.5, 20), np.zeros(20)]
    >>> along = np.c_[np.linspace(-2, 2, 80), np.full(80, 2.0), np.zeros(80)]
    >>> points = np.vstack([across, along])
    >>> sweep = np.vstack([across, along + [0.025, 0, 0]])
    >>> candidates = np.ones(100, dtype=bool)
    >>> ego = (np.eye(3), np.array([-1.0, 0.0, 0.0]))
    >>> body, sweep_body = confirm_body(points, sweep, candidates, candidates, ego,
    ...                                 match=0.1, cell=0.2, near=candidates)
    >>> int(body[:20].sum()), int(body[20:].sum()), int(sweep_body.sum())
    (20, 0, 20)
    """
    body = np.zeros(len(points), dtype=bool)
    sweep_body = np.zeros(len(sweep), dtype=bool)
    first = np.flatnonzero(candidates)
    if not len(first) or not sweep_candidates.any():
        return body, sweep_body
    rotation, translation = ego
    moved = points[first] @ rotation.T + translation
    carried = np.linalg.norm(moved - points[first], axis=1) > 3 * match
    distance, _ = lookup_tree(sweep).query(moved, distance_upper_bound=match)
    carried &= distance > match
    around = np.flatnonzero(near | candidates)
    islands, n_islands = voxel_islands(points[around], cell, 1)
    fixed = candidates[around]
    moved_off = np.zeros(len(points), dtype=bool)
    moved_off[first] = carried
    sizes = np.maximum(np.bincount(islands, minlength=n_islands), 1)
    n_fixed = np.bincount(islands, weights=fixed, minlength=n_islands)
    n_carried = np.bincount(islands, weights=moved_off[around], minlength=n_islands)
    chosen = (n_fixed >= _FIXED_SHARE * sizes) & (n_carried >= _CARRIED_SHARE * n_fixed)
    body[around] = chosen[islands] & fixed
    if body.any():
        second = np.flatnonzero(sweep_candidates)
        distance, _ = lookup_tree(points[body]).query(sweep[second], distance_upper_bound=match)
        sweep_body[second[distance <= match]] = True
    return body, sweep_body


def carried_body(body, points, tau):
    """The points of a sweep where the last sweep's ``body`` points were: the body is
    fixed in the sensor's frame, so a log carries it from sweep to sweep without a search.

    Points within the candidates' reach of the sensor (``0.6 tau``) and nearer than the
    matching distance (``tau / 100``) to a body point, in the same sensor coordinates.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.sweeps._ego_body import carried_body
    >>> body = np.array([[1.0, 0.0, 0.0]])
    >>> carried_body(body, np.array([[1.01, 0.0, 0.0], [1.2, 0.0, 0.0]]), tau=5.0).tolist()
    [True, False]
    """
    near = np.linalg.norm(points, axis=1) <= _REACH * tau
    carried = np.zeros(len(points), dtype=bool)
    if near.any():
        distance, _ = lookup_tree(body).query(points[near], distance_upper_bound=_MATCH * tau)
        carried[near] = np.isfinite(distance)
    return carried


def would_show_body(ego, tau):
    """Whether a pair with ego motion ``ego`` would confirm the body, were there one.

    It would where the motion carries every place within the candidates' reach of the
    sensor (``0.6 tau``) farther than :func:`confirm_body` asks of a body's point (three
    matching distances): at least ``|t| - 2 sin(angle / 2) reach``. A pair that stands
    still, or barely moves, cannot tell a body from the static world.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.sweeps._ego_body import would_show_body
    >>> would_show_body((np.eye(3), np.array([1.0, 0.0, 0.0])), tau=5.0)
    True
    >>> would_show_body((np.eye(3), np.array([0.05, 0.0, 0.0])), tau=5.0)
    False
    """
    rotation, translation = ego
    cosine = np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0)
    swing = 2.0 * np.sin(np.arccos(cosine) / 2.0) * _REACH * tau
    return bool(np.linalg.norm(translation) - swing > 3 * _MATCH * tau)


def find_ego_body(first, second, settings, ground=None, *, known=None):
    """A pair's returns of the ego vehicle's body, or None if it shows none.

    Candidates (:func:`fixed_candidates`): points within ``0.6 tau`` of the sensor, off
    the ``ground`` (the two sweeps' masks, or None), that the other sweep holds within
    ``tau / 100`` at the same sensor coordinates. The ego motion is found without them
    (from ``known`` if given) and confirms those it carries off the second sweep
    (:func:`confirm_body`). ``first`` and ``second`` are the sweeps'
    :class:`~mmreg.sweeps._sweep_state.SweepState`; ``settings`` a
    :class:`~mmreg.sweeps._settings.PairSettings`. Returns ``(body, sweep_body, ego)``,
    the ego motion to start the registration of the rest from.
    """
    tau = settings.tau
    match = _MATCH * tau
    a, sweep = first.points, second.points
    exclude = (None, None) if ground is None else ground
    candidates, sweep_candidates = fixed_candidates(
        a,
        sweep,
        reach=_REACH * tau,
        match=match,
        exclude=exclude[0],
        sweep_exclude=exclude[1],
    )
    if candidates.sum() < _MIN_POINTS or sweep_candidates.sum() < _MIN_POINTS:
        return None
    rest, sweep_rest = a[~candidates], sweep[~sweep_candidates]
    if len(rest) < _MIN_REST or len(sweep_rest) < _MIN_REST:
        return None
    reach = _FINE_REACH * tau if known is not None else max(tau, settings.max_displacement)
    rotation, translation, _ = ego_motion(
        rest, sweep_rest, scale=tau, max_displacement=reach, init=known
    )
    ego = (rotation, translation)
    body, sweep_body = confirm_body(
        a,
        sweep,
        candidates,
        sweep_candidates,
        ego,
        match=match,
        cell=settings.island_radius,
        near=(np.linalg.norm(a, axis=1) < _REACH * tau) & (True if ground is None else ~ground[0]),
    )
    if body.sum() < _MIN_POINTS:
        return None
    return body, sweep_body, ego
