"""Whole logs: SequenceRegistration against each pair judged alone, and KISS-ICP's time.

    pip install -e ".[bench]"                 # kiss-icp, for the time per frame floor
    python benchmarks/sequences.py --data DIR # DIR holds scene-0004/, scene-0006/

The logs:

* the shared nuScenes logs (2 Hz keyframes, HDL-32E, per-point moving labels and boxes, in
  the SemanticKITTI layout: ``velodyne/``, ``labels/`` (uint8: moving = 32-39, 31 the ego
  car's body), ``boundingbox/``, ``poses.txt``), read through
  :func:`mmreg.datasets.open_sequence` as a user's folder is. Extract them first:
  ``tar xJf ../shared/realdata/nuscenes_sequences/scene-0004.tar.xz -C DIR``. Never commit
  them;
* generated logs (:func:`mmreg.datasets.make_lidar_sequence`, 20 frames of 32 x 1024 rays,
  at 10 Hz and 2 Hz, seeds 0 and 1, of 64 x 2048 rays at 10 Hz, an HDL-64's 113k points
  a frame, and of 21 x 1024 rays at 10 Hz, seeds 0 and 1, rings 2 degrees apart as a
  VLP-16's): cars cruising, braking and passing, walkers, cyclists, parked cars, with
  every object's id in every frame.

For each log, ``SequenceRegistration(random_state=0, n_jobs=2)`` (times from the log; its
pairs in a process of their own beside the tracks, ``--jobs``) and, with
``--pairs``, ``SweepRegistration(random_state=0)`` on every pair alone (its moving
clusters, frame k's labels from pair (k, k+1); the last frame has none). Columns:

* ``MOS IoU``: the moving points' IoU (LiDAR-MOS, :func:`mmreg.metrics.moving_iou`), the
  ego car's body left out; ``IoU > 0.5 m/s``: the same with the points of objects moving
  slower than 0.5 m/s left out (nuScenes' "moving" is the annotators' attribute: a car
  waiting at a light is "moving"; no motion can show it);
* ``found``: object-frames in which one track (or, for pairs, one cluster) holds at least
  half of a moving object's points, of all (:func:`mmreg.metrics.tracking_scores`);
  ``found >= 50``: the same for objects of 50 points or more in that frame, and
  ``found >= 50, > 0.5 m/s`` for those of them that move at 0.5 m/s or faster (an
  object's speed is its box centre's, world frame, to the next frame: its points'
  centroid moves with the view);
* ``false/frame``: tracks or clusters called moving of which less than half the points
  move, per frame; ``ID sw``: identity switches (CLEAR-MOT);
* ``s/frame``: wall seconds per frame of the fit, and ``KISS-ICP``: its odometry's on the
  same frames (``benchmarks/kiss_odometry.py``'s settings, as many threads as the fit's
  processes: two on this machine's two cores), each the median
  of ``--repeats`` runs (3) taken in turns, one of each at a time: the machine's speed
  drifts by a tenth or more between runs, a short KISS-ICP run's by a third, and runs
  side by side see the same machine (the load average is in the header); ``x KISS``:
  the ratio of the medians. Pairs alone are timed once;
* ``RPE``: the ego motion's relative pose error against the log's poses (m).

nuScenes boxes carry no track id: the truth's object ids are made by chaining boxes of
one class and size whose world centres are within 4 m from frame to frame.

Writes benchmarks/results/sequences.md and .csv.
"""

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from mmreg import SequenceRegistration, SweepRegistration
from mmreg.datasets import make_lidar_sequence, open_sequence
from mmreg.io import moving_from_labels, read_semantickitti_labels
from mmreg.metrics import moving_iou, tracking_scores

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from real import machine_speed  # noqa: E402  (beside this file)

NUSCENES = ("scene-0004", "scene-0006")
SLOW = 0.5  # m/s: slower objects are left out of "IoU > 0.5 m/s"
MIN_POINTS = 50


