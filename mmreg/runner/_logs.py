"""Whole LiDAR logs as jobs: one sequence fit per log on Dask, resumable log by log.

:func:`log_jobs` lists the logs of a dataset (a bag, a KITTI / SemanticKITTI sequence, an
Argoverse 2 log, a folder of frames; or a folder of logs: an Argoverse 2 split, KITTI's
``sequences/``), :func:`fit_log` fits a :class:`~mmreg.SequenceRegistration` on one log
frame by frame (``partial_fit``: the memory of a few frames) and :func:`run_logs` runs
every log as one task (in this process, or on a Dask cluster when several logs make
workers pay off) and writes its results:

``labels/<frame>.label``
    one little-endian ``uint32`` per row of the frame's file (invalid rows too, 0), the
    last frame included, in LiDAR-MOS's SemanticKITTI convention: lower 16 bits 251
    moving, 9 static, 0 unlabelled (outliers, the ego vehicle's body, invalid returns);
    upper 16 bits the track id (0 for the static world);
``tracks.csv``
    one row per track and frame, in the log's frame (the first sensor pose's):
    ``track, frame, time_s``, the centroid ``x_m, y_m, z_m``, the box ``length_m,
    width_m, height_m, yaw_rad``, the velocity ``vx_m_s, vy_m_s, vz_m_s, speed_m_s`` and
    ``yaw_rate_rad_s`` (per frame, ``..._m_frame`` and ``yaw_rate_rad_frame``, when the
    log has no times and no frame rate is given), ``points``;
``poses.txt``
    the sensor's pose of every frame in KITTI's format (12 numbers a line), the first
    the identity;
``frames.csv``
    one row per frame: its file's name, time (to the microsecond), rows, returns, moving
    points and objects, tracks, points of the static world and of the ego vehicle's
    body, and the seconds it took;
``pictures/<frame>.png`` and ``pictures/animation.gif`` (``pictures=True``)
    every frame from above and the whole log as one animated GIF;
``av2_scene_flow/<log>/<timestamp_ns>.feather`` (Argoverse 2 logs, at the top of ``out``)
    the flow of every point of each sweep but the last in the scene-flow challenge's
    format, ``is_dynamic`` the points of moving tracks;
``log.json``
    written last: the log's summary row, the fingerprint of (log, estimator) and the size
    and modification time of every file the log reads. A log whose record matches and
    whose files are all there is not run again.

A single log writes these into ``out``; a folder of logs into ``out/<log>/``, with
``out/summary.csv`` (one row per log).
"""

import contextlib
import dataclasses
import json
import math
import os
import shutil
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from mmreg import _interrupt
from mmreg.runner._jobs import (
    BrokenLogJob,
    SweepPairJob,
    _file_jobs,
    _is_argoverse2_log,
    _is_sequence,
    _sequence_folders,
    _valid_rows,
    warning_columns,
)
from mmreg.runner._workers import run_tasks, task_threads

__all__ = [
    "LOG_FILES",
    "LogJob",
    "NotALogError",
    "draw_log",
    "fit_log",
    "frame_names",
    "log_jobs",
    "read_log_record",
    "run_logs",
    "tracks_csv",
]

LABELS_FOLDER = "labels"
TRACKS_FILE = "tracks.csv"
POSES_FILE = "poses.txt"
FRAMES_FILE = "frames.csv"
LOG_RECORD = "log.json"
PICTURES_FOLDER = "pictures"
ANIMATION = "animation.gif"
SCENE_FLOW_FOLDER = "av2_scene_flow"
SUMMARY_FILE = "summary.csv"
#: What a log's folder holds.
LOG_FILES = (LABELS_FOLDER, TRACKS_FILE, POSES_FILE, FRAMES_FILE, LOG_RECORD, PICTURES_FOLDER)
# The frames' progress, from the workers to the progress bar (Dask's structured events).
PROGRESS_TOPIC = "mmreg-log-frames"
# The columns of a log's summary row, in this order; the rest follow.
SUMMARY_COLUMNS = [
    "log",
    "status",
    "frames",
    "tracks",
    "moving_objects_per_frame",
    "max_moving_objects",
    "s_per_frame",
    "points_per_frame",
    "load_s",
    "fit_s",
    "velocity_unit",
    "poses_given",
    "resumed",
    "error",
]
# SequenceRegistration.tracks_'s columns.
TRACK_COLUMNS = [
    "track", "frame", "time", "x", "y", "z", "length", "width", "height", "yaw",
    "vx", "vy", "vz", "speed", "yaw_rate", "points",
]  # fmt: skip
_FRAME_SUFFIXES = (".pcd.bin", ".bin", ".ply", ".pcd", ".xyz", ".npy", ".feather")


class NotALogError(ValueError):
    """The dataset holds no LiDAR log (correspondence files: pairs, not a log)."""


