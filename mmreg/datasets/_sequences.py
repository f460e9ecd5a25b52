"""Sequences of LiDAR frames as users keep them: a bag, a KITTI sequence, an AV2 log, a folder.

One class per kind, in the style of KISS-ICP's ``python/kiss_icp/datasets/``, and a
factory, :func:`open_sequence`, that recognises a path. Every sequence reads its frames
lazily, one file (or one bag message) per ``seq[k]``, keeps only paths (it pickles, so a
process pool can share it) and has

``len(seq)``
    the number of frames;
``seq[k]``
    frame ``k`` (negative ``k`` counts from the end; ``IndexError`` beyond), a
    :class:`Frame`;
``iter(seq)``
    the frames in order;
``seq.kind``
    ``"bag"``, ``"kitti"``, ``"argoverse2"`` or ``"folder"``;
``seq.path``
    the path it was opened from (a :class:`pathlib.Path`);
``seq.names``
    one short name per frame (a file name, or ``topic#k`` for a bag), for messages and
    result folders.

A :class:`Frame` holds

``points``
    (n, 3) float64, in the sensor's frame at that sweep; invalid returns (NaN or
    all-zero rows) are kept in place: the estimators count and drop them;
``timestamp``
    the frame's time in seconds (float), or None when the source has none;
``times``
    (n,) per-point capture times in seconds after ``timestamp``, or None;
``pose``
    4 x 4 pose of the sensor in a fixed world frame (x_world = pose @ x_frame), or None;
``index``, ``source``
    the frame's number and where it came from (a file, or ``bag [topic message k]``).

With poses, the motion of the static world from frame ``i`` to frame ``j`` in mmreg's
convention (``b = R a + t``: a point of frame ``i`` to where frame ``j`` sees it) is
``seq.ego_motion(i, j) = inv(pose_j) @ pose_i``.

Kinds
-----
:class:`BagSequence` (``kind="bag"``)
    a ROS 1 ``.bag``, a ROS 2 bag folder (``metadata.yaml``) or its ``.db3`` / ``.mcap``
    file: the messages of one ``sensor_msgs/PointCloud2`` topic (``topic=`` is needed
    only when the bag holds several; the error lists them). ``timestamp``: the header's
    stamp (the bag's receive time when the stamp is zero); ``times`` from a ``t``,
    ``time``, ``timestamp`` or ``offset_time`` field. Needs ``pip install "mmreg[ros]"``.
:class:`KittiSequence` (``kind="kitti"``)
    a KITTI odometry / SemanticKITTI sequence folder: ``velodyne/*.bin``, and optionally
    ``times.txt`` (seconds), ``poses.txt`` (or KITTI odometry's ``../../poses/NN.txt``:
    the left camera's poses, 12 numbers a line) with ``calib.txt`` (its ``Tr``: velodyne
    to camera), from which ``pose = inv(Tr) @ P @ Tr`` (the velodyne's pose). A
    ``poses.txt`` without ``calib.txt`` holds the LiDAR's own poses (conversions of
    nuScenes to this layout), read as they are, with a warning. Both files are read
    when first needed.
:class:`Argoverse2Sweeps` (``kind="argoverse2"``)
    an Argoverse 2 log folder (``sensors/lidar/<timestamp_ns>.feather``) or its
    ``sensors/lidar`` folder: ``timestamp`` from the file name, ``times`` =
    ``offset_ns * 1e-9``, ``pose`` from the log's ``city_SE3_egovehicle.feather`` when
    present (the ego vehicle's pose in the city frame).
:class:`FrameFolder` (``kind="folder"``)
    a folder of frame files of one kind (``*.ply``, ``*.pcd``, ``*.xyz``, ``*.npy``,
    ``*.bin``, ``*.pcd.bin``, ``*.feather``) in natural name order (``frame2`` before
    ``frame10``); ``pattern=`` (a glob) picks one kind when the folder holds several.
    ``timestamp`` from a ``.pcd``'s absolute per-point time field (``t``, ``time``,
    ``timestamp`` or ``offset_time``: its earliest point's), else None; ``times`` from a
    ``.feather``'s ``offset_ns``.

Examples
--------
>>> import tempfile
>>> from pathlib import Path
>>> import numpy as np
>>> from mmreg.datasets import open_sequence
>>> with tempfile.TemporaryDirectory() as folder:
...     (Path(folder) / "velodyne").mkdir()
...     for k in range(3):
...         scan = np.full((4, 4), k, dtype=np.float32)  # x y z reflectance
...         scan.tofile(Path(folder) / "velodyne" / f"{k:06d}.bin")
...     seq = open_sequence(folder)
...     frame = seq[-1]
>>> seq.kind, len(seq), frame.index, frame.points[0].tolist(), frame.pose
('kitti', 3, 2, [2.0, 2.0, 2.0], None)
"""