# --------------------------------------------------------------------------- logs
def _in_box(points, box):
    cx, cy, cz, length, width, height, yaw = box
    c, s = np.cos(yaw), np.sin(yaw)
    d = points - [cx, cy, cz]
    along, across = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    return (
        (np.abs(along) <= length / 2)
        & (np.abs(across) <= width / 2)
        & (np.abs(d[:, 2]) <= height / 2)
    )


def nuscenes_log(folder):
    """Frames, times, poses and the truth of a SemanticKITTI-layout nuScenes log."""
    with warnings.catch_warnings():  # poses.txt without calib.txt: the LiDAR's own poses
        warnings.simplefilter("ignore")
        sequence = open_sequence(folder)
        poses = sequence.poses
    frames = [frame.points for frame in sequence]
    moving, ignore, ids, centres = [], [], [], []
    previous, next_id = [], 1
    for k, points in enumerate(frames):
        name = Path(sequence.names[k]).stem
        labels = read_semantickitti_labels(folder / "labels" / f"{name}.label", len(points))
        move, skip = moving_from_labels(labels.semantic, labels.convention)
        moving.append(move)
        ignore.append(skip)
        boxes = np.load(folder / "boundingbox" / f"{name}.npy", allow_pickle=True)
        object_ids = np.zeros(len(points), dtype=np.int64)
        current = []
        for row in boxes:
            box = np.asarray(row[3], dtype=float)
            centre = poses[k][:3, :3] @ box[:3] + poses[k][:3, 3]
            match, gap = None, 4.0
            for other, name_, size, where in previous:
                if name_ == row[0] and np.abs(size - box[3:6]).max() < 0.05:
                    distance = np.linalg.norm(where - centre)
                    if distance < gap:
                        match, gap = other, distance
            if match is None:
                match, next_id = next_id, next_id + 1
            current.append((match, row[0], box[3:6], centre))
            object_ids[_in_box(points, box) & move] = match
        previous = current
        ids.append(object_ids)
        centres.append({match: centre for match, _, _, centre in current})
    times = np.arange(len(frames)) / 2.0 if sequence.timestamps is None else sequence.timestamps
    speeds = _speeds(ids, centres, times)
    return dict(
        frames=frames,
        times=times,
        poses=poses,
        moving=moving,
        ignore=ignore,
        ids=ids,
        speeds=speeds,
    )


def _speeds(ids, centres, times):
    """Per frame, per point: its object's speed (m/s), from its box's world centre to the
    next (or last) frame's (the points' centroid moves with the view: a car waiting at a
    light reads 0.5-3 m/s by it), NaN where it has no object."""
    out = []
    for k, object_ids in enumerate(ids):
        speed = np.full(len(object_ids), np.nan)
        other = k + 1 if k + 1 < len(ids) else k - 1
        for i in np.unique(object_ids[object_ids > 0]):
            if i not in centres[other]:
                continue
            step = np.linalg.norm(centres[other][i] - centres[k][i])
            speed[object_ids == i] = step / abs(times[other] - times[k])
        out.append(speed)
    return out


def generated_log(frame_rate, seed, beams=32):
    log = make_lidar_sequence(
        20,
        frame_rate=frame_rate,
        n_beams=beams,
        n_azimuths=1024 if beams <= 32 else 2048,
        random_state=seed,
    )
    ids = [np.where(m, labels, 0) for labels, m in zip(log.labels, log.moving, strict=True)]
    speeds = []
    for k, labels in enumerate(log.labels):
        table = log.objects[log.objects.frame == k].set_index("id")["speed"]
        speeds.append(np.array([table.get(i, np.nan) if i > 0 else np.nan for i in labels]))
    return dict(
        frames=log.frames,
        times=log.times,
        poses=log.poses,
        moving=log.moving,
        ignore=[np.zeros(len(f), bool) for f in log.frames],
        ids=ids,
        speeds=speeds,
    )


