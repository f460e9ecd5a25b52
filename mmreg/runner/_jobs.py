"""The jobs of a dataset: what :func:`mmreg.runner.run_dataset` fits, one input each.

A job is a small frozen dataclass (picklable: it holds paths, not data) with a unique
``name`` and a ``load()`` that reads its input where it runs (a Dask worker), returning
a dict with ``X`` (n, 6) and, when the data have them, ``labels_true`` (n,) (negative:
unknown or outlier, not scored) and ``flow_true`` (n, 3). A job of two sweeps gives ``X``
(n, 3), the first sweep's points it uses (or (n, 6), ``[a | a + flow]`` with a given
flow), and ``sweep`` (m, 3), the second (any size, any order), for
:class:`mmreg.SweepRegistration`, with ``indices`` (n,): the rows of the first sweep's
file that ``X`` holds, and ``sweep_points``: every row of that file. An Argoverse 2 one
also gives the capture times of the points used, ``times`` (n,) and ``sweep_times``
(m,) (seconds after each sweep's timestamp, from ``offset_ns``), and ``interval``, the
seconds between the two timestamps, unless every offset is zero or
``capture_times=False``; and with ``ground="auto"`` on a log with a map, ``ground`` (n,)
and ``sweep_ground`` (m,): the map's ground points. ``pairs`` says what the fit is given:
``"sweeps"``, ``"flow"`` (a network's), ``"truth"`` (the ground-truth flow).

:func:`dataset_jobs` lists the jobs of a folder:

* an Argoverse 2 log (it holds ``sensors/lidar``; the annotations, poses and map are
  optional: the test split and the LiDAR dataset have no annotations), or a folder of
  logs (a split): one job per consecutive sweep pair (N sweeps, N - 1 jobs), the two raw
  sweeps registered from the points alone; scored where the log has annotations; a log
  of a split that cannot be read is one failed job, the others go on;
* a KITTI odometry or SemanticKITTI sequence (``velodyne/*.bin``), a ROS bag's
  PointCloud2 topic, or a folder of LiDAR sweep files (``.bin``, ``.pcd.bin``,
  ``.feather``), read by :func:`mmreg.datasets.open_sequence`: the same, frame by frame,
  without truth (with the sequence's poses, when it has them, as the ICP's start); a
  folder of sequences (KITTI's ``sequences/`` holding ``00``, ``01``, ...): the jobs of
  every sequence, named ``<sequence>_<frame>``, a sequence that cannot be read one failed
  job;
* a folder of frames (``*.ply``, ``*.pcd``, ``*.xyz``, or ``*.npy`` of shape (n, 3)), in
  name order: one job per consecutive pair, two raw sweeps of any sizes and orders, or
  with ``pairs="aligned"`` frame ``k + 1`` giving the b-points of frame ``k`` row by row
  (the clouds must be index-aligned: two LiDAR scans stacked row by row are refused, see
  :mod:`mmreg.sweeps._stacked_rows`);
* a folder of correspondence files (``*.npy`` (n, 6), ``*.npz``, ``*.csv``, ``*.txt``):
  one job per file. An ``.npz`` may also hold the truth: ``labels`` (n,) and ``flow``
  (n, 3).
"""

import dataclasses
import functools
import math
import os
import re
from collections import Counter
from pathlib import Path

import numpy as np
from sklearn.utils import Bunch

from mmreg.datasets._argoverse2 import (
    _BOX_EXPANSION,
    _DYNAMIC_THRESHOLD,
    _GROUND_THRESHOLD,
    _MIN_INTERIOR_POINTS,
    _load_pair,
    _Log,
    _MissingPathError,
    _read_points,
    read_scene_flow,
)
from mmreg.io._arrays import _load_npz
from mmreg.io._checks import _check_points
from mmreg.io._correspondences import _read_point_file
from mmreg.io._correspondences import _read_points as read_point_file

__all__ = [
    "Argoverse2PairJob",
    "Argoverse2SweepPairJob",
    "BrokenLogJob",
    "CorrespondenceFileJob",
    "FramePairJob",
    "SequenceSweepPairJob",
    "SweepPairJob",
    "dataset_jobs",
]

FRAME_EXTENSIONS = (".ply", ".pcd", ".xyz")
# LiDAR sweep files: a folder of them only is a sequence (open_sequence reads it).
SWEEP_EXTENSIONS = (".pcd.bin", ".bin", ".feather")
CORRESPONDENCE_EXTENSIONS = (".npy", ".npz", ".csv", ".txt")
PAIRS = ("auto", "sweeps", "truth", "aligned")
GROUND = ("auto", "keep", "drop")
_SWEEP_FILE = re.compile(r"^\d+\.feather$")  # an Argoverse 2 sweep: <timestamp_ns>.feather
LAYOUTS = ("auto", "argoverse2", "sequence", "frames", "correspondences")