@dataclasses.dataclass(frozen=True)
class LogJob:
    """One LiDAR log, read by :func:`mmreg.datasets.open_sequence` where it runs.

    ``name``: the log's name (its folder's); ``folder``: where its results go inside the
    run's folder ("" for a run of one log); ``poses``: hand the log's poses (KITTI's
    ``poses.txt``, Argoverse 2's ego poses) to the estimator, from which its ego motions
    start; ``files``: every file it reads (for resuming); ``n_frames``: its frames;
    ``capture_times``: hand the points' capture times (Argoverse 2's ``offset_ns``, a
    bag's ``t`` field) to the estimator, whose pairs deskew the moving objects.
    """

    name: str
    path: str
    topic: str | None = None
    pattern: str | None = None
    poses: bool = True
    folder: str = ""
    files: tuple = ()
    n_frames: int = 0
    capture_times: bool = True

    def inputs(self):
        """The files the log reads."""
        return self.files

    def open(self):
        """The log as a sequence of frames."""
        from mmreg.datasets import open_sequence

        return open_sequence(self.path, topic=self.topic, pattern=self.pattern)


def frame_names(sequence):
    """One file name (without extension) per frame: ``labels/<name>.label``; a bag's frames
    are numbered ``000000``, ``000001``, ..."""
    if sequence.kind == "bag":
        return [f"{k:06d}" for k in range(len(sequence))]
    names = []
    for name in sequence.names:
        lower = name.lower()
        suffix = next((s for s in _FRAME_SUFFIXES if lower.endswith(s)), "")
        names.append(name[: len(name) - len(suffix)] if suffix else Path(name).stem)
    return names


def _log_files(sequence):
    """Every file a log's fit reads: its frames, and a KITTI sequence's poses, calibration
    and times, an Argoverse 2 log's ego poses, a bag's files."""
    files = getattr(sequence, "_files", None)
    if files is None:  # a bag: its file, or every file of a ROS 2 bag folder
        path = Path(sequence.path)
        if path.is_dir():
            return tuple(sorted(str(p) for p in path.iterdir() if p.is_file()))
        return (str(path),)
    found = [str(p) for p in files]
    root = Path(sequence.path)
    if sequence.kind == "kitti":
        extra = [root / "poses.txt", root / "calib.txt", root / "times.txt"]
        extra.append(root.parent.parent / "poses" / f"{root.name}.txt")
        found += [str(p) for p in extra if p.is_file()]
    elif sequence.kind == "argoverse2":
        log = root if (root / "sensors" / "lidar").is_dir() else root.parent.parent
        if (log / "city_SE3_egovehicle.feather").is_file():
            found.append(str(log / "city_SE3_egovehicle.feather"))
    return tuple(found)


def _log_job(path, name, folder, topic, pattern, poses, split, capture_times=True):
    """The job of one log; in a split (``split``), a log that cannot be read or has one
    frame is a failed row (the others go on)."""
    from mmreg.datasets import open_sequence

    try:
        sequence = open_sequence(path, topic=topic, pattern=pattern)
        if len(sequence) < 2:
            raise ValueError(f"{path}: one frame only; a log needs at least 2.")
    except (OSError, ValueError) as error:
        if not split:
            raise
        return BrokenLogJob(name, str(path), " ".join(str(error).split()))
    return LogJob(
        name,
        str(path),
        topic,
        pattern,
        bool(poses),
        folder,
        _log_files(sequence),
        len(sequence),
        bool(capture_times),
    )


