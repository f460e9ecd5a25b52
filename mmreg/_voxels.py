"""One point per occupied voxel: the sample a large scene is fitted on."""

import numpy as np

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
    >>> from mmreg._voxels import voxel_representatives
    >>> points = np.array([[0.1, 0.1], [0.2, 0.3], [1.5, 0.1], [0.4, 0.2]])
    >>> voxel_representatives(points, 1.0)
    array([0, 2])
    """
    points = np.asarray(points, dtype=float)
    if not len(points):
        return np.zeros(0, dtype=np.intp)
    cells = np.floor((points - points.min(axis=0)) / size).astype(np.int64)
    extent = cells.max(axis=0) + 1
    if np.sum(np.log2(extent.astype(float))) < 62:
        # One integer per voxel (mixed radix): a sort of n integers, not of n rows.
        strides = np.cumprod(np.r_[1, extent[:-1]])
        _, first = np.unique(cells @ strides, return_index=True)
    else:  # pragma: no cover - a grid of more than 2^62 voxels
        _, first = np.unique(cells, axis=0, return_index=True)
    return np.sort(first)


def occupied_voxels(points, size):
    """How many cubic voxels of side ``size`` hold at least one of ``points``."""
    return len(voxel_representatives(points, size))


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
    >>> from mmreg._voxels import occupied_voxels, voxel_side_for
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
    The rows are those of the search's last count, not listed again.

    Returns
    -------
    side : float or None
    rows : ndarray of shape (m,) or None
        None with ``side``.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._voxels import voxel_sample
    >>> points = np.random.default_rng(0).uniform(size=(20_000, 3))
    >>> side, rows = voxel_sample(points, 1_000)
    >>> 850 <= len(rows) <= 1_000
    True
    """
    points = np.asarray(points, dtype=float)
    extent = float(np.max(np.ptp(points, axis=0))) if len(points) else 0.0
    if len(points) <= n_voxels or extent == 0:
        return None, None
    low = n_voxels * (1 - slack)
    side = extent / n_voxels ** (1 / points.shape[1])
    small, large = None, None  # (side, count) above the target; (side, rows) within it
    for _ in range(max_steps):
        rows = voxel_representatives(points, side)
        count = len(rows)
        if count > n_voxels:
            small = (side, count)
        else:
            large = (side, rows) if large is None or count > len(large[1]) else large
            if count >= low:
                return side, rows
        bracket_end = None if large is None else (large[0], len(large[1]))
        side = _next_side(small, bracket_end, (side, count), np.sqrt(low * n_voxels))
    return (None, None) if large is None else large


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
