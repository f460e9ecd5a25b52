"""Point clouds with colours and labels: ``read_point_cloud`` and ``write_point_cloud``."""

import numpy as np

from mmreg.io import _lidar as _lidar_files
from mmreg.io._atomic import atomic_write
from mmreg.io._checks import _CLOUD_EXTENSIONS, _check_points, _check_readable, _extension
from mmreg.io._cloud_formats import _pcd_bytes, _ply_bytes
from mmreg.io._correspondences import _read_point_file, _write_text_table


def read_point_cloud(path, *, colors=False, times=False):
    """Read the points (and colours, capture times) of a point cloud or LiDAR sweep.

    Parameters
    ----------
    path : str or path-like
        ``.ply`` or ``.pcd``, ``.xyz`` (``x y z`` per line), an (n, 3) ``.npy`` /
        ``.csv`` / ``.txt`` array, or a LiDAR sweep: KITTI velodyne ``.bin`` (float32
        ``x y z reflectance``, 16 bytes a point), nuScenes ``.pcd.bin`` (float32 ``x y z
        intensity ring``, 20 bytes) or Argoverse 2 ``.feather`` (columns ``x y z``, and
        ``offset_ns``).
    colors : bool, default=False
        Also return the colours.
    times : bool, default=False
        Also return the per-point capture times, in seconds after the sweep's timestamp:
        an Argoverse 2 ``.feather``'s ``offset_ns * 1e-9``; ``None`` for every other
        file.

    Returns
    -------
    points : ndarray of shape (n, 3)
        A LiDAR sweep's invalid returns (NaN or all-zero rows) are kept in place, and so
        are a ``.pcd``'s NaN rows (an organised cloud's missing returns); every other
        format must be finite.
    colors : ndarray of shape (n, 3) or None
        Only when ``colors=True``: RGB in ``[0, 1]``, or ``None`` when the file holds no
        colours (always for ``.xyz``, array and LiDAR files).
    times : ndarray of shape (n,) or None
        Only when ``times=True``, after ``colors``.

    Raises
    ------
    FileNotFoundError
        If the file is missing.
    ValueError
        If it is unreadable, corrupt, empty, not a whole number of points (``.bin``,
        ``.pcd.bin``), lacks a column (``.feather``), holds NaN or infinity (except NaN
        in a LiDAR sweep or a ``.pcd``), is a ROS bag (many frames: see
        :func:`mmreg.datasets.open_sequence`), or the extension is unknown.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.io import read_point_cloud, write_point_cloud
    >>> points = np.array([[0.0, 0.0, 1.0], [0.5, -1.0, 2.0]])
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_point_cloud(Path(folder) / "cloud.ply", points, colors=[[1, 0, 0], [0, 0, 1]])
    ...     same, rgb = read_point_cloud(Path(folder) / "cloud.ply", colors=True)
    >>> bool(np.array_equal(same, points)), rgb.tolist()
    (True, [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    """
    path = _check_readable(path)
    if _lidar_files.lidar_kind(path) == "bag":
        _lidar_files.read_lidar_file(path, "bag")  # raises: a bag holds many frames
    points, rgb, capture = _read_point_file(path, "the points", colors=colors)
    if capture is not None and len(capture) != len(points):  # pragma: no cover - one table
        raise ValueError(f"{path}: holds {len(points)} points but {len(capture)} times.")
    if rgb is not None:
        rgb = _check_points(rgb, path, 3, "the colours")
        if len(rgb) != len(points):
            raise ValueError(f"{path}: holds {len(points)} points but {len(rgb)} colours.")
    out = (points,) + ((rgb,) if colors else ()) + ((capture,) if times else ())
    return out[0] if len(out) == 1 else out


def write_point_cloud(path, points, colors=None, labels=None):
    """Write a point cloud, atomically, with colours and a per-point label if given.

    Parameters
    ----------
    path : str or path-like
        ``.ply`` (binary, float64 coordinates, 8-bit colours) or ``.pcd`` (binary, float32
        coordinates) through Open3D, or ``.xyz`` (text ``x y z`` per line at round-trip
        precision, no colours).
    points : array-like of shape (n, 3)
        Finite coordinates, ``n >= 1``.
    colors : array-like of shape (n, 3), optional
        RGB in ``[0, 1]`` (stored as 8-bit by both formats).
    labels : array-like of shape (n,), optional
        An integer per point (a cluster, ``-1`` for outliers), stored as a signed 32-bit
        vertex property ``label`` (``.ply``: ``property int label``; ``.pcd``: field
        ``label``, type ``I``, as PCL's ``PointXYZRGBL``). CloudCompare shows it as a
        scalar field to filter by, Open3D's tensor API reads it as ``pcd.point["label"]``
        (``open3d.t.io.read_point_cloud``), plyfile as ``vertex["label"]``.
        :func:`read_point_cloud` ignores it (it returns points and colours only).

    Raises
    ------
    ValueError
        If the shapes are wrong, a value is NaN or infinity, a colour lies outside
        ``[0, 1]``, a label is not an integer of 32 bits, colours or labels are given for
        ``.xyz``, or the extension is unknown.

    Notes
    -----
    The file is written to a temporary file in the same folder first, which is then
    renamed onto ``path``.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.io import read_point_cloud, write_point_cloud
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_point_cloud(Path(folder) / "cloud.xyz", np.eye(3))
    ...     print(read_point_cloud(Path(folder) / "cloud.xyz").tolist())
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    """
    suffix = _extension(path, _CLOUD_EXTENSIONS, "a point cloud")
    points = _check_points(points, "points", 3, "the points")
    if colors is not None:
        if suffix == ".xyz":
            raise ValueError(f"{path}: .xyz files hold no colours; write .ply or .pcd instead.")
        colors = _check_points(colors, "colors", 3, "the colours")
        if len(colors) != len(points):
            raise ValueError(
                f"colors has {len(colors)} rows but points has {len(points)}; one colour per "
                "point is needed."
            )
        if colors.min() < 0 or colors.max() > 1:
            raise ValueError("colors must lie in [0, 1] (RGB fractions).")
    if labels is not None:
        if suffix == ".xyz":
            raise ValueError(f"{path}: .xyz files hold no labels; write .ply or .pcd instead.")
        labels = _check_point_labels(labels, len(points))
    if suffix == ".xyz":
        _write_text_table(path, points, None)
        return
    rgb = None if colors is None else np.round(colors * 255).astype(np.uint8)
    write = _ply_bytes if suffix == ".ply" else _pcd_bytes
    data = write(points, rgb, labels)
    with atomic_write(path) as handle:
        handle.write(data)


def _check_point_labels(labels, n):
    """One integer per point that fits a signed 32-bit property, as int32."""
    array = np.asarray(labels)
    if array.shape != (n,):
        raise ValueError(f"labels must have shape ({n},), one per point; got {array.shape}.")
    if array.dtype.kind == "f":
        if not np.all(np.isfinite(array)) or np.any(array != np.round(array)):
            raise ValueError("labels must be integers.")
    elif array.dtype.kind not in "iub":
        raise ValueError(f"labels must be integers; got dtype {array.dtype}.")
    info = np.iinfo(np.int32)
    if n and (array.min() < info.min or array.max() > info.max):
        raise ValueError("labels must fit in 32 bits (a PLY 'int' property).")
    return array.astype(np.int32)
