"""Correspondences ``[a | b]``: from arrays, from two clouds, from a cloud and its flow."""

from pathlib import Path

import numpy as np

from mmreg.io import _lidar as _lidar_files
from mmreg.io._arrays import _load_npy, _load_npz, _load_text_table, _parse_text_table
from mmreg.io._atomic import atomic_write
from mmreg.io._checks import (
    _ARRAY_EXTENSIONS,
    _CLOUD_EXTENSIONS,
    _CORRESPONDENCE_EXTENSIONS,
    _CSV_HEADER,
    _POINT_EXTENSIONS,
    _TEXT_EXTENSIONS,
    _as_numeric,
    _check_correspondence_array,
    _check_points,
    _check_readable,
    _extension,
    _read_bytes,
)
from mmreg.io._cloud_formats import _parse_pcd, _parse_ply


def _read_cloud_file(path, *, colors=False, stamp=False):
    """Points (and colours or None) of a ``.ply``, ``.pcd`` or ``.xyz`` file; with
    ``stamp``, also its timestamp (a ``.pcd``'s absolute time field, else None)."""
    suffix = Path(path).suffix.lower()
    data = _read_bytes(path)
    when = None
    if suffix == ".xyz":
        points, rgb = _parse_text_table(data, path), None
    elif suffix == ".ply":
        points, rgb = _parse_ply(data, path)
    else:
        points, rgb, when = _parse_pcd(data, path, stamp=True)
    if len(points) == 0:
        raise ValueError(f"{path}: holds no points (its header declares 0).")
    if stamp:
        return points, (rgb if colors else None), when
    return points, (rgb if colors else None)


def _check_lidar_points(points, source, name):
    """Like :func:`_check_points` for (n, 3) LiDAR returns, but NaN / infinite rows are kept.

    A sensor writes its invalid returns as NaN (or zero) rows; the estimators count and
    drop them, and the rows keep their order (per-point times, flow files).
    """
    points = _as_numeric(points, source, name)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 1:
        raise ValueError(f"{source}: {name} must be an array of shape (n, 3); got {points.shape}.")
    return np.ascontiguousarray(points)


def _read_point_file(path, name, *, colors=False, stamp=False):
    """``(points, rgb or None, times or None)`` of any point file (checked readable); with
    ``stamp``, also the frame's timestamp in seconds or None (a ``.pcd``'s absolute time
    field: ``t``, ``time``, ``timestamp`` or ``offset_time``, as a PointCloud2's).

    Clouds and arrays must be finite; LiDAR sweep files and ``.pcd`` clouds keep their
    rows without a return (NaN).
    """
    suffix = _extension(path, _POINT_EXTENSIONS, name)
    kind = _lidar_files.lidar_kind(path)
    when = None
    if kind is not None:
        points, times, _ = _lidar_files.read_lidar_file(path, kind)
        found = _check_lidar_points(points, path, name), None, times
    elif suffix == ".pcd":
        # PCL writes a sensor's missing returns as NaN rows (an organised cloud keeps
        # its grid, HEIGHT > 1; a driver's is_dense false), which stay in place as a
        # LiDAR file's do; infinity is still refused.
        points, rgb, when = _read_cloud_file(path, colors=colors, stamp=True)
        points = _check_lidar_points(points, path, name)
        if np.isinf(points).any():
            _check_points(points, path, 3, name)  # raises, naming the rows
        found = points, rgb, None
    else:
        rgb = None
        if suffix in _CLOUD_EXTENSIONS:
            points, rgb = _read_cloud_file(path, colors=colors)
        elif suffix == ".npy":
            points = _load_npy(path)
        else:
            points = _load_text_table(path)
        found = _check_points(points, path, 3, name), rgb, None
    return (*found, when) if stamp else found


def _read_points(path, name):
    """An (n, 3) array from any point file (a point cloud, an array, a LiDAR sweep)."""
    return _read_point_file(_check_readable(path), name)[0]


def _array_columns(path, suffix):
    """The number of columns of a ``.npy`` / ``.csv`` / ``.txt`` array (None if not 2-D)."""
    array = _load_npy(path) if suffix == ".npy" else _load_text_table(path)
    return array.shape[1] if array.ndim == 2 else None


