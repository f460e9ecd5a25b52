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

from mmreg.io._atomic import atomic_write
from mmreg.io._correspondences import read_correspondences, write_correspondences
from mmreg.io._labels import read_labels, read_times, write_labels
from mmreg.io._motions import read_motions, write_motions
from mmreg.io._point_clouds import read_point_cloud, write_point_cloud

__all__ = [
    "atomic_write",
    "read_correspondences",
    "read_labels",
    "read_motions",
    "read_point_cloud",
    "read_times",
    "write_correspondences",
    "write_labels",
    "write_motions",
    "write_point_cloud",
]
