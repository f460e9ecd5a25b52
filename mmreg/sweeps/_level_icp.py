"""A road user's motion by ICP that keeps it level: a turn about the vertical and a shift
across it.

Cars, cyclists and walkers move on the road: relative to the static world they turn about
the vertical and shift, they do not roll or pitch by more than the road does. A free
six-parameter ICP on a few dozen points of a far car's partial view finds turns of tens
of degrees about any axis that fit its points as well (the pair path's motions of a
43-point car at 2 Hz: 2.5 m vertical shifts). Fitting three parameters, the turn about
the vertical (``up``) and the shift across it, with the height of the static world, keeps the
motion of a road user what it can be.

The motion is written relative to the static world: the points ``a`` of the first sweep
move by ``W`` (level, in the first sweep's frame), then by the ego motion ``E`` into the
second sweep's frame, where the robust point-to-plane cost is read.
"""

from typing import NamedTuple

import numpy as np

__all__ = ["LevelFit", "level_icp", "level_icps", "level_part"]

_MAD_TO_SIGMA = 1.4826
_KERNEL = 2.0  # Tukey's biweight is zero beyond this many robust scales
_MIN_MATCHES = 8  # three unknowns, and a margin
_ANNEAL = 0.7  # the kernel's scale shrinks by this factor per step, to the robust one


def _cross_up(up, vectors):
    """``np.cross(up, vectors)`` for one vector ``up`` and rows ``vectors``, computed as
    numpy computes it (the same floats) without its broadcasting's cost."""
    x, y, z = vectors[:, 0], vectors[:, 1], vectors[:, 2]
    return np.stack([up[1] * z - up[2] * y, up[2] * x - up[0] * z, up[0] * y - up[1] * x], axis=1)


def _median(values):
    """``np.median`` of a 1-D array of numbers, the same float, without its overhead
    (a tenth of a step's time on the few dozen points of a claim's ICP)."""
    half = len(values) // 2
    if len(values) % 2:
        return float(np.partition(values, half)[half])
    low, high = np.partition(values, (half - 1, half))[half - 1 : half + 1]
    return float((low + high) / 2)


def _cross_matrix(up):
    """The matrix of ``x -> up x x``."""
    return np.array([[0.0, -up[2], up[1]], [up[2], 0.0, -up[0]], [-up[1], up[0], 0.0]])


def _turn(angle, up):
    """Rotation by ``angle`` about the unit vector ``up`` (Rodrigues)."""
    cross = _cross_matrix(up)
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * (cross @ cross)


class LevelFit(NamedTuple):
    """What :func:`level_icp` returns."""

    motion: np.ndarray  # 4 x 4, ``ego @ W``: first sweep's frame to the second's
    scale: float  # the robust residual scale of the last step (NaN: too few matches)


def _across(up):
    """Two unit vectors orthogonal to ``up`` and to each other, as rows."""
    side = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    return np.stack([np.cross(side, up), side])


def level_part(motion, ego, centre, up=(0.0, 0.0, 1.0)):
    """The level motion (a turn about ``up`` through ``centre`` and a shift across ``up``)
    closest to ``inv(ego) @ motion``: its centre's displacement across ``up``, and its
    turn about ``up``.

    Returns a 4 x 4 matrix in the first sweep's frame.
    """
    up = np.asarray(up, dtype=float)
    relative = np.linalg.inv(ego) @ motion
    rotation = relative[:3, :3]
    # The turn about ``up``: the angle by which the rotation carries a level direction.
    side = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    turned = rotation @ side
    turned -= up * (turned @ up)
    angle = np.arctan2(np.cross(side, turned) @ up, side @ turned) if turned.any() else 0.0
    shift = rotation @ centre + relative[:3, 3] - centre
    shift -= up * (shift @ up)  # the height follows the static world's
    level = np.eye(4)
    level[:3, :3] = _turn(angle, up)
    level[:3, 3] = centre + shift - level[:3, :3] @ centre
    return level