@dataclasses.dataclass(frozen=True)
class FramePairJob:
    """Frame ``source`` and the next frame ``target``, index-aligned (b_i = target row i).

    Two LiDAR sweeps stacked row by row are refused (their rows pair rays, not points:
    :func:`mmreg.sweeps._stacked_rows.check_rows_follow_motion`).
    """

    name: str
    source: str
    target: str

    def inputs(self):
        """The files the job reads."""
        return (self.source, self.target)

    def load(self):
        from mmreg.sweeps._stacked_rows import check_rows_follow_motion

        a = read_point_file(self.source, "the frame's points")
        b = read_point_file(self.target, "the next frame's points")
        if len(a) != len(b):
            raise ValueError(
                f"{self.target}: holds {len(b)} points but {self.source} holds {len(a)}; "
                "with pairs='aligned' (--pairs aligned) consecutive frames must be "
                "index-aligned (row i of one is row i of the other); for raw sweeps of any "
                "sizes and orders leave pairs at 'auto' (drop --pairs aligned)."
            )
        check_rows_follow_motion(
            a,
            b,
            where=f"{self.source} and {self.target}",
            advice="Register them as two sweeps: leave pairs at 'auto' (drop --pairs aligned).",
        )
        return {"X": np.hstack([a, b])}


@dataclasses.dataclass(frozen=True)
class SweepPairJob:
    """Frame ``source`` and the next frame ``target`` as two raw sweeps (any sizes, orders).

    The seconds between them (``interval``: it bounds the objects' motions and gives
    their speeds in m/s) come from the frames' own timestamps (a ``.pcd``'s absolute time
    field), else from ``frame_rate`` (frames per second), else are unknown.
    """

    name: str
    source: str
    target: str
    frame_rate: float | None = None

    def inputs(self):
        """The files the job reads."""
        return (self.source, self.target)

    def load(self):
        a, _, _, first = read_point_file_stamped(self.source, "the first sweep's points")
        sweep, _, _, second = read_point_file_stamped(self.target, "the second sweep's points")
        data = {"X": a, "sweep": sweep, "pairs": "sweeps"}
        interval = _interval(first, second, self.target, self.frame_rate)
        if interval is not None:
            data["interval"] = interval
        return data


def read_point_file_stamped(path, name):
    """``(points, rgb, times, timestamp)`` of a point file (checked readable); the
    timestamp from a ``.pcd``'s absolute time field, else None."""
    from mmreg.io._checks import _check_readable

    return _read_point_file(_check_readable(path), name, stamp=True)


def _interval(first, second, where, frame_rate=None):
    """Seconds between two frames' timestamps, else ``1 / frame_rate``, else None; a
    second stamp not after the first is an error naming ``where``."""
    if first is not None and second is not None:
        if not second > first:
            raise ValueError(
                f"{where}: its timestamp ({second:.9f} s) is not after the previous "
                f"frame's ({first:.9f} s)."
            )
        return float(second - first)
    return None if frame_rate is None else 1.0 / float(frame_rate)


@dataclasses.dataclass(frozen=True)
class CorrespondenceFileJob:
    """One file of correspondences; an ``.npz`` may add ``labels`` and ``flow`` (truth)."""

    name: str
    path: str

    def inputs(self):
        """The files the job reads."""
        return (self.path,)

    def load(self):
        from mmreg import io as mmio

        X = mmio.read_correspondences(self.path)
        data = {"X": X}
        if Path(self.path).suffix.lower() == ".npz":
            arrays = _load_npz(self.path)
            if "labels" in arrays:
                labels = np.asarray(arrays["labels"])
                if labels.shape != (len(X),) or labels.dtype.kind not in "iu":
                    raise ValueError(
                        f"{self.path}: 'labels' must be {len(X)} integers, one per "
                        f"correspondence; got {labels.dtype} of shape {labels.shape}."
                    )
                data["labels_true"] = labels.astype(np.intp)
            if "flow" in arrays:
                flow = _check_points(arrays["flow"], self.path, 3, "key 'flow'")
                if len(flow) != len(X):
                    raise ValueError(f"{self.path}: 'flow' has {len(flow)} rows for {len(X)}.")
                data["flow_true"] = flow
        return data


# --------------------------------------------------------------------------- sweep pairs
def _pair_data(
    a,
    sweep,
    *,
    ground,
    masks,
    flow=None,
    times=None,
    sweep_times=None,
    interval=None,
    truth=None,
    where="the log",
):
    """What a job of two sweeps hands the runner, from the sweeps as the files hold them.

    ``a`` (n, 3) and ``sweep`` (m, 3): every row of the two files; ``masks``: their known
    ground points (two boolean arrays) or None; ``flow``: correspondences for every row of
    ``a`` (a network's flow or the truth) or None (raw sweeps); ``truth``: ``(labels,
    flow)`` of every row of ``a``, or None. The rows used are ``indices`` (all of them,
    or those off the map's ground with ``ground="drop"``). Without a map, ``ground``
    goes to the estimator (``ground_choice``): SweepRegistration finds the ground itself
    (Patchwork++) and keeps it, joins it to the static world or drops it.
    """
    if ground == "drop" and masks is not None:
        keep, keep_sweep = ~masks[0], ~masks[1]
    else:
        keep, keep_sweep = np.ones(len(a), bool), np.ones(len(sweep), bool)
    indices = np.flatnonzero(keep)
    X = a[indices]
    if flow is not None:
        X = np.hstack([X, X + flow[indices]])
    data = {"X": X, "sweep": sweep[keep_sweep], "indices": indices, "sweep_points": a}
    data["ground_rule"] = "dropped" if ground == "drop" and masks is not None else "kept"
    data["ground_choice"] = ground
    if ground == "auto" and masks is not None:
        data["ground"], data["sweep_ground"] = masks[0][indices], masks[1][keep_sweep]
    if (
        times is not None
        and sweep_times is not None
        and (np.any(times != 0) or np.any(sweep_times != 0))
    ):
        data.update(times=times[indices], sweep_times=sweep_times[keep_sweep], interval=interval)
    if truth is not None:
        data["labels_true"], data["flow_true"] = truth[0][indices], truth[1][indices]
    return data