def log_jobs(path, *, layout="auto", topic=None, pattern=None, poses=True, capture_times=True):
    """The logs of a dataset, one job each, in a stable order.

    Parameters
    ----------
    path : str or path-like
        A ROS bag, a KITTI / SemanticKITTI sequence (``velodyne/``), an Argoverse 2 log
        (``sensors/lidar``), a folder of frames (``.ply``, ``.pcd``, ``.xyz``, ``.bin``,
        ``.pcd.bin``, (n, 3) ``.npy``): one log, whose results go to the run's folder;
        or a folder of logs (Argoverse 2 logs, KITTI sequences, or the KITTI root
        holding ``sequences/``): one job per log, its results in ``<log>/``.
    layout : {"auto", "argoverse2", "sequence", "frames"}, default="auto"
        What ``path`` holds (as :func:`mmreg.runner.dataset_jobs`'s).
    topic : str, optional
        A bag's PointCloud2 topic (needed when it has several).
    pattern : str, optional
        A glob picking the frames of a folder holding several kinds.
    poses : bool, default=True
        Hand each log's poses, where it has them, to the estimator.
    capture_times : bool, default=True
        Hand the points' capture times, where the log has them (Argoverse 2, a bag's
        per-point time field), to the estimator, which deskews the moving objects.

    Returns
    -------
    jobs : list of LogJob (and BrokenLogJob: a log of a folder of logs that cannot be
        read)

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    NotALogError
        If ``path`` holds correspondence files (or ``layout="correspondences"``).
    ValueError
        If a single log cannot be read, or the folder mixes kinds of files.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.runner._logs import log_jobs
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     for k in range(3):
    ...         np.save(Path(folder) / f"frame{k}.npy", np.ones((5, 3)) * k)
    ...     (job,) = log_jobs(folder)
    >>> job.n_frames, job.folder, len(job.inputs())
    (3, '', 3)
    """
    folder = Path(path)
    if not folder.exists():
        raise FileNotFoundError(f"{folder}: no such file or folder (the dataset).")
    if layout == "correspondences":
        raise NotALogError(f"{folder}: correspondence files are pairs, not a LiDAR log.")
    name = Path(os.path.abspath(folder)).name or folder.name
    options = {"topic": topic, "pattern": pattern, "poses": poses, "capture_times": capture_times}

    def one():
        return [_log_job(folder, name, "", split=False, **options)]

    sequences = [] if pattern is not None or not folder.is_dir() else _sequence_folders(folder)
    if layout in ("auto", "sequence") and sequences:
        if topic is not None:
            raise ValueError(f"{folder}: topic= (--topic) applies to a ROS bag only.")
        return [_log_job(p, p.name, p.name, split=True, **options) for p in sequences]
    if layout in ("auto", "argoverse2") and pattern is None and folder.is_dir():
        if _is_argoverse2_log(folder):
            return one()
        logs = sorted(p for p in folder.iterdir() if p.is_dir() and _is_argoverse2_log(p))
        if logs:
            return [_log_job(p, p.name, p.name, split=True, **options) for p in logs]
    if layout == "argoverse2":
        raise ValueError(
            f"{folder}: not an Argoverse 2 log (no sensors/lidar) nor a folder of logs."
        )
    if layout == "sequence" or _is_sequence(folder, pattern):
        return one()
    if topic is not None:
        raise ValueError(f"{folder}: topic= (--topic) applies to a ROS bag only.")
    if not folder.is_dir():
        raise ValueError(f"{folder}: not a folder; a log is a bag or a folder of frames.")
    jobs = _file_jobs(folder, layout, "auto", pattern)  # its errors: mixed kinds, no frames
    if all(isinstance(job, SweepPairJob) for job in jobs):
        return one()
    raise NotALogError(f"{folder}: holds correspondence files, pairs rather than a LiDAR log.")


# --------------------------------------------------------------------------- one log
def _to_log_frame(table, first):
    """Tracks' rows from the estimator's world into the log's frame (``inv(first)``)."""
    if not len(table):
        return table
    inverse = np.linalg.inv(first)
    rotation, translation = inverse[:3, :3], inverse[:3, 3]
    table = table.copy()
    centre = table[["x", "y", "z"]].to_numpy(float) @ rotation.T + translation
    velocity = table[["vx", "vy", "vz"]].to_numpy(float) @ rotation.T
    yaw = table["yaw"].to_numpy(float)
    heading = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], axis=1) @ rotation.T
    table[["x", "y", "z"]] = centre
    table[["vx", "vy", "vz"]] = velocity
    table["yaw"] = np.arctan2(heading[:, 1], heading[:, 0])
    return table


def tracks_csv(table, per_second):
    """The tracks' table with the units in its column names, as ``tracks.csv`` holds it.

    Examples
    --------
    >>> import pandas as pd
    >>> from mmreg.runner._logs import tracks_csv
    >>> columns = ["track", "frame", "time", "x", "y", "z", "length", "width", "height",
    ...            "yaw", "vx", "vy", "vz", "speed", "yaw_rate", "points"]
    >>> list(tracks_csv(pd.DataFrame(columns=columns), per_second=False).columns)[9:15]
    ['yaw_rad', 'vx_m_frame', 'vy_m_frame', 'vz_m_frame', 'speed_m_frame', 'yaw_rate_rad_frame']
    """
    per = "s" if per_second else "frame"
    names = {
        "time": "time_s",
        "x": "x_m",
        "y": "y_m",
        "z": "z_m",
        "length": "length_m",
        "width": "width_m",
        "height": "height_m",
        "yaw": "yaw_rad",
        "vx": f"vx_m_{per}",
        "vy": f"vy_m_{per}",
        "vz": f"vz_m_{per}",
        "speed": f"speed_m_{per}",
        "yaw_rate": f"yaw_rate_rad_{per}",
    }
    table = table.rename(columns=names)
    if not per_second:
        table["time_s"] = math.nan  # the estimator's clock was the frame number
    return table


def _reporter(name):
    """A function telling the client that a frame is done, on a Dask worker; else None."""
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):
        return None

    def report(k):
        with contextlib.suppress(Exception):  # progress is never worth a failed log
            worker.log_event(PROGRESS_TOPIC, {"log": name, "frame": k})

    return report


def _picture(points, raw, body, pose, tracks, k, title):
    from mmreg.plotting._log import plot_log_frame

    ax = plot_log_frame(
        points,
        (raw & 0xFFFF).astype(np.int64),
        (raw >> 16).astype(np.int64),
        pose,
        tracks=tracks,
        frame=k,
        body=body,
        title=title,
    )
    import io

    buffer = io.BytesIO()
    ax.get_figure().savefig(buffer, format="png", dpi=100)
    return buffer.getvalue()