import functools
import os
import re
from pathlib import Path

import numpy as np

from mmreg._warnings import warn
from mmreg.io import _lidar as _lidar_files
from mmreg.io._checks import _check_readable
from mmreg.io._correspondences import _read_point_file
from mmreg.io._kitti_poses import _kitti_matrices

__all__ = [
    "Argoverse2Sweeps",
    "BagSequence",
    "Frame",
    "FrameFolder",
    "KittiSequence",
    "open_sequence",
]

# The frame files a plain folder may hold (".pcd.bin" before ".bin": the longer name wins).
FRAME_SUFFIXES = (".ply", ".pcd", ".xyz", ".npy", ".pcd.bin", ".bin", ".feather")
_AV2_NAME = re.compile(r"^(\d+)\.feather$")


class Frame:
    """One LiDAR frame of a sequence (see :mod:`mmreg.datasets._sequences`).

    ``pose`` may be given as a function of no argument, called on the first read of
    ``frame.pose``: a sequence whose poses file is broken still gives its points.
    """

    __slots__ = ("index", "points", "source", "times", "timestamp", "_pose")

    def __init__(self, points, timestamp, times, index, source, pose=None):
        self.points, self.timestamp, self.times = points, timestamp, times
        self.index, self.source, self._pose = index, source, pose

    @property
    def pose(self):
        """4 x 4 pose of the sensor (x_world = pose @ x_frame), or None."""
        if callable(self._pose):
            self._pose = self._pose()
        return self._pose

    def __repr__(self):
        return (
            f"Frame(index={self.index}, source={self.source!r}, points={len(self.points)}, "
            f"timestamp={self.timestamp!r})"
        )


class _Sequence:
    """``__len__``, ``__getitem__`` with negative indices, ``__iter__``, ``ego_motion``."""

    kind = ""

    def __len__(self):
        return len(self.names)

    def __getitem__(self, k):
        n = len(self)
        if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)):
            raise TypeError(f"frame index must be an integer; got {k!r}.")
        if not -n <= k < n:
            raise IndexError(f"{self.path}: frame {k} out of range; it has {n} frame(s).")
        return self._frame(int(k) % n)

    def __iter__(self):
        for k in range(len(self)):
            yield self[k]

    def __repr__(self):
        return f"{type(self).__name__}({str(self.path)!r}, frames={len(self)})"

    def _pose(self, k):
        """Frame ``k``'s pose as :class:`Frame` takes it: read when asked for."""
        return functools.partial(_pose_of, self, k)

    def ego_motion(self, i, j):
        """4 x 4 motion of the static world from frame ``i`` to frame ``j``: ``inv(P_j) P_i``.

        ``b = R a + t`` takes a static point ``a`` of frame ``i`` to where frame ``j``
        sees it. ValueError when the sequence has no poses.
        """
        poses = getattr(self, "poses", None)
        if poses is None:
            raise ValueError(f"{self.path}: has no poses, so no ego motion.")
        n = len(self)
        for k in (i, j):
            if not -n <= k < n:
                raise IndexError(f"{self.path}: frame {k} out of range; it has {n} frame(s).")
        return np.linalg.inv(poses[j]) @ poses[i]


def _pose_of(sequence, k):
    poses = getattr(sequence, "poses", None)
    return None if poses is None else poses[k].copy()


def _read_frame_file(path, stamp=False):
    path = _check_readable(path, "a frame")
    points, _, times, when = _read_point_file(path, "the points", stamp=True)
    return (points, times, when) if stamp else (points, times)


def _natural_key(name):
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", name)]


def _frame_suffix(name):
    lower = name.lower()
    return next((s for s in FRAME_SUFFIXES if lower.endswith(s)), None)


