"""KISS-ICP odometry on the nuScenes logs: the floor for a log's ego motion.

    pip install -e ".[bench]"        # kiss-icp, a benchmark extra, not a dependency
    python benchmarks/kiss_odometry.py --data /work/data

A log is a folder in the SemanticKITTI layout: ``velodyne/NNNNNN.bin`` (float32 rows of
x, y, z, intensity, in the LiDAR's frame) and ``poses.txt`` (the LiDAR's pose in the world
of every frame, the first 3 rows of the 4 x 4 matrix, 12 numbers a line). The nuScenes
logs hold their 2 Hz keyframes, 0.5 s apart (the car moves 1.5-5 m between them).

For each log the script runs KISS-ICP's own pipeline (:func:`kiss_icp_odometry`:
``kiss_icp.kiss_icp.KissICP``, a local voxel map, its constant-velocity guess and adaptive
threshold) over every frame and prints, and writes to ``benchmarks/results/kiss_icp.md``:
frames, points per frame, seconds per frame (median and mean, wall and CPU), the relative
pose error of every pair of consecutive frames against ``poses.txt`` (translation in m,
rotation in degrees, mean and max) and the absolute trajectory error (ATE: where the
trajectory puts the sensor, the first frames aligned; RMS and max). Beside it, mmreg's own
ego motion of each pair of frames (``SweepRegistration(random_state=0).fit(frame_k,
sweep=frame_k+1).ego_motion_``, raw frames in: it sets the ego car's body apart itself)
on the logs named by ``--mmreg`` (all by default), and its pair motions chained into a
trajectory. KISS-ICP runs on one thread (``--threads``), as mmreg's fits mostly do.

The settings, for sensor and logs alike (``--min-range``, ``--max-range``):

* ``min_range = 2.5`` m: about a fifth to a quarter of a nuScenes point cloud is the ego
  car's own body (labelled 31, all within 2.3 m of the sensor) and a few returns at the
  sensor; they ride along with it and would pull the ego motion towards standing still.
* ``max_range = 70`` m: the HDL-32E's rated range (99 % of the returns of both logs lie
  within 68 m); KISS-ICP's voxel is then ``max_range / 100`` = 0.7 m.
* No deskewing: the files hold no capture time per point, and KISS-ICP's deskewing spreads
  the motion between two frames over each frame's capture times, which is right only when
  a frame lasts as long as the gap between frames (a 20 Hz sensor's 0.05 s sweeps are
  0.5 s apart here).

Rows with KISS-ICP's defaults (``max_range = 100``, 1 m voxels) and without ``min_range``
show what those choices change.

(Not ``benchmarks/kiss_icp.py``: the benchmarks that put this folder on ``sys.path`` would
import it in place of the ``kiss_icp`` package.)
"""

import argparse
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
LOGS = ("scene-0004", "scene-0006")
FRAME_RATE = 2.0  # nuScenes keyframes
MIN_RANGE = 2.5
MAX_RANGE = 70.0


@dataclass
class Odometry:
    """Poses of a sequence of frames and what they cost.

    ``poses`` (N, 4, 4): frame ``k``'s points into the first frame's (``poses[0]`` the
    identity); ``wall_s``, ``cpu_s`` (N,): seconds spent on each frame (CPU: this
    process, every thread); ``points`` (N,): points given per frame; ``frame_rate``:
    frames per second of the log, if known.
    """

    poses: np.ndarray
    wall_s: np.ndarray
    cpu_s: np.ndarray
    points: np.ndarray
    frame_rate: float | None = None

    @property
    def real_time_factor(self):
        """Median wall seconds per frame times the frame rate (below 1: faster than the
        sensor), NaN without a frame rate."""
        if self.frame_rate is None:
            return float("nan")
        return float(np.median(self.wall_s) * self.frame_rate)