# --------------------------------------------------------------------------- scores
def scores(log, labels, moving, seconds):
    """The row's figures for predicted per-frame ``labels`` and ``moving`` masks."""
    fast_ignore = [
        skip | (np.nan_to_num(speed, nan=np.inf) < SLOW)
        for skip, speed in zip(log["ignore"], log["speeds"], strict=True)
    ]
    predicted = [np.where(m & (lab > 0), lab, 0) for lab, m in zip(labels, moving, strict=True)]
    tracking = tracking_scores(log["ids"], predicted, ignore=log["ignore"])
    summary = tracking.summary()
    big = [np.where(np.bincount(ids)[ids] >= MIN_POINTS, ids, 0) for ids in log["ids"]]
    tracking_big = tracking_scores(big, predicted, ignore=log["ignore"])
    # Objects that move visibly: 50 points or more, 0.5 m/s or faster.
    fast = [
        np.where(np.nan_to_num(speed, nan=0.0) >= SLOW, ids, 0)
        for ids, speed in zip(big, log["speeds"], strict=True)
    ]
    tracking_fast = tracking_scores(fast, predicted, ignore=log["ignore"])
    return {
        "MOS IoU": moving_iou(log["moving"], moving, ignore=log["ignore"]),
        "IoU > 0.5 m/s": moving_iou(log["moving"], moving, ignore=fast_ignore),
        "found": f"{int(tracking.found.sum())}/{int(tracking.visible.sum())}",
        "found >= 50": f"{int(tracking_big.found.sum())}/{int(tracking_big.visible.sum())}",
        "found >= 50, > 0.5 m/s": (
            f"{int(tracking_fast.found.sum())}/{int(tracking_fast.visible.sum())}"
        ),
        "false/frame": summary["false_tracks_per_frame"],
        "ID sw": summary["id_switches"],
        "s/frame": seconds,
    }


def run_sequence(log, repeats=3, jobs=2):
    """The sequence's scores, and its seconds a frame and KISS-ICP's: the medians of
    ``repeats`` runs of each, taken in turns (every fit gives the same labels), the fit
    on ``jobs`` processes and KISS-ICP on as many threads."""
    seconds, kiss = [], []
    for _ in range(repeats):
        start = time.perf_counter()
        est = SequenceRegistration(random_state=0, n_jobs=jobs)
        est.fit(log["frames"], times=log["times"])
        seconds.append((time.perf_counter() - start) / len(log["frames"]))
        kiss.append(kiss_seconds(log, jobs))
    row = scores(log, est.labels_, est.moving_, float(np.median(seconds)))
    truth = log["poses"]
    errors = [
        np.linalg.norm(
            (np.linalg.inv(truth[k + 1]) @ truth[k])[:3, 3]
            - (np.linalg.inv(est.ego_poses_[k + 1]) @ est.ego_poses_[k])[:3, 3]
        )
        for k in range(len(truth) - 1)
    ]
    row["RPE m"] = float(np.mean(errors))
    row["tracks"] = est.n_tracks_
    row["KISS-ICP s/frame"] = float(np.median(kiss))  # NaN without kiss-icp
    return row


def run_pairs(log):
    """Each pair judged alone: frame k labelled by pair (k, k + 1); the last frame not."""
    frames = log["frames"]
    labels, moving = [], []
    start = time.perf_counter()
    for k in range(len(frames) - 1):
        pair = SweepRegistration(random_state=0).fit(frames[k], sweep=frames[k + 1])
        lab = np.asarray(pair.labels_)
        move = (lab >= 0) & np.asarray(pair.moving_)[np.maximum(lab, 0)]
        labels.append(np.where(move, lab + 1, 0))
        moving.append(move)
    seconds = (time.perf_counter() - start) / (len(frames) - 1)
    labels.append(np.zeros(len(frames[-1]), np.intp))
    moving.append(np.zeros(len(frames[-1]), bool))
    # Ids are per pair: no identity over time; ID switches are not meaningful.
    row = scores(log, labels, moving, seconds)
    row["ID sw"] = "-"
    return row


