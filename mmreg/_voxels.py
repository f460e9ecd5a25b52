"""One point per occupied voxel: the sample a large scene is fitted on."""

import numpy as np

__all__ = ["voxel_representatives"]


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