def _check_frames(frames):
    out = []
    for k, frame in enumerate(frames):
        frame = np.asarray(frame)
        if frame.ndim != 2 or frame.shape[1] < 3:
            raise ValueError(f"frame {k}: expected (n, 3) or (n, 4) points, got {frame.shape}")
        points = np.ascontiguousarray(frame[:, :3], dtype=np.float64)
        if not np.all(np.isfinite(points)):
            raise ValueError(f"frame {k}: NaN or infinite coordinates")
        out.append(points)
    if not out:
        raise ValueError("no frames")
    return out


def kiss_icp_odometry(
    frames,
    frame_rate=None,
    *,
    max_range=MAX_RANGE,
    min_range=MIN_RANGE,
    voxel_size=None,
    timestamps=None,
    max_num_threads=0,
):
    """KISS-ICP's odometry over ``frames``, with the time each frame took.

    Parameters
    ----------
    frames : sequence of ndarray of shape (n_k, 3) or (n_k, 4)
        The point clouds, in the sensor's frame; columns past the third are ignored.
    frame_rate : float, default=None
        Frames per second of the log. KISS-ICP counts in frames (its constant-velocity
        guess is the last frame's motion), so the poses do not depend on it; it gives the
        real-time factor and, with ``timestamps``, checks that deskewing can be right.
    max_range, min_range : float
        Points beyond ``max_range`` or within ``min_range`` of the sensor are left out
        (KISS-ICP's ``data.max_range``, ``data.min_range``).
    voxel_size : float, default=None
        KISS-ICP's map voxel; None: its own rule, ``max_range / 100``.
    timestamps : sequence of ndarray of shape (n_k,), default=None
        Capture time of every point, for KISS-ICP's deskewing; None: no deskewing.
        KISS-ICP spreads the motion between two frames over each frame's capture times:
        with ``frame_rate`` given, times that span less than half the gap between frames
        are refused (keyframes of a faster sensor, whose deskewing would be wrong).
    max_num_threads : int, default=0
        KISS-ICP's threads (0: as many as the machine has). Set once per process.

    Returns
    -------
    Odometry

    Examples
    --------
    >>> frames, poses = read_log("/work/data/scene-0004")  # doctest: +SKIP
    >>> odometry = kiss_icp_odometry(frames, frame_rate=2.0)  # doctest: +SKIP
    >>> odometry.poses.shape  # doctest: +SKIP
    (40, 4, 4)
    """
    frames = _check_frames(frames)
    deskew = timestamps is not None
    if deskew:
        timestamps = [np.asarray(t, dtype=np.float64).ravel() for t in timestamps]
        if len(timestamps) != len(frames):
            raise ValueError(f"{len(timestamps)} timestamp arrays for {len(frames)} frames")
        for k, (t, frame) in enumerate(zip(timestamps, frames, strict=True)):
            if len(t) != len(frame):
                raise ValueError(f"frame {k}: {len(t)} timestamps for {len(frame)} points")
            if frame_rate is not None and len(t) and np.ptp(t) * frame_rate < 0.5:
                raise ValueError(
                    f"frame {k}: capture times span {np.ptp(t):.3g} s of the "
                    f"{1 / frame_rate:.3g} s between frames; KISS-ICP's deskewing would "
                    "spread the whole gap over them (pass timestamps=None)"
                )
    if min_range < 0 or max_range <= min_range:
        raise ValueError(f"need 0 <= min_range < max_range, got {min_range}, {max_range}")

    from kiss_icp.config import KISSConfig
    from kiss_icp.kiss_icp import KissICP

    config = KISSConfig()
    config.data.max_range = float(max_range)
    config.data.min_range = float(min_range)
    config.data.deskew = deskew
    config.mapping.voxel_size = float(voxel_size) if voxel_size else float(max_range) / 100.0
    config.registration.max_num_threads = int(max_num_threads)
    odometry = KissICP(config=config)
    n = len(frames)
    poses = np.empty((n, 4, 4))
    wall, cpu = np.empty(n), np.empty(n)
    for k, frame in enumerate(frames):
        stamps = timestamps[k] if deskew else np.empty(0)
        start_wall, start_cpu = time.perf_counter(), time.process_time()
        odometry.register_frame(frame, stamps)
        wall[k] = time.perf_counter() - start_wall
        cpu[k] = time.process_time() - start_cpu
        poses[k] = odometry.last_pose
    # KISS-ICP starts at the identity; made exact for the record.
    poses = np.linalg.inv(poses[0]) @ poses
    points = np.array([len(f) for f in frames])
    return Odometry(poses, wall, cpu, points, frame_rate)