def kiss_seconds(log, threads=1):
    """KISS-ICP's odometry's seconds a frame on the log's frames, one run on ``threads``
    threads (NaN without kiss-icp)."""
    try:
        from kiss_odometry import kiss_icp_odometry

        result = kiss_icp_odometry(log["frames"], max_num_threads=threads)
    except ImportError:  # kiss-icp not installed
        return np.nan
    return float(np.mean(result.wall_s))


def markdown(table):
    """The table as markdown: 3 decimals, counts whole, "-" where a method has none."""

    def cell(value, column):
        if isinstance(value, str):
            return value
        if value is None or value != value:
            return "-"
        if column in ("tracks", "ID sw"):
            return str(int(value))
        return f"{value:.3f}"

    shown = pd.DataFrame({c: [cell(v, c) for v in table[c]] for c in table.columns})
    return shown.to_markdown(index=False, disable_numparse=True)


# --------------------------------------------------------------------------- main
def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="/work/data", help="folder of the nuScenes logs")
    parser.add_argument("--pairs", action="store_true", help="also each pair alone")
    parser.add_argument(
        "--generated",
        default="10:0,10:1,2:0,2:1,10:0:64,10:0:21,10:1:21",
        help="rate:seed[:beams],...",
    )
    parser.add_argument(
        "--repeats", type=int, default=3, help="timed runs of each method (the median)"
    )
    parser.add_argument(
        "--jobs",
        type=int,
        default=2,
        help="the fit's processes (n_jobs) and KISS-ICP's threads (default: 2)",
    )
    parser.add_argument("--out", default=str(HERE / "results" / "sequences"))
    args = parser.parse_args(argv)
    logs = []
    for name in NUSCENES:
        folder = Path(args.data) / name
        if folder.is_dir():
            logs.append((f"nuScenes {name}", nuscenes_log(folder)))
        else:
            print(f"{folder}: absent, skipped", flush=True)
    for item in filter(None, args.generated.split(",")):
        rate, seed, *beams = item.split(":")
        beams = int(beams[0]) if beams else 32
        name = f"generated {rate} Hz, " + (f"{beams} beams, " if beams != 32 else "")
        logs.append((f"{name}seed {seed}", generated_log(float(rate), int(seed), beams)))
    # The machine's speed drifts by tens of percent over a day, KISS-ICP's less than
    # ours: the yardstick before and after says which machine a run saw.
    before = machine_speed()
    header = (
        f"load average at start: {os.getloadavg()[0]:.2f} ({os.cpu_count()} CPUs), "
        f"python {sys.version.split()[0]}, numpy {np.__version__}, "
        f"machine speed (`real.machine_speed`, a k-d tree's 8-NN pass over 100,000 "
        f"points) {before:.3f} s before the run; the fit with n_jobs={args.jobs}, KISS-ICP "
        f"with max_num_threads={args.jobs}"
    )
    print(header, flush=True)
    rows = []
    for name, log in logs:
        row = {
            "log": name,
            "method": "SequenceRegistration",
            **run_sequence(log, args.repeats, args.jobs),
        }
        kiss = row["KISS-ICP s/frame"]
        row["x KISS"] = row["s/frame"] / kiss if kiss == kiss else np.nan
        rows.append(row)
        print(row, flush=True)
        if args.pairs:
            pair_row = {"log": name, "method": "pairs alone", **run_pairs(log)}
            rows.append(pair_row)
            print(pair_row, flush=True)
    table = pd.DataFrame(rows)
    table.to_csv(f"{args.out}.csv", index=False)
    command = "python benchmarks/sequences.py " + " ".join(
        argv if argv is not None else sys.argv[1:]
    )
    header += f", {machine_speed():.3f} s after"
    Path(f"{args.out}.md").write_text(
        f"# Whole logs: tracks against pairs alone\n\n`{command.strip()}`\n\n{header}\n\n"
        + markdown(table)
        + "\n"
    )


if __name__ == "__main__":
    main()