# --------------------------------------------------------------------------- bags
class BagSequence(_Sequence):
    """The ``sensor_msgs/PointCloud2`` messages of one topic of a ROS 1 or ROS 2 bag.

    Parameters
    ----------
    path : str or path-like
        A ``.bag`` file (ROS 1), a ROS 2 bag folder (``metadata.yaml``) or its ``.db3`` /
        ``.mcap`` file.
    topic : str, optional
        The PointCloud2 topic; needed only when the bag holds several.

    Attributes
    ----------
    path : pathlib.Path
    topic : str
    names : list of str
        ``"<topic>#<k>"``.
    """

    kind = "bag"

    def __init__(self, path, topic=None):
        self._bag = _lidar_files.Bag(path, topic)
        self.path = self._bag.path
        self.topic = self._bag.topic
        self.names = [f"{self.topic}#{k}" for k in range(len(self._bag))]

    def _frame(self, k):
        points, stamp, times = self._bag.read(k)
        source = f"{self.path} [{self.topic} message {k}]"
        return Frame(points, stamp, times, k, source)


# --------------------------------------------------------------------------- KITTI
def _kitti_tr(path):
    """The 4 x 4 velodyne-to-camera transform ``Tr`` of a KITTI ``calib.txt``."""
    path = _check_readable(path, "KITTI calibration")
    for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
        key, _, values = line.partition(":")
        if key.strip() != "Tr":
            continue
        try:
            values = np.array(values.split(), dtype=float)
        except ValueError:
            values = np.empty(0)
        if values.shape != (12,) or not np.all(np.isfinite(values)):
            raise ValueError(f"{path}: line {number}: Tr must hold 12 finite numbers.")
        tr = np.eye(4)
        tr[:3] = values.reshape(3, 4)
        return tr
    raise ValueError(f"{path}: no 'Tr:' line (the velodyne-to-camera transform).")


class KittiSequence(_Sequence):
    """A KITTI odometry or SemanticKITTI sequence folder: ``velodyne/*.bin`` frames.

    The poses and times are read when first asked for (``poses``, ``timestamps``, a
    frame's ``pose`` or ``timestamp``, :meth:`ego_motion`): a broken or missing file
    fails only what needs it.

    Parameters
    ----------
    path : str or path-like
        The sequence folder (``.../sequences/08``).

    Attributes
    ----------
    path : pathlib.Path
    names : list of str
        The ``.bin`` file names, in order.
    poses : ndarray of shape (n_frames, 4, 4) or None
        The velodyne's pose of every frame: ``inv(Tr) @ P @ Tr`` from the camera poses
        ``P`` (``poses.txt`` in the folder, else ``../../poses/<folder name>.txt``) and
        ``calib.txt``'s ``Tr``; a ``poses.txt`` without a ``calib.txt`` beside it is
        read as the LiDAR's own poses, as conversions of other datasets to the
        SemanticKITTI layout (nuScenes) write them, with a warning saying so. None
        without a poses file.
    timestamps : ndarray of shape (n_frames,) or None
        ``times.txt`` (seconds), or None.
    """

    kind = "kitti"

    def __init__(self, path):
        self.path = Path(path)
        velodyne = self.path / "velodyne"
        if not velodyne.is_dir():
            raise FileNotFoundError(f"{velodyne}: no such folder (a KITTI sequence's scans).")
        files = sorted(
            (e.name for e in os.scandir(velodyne) if e.name.lower().endswith(".bin")),
            key=_natural_key,
        )
        if not files:
            raise ValueError(f"{velodyne}: no .bin scans.")
        self.names = files
        self._files = [velodyne / name for name in files]

    # Plain properties (not functools.cached_property, whose frame is not mmreg's): the
    # poses' warning names the user's line.
    @property
    def timestamps(self):
        if "_timestamps" not in vars(self):
            self._timestamps = self._read_timestamps()
        return self._timestamps

    @property
    def poses(self):
        if "_poses" not in vars(self):
            self._poses = self._read_poses()
        return self._poses

    def _read_timestamps(self):
        path = self.path / "times.txt"
        if not path.is_file():
            return None
        times = _kitti_matrices(path, 1, "frame times")[:, 0]
        return self._matching(times, len(self), path, "times")

    def _read_poses(self):
        n = len(self)
        poses_path = self.path / "poses.txt"
        beside = poses_path.is_file()
        if not beside:
            poses_path = self.path.parent.parent / "poses" / f"{self.path.name}.txt"
        if not poses_path.is_file():
            return None
        matrices = _kitti_matrices(poses_path, 12, "poses (3 x 4 row-major)")
        P = np.tile(np.eye(4), (n, 1, 1))
        P[:, :3] = self._matching(matrices, n, poses_path, "poses").reshape(n, 3, 4)
        calib = self.path / "calib.txt"
        if not calib.is_file():
            if beside:  # a conversion's LiDAR poses (nuScenes to SemanticKITTI)
                warn(
                    f"{poses_path}: no calib.txt beside it, so its poses are read as the "
                    "LiDAR's own (as conversions of nuScenes to the SemanticKITTI layout "
                    "write them); for KITTI's camera poses, add the sequence's calib.txt."
                )
                return P
            raise FileNotFoundError(
                f"{calib}: no such file; {poses_path} holds the camera's poses, and "
                "calib.txt's Tr turns them into the velodyne's."
            )
        tr = _kitti_tr(calib)
        return np.linalg.inv(tr) @ P @ tr

    def _matching(self, values, n, path, what):
        if len(values) != n:
            raise ValueError(
                f"{path}: {len(values)} {what} for the {n} scans of {self.path / 'velodyne'}."
            )
        return values

    def _frame(self, k):
        points, _ = _read_frame_file(self._files[k])
        stamp = None if self.timestamps is None else float(self.timestamps[k])
        return Frame(points, stamp, None, k, str(self._files[k]), self._pose(k))