def level_icp(
    a,
    start,
    ego,
    target,
    *,
    max_distance,
    max_iter=20,
    up=(0.0, 0.0, 1.0),
    turn=True,
    min_scale=1e-12,
):
    """Refine a level motion of the points ``a`` on the second sweep.

    Parameters
    ----------
    a : ndarray of shape (n, 3)
        Points of one object in the first sweep's frame.
    start : ndarray of shape (4, 4)
        A level motion ``W`` in the first sweep's frame to start from (see
        :func:`level_part`).
    ego : ndarray of shape (4, 4)
        The ego motion, first sweep to second.
    target : tuple
        ``(sweep, tree, normals)`` of the second sweep.
    max_distance : float
        Points farther than this from the second sweep are not matched.
    up : array-like of shape (3,)
        The vertical in the first sweep's frame.
    turn : bool, default=True
        Whether the motion may turn about ``up``; False: a shift alone (the simplest
        motion of a road user, driving on).
    min_scale : float, default=1e-12
        Floor of the robust residual scale, in units of ``max_distance``.

    Returns
    -------
    fit : LevelFit
        ``motion`` (4, 4), ``ego @ W``: the object's motion from the first sweep's frame
        to the second's; ``scale``, the robust residual scale of the last step (NaN when
        too few points matched at the start).

    Examples
    --------
    A box turned by 5 degrees about the vertical and shifted by (0.4, 0.1, 0), seen
    again; the ego motion is the identity.

    >>> import numpy as np
    >>> from scipy.spatial import cKDTree
    >>> from mmreg.sweeps._icp import SurfaceNormals
    >>> from mmreg.sweeps._level_icp import level_icp
    >>> rng = np.random.default_rng(0)
    >>> def box(n):
    ...     p = rng.uniform(-1, 1, (n, 3)) * [2.0, 1.0, 0.7]
    ...     side = rng.integers(0, 3, n)
    ...     p[np.arange(n), side] = np.sign(rng.uniform(-1, 1, n)) * np.array([2.0, 1.0, 0.7])[side]
    ...     return p
    >>> c, s = np.cos(np.radians(5)), np.sin(np.radians(5))
    >>> turn = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    >>> sweep = box(20000) @ turn.T + [0.4, 0.1, 0.0]
    >>> tree = cKDTree(sweep)
    >>> target = (sweep, tree, SurfaceNormals(sweep, tree, 10))
    >>> motion = level_icp(box(2000), np.eye(4), np.eye(4), target, max_distance=1.0).motion
    >>> yaw = np.degrees(np.arctan2(motion[1, 0], motion[0, 0]))
    >>> np.round(motion[:3, 3], 2) + 0.0, round(float(yaw), 1)
    (array([0.4, 0.1, 0. ]), 5.0)
    """
    return level_icps(
        [a], [start], ego, target, max_distance=max_distance, max_iter=max_iter, up=up,
        turn=turn, min_scale=min_scale,
    )[0]  # fmt: skip