def fit_log(job, estimator, *, pictures=False, report=None):
    """Fit ``estimator`` on one log, frame by frame; what :func:`run_logs` writes.

    Each frame goes to ``partial_fit`` with its time (where the log has times) and pose
    (where it has poses and ``job.poses``); a frame's result comes once the estimator
    makes it final, so only a few frames are held at once.

    Parameters
    ----------
    job : LogJob
    estimator : SequenceRegistration
        Cloned, not changed.
    pictures : bool, default=False
        Also draw every frame (PNG bytes) and the log's animation (GIF bytes).
    report : callable, optional
        Called with each frame's number once it is fitted.

    Returns
    -------
    result : dict
        ``names`` (one per frame), ``labels`` (per frame, uint32, the ``.label`` file's
        values), ``poses`` (n_frames, 4, 4; the first the identity), ``tracks`` (a
        DataFrame in the log's frame, the estimator's column names), ``frames`` (a
        DataFrame, one row per frame), ``per_second`` (velocities per second),
        ``challenge`` (Argoverse 2: ``(relative path, flow, is_dynamic)`` per sweep but
        the last), ``pictures`` and ``animation`` (or None), ``row`` (the summary).

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg import SequenceRegistration
    >>> from mmreg.datasets import make_lidar_sequence
    >>> from mmreg.runner import fit_log, log_jobs
    >>> log = make_lidar_sequence(3, n_azimuths=128, random_state=0)
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     for k, frame in enumerate(log.frames):
    ...         np.save(Path(folder) / f"scan{k}.npy", frame)
    ...     (job,) = log_jobs(folder)
    ...     result = fit_log(job, SequenceRegistration(random_state=0))
    >>> result["names"], [len(raw) for raw in result["labels"]] == [len(f) for f in log.frames]
    (['scan0', 'scan1', 'scan2'], True)
    >>> bool(np.allclose(result["poses"][0], np.eye(4)))
    True
    """
    import pandas as pd
    from sklearn.base import clone

    from mmreg.io import semantickitti_mos_labels
    from mmreg.io._semantickitti import MOS_STATIC

    start = time.perf_counter()
    sequence = job.open()
    names = frame_names(sequence)
    n = len(sequence)
    if n < 2:
        raise ValueError(f"{job.path}: one frame only; a log needs at least 2.")
    poses = getattr(sequence, "poses", None) if job.poses else None
    model = clone(estimator)
    av2 = sequence.kind == "argoverse2"
    log_id = Path(os.path.abspath(job.path)).name
    held = {}  # frame number -> its points, until its result is final
    labels, rel_poses, tables, rows = [None] * n, [None] * n, [], []
    challenge, drawn = [], []
    state = {"first": None, "timed": None}
    load_s, fit_s = np.zeros(n), np.zeros(n)
    opened = time.perf_counter() - start  # counted with the first frame
    waiting_flow = {}  # Argoverse 2: sweep k's flow waits for sweep k + 1's pose

    def take(results):
        for r in results:
            k = int(r.index)
            if state["first"] is None:
                state["first"] = np.asarray(r.pose, float)
            pose = np.linalg.inv(state["first"]) @ np.asarray(r.pose, float)
            rel_poses[k] = pose
            semantic, instance = semantickitti_mos_labels(r.labels, r.moving)
            raw = (instance.astype(np.uint32) << 16) | semantic.astype(np.uint32)
            labels[k] = raw
            table = _to_log_frame(r.tracks, state["first"])
            if len(table):
                tables.append(table)
            moving_ids = np.unique(np.asarray(r.labels)[np.asarray(r.moving, bool)])
            points = held.pop(k)
            body = getattr(r, "body", None)
            rows.append(
                {
                    "frame": k,
                    "name": names[k],
                    "time_s": r.time if state["timed"] or model.frame_rate else math.nan,
                    "points": len(points),
                    "returns": int(_valid_rows(points).sum()),
                    "moving_points": int(np.count_nonzero(r.moving)),
                    "moving_objects": int(np.count_nonzero(moving_ids > 0)),
                    "tracks": int(len(np.unique(instance[instance > 0]))),
                    "unlabelled_points": int(np.count_nonzero(semantic == 0)),
                    "static_points": int(np.count_nonzero(semantic == MOS_STATIC)),
                    "ego_body_points": 0 if body is None else int(np.count_nonzero(body)),
                    "load_s": float(load_s[k]),
                    "fit_s": float(fit_s[k]),
                }
            )
            if av2:
                waiting_flow[k] = (points, np.asarray(r.flow, float), np.asarray(r.moving, bool))
                _flush_flows(waiting_flow, rel_poses, names, log_id, challenge, n)
            if pictures:
                every = pd.concat(tables, ignore_index=True) if tables else None
                title = (
                    f"{job.name} {names[k]} ({k + 1}/{n}): "
                    f"{rows[-1]['moving_objects']} moving, {rows[-1]['tracks']} tracks"
                )
                drawn.append(_picture(points, raw, body, pose, every, k, title))
            if report is not None:
                report(k)

    for k in range(n):
        begin = time.perf_counter()
        frame = sequence[k]
        load_s[k] = time.perf_counter() - begin + (opened if k == 0 else 0.0)
        stamp = frame.timestamp
        if state["timed"] is None:
            state["timed"] = stamp is not None
        elif state["timed"] != (stamp is not None):
            raise ValueError(f"{frame.source}: has no time while the log's other frames do.")
        pose = None if poses is None else poses[k]
        held[k] = np.asarray(frame.points, float)
        begin = time.perf_counter()
        capture = None
        if state["timed"] and job.capture_times and frame.times is not None:
            capture = frame.times  # the pairs deskew the moving objects
        model.partial_fit(
            frame.points,
            time=stamp if state["timed"] else None,
            pose=pose,
            point_times=capture,
        )
        fit_s[k] = time.perf_counter() - begin
        take(model.finished_)
        _interrupt.check()
    begin = time.perf_counter()
    model.finish()
    fit_s[n - 1] += time.perf_counter() - begin
    take(model.finished_)
    per_second = bool(state["timed"] or model.frame_rate is not None)
    tracks = (
        pd.concat(tables, ignore_index=True).sort_values(["track", "frame"], ignore_index=True)
        if tables
        else pd.DataFrame(columns=TRACK_COLUMNS)
    )
    frames = pd.DataFrame(rows).sort_values("frame", ignore_index=True)
    frames["fit_s"] = fit_s  # the last frame's finish() is counted in
    frames["load_s"] = load_s
    animation = None
    if pictures:
        order = np.argsort([r["frame"] for r in rows])
        drawn = [drawn[i] for i in order]
        animation = _animation(drawn, frames["time_s"].to_numpy(float), model.frame_rate)
    row = _summary_row(job, frames, tracks, per_second, poses is not None)
    return {
        "names": names,
        "labels": labels,
        "poses": np.stack(rel_poses),
        "tracks": tracks,
        "frames": frames,
        "per_second": per_second,
        "challenge": challenge,
        "pictures": drawn if pictures else None,
        "animation": animation,
        "row": row,
    }