# --- logs and errors -------------------------------------------------------------------


def read_log(folder):
    """The frames (float32 (n, 4) each) and poses (N, 4, 4) of a SemanticKITTI-layout log."""
    folder = Path(folder)
    files = sorted((folder / "velodyne").glob("*.bin"))
    if not files:
        raise FileNotFoundError(f"{folder}: no velodyne/*.bin")
    frames = []
    for path in files:
        raw = np.fromfile(path, dtype=np.float32)
        if raw.size % 4:
            raise ValueError(f"{path}: {raw.size} floats, not rows of 4 (x, y, z, intensity)")
        frames.append(raw.reshape(-1, 4))
    poses = read_poses(folder / "poses.txt")
    if len(poses) != len(frames):
        raise ValueError(f"{folder}: {len(poses)} poses for {len(frames)} frames")
    return frames, poses


def read_poses(path):
    """``poses.txt``: 12 numbers a line (the top 3 rows of each 4 x 4 pose)."""
    rows = np.loadtxt(path, ndmin=2)
    if rows.shape[1] != 12:
        raise ValueError(f"{path}: {rows.shape[1]} numbers a line, expected 12")
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :] = rows.reshape(-1, 3, 4)
    return poses


def relative_motions(poses):
    """``P_{k+1}^-1 P_k``: what carries frame ``k``'s static points into frame ``k+1``'s."""
    poses = np.asarray(poses, dtype=float)
    return np.linalg.inv(poses[1:]) @ poses[:-1]


def chain(motions):
    """The poses (first the identity) whose :func:`relative_motions` are ``motions``."""
    poses = [np.eye(4)]
    for motion in np.asarray(motions, dtype=float):
        poses.append(poses[-1] @ np.linalg.inv(motion))
    return np.stack(poses)