# --------------------------------------------------------------------------- Argoverse 2
class Argoverse2Sweeps(_Sequence):
    """The LiDAR sweeps of an Argoverse 2 log, ``sensors/lidar/<timestamp_ns>.feather``.

    Parameters
    ----------
    path : str or path-like
        The log folder, or its ``sensors/lidar`` folder.

    Attributes
    ----------
    path : pathlib.Path
    names : list of str
        The sweep file names, by timestamp.
    timestamps : ndarray of shape (n_frames,)
        Seconds (the file names' nanoseconds times 1e-9).
    poses : ndarray of shape (n_frames, 4, 4) or None
        The ego vehicle's pose in the city frame (``city_SE3_egovehicle.feather``), or
        None when the log has no such file.
    """

    kind = "argoverse2"

    def __init__(self, path):
        self.path = Path(path)
        lidar = self.path / "sensors" / "lidar"
        log = self.path
        if not lidar.is_dir():
            lidar, log = self.path, self.path.parent.parent
        found = {}
        if lidar.is_dir():
            for entry in os.scandir(lidar):
                match = _AV2_NAME.match(entry.name)
                if match:
                    found[int(match.group(1))] = entry.name
        if not found:
            raise ValueError(f"{lidar}: no Argoverse 2 sweeps (<timestamp_ns>.feather files).")
        stamps = sorted(found)
        self.names = [found[t] for t in stamps]
        self._files = [lidar / name for name in self.names]
        self._stamps_ns = np.array(stamps, dtype=np.int64)
        self.timestamps = self._stamps_ns * 1e-9
        self.poses = None
        poses_path = log / "city_SE3_egovehicle.feather"
        if poses_path.is_file():
            self.poses = self._read_poses(poses_path)

    def _read_poses(self, path):
        from mmreg.datasets._argoverse2 import _POSE_COLUMNS, _poses, _read_feather

        columns = _read_feather(path, _POSE_COLUMNS, "the ego-vehicle poses")
        by_time = dict(zip(columns["timestamp_ns"].tolist(), _poses(columns, path), strict=True))
        missing = [int(t) for t in self._stamps_ns if int(t) not in by_time]
        if missing:
            raise ValueError(
                f"{path}: no pose for {len(missing)} sweep(s), the first at {missing[0]} ns."
            )
        return np.stack([by_time[int(t)] for t in self._stamps_ns])

    def _frame(self, k):
        points, times = _read_frame_file(self._files[k])
        stamp = float(self.timestamps[k])
        return Frame(points, stamp, times, k, str(self._files[k]), self._pose(k))