@functools.lru_cache(maxsize=64)
def _log_files(log_dir):
    """The files an Argoverse 2 log's jobs read besides their sweeps: annotations, poses,
    map (listed once per log)."""
    log_dir = Path(log_dir)
    files = [log_dir / "annotations.feather", log_dir / "city_SE3_egovehicle.feather"]
    if (log_dir / "map").is_dir():
        files += sorted(p for p in (log_dir / "map").iterdir() if p.is_file())
    return tuple(str(p) for p in files)


@functools.lru_cache(maxsize=64)
def _log_sweeps(log_dir):
    """An Argoverse 2 log's sweep files, by timestamp (listed once per log)."""
    lidar = Path(log_dir) / "sensors" / "lidar"
    names = [e.name for e in os.scandir(lidar) if _SWEEP_FILE.match(e.name)]
    return tuple(str(lidar / n) for n in sorted(names, key=lambda n: int(n.split(".")[0])))


def _log_inputs(log_dir, index, *extra):
    sweeps = _log_sweeps(str(log_dir))
    return (*sweeps[index : index + 2], *_log_files(str(log_dir)), *(e for e in extra if e))


class _PartialLog(_Log):
    """An Argoverse 2 log whose annotations, ego poses or map may be missing.

    The sensor dataset's test split has no annotations; the LiDAR dataset has no
    annotations either. Only the sweeps are required: the map (with the poses) gives the
    ground, the annotations (with the poses) the truth to score against.
    """

    def __init__(self, log_dir):
        try:
            super().__init__(log_dir)
        except _MissingPathError:
            if not hasattr(self, "map_dir"):  # the sweeps themselves are missing
                raise
        self.has_poses = self.poses_path.is_file()
        self.has_annotations = self.has_poses and self.annotations_path.is_file()
        self.has_map = self.has_poses and self.map_dir.is_dir()

    def ground(self, points_ego, city_SE3_ego, threshold=_GROUND_THRESHOLD):
        if not self.has_map:  # the truth's loader asks for it: no map, no known ground
            return np.zeros(len(points_ego), bool)
        return super().ground(points_ego, city_SE3_ego, threshold)

    def sweep_pair(self, index):
        """Both sweeps of pair ``index`` (every row), their times, ground masks and truth.

        The truth where both sweeps are annotated; a log annotated at some sweeps only
        is scored there.
        """
        t0, t1 = (int(t) for t in self.sweep_timestamps[index : index + 2])
        truth = None
        if self.has_annotations and np.isin([t0, t1], self.annotations["timestamps"]).all():
            scene = _load_pair(
                self, index, False, _MIN_INTERIOR_POINTS, _BOX_EXPANSION, _DYNAMIC_THRESHOLD
            )
            a, times, sweep, sweep_times = scene.a, scene.times, scene.sweep2, scene.sweep2_times
            masks = (scene.ground, scene.sweep2_ground) if self.has_map else None
            truth = (scene.labels, scene.flow)
        else:
            (a, times), (sweep, sweep_times) = (_read_points(self.sweep_paths[t]) for t in (t0, t1))
            masks = None
            if self.has_map:
                masks = (self.ground(a, self.pose(t0)), self.ground(sweep, self.pose(t1)))
        return Bunch(
            a=a,
            sweep=sweep,
            times=times,
            sweep_times=sweep_times,
            masks=masks,
            truth=truth,
            interval=(t1 - t0) * 1e-9,
        )


@dataclasses.dataclass(frozen=True)
class Argoverse2PairJob:
    """Sweep pair ``index`` of an Argoverse 2 log fitted on the ground-truth flow.

    ``X`` is ``[a | a + flow]`` with the true flow (``pairs="truth"``): the fit sees the
    answer, and its scores measure the clustering alone. Needs the log's annotations.
    """

    name: str
    log_dir: str
    index: int
    ground: str = "auto"
    challenge: str = ""

    def inputs(self):
        """The files the job reads: its two sweeps, the log's annotations, poses and map."""
        return _log_inputs(self.log_dir, self.index)

    def load(self):
        log = _PartialLog(self.log_dir)
        if not log.has_annotations:
            raise ValueError(
                f"{self.log_dir}: has no annotations.feather (or no ego poses): no "
                "ground-truth flow to fit on; --pairs truth needs the annotations."
            )
        pair = log.sweep_pair(self.index)
        if pair.truth is None:
            t0, t1 = log.sweep_timestamps[self.index : self.index + 2]
            raise ValueError(
                f"{log.annotations_path}: no cuboid annotated at {t0} or {t1} ns: no "
                "ground-truth flow for this pair; --pairs truth needs both annotated."
            )
        data = _pair_data(
            pair.a,
            pair.sweep,
            ground=self.ground,
            masks=pair.masks,
            flow=pair.truth[1],
            truth=pair.truth,
            where=self.log_dir,
        )
        data.pop("sweep")  # the truth is the correspondence: no second sweep to fit on
        return data | {"pairs": "truth"}