def _flush_flows(waiting, poses, names, log_id, challenge, n):
    """Argoverse 2: each sweep's flow once the next sweep's pose is known, in the
    challenge's format; rows without a flow move with the static world."""
    from mmreg.runner import sweep_flow

    for k in sorted(waiting):
        if k == n - 1:  # the last sweep has no next one: no flow
            del waiting[k]
            continue
        if poses[k + 1] is None:
            break
        points, flow, moving = waiting.pop(k)
        motion = np.linalg.inv(poses[k + 1]) @ poses[k]  # frame k's points to frame k + 1
        finite = np.nan_to_num(points)
        out, _ = sweep_flow(finite, np.arange(len(points)), flow, motion[:3, :3], motion[:3, 3])
        challenge.append((f"{log_id}/{names[k]}.feather", out.astype(np.float32), moving))


def _animation(pictures, times, frame_rate):
    from mmreg.plotting._log import animate_log

    if not pictures:
        return None
    steps = np.diff(times)
    if len(steps) and np.all(np.isfinite(steps)):
        seconds = float(np.median(steps))
    elif frame_rate:
        seconds = 1.0 / frame_rate
    else:
        seconds = 0.2
    return animate_log(pictures, seconds_per_frame=float(np.clip(seconds, 0.1, 1.0)))


def _summary_row(job, frames, tracks, per_second, poses_given):
    fits = frames["fit_s"].to_numpy(float)
    return {
        "log": job.name,
        "status": "done",
        "frames": int(len(frames)),
        "tracks": int(tracks["track"].nunique()) if len(tracks) else 0,
        "moving_objects_per_frame": float(frames["moving_objects"].mean()),
        "max_moving_objects": int(frames["moving_objects"].max()),
        "s_per_frame": float(fits[1:].mean()) if len(fits) > 1 else math.nan,
        "points_per_frame": float(frames["points"].mean()),
        "load_s": float(frames["load_s"].sum()),
        "fit_s": float(fits.sum()),
        "velocity_unit": "m/s" if per_second else "m/frame",
        "poses_given": bool(poses_given),
    }


def _process_log(job, estimator, pictures, report=None):
    """Fit one log (on a worker, or here with ``report``: called with each frame done):
    ``(name, result or None, row)``; an error is the log's row, the others go on."""
    row = {"log": job.name, "status": "error"}
    try:
        if isinstance(job, BrokenLogJob):
            raise ValueError(job.error)
        report = _reporter(job.name) if report is None else report
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = fit_log(job, estimator, pictures=pictures, report=report)
        row = result["row"]
        row.update(warning_columns(caught))
    except Exception as error:  # one log's failure is its row, not the run's end
        row["error"] = f"{type(error).__name__}: {' '.join(str(error).split())}"[:1000]
        return job.name, None, row
    return job.name, result, row


# --------------------------------------------------------------------------- the files
def read_log_record(folder):
    """A log folder's ``log.json`` (a dict), or None when missing or unreadable."""
    try:
        record = json.loads((Path(folder) / LOG_RECORD).read_text())
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) and "row" in record else None