def read_correspondences(path, *, target=None, flow=None):
    """Read stacked correspondences ``X = [a | b]`` of shape (n, 6) from a file.

    Also available as :func:`mmreg.datasets.load_correspondences`.

    Parameters
    ----------
    path : str or path-like
        One of

        - ``.npy``: an array of shape (n, 6);
        - ``.npz``: key ``X`` (n, 6), or keys ``a`` and ``b`` (n, 3) each;
        - ``.csv`` / ``.txt``: 6 numeric columns ``ax ay az bx by bz``, with or without a
          header row, delimited by commas, spaces or tabs; ``#`` starts a comment line;
        - the a-points, which need exactly one of ``target`` and ``flow``: a point cloud
          (``.ply`` / ``.pcd`` / ``.xyz``), a LiDAR sweep (``.bin``, ``.pcd.bin``,
          ``.feather``) or an (n, 3) ``.npy`` / ``.csv`` / ``.txt`` array.
    target : str or path-like, optional
        With a-points in ``path``: a second file with the b-points, index-aligned with
        the a-points (row ``i`` corresponds to point ``i``): any point file.
    flow : str or path-like, optional
        With a-points in ``path``: an (n, 3) per-point flow (``.npy`` / ``.csv`` /
        ``.txt``, or a point file whose coordinates are the flow vectors); ``b = a + flow``.

    Returns
    -------
    X : ndarray of shape (n, 6)
        Finite floats, ``n >= 1``.

    Raises
    ------
    FileNotFoundError
        If a file is missing.
    ValueError
        If a file is unreadable or corrupt, has an unknown extension, has the wrong shape,
        no rows, NaN or infinity, if the a- and b-points differ in number, or if
        ``target``/``flow`` are missing, both given, or given for an array file.
    TypeError
        If a file holds values that are not numbers.

    See Also
    --------
    write_correspondences : The inverse, for ``.npy``, ``.npz``, ``.csv`` and ``.txt``.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.io import read_correspondences
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = Path(folder) / "pairs.csv"
    ...     _ = path.write_text("ax,ay,az,bx,by,bz\\n0,0,0,1,0,0\\n1,2,3,2,2,3\\n")
    ...     X = read_correspondences(path)
    >>> X.shape, X[1].tolist()
    ((2, 6), [1.0, 2.0, 3.0, 2.0, 2.0, 3.0])
    """
    path = _check_readable(path)
    suffix = _extension(path, _CORRESPONDENCE_EXTENSIONS, "correspondences")
    points_only = suffix in _CLOUD_EXTENSIONS or _lidar_files.lidar_kind(path) is not None
    if not points_only and suffix in _ARRAY_EXTENSIONS and (target, flow) != (None, None):
        # An (n, 3) array is a-points (with target= or flow=), an (n, 6) one both.
        columns = _array_columns(path, suffix)
        if columns not in (3, 6):
            raise ValueError(
                f"{path}: target= and flow= need the a-points as an (n, 3) array; this one "
                f"has {'no 2-D shape' if columns is None else f'{columns} columns'}."
            )
        points_only = columns == 3
    if points_only:
        if (target is None) == (flow is None):
            raise ValueError(
                f"{path}: a point cloud holds only the a-points; pass exactly one of "
                "target= (a file with the b-points) or flow= (a file with the per-point "
                f"flow, b = a + flow); got {'both' if target is not None else 'neither'}."
            )
        a = _read_point_file(path, "the a-points")[0]
        other_path = target if target is not None else flow
        other = _read_points(other_path, "the b-points" if target is not None else "the flow")
        if len(other) != len(a):
            raise ValueError(
                f"{other_path}: holds {len(other)} points but {path} holds {len(a)}; "
                "the files must be index-aligned (one row per point)."
            )
        b = other if target is not None else a + other
        return _check_correspondence_array(np.hstack([a, b]), path)
    if target is not None or flow is not None:
        raise ValueError(
            f"{path}: target= and flow= only apply when path holds only the a-points (a "
            "point cloud, a LiDAR sweep or an (n, 3) array); this file holds both a and b "
            "(6 columns)."
        )
    if suffix == ".npy":
        X = _load_npy(path)
    elif suffix == ".npz":
        arrays = _load_npz(path)
        if "X" in arrays:
            X = arrays["X"]
        elif "a" in arrays and "b" in arrays:
            a = _check_points(arrays["a"], path, 3, "key 'a'")
            b = _check_points(arrays["b"], path, 3, "key 'b'")
            if len(a) != len(b):
                raise ValueError(
                    f"{path}: key 'a' has {len(a)} rows but key 'b' has {len(b)}; they must match."
                )
            X = np.hstack([a, b])
        else:
            raise ValueError(
                f"{path}: needs key 'X' (n, 6), or keys 'a' and 'b' (n, 3); found keys "
                f"{sorted(arrays)}."
            )
    else:
        X = _load_text_table(path)
    return _check_correspondence_array(X, path)


def _text_float(value):
    """Shortest text that reads back as exactly the same float."""
    return repr(float(value))


def _write_text_table(path, array, header):
    with atomic_write(path, "w") as handle:
        if header is not None:
            handle.write(header + "\n")
        delimiter = "," if Path(path).suffix.lower() == ".csv" else " "
        for row in np.atleast_2d(array):
            handle.write(delimiter.join(_text_float(v) for v in row) + "\n")


def write_correspondences(path, X):
    """Write stacked correspondences ``X = [a | b]`` (n, 6), atomically.

    Parameters
    ----------
    path : str or path-like
        ``.npy`` (the array), ``.npz`` (key ``X``), ``.csv`` (a header row
        ``ax,ay,az,bx,by,bz``, then comma-separated rows) or ``.txt`` (space-separated
        rows, no header). Text is written with round-trip precision.
    X : array-like of shape (n, 6)
        Finite numbers, ``n >= 1``.

    Raises
    ------
    ValueError
        If ``X`` has the wrong shape, no rows or NaN/infinity, or the extension is not one
        of the above.

    See Also
    --------
    read_correspondences : The inverse.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.io import read_correspondences, write_correspondences
    >>> X = np.arange(12.0).reshape(2, 6) / 3
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_correspondences(Path(folder) / "pairs.csv", X)
    ...     same = read_correspondences(Path(folder) / "pairs.csv")
    >>> bool(np.array_equal(same, X))
    True
    """
    suffix = _extension(path, (".npy", ".npz", *_TEXT_EXTENSIONS), "correspondences")
    X = _check_correspondence_array(X)
    if suffix == ".npy":
        with atomic_write(path) as handle:
            np.save(handle, X)
    elif suffix == ".npz":
        with atomic_write(path) as handle:
            np.savez(handle, X=X)
    else:
        _write_text_table(path, X, ",".join(_CSV_HEADER) if suffix == ".csv" else None)