@dataclasses.dataclass(frozen=True)
class Argoverse2SweepPairJob:
    """Sweep pair ``index`` of an Argoverse 2 log as two raw sweeps (or refined ``flow``).

    ``X`` is sweep t's points and ``sweep`` sweep t+1's, all rows or (``ground="drop"``)
    those off the map's ground; ``indices`` are the rows of sweep t used. With ``flow``
    (a feather file of the challenge's layout, one row per point of sweep t), ``X`` is
    ``[a | a + flow]``: SweepRegistration refines it on the second sweep. ``ground="auto"``
    adds the map's ground masks (``ground``, ``sweep_ground``) when the log has a map.
    The truth (labels, flow) when the log has annotations. With ``capture_times``,
    ``times``, ``sweep_times`` (``offset_ns`` in seconds) and ``interval`` (seconds
    between the timestamps), unless every offset is zero.
    """

    name: str
    log_dir: str
    index: int
    ground: str = "auto"
    capture_times: bool = True
    flow: str = ""
    challenge: str = ""

    def inputs(self):
        """The files the job reads: its two sweeps, the log's annotations, poses and map,
        the flow."""
        return _log_inputs(self.log_dir, self.index, self.flow)

    def load(self):
        log = _PartialLog(self.log_dir)
        pair = log.sweep_pair(self.index)
        flow = None
        if self.flow:
            flow = read_scene_flow(self.flow, n=len(pair.a))
        timed = self.capture_times
        data = _pair_data(
            pair.a,
            pair.sweep,
            ground=self.ground,
            masks=pair.masks,
            flow=flow,
            times=pair.times if timed else None,
            sweep_times=pair.sweep_times if timed else None,
            interval=pair.interval,
            truth=pair.truth,
            where=self.log_dir,
        )
        return data | {"pairs": "flow" if flow is not None else "sweeps"}


@dataclasses.dataclass(frozen=True)
class BrokenLogJob:
    """A log (or a sequence) whose sweeps cannot even be listed: one failed row, the other
    logs go on."""

    name: str
    log_dir: str
    error: str

    def inputs(self):
        """None read: it never leaves a result to resume."""
        return ()

    def load(self):
        raise ValueError(self.error)


def _is_argoverse2_log(folder):
    return (Path(folder) / "sensors" / "lidar").is_dir()


def _flow_file(flow_dir, log_name, timestamp):
    """``DIR/<log>/<timestamp_ns>.feather`` if DIR has the log's folder, else ``DIR/<ts>``."""
    if not flow_dir:
        return ""
    folder = Path(flow_dir) / log_name
    folder = folder if folder.is_dir() else Path(flow_dir)
    return str(folder / f"{timestamp}.feather")


def _argoverse2_jobs(log_dir, ground, pairs, capture_times, flow_dir, prefix=""):
    log_dir = Path(log_dir)
    try:
        stamps = _PartialLog(log_dir).sweep_timestamps
    except (OSError, ValueError) as error:
        if not prefix:  # a single log: the user's input is wrong
            raise
        return [BrokenLogJob(log_dir.name, str(log_dir), " ".join(str(error).split()))]
    name = Path(os.path.abspath(log_dir)).name  # the log id as the user has it (symlinks too)
    if len(stamps) < 2 and prefix:  # a split's log that gives no pair: said, not skipped
        error = f"{log_dir / 'sensors' / 'lidar'}: one sweep only; a job is a pair of sweeps."
        return [BrokenLogJob(log_dir.name, str(log_dir), error)]
    jobs = []
    for i in range(len(stamps) - 1):  # N sweeps: N - 1 consecutive pairs
        job_name, challenge = f"{prefix}{stamps[i]}", f"{name}/{stamps[i]}.feather"
        if pairs == "truth":
            jobs.append(Argoverse2PairJob(job_name, str(log_dir), i, ground, challenge))
        else:
            flow = _flow_file(flow_dir, name, stamps[i])
            jobs.append(
                Argoverse2SweepPairJob(
                    job_name, str(log_dir), i, ground, capture_times, flow, challenge
                )
            )
    return jobs


def _check_some(jobs, folder):
    if not jobs:
        raise ValueError(f"{folder}: no pair of consecutive LiDAR sweeps in its log(s).")
    return jobs


def _npy_columns(path):
    """The number of columns of a 2-D ``.npy`` file, from its header (None if not 2-D)."""
    # A memory map reads the header only.
    shape = np.load(path, mmap_mode="r", allow_pickle=False).shape
    return shape[1] if len(shape) == 2 else None


def _check_choice(value, name, allowed):
    if value not in allowed:
        raise ValueError(f"{name} must be one of {allowed}; got {value!r}.")
    return value


def _ground_choice(ground, drop_ground):
    if drop_ground is None:
        return _check_choice(ground, "ground", GROUND)
    if not isinstance(drop_ground, (bool, np.bool_)):
        raise TypeError(f"drop_ground must be True or False; got {drop_ground!r}.")
    return "drop" if drop_ground else "keep"


def _valid_rows(points):
    """Rows of a sweep that are returns: finite and not the all-zero "no return" row."""
    return np.all(np.isfinite(points), axis=1) & np.any(points != 0, axis=1)