def _expected_files(folder, record, out, pictures):
    files = [Path(folder) / TRACKS_FILE, Path(folder) / POSES_FILE, Path(folder) / FRAMES_FILE]
    files += [Path(folder) / LABELS_FOLDER / f"{name}.label" for name in record["frames"]]
    files += [Path(out) / SCENE_FLOW_FOLDER / p for p in record.get("challenge", [])]
    if pictures:
        files.append(Path(folder) / PICTURES_FOLDER / ANIMATION)
    return files


def _finished(job, folder, out, fingerprint, stamps, pictures):
    """``(row, changed)``: the row of the log's complete earlier result (None if there is
    none, it is of another log or estimator, a file is missing, or an input changed:
    ``changed`` names that input)."""
    from mmreg.runner import _changed_input

    record = read_log_record(folder)
    if record is None or record.get("fingerprint") != fingerprint:
        return None, ""
    changed = _changed_input(stamps, record.get("inputs"))
    if changed:
        return None, changed
    if not all(p.is_file() for p in _expected_files(folder, record, out, False)):
        return None, ""
    return record["row"], ""


def _pictures_missing(folder, record):
    """Whether a finished log lacks a picture of a frame or its animation."""
    pictures = Path(folder) / PICTURES_FOLDER
    names = [f"{name}.png" for name in record["frames"]] + [ANIMATION]
    return not all((pictures / name).is_file() for name in names)


def draw_log(job, folder):
    """The pictures of a finished log drawn from its files (``labels/``, ``poses.txt``,
    ``tracks.csv``, ``frames.csv``) and its frames, without fitting it again: written
    into ``folder/pictures/``, as :func:`fit_log` draws them (the ego vehicle's body is
    drawn with the unlabelled points: the files do not tell it apart)."""
    import pandas as pd

    from mmreg import io as mmio

    folder = Path(folder)
    record = read_log_record(folder)
    names = [str(n) for n in record["frames"]]
    sequence = job.open()
    if len(sequence) != len(names):
        raise ValueError(
            f"{job.path}: holds {len(sequence)} frames but its result {len(names)}; the log "
            "changed since it was run."
        )
    poses = mmio.read_kitti_poses(folder / POSES_FILE)
    tracks = pd.read_csv(folder / TRACKS_FILE).rename(
        columns={"x_m": "x", "y_m": "y", "z_m": "z", "time_s": "time"}
    )
    frames = pd.read_csv(folder / FRAMES_FILE, dtype={"name": str})
    drawn = []
    n = len(names)
    for k, name in enumerate(names):
        raw = np.fromfile(folder / LABELS_FOLDER / f"{name}.label", dtype="<u4")
        points = np.asarray(sequence[k].points, float)
        if len(raw) != len(points):
            raise ValueError(
                f"{folder / LABELS_FOLDER / (name + '.label')}: {len(raw)} labels for the "
                f"{len(points)} rows of frame {k}; the log changed since it was run."
            )
        row = frames.iloc[k]
        title = (
            f"{job.name} {name} ({k + 1}/{n}): "
            f"{int(row['moving_objects'])} moving, {int(row['tracks'])} tracks"
        )
        shown = tracks[tracks["frame"] <= k] if len(tracks) else None
        drawn.append(_picture(points, raw, None, poses[k], shown, k, title))
    animation = _animation(drawn, frames["time_s"].to_numpy(float), None)
    target = folder / PICTURES_FOLDER
    target.mkdir(exist_ok=True)
    for name, png in zip(names, drawn, strict=True):
        with mmio.atomic_write(target / f"{name}.png") as handle:
            handle.write(png)
    with mmio.atomic_write(target / ANIMATION) as handle:
        handle.write(animation)


