"""The file extensions mmreg reads and the checks every reader shares."""

import os
from pathlib import Path

import numpy as np

_CLOUD_EXTENSIONS = (".ply", ".pcd", ".xyz")
_TEXT_EXTENSIONS = (".csv", ".txt")
_CORRESPONDENCE_EXTENSIONS = (
    ".npy",
    ".npz",
    *_TEXT_EXTENSIONS,
    *_CLOUD_EXTENSIONS,
    ".bin",
    ".pcd.bin",
    ".feather",
)
# LiDAR sweep files (".pcd.bin" is told from KITTI's ".bin" by its whole name).
_LIDAR_EXTENSIONS = (".bin", ".pcd.bin", ".feather")
_POINT_EXTENSIONS = (".npy", *_TEXT_EXTENSIONS, *_CLOUD_EXTENSIONS, *_LIDAR_EXTENSIONS)
_ARRAY_EXTENSIONS = (".npy", *_TEXT_EXTENSIONS)
_CSV_HEADER = ("ax", "ay", "az", "bx", "by", "bz")


def _extension(path, allowed, what):
    suffix = Path(path).suffix.lower()
    if suffix not in allowed:
        raise ValueError(
            f"{path}: unknown extension {suffix or '(none)'!r} for {what}; "
            f"expected one of {', '.join(allowed)}."
        )
    return suffix


def _check_readable(path, what=None):
    """``Path(path)``, or FileNotFoundError / ValueError naming it (and ``what`` it holds)."""
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"path must be a str or path-like; got {type(path).__name__}.")
    path = Path(path)
    holds = f" ({what})" if what else ""
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file{holds}.")
    if path.is_dir():
        raise ValueError(f"{path}: is a folder, not a file{holds}.")
    if not os.access(path, os.R_OK):
        raise ValueError(f"{path}: cannot be read (permission denied){holds}.")
    return path


def _as_numeric(array, source, name="the data"):
    """A float array, or TypeError naming ``source`` when ``array`` is not numeric."""
    array = np.asarray(array)
    if array.dtype.kind not in "biuf":
        raise TypeError(f"{source}: {name} must be numeric; got dtype {array.dtype}.")
    return array.astype(float)


def _check_points(array, source, n_columns, name):
    """A finite 2-D float array with ``n_columns`` columns and >= 1 row."""
    array = _as_numeric(array, source, name)
    if array.ndim != 2 or array.shape[1] != n_columns:
        raise ValueError(
            f"{source}: {name} must be an array of shape (n, {n_columns}); got shape {array.shape}."
        )
    if array.shape[0] < 1:
        raise ValueError(f"{source}: {name} holds no rows; at least one is needed.")
    if not np.all(np.isfinite(array)):
        bad = np.flatnonzero(~np.all(np.isfinite(array), axis=1))
        raise ValueError(
            f"{source}: {name} contains NaN or infinity ({len(bad)} rows, the first is row "
            f"{bad[0]})."
        )
    return np.ascontiguousarray(array)


def _check_correspondence_array(X, source="X"):
    return _check_points(X, source, 6, "the correspondences")


def _read_bytes(path):
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise ValueError(f"{path}: cannot be read: {exc}") from exc


def _one_line(error):
    """The message of ``error`` on one line."""
    return " ".join(str(error).split())