@dataclasses.dataclass(frozen=True)
class SequenceSweepPairJob:
    """Frames ``index`` and ``index + 1`` of a LiDAR sequence (a KITTI sequence, a ROS bag).

    Read by :func:`mmreg.datasets.open_sequence` (``topic``: a bag's PointCloud2
    topic; ``pattern``: the frame files of a folder). ``X`` is the first frame's returns
    (rows that are NaN or all zero, the sensor's "no return", are left out: ``indices``
    are the rows used), ``sweep`` the next frame's; with ``capture_times``, the frames'
    per-point ``times`` (a bag's ``t`` / ``time`` field) and the interval between their
    timestamps; with the sequence's poses (a KITTI ``poses.txt``), ``ego_motion``: the
    static world's motion between the frames, ``(rotation, translation)``, the ICP's
    start (unless ``poses`` is False). Without capture times, the interval between the
    frames' timestamps (KITTI's ``times.txt``, a bag's header stamps, a ``.pcd``'s
    absolute time field), else ``1 / frame_rate``, bounds the objects' motions and gives
    their speeds in m/s. No
    ground map (``ground`` goes to the estimator: ``ground_choice``), no truth.
    ``files``: the files it reads (its two frames, a KITTI sequence's poses, calibration
    and times), for :meth:`inputs`.
    """

    name: str
    path: str
    index: int
    ground: str = "auto"
    capture_times: bool = True
    topic: str | None = None
    pattern: str | None = None
    files: tuple = ()
    frame_rate: float | None = None
    poses: bool = True

    def inputs(self):
        """The files the job reads (a bag: its file, or every file of a ROS 2 bag folder)."""
        if self.files:
            return self.files
        path = Path(self.path)
        if path.is_dir():
            return tuple(sorted(str(p) for p in path.iterdir() if p.is_file()))
        return (self.path,)

    def load(self):
        from mmreg.datasets import open_sequence

        sequence = open_sequence(self.path, topic=self.topic, pattern=self.pattern)
        first, second = sequence[self.index], sequence[self.index + 1]
        valid, sweep_valid = _valid_rows(first.points), _valid_rows(second.points)
        if not valid.any() or not sweep_valid.any():
            empty = first if not valid.any() else second
            raise ValueError(f"{empty.source}: holds no valid point.")
        timed = (
            self.capture_times
            and first.times is not None
            and second.times is not None
            and first.timestamp is not None
            and second.timestamp is not None
        )
        data = _pair_data(
            first.points[valid],
            second.points[sweep_valid],
            ground=self.ground,
            masks=None,
            times=first.times[valid] if timed else None,
            sweep_times=second.times[sweep_valid] if timed else None,
            interval=second.timestamp - first.timestamp if timed else None,
            where=self.path,
        )
        data["indices"] = np.flatnonzero(valid)[data["indices"]]
        data["sweep_points"] = first.points
        if self.poses and getattr(sequence, "poses", None) is not None:
            motion = sequence.ego_motion(self.index, self.index + 1)
            data["ego_motion"] = (motion[:3, :3], motion[:3, 3])
        if not timed:  # the interval alone bounds the motions (and gives speeds in m/s)
            interval = _interval(first.timestamp, second.timestamp, second.source, self.frame_rate)
            if interval is not None:
                data["interval"] = interval
        return data | {"pairs": "sweeps"}


def _sweep_file(path):
    """Whether ``path`` is a LiDAR sweep file (KITTI ``.bin``, nuScenes ``.pcd.bin``, an
    Argoverse 2 ``<timestamp_ns>.feather``)."""
    from mmreg.io._lidar import lidar_kind

    return lidar_kind(path) in ("kitti", "nuscenes") or bool(_SWEEP_FILE.match(Path(path).name))


def _listed(folder, pattern=None):
    """The files of ``folder`` (not hidden), or those matching ``pattern``, by name."""
    if pattern is not None:
        return sorted(p for p in folder.glob(pattern) if p.is_file())
    return sorted(p for p in folder.iterdir() if p.is_file() and not p.name.startswith("."))


def _is_sequence(path, pattern=None):
    """A KITTI sequence folder, a ROS bag (a ``.bag``, ``.db3``, ``.mcap`` or folder), or a
    folder of LiDAR sweep files (KITTI ``.bin``, nuScenes ``.pcd.bin``, ``.feather``)."""
    from mmreg.io._lidar import lidar_kind

    path = Path(path)
    if lidar_kind(path) == "bag":
        return True
    if not path.is_dir() or _is_argoverse2_log(path):
        return False
    if pattern is None and (path / "velodyne").is_dir():
        return True
    # Sweep files only: a log's own tables (annotations.feather, ...) are not sweeps.
    files = _listed(path, pattern)
    return bool(files) and all(_sweep_file(p) for p in files)


def _sequence_files(sequence, k):
    """The files frames ``k`` and ``k + 1`` of ``sequence`` are read from, with a KITTI
    sequence's poses, calibration and times (a bag: none, the job names the bag)."""
    files = getattr(sequence, "_files", None)
    if files is None:
        return ()
    found = [str(files[k]), str(files[k + 1])]
    if sequence.kind == "kitti":
        root = sequence.path
        extra = [root / "poses.txt", root / "calib.txt", root / "times.txt"]
        extra.append(root.parent.parent / "poses" / f"{root.name}.txt")
        found += [str(p) for p in extra if p.is_file()]
    return tuple(found)


def _sequence_jobs(path, ground, capture_times, topic, pattern=None, prefix=""):
    from mmreg.datasets import open_sequence

    sequence = open_sequence(path, topic=topic, pattern=pattern)
    bag = sequence.kind == "bag"
    names = [f"{k:06d}" if bag else Path(name).stem for k, name in enumerate(sequence.names)]
    return [
        SequenceSweepPairJob(
            f"{prefix}{names[k]}",
            str(path),
            k,
            ground,
            capture_times,
            topic,
            pattern,
            _sequence_files(sequence, k),
        )
        for k in range(len(sequence) - 1)
    ]


