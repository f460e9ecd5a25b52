"""One point per occupied voxel: the sample a large scene is fitted on."""

import numpy as np

from mmreg._array.geometry import column_bounds
from mmreg._array.grouping import unique_sorted

__all__ = ["occupied_voxels", "voxel_representatives", "voxel_sample", "voxel_side_for"]


def voxel_representatives(points, size):
    """Rows of the first point in every occupied cubic voxel of side ``size``.

    The voxel grid of Open3D's ``voxel_down_sample``, keeping an input point (the first,
    in row order) instead of the voxel's mean: a LiDAR sweep is thinned where it is
    dense (near the sensor) and kept where it is sparse (far objects).

    Parameters
    ----------
    points : ndarray of shape (n, d)
    size : float
        Side of the voxels, in the units of the points.

    Returns
    -------
    rows : ndarray of shape (m,)
        Increasing row indices, one per occupied voxel.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.voxels import voxel_representatives
    >>> points = np.array([[0.1, 0.1], [0.2, 0.3], [1.5, 0.1], [0.4, 0.2]])
    >>> voxel_representatives(points, 1.0)
    array([0, 2])
    """
    points = np.asarray(points, dtype=float)
    if not len(points):
        return np.zeros(0, dtype=np.intp)
    shifted = points - column_bounds(points)[0]
    codes = _voxel_codes(shifted, size)
    if codes is None:  # pragma: no cover - a grid of more than 2^62 voxels
        cells = np.floor(shifted / size).astype(np.int64)
        _, first = np.unique(cells, axis=0, return_index=True)
        return np.sort(first)
    # A stable sort keeps each voxel's rows in row order: its run starts at its first.
    order = np.argsort(codes, kind="stable")
    return np.sort(order[unique_sorted(codes[order])[1]])


def _voxel_codes(shifted, size):
    """One integer per voxel of side ``size`` (mixed radix) for points whose columns
    start at 0, or None if the grid has more than 2^62 voxels."""
    cells = np.floor(shifted / size).astype(np.int64)
    extent = np.floor(column_bounds(shifted)[1] / size).astype(np.int64) + 1
    if np.sum(np.log2(extent.astype(float))) >= 62:
        return None
    return cells @ np.cumprod(np.r_[1, extent[:-1]])


def _count_voxels(shifted, size):
    """How many voxels of side ``size`` the points (columns starting at 0) occupy."""
    codes = _voxel_codes(shifted, size)
    if codes is None:  # pragma: no cover - a grid of more than 2^62 voxels
        return len(np.unique(np.floor(shifted / size), axis=0))
    return len(unique_sorted(codes)[0])


def occupied_voxels(points, size):
    """How many cubic voxels of side ``size`` hold at least one of ``points``."""
    points = np.asarray(points, dtype=float)
    if not len(points):
        return 0
    return _count_voxels(points - column_bounds(points)[0], size)


def voxel_side_for(points, n_voxels, *, slack=0.15, max_steps=12):
    """A voxel side whose grid holds between ``(1 - slack) n_voxels`` and ``n_voxels``
    occupied voxels, None if the points occupy fewer voxels than that at any side
    (:func:`voxel_sample`, without the rows).

    Parameters
    ----------
    points : ndarray of shape (n, d)
    n_voxels : int
        The most occupied voxels wanted.
    slack : float, default=0.15
    max_steps : int, default=12
        Counts tried; then the largest count below ``n_voxels`` found wins.

    Returns
    -------
    side : float or None

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.voxels import occupied_voxels, voxel_side_for
    >>> points = np.random.default_rng(0).uniform(size=(20_000, 3))
    >>> side = voxel_side_for(points, 1_000)
    >>> 850 <= occupied_voxels(points, side) <= 1_000
    True
    """
    return voxel_sample(points, n_voxels, slack=slack, max_steps=max_steps)[0]


def voxel_sample(points, n_voxels, *, slack=0.15, max_steps=12):
    """The side of :func:`voxel_side_for` and its :func:`voxel_representatives`.

    The count falls with the side as a power law (about ``side^-2`` on surfaces), so the
    search steps along the secant of ``log count`` against ``log side``, bisecting when
    a step would leave the bracket found so far. It is a function of the points alone.
    The search counts voxels; the rows are listed once, for the side it chose.

    Returns
    -------
    side : float or None
    rows : ndarray of shape (m,) or None
        None with ``side``.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.voxels import voxel_sample
    >>> points = np.random.default_rng(0).uniform(size=(20_000, 3))
    >>> side, rows = voxel_sample(points, 1_000)
    >>> 850 <= len(rows) <= 1_000
    True
    """
    points = np.asarray(points, dtype=float)
    if len(points) <= n_voxels:
        return None, None
    low, high = column_bounds(points)
    extent = float(np.max(high - low))
    if extent == 0:
        return None, None
    shifted = points - low
    fewest = n_voxels * (1 - slack)
    side = extent / n_voxels ** (1 / points.shape[1])
    small, large = None, None  # (side, count): above the target; the most within it
    for _ in range(max_steps):
        count = _count_voxels(shifted, side)
        if count > n_voxels:
            small = (side, count)
        else:
            large = (side, count) if large is None or count > large[1] else large
            if count >= fewest:
                break
        side = _next_side(small, large, (side, count), np.sqrt(fewest * n_voxels))
    if large is None:
        return None, None
    return large[0], voxel_representatives(points, large[0])


def _next_side(small, large, last, target):
    """The side that the secant of the bracket's ends (or a slope of -2 from the last
    count) gives ``target`` voxels, kept strictly inside the bracket."""
    if small is not None and large is not None:
        (s0, c0), (s1, c1) = small, large
        slope = np.log(c1 / c0) / np.log(s1 / s0) if c1 != c0 else -2.0
        side = s0 * np.exp(np.log(target / c0) / min(slope, -0.5))
        if not s0 < side < s1:
            side = np.sqrt(s0 * s1)
        return side
    side, count = last
    return side * (max(count, 1) / target) ** 0.5
