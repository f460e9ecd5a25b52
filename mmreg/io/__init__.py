"""Reading and writing correspondences, labels, motions and point clouds.

Every reader checks its file and raises one clear error that names it: ``FileNotFoundError``
when it is missing, ``ValueError`` when it is unreadable, corrupt, truncated, has bytes
after its end, the wrong shape, NaN or infinity, or an unknown extension, ``TypeError``
when it holds the wrong kind of values (text where numbers belong, non-integer labels).
Every writer goes through :func:`atomic_write`: the file appears whole or not at all.

File formats
------------
correspondences
    ``.npy`` (an ``(n, 6)`` array), ``.npz`` (key ``X``, or keys ``a`` and ``b``),
    ``.csv`` / ``.txt`` (6 numeric columns, an optional header row, comma, space or tab
    delimited), or a point cloud ``.ply`` / ``.pcd`` / ``.xyz`` together with the b-points
    (``target``) or the per-point flow (``flow``).
labels
    ``.npy`` or ``.csv`` / ``.txt`` (one integer per line, an optional header row).
capture times
    ``.npy`` or ``.csv`` / ``.txt`` (one number of seconds per line, an optional header
    row).
motions
    JSON: a list with one object per motion (see :func:`write_motions`).
point clouds
    ``.ply`` (ascii, binary little or big endian; the ``vertex`` element's ``x``, ``y``,
    ``z`` and ``red``, ``green``, ``blue``) and ``.pcd`` (``ascii``, ``binary``,
    ``binary_compressed``; ``x``, ``y``, ``z`` and packed ``rgb``), read and written by
    mmreg itself (the files agree with Open3D's); ``.xyz`` (``x y z`` per line) as text;
    ``.npy`` / ``.csv`` / ``.txt`` ``(n, 3)`` arrays for reading.
SemanticKITTI ``.label``
    one little-endian ``uint32`` per point (class in the lower 16 bits, instance id in
    the upper 16), or one ``uint8`` per point (nuScenes logs converted to the
    SemanticKITTI layout), told apart by the scan's point count; LiDAR-MOS's moving
    (251) and static (9) classes from a sequence's tracks
    (:func:`semantickitti_mos_labels`), the true moving mask and the points to leave
    out (:func:`moving_from_labels`).
KITTI poses
    one ``3 x 4`` matrix ``[R | t]`` a line, 12 numbers row-major; written in the
    shortest form that reads back exactly, read with a check that every ``R`` is a
    rotation.
LiDAR sweeps (reading; see :mod:`mmreg.io._lidar`)
    KITTI velodyne ``.bin`` (float32 ``x y z reflectance``), nuScenes ``.pcd.bin``
    (float32 ``x y z intensity ring``), Argoverse 2 ``.feather`` (``x y z``, and
    ``offset_ns``: the capture times). Invalid returns (NaN or all-zero rows) are kept in
    place; ROS bags hold many frames and are read with
    :func:`mmreg.datasets.open_sequence`.

Text tables
-----------
Blank lines are skipped; lines starting with ``#`` are comments, allowed only before the
data. The first line is a header when none of its fields is a number (a line mixing
names and numbers is an error). The last line must end with a line break.

What a damaged file gives
-------------------------
No reader zero-fills, shortens or pads data silently. What each format can detect
follows from what it stores (``tests/test_io_fuzz.py`` checks it on thousands of
damaged files):

* cut short: an error for every format whose header counts its data (``.npy``,
  ``.npz``, ``.ply``, ``.pcd``, and the loaders' ``.png``, ``.pfm``, ``.flo``; the error
  names how many vertices or points the header promised and how many were read). A text
  table (``.csv``, ``.txt``, ``.xyz``) holds no count: a cut inside a line is an error
  (the last line must end with a line break), a cut exactly at a line end leaves a
  valid shorter table (``mmreg register`` then finds the files' lengths differ when
  another file is read with it);
* bytes appended after the end: an error for every binary format and every format with
  a count; for a text table an error unless they form whole valid rows;
* a changed byte: ``.npz`` (a CRC-32 per array) and ``.png`` (a CRC-32 per chunk) detect
  it (an error, or the data are unchanged). A changed byte in the header of the other
  formats is an error or leaves a valid header (e.g. the byte order of a ``.npy`` or
  ``.pfm``); in their values it cannot be detected: raw binary (``.npy``, binary
  ``.ply`` / ``.pcd``, ``.pfm``, ``.flo``) keeps the shape but may change a value; text
  changes at most one number (a digit, sign or exponent), or, in a one-column table,
  the number of rows by one. Values that become NaN or infinite are always an error.
"""

import importlib

# Each public name and the module that holds it, imported on first use (PEP 562): the
# command line imports mmreg.io's small helpers without paying for every reader.
_LAZY = {
    "SemanticKittiLabels": "mmreg.io._semantickitti",
    "atomic_write": "mmreg.io._atomic",
    "moving_from_labels": "mmreg.io._semantickitti",
    "read_correspondences": "mmreg.io._correspondences",
    "read_kitti_poses": "mmreg.io._kitti_poses",
    "read_labels": "mmreg.io._labels",
    "read_motions": "mmreg.io._motions",
    "read_point_cloud": "mmreg.io._point_clouds",
    "read_semantickitti_labels": "mmreg.io._semantickitti",
    "read_times": "mmreg.io._labels",
    "semantickitti_mos_labels": "mmreg.io._semantickitti",
    "write_correspondences": "mmreg.io._correspondences",
    "write_kitti_poses": "mmreg.io._kitti_poses",
    "write_labels": "mmreg.io._labels",
    "write_motions": "mmreg.io._motions",
    "write_point_cloud": "mmreg.io._point_clouds",
    "write_semantickitti_labels": "mmreg.io._semantickitti",
}

__all__ = sorted(_LAZY)


def __getattr__(name):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'mmreg.io' has no attribute {name!r}")


def __dir__():
    return sorted({*globals(), *__all__})