def _sequence_folders(folder):
    """The KITTI sequences a folder holds (``NN/velodyne``), or those of its
    ``sequences/`` folder (a KITTI root), by name; empty when neither."""
    for root in (folder, folder / "sequences"):
        if root.is_dir():
            found = sorted(p for p in root.iterdir() if p.is_dir() and (p / "velodyne").is_dir())
            if found:
                return found
    return []


def _sequences_jobs(folders, ground, capture_times):
    """The jobs of every sequence, ``<sequence>_<frame>``; one that cannot be read, or has
    one frame, is one failed job (as a log of an Argoverse 2 split)."""
    jobs = []
    for folder in folders:
        try:
            found = _sequence_jobs(folder, ground, capture_times, None, prefix=f"{folder.name}_")
        except (OSError, ValueError) as error:
            found = [BrokenLogJob(folder.name, str(folder), " ".join(str(error).split()))]
        if not found:
            error = f"{folder / 'velodyne'}: one scan only; a job is a pair of scans."
            found = [BrokenLogJob(folder.name, str(folder), error)]
        jobs += found
    return jobs


def dataset_jobs(
    path,
    *,
    layout="auto",
    ground="auto",
    pairs="auto",
    capture_times=True,
    flow=None,
    topic=None,
    pattern=None,
    drop_ground=None,
    frame_rate=None,
    poses=True,
):
    """The jobs of the dataset at ``path`` (a folder), in a stable order.

    Parameters
    ----------
    path : str or path-like
        An Argoverse 2 log or a folder of logs (a split), a KITTI odometry or
        SemanticKITTI sequence (``velodyne/*.bin``) or a folder of them (KITTI's
        ``sequences/``, or the root holding it), a ROS bag, a folder of frames or of
        correspondence files.
    layout : {"auto", "argoverse2", "sequence", "frames", "correspondences"}, default="auto"
        What the path holds; ``"auto"``: an Argoverse 2 log or folder of logs if it
        looks like one (``sensors/lidar``), a sequence (read by
        :func:`mmreg.datasets.open_sequence`) if it is a KITTI sequence (``velodyne/``),
        a folder of them, a ROS bag (``.bag``, ``.db3``, ``.mcap``, a ROS 2 bag folder)
        or a folder of LiDAR sweep files only (``.bin``, ``.pcd.bin``,
        ``<timestamp_ns>.feather``), else frames when the files are point clouds or
        (n, 3) ``.npy`` arrays, else correspondence files.
    ground : {"auto", "keep", "drop"}, default="auto"
        LiDAR logs: ``"drop"`` removes the ground points before the fit, by the map's
        rule on an Argoverse 2 log with a map; ``"keep"`` fits them as any other point;
        ``"auto"`` gives the map's ground masks (``ground``, ``sweep_ground``) when the
        log has a map; :func:`mmreg.runner.run_dataset` hands them to an estimator whose
        ``fit`` names them and drops the ground rows for any other (as ``"drop"``).
        Where there is no map (KITTI, bags, folders, an Argoverse 2 log without one), the
        choice goes to the estimator as its ``ground`` parameter
        (:class:`mmreg.SweepRegistration`: Patchwork++ finds the ground, which joins
        the static world with ``"auto"``, is left out with ``"drop"``, and is registered
        as any point with ``"keep"``); ``"auto"`` leaves the estimator's own setting.
    pairs : {"auto", "sweeps", "truth", "aligned"}, default="auto"
        What a job fits. ``"sweeps"``: two raw sweeps or frames of any sizes and orders,
        registered from the points alone by :class:`mmreg.SweepRegistration` (the
        default for LiDAR logs and frames), or with ``flow`` a network's flow refined on
        the second sweep. ``"truth"``: an Argoverse 2 log's ground-truth flow as the
        correspondences (the fit sees the answer; its summary row says so).
        ``"aligned"``: index-aligned frames (row ``i`` of frame ``k + 1`` matches row
        ``i`` of frame ``k``, as a simulation's particles; two LiDAR scans stacked row
        by row are refused); on an Argoverse 2 log the same as ``"truth"``.
        Correspondence files are their own pairs.
    capture_times : bool, default=True
        Argoverse 2 sweep pairs: hand the points' capture times (``offset_ns``) and the
        interval between the sweeps to the estimator, whose ``fit`` deskews the moving
        objects with them (:class:`mmreg.SweepRegistration`). Ignored elsewhere.
    flow : str or path-like, default=None
        A folder of scene flow in the Argoverse 2 challenge's layout,
        ``<flow>/<log>/<timestamp_ns>.feather`` (or ``<flow>/<timestamp_ns>.feather``
        for one log) with ``flow_tx_m``, ``flow_ty_m``, ``flow_tz_m``, one row per point
        of the sweep as the log holds it (ZeroFlow, DeFlow); each pair is then fitted as
        ``fit([a | a + flow], sweep=next)``. Argoverse 2 only.
    topic : str, default=None
        A ROS bag's ``sensor_msgs/PointCloud2`` topic; needed only when the bag holds
        several.
    pattern : str, default=None
        A glob (``"*.bin"``) choosing the files of a folder of frames or sweeps; needed
        when it holds frames of several kinds.
    drop_ground : bool, default=None
        Deprecated spelling of ``ground``: True is ``"drop"``, False ``"keep"``.
    frame_rate : float, default=None
        Frames per second of LiDAR sequences and folders of frames whose frames carry no
        timestamps (a nuScenes log's keyframes: 2): ``1 / frame_rate`` is the interval
        between a pair's sweeps, which bounds the objects' motions and gives their speeds
        in m/s. Frames with timestamps (KITTI's ``times.txt``, a bag's header stamps, a
        ``.pcd``'s absolute time field) keep theirs.
    poses : bool, default=True
        LiDAR sequences: start each pair's ego-motion ICP from the sequence's poses
        (KITTI's ``poses.txt``), where it has them; False registers from the points
        alone, so that the ego motions found can be compared with independent poses.

    Returns
    -------
    jobs : list
        Of FramePairJob, SweepPairJob, CorrespondenceFileJob, Argoverse2PairJob,
        Argoverse2SweepPairJob, SequenceSweepPairJob or (a log of a split or a sequence
        of a folder of them that cannot be read: one failed row) BrokenLogJob.

    Raises
    ------
    FileNotFoundError
        If ``path`` or ``flow`` does not exist (also a ValueError).
    ValueError
        If ``path`` is not a folder, holds no job, or mixes kinds of files.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.runner._jobs import dataset_jobs
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     for k in range(3):
    ...         np.save(Path(folder) / f"frame{k}.npy", np.zeros((5, 3)))
    ...     jobs = dataset_jobs(folder)
    >>> [(type(job).__name__, job.name) for job in jobs]
    [('SweepPairJob', 'frame0__frame1'), ('SweepPairJob', 'frame1__frame2')]
    """
    if frame_rate is not None:
        try:
            frame_rate = float(frame_rate)
        except (TypeError, ValueError):
            raise TypeError(f"frame_rate must be a number of Hz; got {frame_rate!r}.") from None
        if not (0 < frame_rate < math.inf):
            raise ValueError(f"frame_rate must be a positive number of Hz; got {frame_rate}.")
    jobs = _dataset_jobs(
        path, layout, ground, pairs, capture_times, flow, topic, pattern, drop_ground
    )
    if frame_rate is not None:
        jobs = [
            dataclasses.replace(job, frame_rate=frame_rate)
            if isinstance(job, (SweepPairJob, SequenceSweepPairJob))
            else job
            for job in jobs
        ]
    if not poses:
        jobs = [
            dataclasses.replace(job, poses=False) if isinstance(job, SequenceSweepPairJob) else job
            for job in jobs
        ]
    return jobs