def level_icps(
    parts,
    starts,
    ego,
    target,
    *,
    max_distance,
    max_iter=20,
    up=(0.0, 0.0, 1.0),
    turn=True,
    min_scale=1e-12,
):
    """:func:`level_icp` of several point sets at once, each from its own start.

    A claim refines its best starts on different points; one ICP of them all queries the
    tree once a step, where a step of a few hundred points costs mostly numpy's
    overhead. Each set stops on its own, as it would alone.

    Parameters
    ----------
    parts : list of ndarray of shape (n_k, 3)
    starts : list of ndarray of shape (4, 4)
    ego, target, max_distance, max_iter, up, turn, min_scale
        As :func:`level_icp`.

    Returns
    -------
    fits : list of LevelFit
        One per part.

    Examples
    --------
    Two boxes, one shifted by 0.4 m along x and one by 0.3 m along y, refined at once:

    >>> import numpy as np
    >>> from scipy.spatial import cKDTree
    >>> from mmreg.sweeps._icp import SurfaceNormals
    >>> from mmreg.sweeps._level_icp import level_icps
    >>> rng = np.random.default_rng(0)
    >>> def box(n, centre):
    ...     p = rng.uniform(-1, 1, (n, 3)) * [2.0, 1.0, 0.7]
    ...     side = rng.integers(0, 3, n)
    ...     p[np.arange(n), side] = np.sign(rng.uniform(-1, 1, n)) * np.array([2.0, 1.0, 0.7])[side]
    ...     return p + centre
    >>> sweep = np.vstack([box(20000, [0.4, 0.0, 0.0]), box(20000, [10.0, 0.3, 0.0])])
    >>> tree = cKDTree(sweep)
    >>> target = (sweep, tree, SurfaceNormals(sweep, tree, 10))
    >>> fits = level_icps([box(2000, [0.0, 0, 0]), box(2000, [10.0, 0, 0])], [np.eye(4)] * 2,
    ...                   np.eye(4), target, max_distance=1.0)
    >>> [np.round(fit.motion[:2, 3], 2) + 0.0 for fit in fits]
    [array([0.4, 0. ]), array([0. , 0.3])]
    """
    sweep, tree, normals = target
    up = np.asarray(up, dtype=float)
    across = _across(up)
    n_parts = len(parts)
    sizes = np.array([len(part) for part in parts], dtype=np.intp)
    every_point = np.concatenate(parts).reshape(-1, 3) if n_parts else np.zeros((0, 3))
    every_group = np.repeat(np.arange(n_parts), sizes)
    levels = np.array(starts, dtype=float).reshape(n_parts, 4, 4)
    rotation_e, translation_e = ego[:3, :3], ego[:3, 3]
    robust = np.full(n_parts, np.nan)
    # The kernel starts as wide as the reach and narrows to the robust scale (as
    # mmreg.sweeps._icp anneals it): a narrow kernel at the start would drop the very
    # points that show how far the object moved.
    scale = np.full(n_parts, max_distance / _KERNEL)
    alive = sizes > 0
    cross = _cross_matrix(up)
    twice = cross @ cross
    for _ in range(max_iter):
        if not alive.any():
            break
        keep = alive[every_group]
        a, group = every_point[keep], every_group[keep]
        # In the first sweep's frame, then landed in the second's.
        moved = np.einsum("nij,nj->ni", levels[group, :3, :3], a) + levels[group, :3, 3]
        landed = moved @ rotation_e.T + translation_e
        distance, nearest = tree.query(landed, distance_upper_bound=max_distance)
        matched = np.flatnonzero(np.isfinite(distance))
        alive &= np.bincount(group[matched], minlength=n_parts) >= _MIN_MATCHES
        normal, _, flatness = normals(nearest[matched])
        usable = np.isfinite(flatness) & (flatness >= 0.2) & alive[group[matched]]
        alive &= np.bincount(group[matched[usable]], minlength=n_parts) >= _MIN_MATCHES
        usable &= alive[group[matched]]
        if not usable.any():
            break
        rows, n = matched[usable], normal[usable]
        # The rows are sorted by part: each part's sums and medians run over one segment.
        g = group[rows]
        first = np.flatnonzero(np.concatenate([[True], g[1:] != g[:-1]]))
        present = g[first]
        ends = np.append(first[1:], len(g))
        residual = np.einsum("ni,ni->n", n, landed[rows] - sweep[nearest[rows]])
        absolute = np.abs(residual)
        middle = np.array([_median(absolute[b:e]) for b, e in zip(first, ends, strict=True)])
        robust[present] = np.fmax(_MAD_TO_SIGMA * middle, min_scale * max_distance)
        scale[present] = np.fmax(robust[present], _ANNEAL * scale[present])
        u = residual / (_KERNEL * np.repeat(scale[present], ends - first))
        weight = np.where(np.abs(u) < 1, (1 - u**2) ** 2, 0.0)
        # Unknowns: a small turn about ``up`` through the points' centre, and a shift
        # across ``up``, both in the first sweep's frame; their effect read in the
        # second's. The height follows the static world's: a road user climbs with the
        # road, and a free height would take up the ego motion's own error in it.
        p = moved[rows]
        centre = np.add.reduceat(p, first, axis=0) / (ends - first)[:, None]
        n_first = n @ rotation_e  # the normals in the first sweep's frame
        arm = _cross_up(up, p - np.repeat(centre, ends - first, axis=0))
        shifts = n_first @ across.T
        # The turn is solved as the distance it moves a point ``max_distance`` from the
        # centre, so that its curvature and the shifts' compare alike in any units (in
        # the unknown angle, a turn's curvature grows with the square of the unit; the
        # points' own spread weighed them otherwise and lost movers in thinned sweeps).
        if turn:
            turning = np.einsum("ni,ni->n", n_first, arm) / max_distance
            jacobian = np.column_stack([turning, shifts])
        else:
            jacobian = shifts
        size = jacobian.shape[1]
        weighted = jacobian * weight[:, None]
        products = (weighted[:, :, None] * jacobian[:, None, :]).reshape(len(g), -1)
        sums = np.add.reduceat(
            np.column_stack([products, weighted * residual[:, None], weight]), first, axis=0
        )
        # A part that no point weighs any more stops where it is.
        moving = sums[:, -1] > 0
        alive[present[~moving]] = False
        if not moving.any():
            break
        present, centre, sums = present[moving], centre[moving], sums[moving]
        hessian = sums[:, : size * size].reshape(-1, size, size)
        gradient = sums[:, size * size : size * size + size]
        # Directions the surfaces do not constrain (a wall's along itself) stay put.
        values, vectors = np.linalg.eigh(hessian)
        largest = np.fmax(values.max(axis=1), np.finfo(float).tiny)
        constrained = values > 1e-3 * largest[:, None]
        projected = np.einsum("kji,kj->ki", vectors, gradient)
        projected = np.where(constrained, projected / np.where(constrained, values, 1.0), 0.0)
        step = -np.einsum("kij,kj->ki", vectors, projected)
        if turn:
            angle, shift = step[:, 0] / max_distance, step[:, 1:]
        else:
            angle, shift = np.zeros(len(present)), step
        rotation = (
            np.eye(3)
            + np.sin(angle)[:, None, None] * cross
            + (1 - np.cos(angle))[:, None, None] * twice
        )
        update = np.zeros((len(present), 4, 4))
        update[:, :3, :3] = rotation
        update[:, :3, 3] = centre + shift @ across - np.einsum("kij,kj->ki", rotation, centre)
        update[:, 3, 3] = 1.0
        levels[present] = update @ levels[present]
        # How far the step moved the points: the shift, and the turn at the farthest arm.
        reach = np.sqrt(np.maximum.reduceat(np.einsum("ni,ni->n", arm, arm), first)[moving])
        moved_by = np.linalg.norm(shift, axis=1) + np.abs(angle) * reach
        alive[present[moved_by < 1e-4 * max_distance]] = False
    return [
        LevelFit(ego @ level, float(value)) for level, value in zip(levels, robust, strict=True)
    ]