def _angle_deg(rotations):
    cosine = (np.trace(rotations, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def relative_pose_errors(estimated, truth):
    """Translation (m) and rotation (deg) of ``truth_k^-1 estimated_k`` for every pair of
    relative motions (4 x 4 stacks alike)."""
    error = np.linalg.inv(np.asarray(truth, dtype=float)) @ np.asarray(estimated, dtype=float)
    return np.linalg.norm(error[:, :3, 3], axis=1), _angle_deg(error[:, :3, :3])


def trajectory_errors(estimated, truth):
    """How far apart (m) the two trajectories put the sensor in every frame, each taken
    relative to its first frame (the first frames aligned)."""
    estimated = np.linalg.inv(estimated[0]) @ np.asarray(estimated, dtype=float)
    truth = np.linalg.inv(truth[0]) @ np.asarray(truth, dtype=float)
    return np.linalg.norm(estimated[:, :3, 3] - truth[:, :3, 3], axis=1)


def pose_scores(poses, truth):
    """The errors of a trajectory against the true poses, as a dict of numbers."""
    translation, rotation = relative_pose_errors(relative_motions(poses), relative_motions(truth))
    ate = trajectory_errors(poses, truth)
    return {
        "rpe_m_mean": float(translation.mean()),
        "rpe_m_max": float(translation.max()),
        "rpe_deg_mean": float(rotation.mean()),
        "rpe_deg_max": float(rotation.max()),
        "ate_m_rms": float(np.sqrt(np.mean(ate**2))),
        "ate_m_max": float(ate.max()),
    }


def mmreg_pair_motions(frames, random_state=0):
    """mmreg's ego motion of every pair of consecutive frames (N-1, 4, 4), with the wall
    and CPU seconds of each fit."""
    from mmreg import SweepRegistration

    frames = _check_frames(frames)
    motions, wall, cpu = [], [], []
    for first, second in zip(frames[:-1], frames[1:], strict=True):
        start_wall, start_cpu = time.perf_counter(), time.process_time()
        fitted = SweepRegistration(random_state=random_state).fit(first, sweep=second)
        wall.append(time.perf_counter() - start_wall)
        cpu.append(time.process_time() - start_cpu)
        rotation, translation = fitted.ego_motion_
        motion = np.eye(4)
        motion[:3, :3], motion[:3, 3] = rotation, translation
        motions.append(motion)
    return np.stack(motions), np.array(wall), np.array(cpu)


# --- the script ------------------------------------------------------------------------


def _timing(wall, cpu):
    return {
        "wall_s_median": float(np.median(wall)),
        "wall_s_mean": float(np.mean(wall)),
        "cpu_s_median": float(np.median(cpu)),
        "cpu_s_mean": float(np.mean(cpu)),
    }


def run_log(folder, settings, with_mmreg, log=print):
    """Rows of one log: KISS-ICP under each of ``settings`` ((name, kwargs) pairs), then
    mmreg's pairs if ``with_mmreg``."""
    frames, truth = read_log(folder)
    base = {"log": Path(folder).name, "frames": len(frames)}
    base["points_per_frame"] = float(np.mean([len(f) for f in frames]))
    rows = []
    for name, kwargs in settings:
        odometry = kiss_icp_odometry(frames, FRAME_RATE, **kwargs)
        row = base | {"method": name} | _timing(odometry.wall_s, odometry.cpu_s)
        row |= pose_scores(odometry.poses, truth)
        ranges = [np.linalg.norm(f[:, :3], axis=1) for f in frames]
        low, high = kwargs.get("min_range", MIN_RANGE), kwargs.get("max_range", MAX_RANGE)
        row["points_used"] = float(np.mean([np.sum((r > low) & (r < high)) for r in ranges]))
        rows.append(row)
        log(_line(row))
    if with_mmreg:
        motions, wall, cpu = mmreg_pair_motions(frames)
        row = base | {"method": "mmreg SweepRegistration, pairs"} | _timing(wall, cpu)
        row |= pose_scores(chain(motions), truth)
        row["points_used"] = float("nan")
        rows.append(row)
        log(_line(row))
    return rows


def _line(row):
    return (
        f"{row['log']} {row['method']}: {row['frames']} frames, "
        f"{row['wall_s_median'] * 1000:.0f} ms/frame wall, "
        f"RPE {row['rpe_m_mean']:.3f} m {row['rpe_deg_mean']:.3f} deg, ATE {row['ate_m_rms']:.2f} m"
    )


def settings_rows(min_range, max_range, threads):
    """The chosen setting, then KISS-ICP's defaults and the chosen one without min_range."""
    chosen = {"min_range": min_range, "max_range": max_range, "max_num_threads": threads}
    return [
        (f"KISS-ICP, {min_range:g}-{max_range:g} m", chosen),
        (
            "KISS-ICP defaults (0-100 m, 1 m voxels)",
            chosen | {"min_range": 0.0, "max_range": 100.0},
        ),
        (f"KISS-ICP, 0-{max_range:g} m (ego body in)", chosen | {"min_range": 0.0}),
    ]


COLUMNS = (
    ("log", "log", "{}"),
    ("method", "method", "{}"),
    ("frames", "frames", "{}"),
    ("points_per_frame", "points/frame", "{:,.0f}"),
    ("points_used", "used", "{:,.0f}"),
    ("wall_s_median", "wall s/frame median", "{:.3f}"),
    ("wall_s_mean", "mean", "{:.3f}"),
    ("cpu_s_median", "CPU s/frame median", "{:.3f}"),
    ("cpu_s_mean", "mean", "{:.3f}"),
    ("rpe_m_mean", "RPE m mean", "{:.3f}"),
    ("rpe_m_max", "max", "{:.3f}"),
    ("rpe_deg_mean", "RPE deg mean", "{:.3f}"),
    ("rpe_deg_max", "max", "{:.3f}"),
    ("ate_m_rms", "ATE m RMS", "{:.2f}"),
    ("ate_m_max", "max", "{:.2f}"),
)


def markdown(rows):
    """The rows as a markdown table."""

    def cell(row, key, fmt):
        value = row.get(key)
        if value is None or (isinstance(value, float) and np.isnan(value)):
            return ""
        return fmt.format(value)

    lines = [
        "| " + " | ".join(title for _, title, _ in COLUMNS) + " |",
        "|" + "---|" * len(COLUMNS),
    ]
    lines += ["| " + " | ".join(cell(r, k, f) for k, _, f in COLUMNS) + " |" for r in rows]
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="/work/data", help="folder of the log folders")
    parser.add_argument("--logs", default=",".join(LOGS), help="comma-separated log folders")
    parser.add_argument(
        "--mmreg",
        default="all",
        help="comma-separated logs on which to run mmreg's pairs too (1-2 s a pair), "
        "'all' or 'none'",
    )
    parser.add_argument("--min-range", type=float, default=MIN_RANGE)
    parser.add_argument("--max-range", type=float, default=MAX_RANGE)
    parser.add_argument(
        "--threads",
        type=int,
        default=1,
        help="KISS-ICP's threads (0: every core); one by default, as mmreg's fits mostly run",
    )
    parser.add_argument("--out", default=str(HERE / "results" / "kiss_icp.md"))
    args = parser.parse_args(argv)
    logs = [name for name in args.logs.split(",") if name]
    with_mmreg = set(logs if args.mmreg == "all" else args.mmreg.split(","))
    header = (
        f"load average at start: {os.getloadavg()[0]:.2f} ({os.cpu_count()} CPUs), "
        f"python {sys.version.split()[0]}, numpy {np.__version__}, "
        f"kiss-icp {_version('kiss-icp')}, KISS-ICP threads {args.threads or 'all'}"
    )
    print(header, flush=True)
    settings = settings_rows(args.min_range, args.max_range, args.threads)
    rows = []
    for name in logs:
        folder = Path(args.data) / name
        if not folder.is_dir():
            print(f"{folder}: absent, skipped")
            continue
        rows += run_log(folder, settings, name in with_mmreg)
    table = markdown(rows)
    print("\n" + table)
    command = "python benchmarks/kiss_odometry.py" + "".join(
        f" {item}" for item in (argv if argv is not None else sys.argv[1:])
    )
    Path(args.out).write_text(
        f"# KISS-ICP odometry on the nuScenes logs, and mmreg's pair ego motion\n\n"
        f"`{command}`\n\n{header}\n\n{table}\n\n{NOTES}"
    )


def _version(name):
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(name)
    except PackageNotFoundError:
        return "not installed"


NOTES = """\
Frames: nuScenes keyframes, 2 Hz (0.5 s apart), in the LiDAR's frame; points per frame:
all of them, used: those KISS-ICP keeps (between min_range and max_range). RPE: the error
of every relative motion of consecutive frames against poses.txt (P_k+1^-1 P_k);
ATE: how far apart the estimated and true trajectories put the sensor in each frame,
both taken from their first frame. mmreg's pairs are independent (each pair's ego motion
from scratch, no map, no motion model): its times are per pair of frames (one fewer than
the frames), its ATE that of its motions chained. CPU seconds count every thread of the
process. No deskewing (no capture times in the files).
"""


if __name__ == "__main__":
    main()