def _dataset_jobs(path, layout, ground, pairs, capture_times, flow, topic, pattern, drop_ground):
    _check_choice(layout, "layout", LAYOUTS)
    _check_choice(pairs, "pairs", PAIRS)
    ground = _ground_choice(ground, drop_ground)
    if not isinstance(capture_times, (bool, np.bool_)):
        raise TypeError(f"capture_times must be True or False; got {capture_times!r}.")
    if pattern is not None and not isinstance(pattern, str):
        raise TypeError(f"pattern must be a str (a glob such as '*.bin'); got {pattern!r}.")
    capture_times = bool(capture_times)
    folder = Path(path)
    if not folder.exists():
        raise FileNotFoundError(f"{folder}: no such folder (the dataset).")
    sequences = [] if pattern is not None or not folder.is_dir() else _sequence_folders(folder)
    if layout in ("auto", "sequence") and flow is None and sequences:
        if pairs in ("truth", "aligned"):
            raise ValueError(f"{folder}: KITTI sequences have no flow to fit on; pairs='sweeps'.")
        if topic is not None:
            raise ValueError(f"{folder}: topic= (--topic) applies to a ROS bag only.")
        return _check_some(_sequences_jobs(sequences, ground, capture_times), folder)
    if layout == "sequence" or (
        layout == "auto" and flow is None and _is_sequence(folder, pattern)
    ):
        if pairs in ("truth", "aligned"):
            raise ValueError(
                f"{folder}: a KITTI sequence or a bag has no flow to fit on; pairs='sweeps'."
            )
        jobs = _sequence_jobs(folder, ground, capture_times, topic, pattern)
        return _check_some(jobs, folder)
    if topic is not None:
        raise ValueError(f"{folder}: topic= (--topic) applies to a ROS bag only.")
    if not folder.is_dir():
        raise ValueError(f"{folder}: not a folder; a dataset is a folder of files or logs.")
    if flow is not None:
        if not Path(flow).is_dir():
            raise FileNotFoundError(f"{flow}: no such folder (the scene flow to refine).")
        if pairs not in ("auto", "sweeps"):
            raise ValueError(f"flow is refined on raw sweeps; pairs={pairs!r} takes none.")
    truth = "truth" if pairs in ("truth", "aligned") else "sweeps"
    if layout in ("auto", "argoverse2") and pattern is None:
        options = (ground, truth, capture_times, "" if flow is None else str(flow))
        if _is_argoverse2_log(folder):
            return _check_some(_argoverse2_jobs(folder, *options), folder)
        logs = sorted(p for p in folder.iterdir() if p.is_dir() and _is_argoverse2_log(p))
        if logs:
            jobs = [job for log in logs for job in _argoverse2_jobs(log, *options, f"{log.name}_")]
            return _check_some(jobs, folder)
    if layout == "argoverse2":
        raise ValueError(
            f"{folder}: not an Argoverse 2 log (no sensors/lidar) nor a folder of logs."
        )
    if flow is not None:
        raise ValueError(
            f"{folder}: not an Argoverse 2 log nor a folder of logs; a flow folder "
            "(flow=, --flow) refines the sweeps of Argoverse 2 logs."
        )
    if pairs == "truth":
        raise ValueError(
            f"{folder}: pairs='truth' fits an Argoverse 2 log's ground-truth flow; this "
            "folder is no Argoverse 2 log."
        )
    return _file_jobs(folder, layout, pairs, pattern)