def _write_log(folder, out, job, result, row, fingerprint, stamps):
    """Every file of one log; ``log.json`` last, so that a log is done once it is there."""
    import pandas as pd

    from mmreg import io as mmio
    from mmreg.runner import write_scene_flow

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    with contextlib.suppress(FileNotFoundError):
        (folder / LOG_RECORD).unlink()  # not done until written again
    for name in (LABELS_FOLDER, PICTURES_FOLDER):  # an earlier run's frames may differ
        if (folder / name).is_dir():
            shutil.rmtree(folder / name)
    (folder / LABELS_FOLDER).mkdir()
    for name, raw in zip(result["names"], result["labels"], strict=True):
        mmio.write_semantickitti_labels(
            folder / LABELS_FOLDER / f"{name}.label", raw & 0xFFFF, raw >> 16
        )
    tracks = tracks_csv(result["tracks"], result["per_second"])
    with mmio.atomic_write(folder / TRACKS_FILE, "w") as handle:
        _exact_times(tracks).to_csv(handle, index=False, float_format="%.6g")
    mmio.write_kitti_poses(folder / POSES_FILE, result["poses"])
    frames = pd.DataFrame(result["frames"])
    with mmio.atomic_write(folder / FRAMES_FILE, "w") as handle:
        _exact_times(frames).to_csv(handle, index=False, float_format="%.6g")
    if result["pictures"] is not None:
        (folder / PICTURES_FOLDER).mkdir()
        for name, png in zip(result["names"], result["pictures"], strict=True):
            with mmio.atomic_write(folder / PICTURES_FOLDER / f"{name}.png") as handle:
                handle.write(png)
        with mmio.atomic_write(folder / PICTURES_FOLDER / ANIMATION) as handle:
            handle.write(result["animation"])
    challenge = []
    for relative, flow, dynamic in result["challenge"]:
        write_scene_flow(Path(out) / SCENE_FLOW_FOLDER / relative, flow, dynamic)
        challenge.append(relative)
    record = {
        "fingerprint": fingerprint,
        "inputs": stamps,
        "row": row,
        "log": job.name,
        "path": str(Path(job.path).resolve()),
        "topic": job.topic,
        "pattern": job.pattern,
        "frames": list(result["names"]),
        "challenge": challenge,
        "velocity_unit": row.get("velocity_unit"),
    }
    from mmreg.runner import json_value

    with mmio.atomic_write(folder / LOG_RECORD, "w") as handle:
        handle.write(json.dumps(record, indent=1, default=json_value) + "\n")


def _exact_times(table):
    """``table`` with its ``time_s`` to the microsecond: a bag's stamps are seconds since
    1970, which six significant digits round to a quarter of an hour."""
    if "time_s" not in table or not len(table):
        return table
    times = table["time_s"].to_numpy(float)
    text = np.where(np.isfinite(times), np.char.mod("%.6f", times), "")
    return table.assign(time_s=text)