# --------------------------------------------------------------------------- plain folder
class FrameFolder(_Sequence):
    """A folder of frame files of one kind, in natural name order.

    Parameters
    ----------
    path : str or path-like
        The folder.
    pattern : str, optional
        A glob (``"*.bin"``) choosing the frames; needed when the folder holds frame
        files of several kinds.

    Attributes
    ----------
    path : pathlib.Path
    names : list of str
        The frame files' names, in order.
    """

    kind = "folder"

    def __init__(self, path, pattern=None):
        self.path = Path(path)
        if not self.path.is_dir():
            raise FileNotFoundError(f"{self.path}: no such folder (a sequence of frames).")
        if pattern is not None:
            names = [p.name for p in self.path.glob(pattern) if p.is_file()]
            unknown = [n for n in names if _frame_suffix(n) is None]
            if unknown:
                raise ValueError(
                    f"{self.path}: pattern {pattern!r} matches {unknown[0]!r}, not a frame "
                    f"file ({', '.join(FRAME_SUFFIXES)})."
                )
        else:
            names = [e.name for e in os.scandir(self.path) if e.is_file()]
            names = [n for n in names if _frame_suffix(n) is not None]
            kinds = {}
            for n in names:
                kinds[_frame_suffix(n)] = kinds.get(_frame_suffix(n), 0) + 1
            if len(kinds) > 1:
                listed = ", ".join(f"{count} {s}" for s, count in sorted(kinds.items()))
                first = sorted(kinds)[0]
                raise ValueError(
                    f"{self.path}: holds frames of several kinds ({listed}); choose one with "
                    f"pattern='*{first}' (on the command line: --pattern '*{first}')."
                )
        if not names:
            raise ValueError(
                f"{self.path}: no frames ({', '.join('*' + s for s in FRAME_SUFFIXES)})."
            )
        self.names = sorted(names, key=_natural_key)
        self._files = [self.path / name for name in self.names]

    def _frame(self, k):
        points, times, stamp = _read_frame_file(self._files[k], stamp=True)
        return Frame(points, stamp, times, k, str(self._files[k]))


# --------------------------------------------------------------------------- the factory
def open_sequence(path, *, topic=None, pattern=None):
    """Open a sequence of LiDAR frames, recognising what ``path`` is.

    Parameters
    ----------
    path : str or path-like
        A ROS bag (``.bag``, a ROS 2 bag folder holding ``metadata.yaml``, or its ``.db3``
        / ``.mcap`` file), a KITTI / SemanticKITTI sequence folder (holding
        ``velodyne/``), an Argoverse 2 log (holding ``sensors/lidar/``) or its
        ``sensors/lidar`` folder (``<timestamp_ns>.feather`` files), or a folder of frame
        files.
    topic : str, optional
        A bag's PointCloud2 topic; needed only when the bag holds several.
    pattern : str, optional
        A glob choosing the frames of a plain folder.

    Returns
    -------
    sequence : BagSequence, KittiSequence, Argoverse2Sweeps or FrameFolder
        ``len(sequence)`` frames; ``sequence[k]`` is a :class:`Frame` (``points``,
        ``timestamp``, ``times``, ``pose``, ``index``, ``source``).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If it is none of the above, holds no frames, a bag holds no PointCloud2 topic or
        several without ``topic``, a KITTI poses or times file does not match its scans,
        or ``topic`` / ``pattern`` do not apply to it.
    ImportError
        For a bag, when the ``rosbags`` package is missing (``pip install "mmreg[ros]"``).

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.datasets import open_sequence
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     for k in (1, 2, 10):
    ...         np.save(Path(folder) / f"frame{k}.npy", np.full((5, 3), float(k)))
    ...     seq = open_sequence(folder)
    ...     frames = [(f.index, float(f.points[0, 0])) for f in seq]
    >>> seq.kind, seq.names, frames
    ('folder', ['frame1.npy', 'frame2.npy', 'frame10.npy'], [(0, 1.0), (1, 2.0), (2, 10.0)])
    """
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"path must be a str or path-like; got {type(path).__name__}.")
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or folder (a sequence of frames).")
    is_bag = _lidar_files.lidar_kind(path) == "bag"
    if topic is not None and not is_bag:
        raise ValueError(f"{path}: topic= (--topic) applies to a ROS bag only.")
    if pattern is not None and (is_bag or not path.is_dir()):
        raise ValueError(f"{path}: pattern= applies to a folder of frame files only.")
    if is_bag:
        return BagSequence(path, topic)
    if not path.is_dir():
        raise ValueError(
            f"{path}: is one file, not a sequence; a sequence is a ROS bag (.bag, a ROS 2 "
            "bag folder, .db3, .mcap) or a folder (KITTI velodyne/, Argoverse 2 "
            "sensors/lidar/, or frame files)."
        )
    if pattern is None:
        if (path / "velodyne").is_dir():
            return KittiSequence(path)
        if (path / "sensors" / "lidar").is_dir():
            return Argoverse2Sweeps(path)
        frames = [e.name for e in os.scandir(path) if _frame_suffix(e.name) is not None]
        if frames and all(_AV2_NAME.match(name) for name in frames):
            return Argoverse2Sweeps(path)
    return FrameFolder(path, pattern)