def _kinds(files):
    """``"3 .bin, 3 .pcd"``: how many files of each kind."""
    counts = Counter(_suffix(p) for p in files)
    return ", ".join(f"{count} {suffix}" for suffix, count in sorted(counts.items()))


def _suffix(path):
    name = path.name.lower()
    return next((s for s in SWEEP_EXTENSIONS if name.endswith(s)), path.suffix.lower())


def _file_jobs(folder, layout, pairs, pattern):
    """The jobs of a folder of frames or of correspondence files."""
    known = (*FRAME_EXTENSIONS, *SWEEP_EXTENSIONS, *CORRESPONDENCE_EXTENSIONS)
    files = [p for p in _listed(folder, pattern) if _suffix(p) in known]
    if not files:
        where = f"{folder}: no file matches {pattern!r}" if pattern else f"{folder}: no frames"
        raise ValueError(
            f"{where} ({', '.join(FRAME_EXTENSIONS)}, .npy, LiDAR sweeps "
            f"{', '.join(SWEEP_EXTENSIONS)}) nor correspondence files "
            f"({', '.join(CORRESPONDENCE_EXTENSIONS)})."
        )
    sweeps = [p for p in files if _sweep_file(p)]
    if sweeps and len(sweeps) < len(files):
        first = _suffix(sweeps[0])
        raise ValueError(
            f"{folder}: holds LiDAR sweeps and other files ({_kinds(files)}); choose one "
            f"kind with pattern='*{first}' (--pattern '*{first}')."
        )
    if layout == "auto":
        suffixes = {p.suffix.lower() for p in files}
        if sweeps or suffixes <= set(FRAME_EXTENSIONS):
            layout = "frames"
        elif suffixes == {".npy"}:
            columns = {_npy_columns(p) for p in files}
            if columns == {3}:
                layout = "frames"
            elif columns == {6}:
                layout = "correspondences"
            else:
                raise ValueError(
                    f"{folder}: its .npy files are neither all frames (n, 3) nor all "
                    f"correspondences (n, 6); found {sorted(map(str, columns))} columns."
                )
        elif suffixes & set(FRAME_EXTENSIONS):
            first = sorted(suffixes & set(FRAME_EXTENSIONS))[0]
            raise ValueError(
                f"{folder}: mixes point clouds and other files ({_kinds(files)}); a dataset "
                "folder holds frames or correspondence files, not both; choose one kind "
                f"with pattern='*{first}' (--pattern '*{first}')."
            )
        else:
            layout = "correspondences"
    if layout == "frames":
        if len(files) < 2:
            raise ValueError(f"{folder}: one frame only; a job is a pair of consecutive frames.")
        kind = FramePairJob if pairs == "aligned" else SweepPairJob  # auto: sweeps
        return [
            kind(f"{first.stem}__{second.stem}", str(first), str(second))
            for first, second in zip(files[:-1], files[1:], strict=True)
        ]
    if pairs == "sweeps":
        raise ValueError(
            f"{folder}: holds correspondence files; pairs='sweeps' needs frames (point "
            "clouds or (n, 3) .npy files) or Argoverse 2 logs."
        )
    names = [p.stem for p in files]
    if len(set(names)) != len(names):
        raise ValueError(f"{folder}: two files share a name but for the extension.")
    return [CorrespondenceFileJob(p.stem, str(p)) for p in files]


def check_jobs(jobs):
    """``jobs`` as a list, each with a ``name`` usable as a file name and a ``load()``."""
    jobs = list(jobs)
    names = []
    for job in jobs:
        name = getattr(job, "name", None)
        if not callable(getattr(job, "load", None)) or not isinstance(name, str):
            raise TypeError(f"a job needs a str 'name' and a 'load()' method; got {job!r}.")
        if not name or name in (".", "..") or os.sep in name or "/" in name or name[0] == ".":
            raise ValueError(f"job name {name!r} cannot be a file name.")
        names.append(name)
    repeated = sorted(name for name, count in Counter(names).items() if count > 1)
    if repeated:
        raise ValueError(f"job names must be unique; repeated: {repeated[:3]}.")
    return jobs


def warning_columns(caught):
    """The warnings ``caught`` as a job's or a log's row keeps them: ``warnings``, each
    message once, and ``input_warnings``, those that say the input is not what the
    registration reads: a length or the times not in the points' units
    (:class:`~mmreg.estimators.ScaleWarning`), points not in their sensor's frame
    (:class:`~mmreg.estimators.SensorFrameWarning`). The command line shows those
    without ``-v``: the result is wrong as it stands."""
    from mmreg.estimators import ScaleWarning, SensorFrameWarning

    def joined(found):
        return " | ".join(sorted({str(w.message) for w in found}))[:500]

    wrong = [w for w in caught if issubclass(w.category, (ScaleWarning, SensorFrameWarning))]
    return {"warnings": joined(caught), "input_warnings": joined(wrong)}