def run_logs(
    jobs,
    estimator=None,
    out="mmreg-run",
    *,
    scheduler=None,
    n_workers=None,
    overwrite=False,
    progress=True,
    pictures=False,
):
    """Fit ``estimator`` on every log, one task per log; resumable log by log.

    Parameters
    ----------
    jobs : list of LogJob
        From :func:`log_jobs` (a failed listing, BrokenLogJob, is a failed row).
    estimator : SequenceRegistration, default=None
        None: ``SequenceRegistration(random_state=0)``.
    out : str or path-like
        The run's folder: a single log's files go there, a folder of logs' into
        ``out/<log>/`` (``job.folder``), with ``out/summary.csv``.
    scheduler : str, default=None
        Address of a running Dask scheduler; None starts a LocalCluster.
    n_workers : int, default=None
        Worker processes of a LocalCluster; 0, or None with a single log: in this
        process, no cluster; None with several: chosen as :func:`run_dataset` chooses.
    overwrite : bool, default=False
        Run every log again.
    progress : bool, default=True
        A progress bar over the frames on stderr.
    pictures : bool, default=False
        Draw every frame and the log's animation (``pictures/``); a finished log without
        them gets them drawn from its files (:func:`draw_log`), not fitted again.

    Returns
    -------
    summary : pandas.DataFrame
        One row per log: ``log``, ``status``, ``frames``, ``tracks``,
        ``moving_objects_per_frame``, ``max_moving_objects``, ``s_per_frame`` (the fit's
        seconds per frame), ``points_per_frame``, ``load_s``, ``fit_s``,
        ``velocity_unit``, ``poses_given``, ``resumed``, ``error``, ``warnings``,
        ``input_warnings`` (those that say the input is not in the points' units or
        their sensor's frame), ``changed_input`` (a log
        run again because that file changed), ``picture_error``;
        ``summary.attrs["plan"]``: where the logs ran, as :func:`run_dataset`'s.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from distributed import LocalCluster
    >>> from mmreg import SequenceRegistration
    >>> from mmreg.datasets import make_lidar_sequence
    >>> from mmreg.runner import log_jobs, run_logs
    >>> log = make_lidar_sequence(3, n_azimuths=128, random_state=0)
    >>> with tempfile.TemporaryDirectory() as folder, LocalCluster(
    ...         n_workers=1, processes=False, dashboard_address=":0") as cluster:
    ...     for k, frame in enumerate(log.frames):
    ...         np.save(Path(folder) / f"scan{k}.npy", frame)
    ...     summary = run_logs(log_jobs(folder), SequenceRegistration(random_state=0),
    ...                        Path(folder) / "out", scheduler=cluster.scheduler_address,
    ...                        progress=False)
    ...     labels = sorted(p.name for p in (Path(folder) / "out" / "labels").iterdir())
    >>> summary[["status", "frames"]].values.tolist(), labels
    ([['done', 3]], ['scan0.label', 'scan1.label', 'scan2.label'])
    """
    import pandas as pd
    from tqdm import tqdm

    from mmreg.runner import _describe, _input_stamps

    if estimator is None:
        from mmreg import SequenceRegistration

        estimator = SequenceRegistration(random_state=0)
    jobs = list(jobs)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    folders = {job.name: out / getattr(job, "folder", "") for job in jobs}
    fingerprints = {job.name: _log_fingerprint(job, estimator, _describe) for job in jobs}
    stamps = {job.name: _input_stamps(job) for job in jobs}
    rows, todo, changed, redraw = {}, [], {}, []
    for job in jobs:
        found = None
        if not overwrite and not isinstance(job, BrokenLogJob):
            found, changed[job.name] = _finished(
                job, folders[job.name], out, fingerprints[job.name], stamps[job.name], pictures
            )
        if found is None:
            todo.append(job)
        else:
            rows[job.name] = found | {"resumed": True}
            record = read_log_record(folders[job.name])
            if pictures and _pictures_missing(folders[job.name], record):
                redraw.append(job)  # --pictures added to a finished run: drawn from files
    total = sum(getattr(job, "n_frames", 0) for job in jobs)
    done = sum(getattr(job, "n_frames", 0) for job in jobs if job.name in rows)
    bar = tqdm(
        total=total,
        initial=done,
        disable=not progress,
        file=sys.stderr,
        unit="frame",
        desc="mmreg run",
    )

    def handle(name, result, row):
        if result is not None:
            job = by_name[name]
            _write_log(folders[name], out, job, result, row, fingerprints[name], stamps[name])
        else:  # an earlier result of this log is of other inputs: no longer its result
            with contextlib.suppress(OSError):
                (folders[name] / LOG_RECORD).unlink()
        rows[name] = row | {"resumed": False}
        _interrupt.check()

    def here(chosen):
        for job in chosen:
            handle(*_process_log(job, estimator, pictures, report=lambda k: bar.update(1)))

    def cluster(chosen, address, workers):
        begin = time.perf_counter()
        from mmreg.runner import dask_client

        with dask_client(address, workers, needed_by="run_logs") as client:
            start_s = time.perf_counter() - begin
            _run_on(client, chosen, estimator, pictures, bar, handle)
        return start_s

    by_name = {job.name: job for job in jobs}
    plan = {"where": "this process", "workers": 0, "start_s": 0.0, "why": "nothing to run"}
    with bar:
        broken = [job for job in todo if isinstance(job, BrokenLogJob)]
        for job in broken:
            rows[job.name] = _process_log(job, estimator, pictures)[2] | {"resumed": False}
        todo = [job for job in todo if not isinstance(job, BrokenLogJob)]
        plan = run_tasks(
            todo,
            here,
            cluster,
            scheduler=scheduler,
            n_workers=n_workers,
            threads=task_threads(estimator),
        )
        for job in redraw:
            try:
                draw_log(job, folders[job.name])
            except Exception as error:  # a picture's failure is a note, not the log's
                rows[job.name]["picture_error"] = f"{type(error).__name__}: {error}"[:500]
        for name, change in changed.items():
            if change and name in rows and not rows[name].get("resumed"):
                rows[name]["changed_input"] = change
    frame = pd.DataFrame([rows[job.name] for job in jobs])
    columns = SUMMARY_COLUMNS + [c for c in frame.columns if c not in SUMMARY_COLUMNS]
    frame = frame.reindex(columns=columns)
    for column in ("error", "changed_input", "warnings", "input_warnings", "picture_error"):
        if column in frame:
            frame[column] = frame[column].astype(object).where(frame[column].notna(), "")
    if any(getattr(job, "folder", "") for job in jobs):
        from mmreg import io as mmio

        with mmio.atomic_write(out / SUMMARY_FILE, "w") as handle:
            frame.to_csv(handle, index=False, float_format="%.6g")
    frame.attrs["plan"] = plan | {"redrawn": len(redraw)}
    return frame


def _run_on(client, todo, estimator, pictures, bar, handle):
    """Submit every log, hand each to ``handle(name, result, row)`` as it comes back."""
    from distributed import as_completed

    def advance(event):
        bar.update(1)

    with contextlib.suppress(Exception):  # no progress events: the bar moves by logs
        client.subscribe_topic(PROGRESS_TOPIC, advance)
    futures = [client.submit(_process_log, job, estimator, pictures, pure=False) for job in todo]
    names = {future.key: job.name for future, job in zip(futures, todo, strict=True)}
    for future in as_completed(futures):
        try:
            name, result, row = future.result()
        except Exception as error:  # a lost worker, a result that cannot be sent
            name = names[future.key]
            result = None
            row = {"log": name, "status": "error", "error": f"{type(error).__name__}: {error}"}
        handle(name, result, row)
        future.release()
    with contextlib.suppress(Exception):
        client.unsubscribe_topic(PROGRESS_TOPIC)


def _log_fingerprint(job, estimator, describe):
    """What a log's result depends on: the job, the estimator with its parameters, mmreg."""
    import hashlib

    from sklearn.base import clone

    from mmreg import __version__

    if "n_jobs" in estimator.get_params(deep=False):  # the same results on any number
        estimator = clone(estimator).set_params(n_jobs=None)
    text = "\n".join(["log", repr(job), describe(estimator), __version__])
    return hashlib.sha256(text.encode("utf-8", "surrogateescape")).hexdigest()[:16]
