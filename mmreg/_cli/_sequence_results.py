"""A result of ``mmreg run`` on LiDAR logs, read back: a frame to draw, the log's scores.

``mmreg view`` draws a frame of it from above (:func:`view_log`); ``mmreg evaluate``
scores it (:func:`evaluate_logs`) with the moving-object IoU of LiDAR-MOS where the log
has labels (``labels/<frame>.label`` beside its frames: SemanticKITTI's ``uint32`` or a
nuScenes conversion's ``uint8``), the tracking scores where those labels carry instance
ids, and the relative pose error of the poses found against the log's own poses.
"""

import json
import math
from pathlib import Path

from mmreg._cli._common import CLIError, plural, reading

__all__ = ["evaluate_logs", "is_log_result", "open_log_results", "view_log"]

_MOVING = 251
# tracks.csv's names (units in them) back to the estimator's.
_TRACK_NAMES = {
    "time_s": "time",
    "x_m": "x",
    "y_m": "y",
    "z_m": "z",
    "length_m": "length",
    "width_m": "width",
    "height_m": "height",
    "yaw_rad": "yaw",
}


def is_log_result(path):
    """Whether ``path`` is the folder of a run on logs (or of one of its logs)."""
    path = Path(path)
    if not path.is_dir():
        return False
    if (path / "log.json").is_file():
        return True
    try:
        record = json.loads((path / "run.json").read_text())
    except (OSError, ValueError):
        return False
    configuration = record.get("configuration") if isinstance(record, dict) else None
    return isinstance(configuration, dict) and configuration.get("kind") == "logs"


class LogResult:
    """One log's results: ``labels/``, ``poses.txt``, ``tracks.csv`` and ``log.json``."""

    def __init__(self, folder):
        from mmreg.runner._logs import read_log_record

        self.folder = Path(folder)
        self.record = read_log_record(self.folder)
        if self.record is None:
            raise CLIError(f"{self.folder / 'log.json'}: missing or unreadable (a finished log)")
        self.name = str(self.record.get("log", self.folder.name))
        self.names = [str(n) for n in self.record["frames"]]

    def labels(self, k):
        """``(semantic, instance)`` of frame ``k`` as written."""
        from mmreg import io as mmio

        path = self.folder / "labels" / f"{self.names[k]}.label"
        with reading(path):
            found = mmio.read_semantickitti_labels(path)
        return found.semantic, found.instance

    def poses(self):
        from mmreg import io as mmio

        path = self.folder / "poses.txt"
        with reading(path):
            poses = mmio.read_kitti_poses(path)
        if len(poses) != len(self.names):
            raise CLIError(f"{path}: {len(poses)} poses for {len(self.names)} frames")
        return poses

    def tracks(self):
        import pandas as pd

        path = self.folder / "tracks.csv"
        with reading(path):
            table = pd.read_csv(path)
        return table.rename(columns=_TRACK_NAMES)

    def sequence(self):
        """The log the result was fitted on (it must still be where it was)."""
        from mmreg.datasets import open_sequence

        path = self.record.get("path")
        with reading(path):
            sequence = open_sequence(
                path, topic=self.record.get("topic"), pattern=self.record.get("pattern")
            )
        if len(sequence) != len(self.names):
            raise CLIError(
                f"{path}: holds {len(sequence)} frames but the result {len(self.names)}; the "
                "log changed since 'mmreg run'"
            )
        return sequence


def open_log_results(path, log=None):
    """The logs of a run on logs (all, or the one named ``log``)."""
    path = Path(path)
    if (path / "log.json").is_file():
        return [LogResult(path)]
    found = sorted(p for p in path.iterdir() if p.is_dir() and (p / "log.json").is_file())
    if not found:
        raise CLIError(
            f"{path}: holds no finished log (no log.json); run 'mmreg run' again to finish it"
        )
    if log is None:
        return [LogResult(p) for p in found]
    chosen = [p for p in found if p.name == log]
    if not chosen:
        names = ", ".join(p.name for p in found[:5]) + (", ..." if len(found) > 5 else "")
        raise CLIError(f"{path}: holds no log {log!r}; its logs: {names}")
    return [LogResult(chosen[0])]


# --------------------------------------------------------------------------- view
def _frame_index(result, at):
    """Frame ``at`` (its name, or its number; negative from the end); None: the last."""
    n = len(result.names)
    if at is None:
        return n - 1
    if at in result.names:
        return result.names.index(at)
    try:
        k = int(at)
    except ValueError:
        k = None
    if k is None or not -n <= k < n:
        shown = ", ".join(result.names[:3]) + (", ..." if n > 3 else "")
        raise CLIError(
            f"{result.folder}: no frame {at!r}; give a frame's name ({shown}) or its number "
            f"(0 to {n - 1})"
        )
    return k % n


def view_log(args):
    """``mmreg view`` of a run on logs: one frame from above, in the log's frame."""
    from mmreg import io as mmio
    from mmreg._cli._common import picture_format, render_picture
    from mmreg.plotting._log import LOG_RANGE, plot_log_frame

    results = open_log_results(args.result_dir, log=args.job)
    if len(results) > 1:
        names = ", ".join(r.folder.name for r in results[:5])
        raise CLIError(
            f"{args.result_dir}: holds {len(results)} logs; choose one with --job ({names})"
        )
    (result,) = results
    k = _frame_index(result, args.at)
    name = result.names[k]
    single = result.folder == Path(args.result_dir)
    own = Path(f"{name}.png" if single else f"{result.folder.name}_{name}.png")
    out = Path(args.out) if args.out is not None else own
    fmt = picture_format(out)
    if out.is_dir():
        raise CLIError(f"{out}: is a folder; --out names the picture file")
    if not args.overwrite and out.exists():
        raise CLIError(f"{out}: exists; pass --overwrite to replace it")
    semantic, instance = result.labels(k)
    frame = result.sequence()[k]
    if len(frame.points) != len(semantic):
        raise CLIError(
            f"{result.folder / 'labels' / (name + '.label')}: {len(semantic)} labels for the "
            f"{len(frame.points)} rows of {frame.source}; the log changed since 'mmreg run'"
        )
    moving = semantic == _MOVING
    title = args.title
    if title is None:
        ids = set(instance[moving].tolist()) - {0}
        title = (
            f"{result.name} {name} ({k + 1}/{len(result.names)}): "
            f"{plural(len(ids), 'moving object')}, {int(moving.sum()):,} moving points"
        )
    ax = plot_log_frame(
        frame.points,
        semantic,
        instance,
        result.poses()[k],
        tracks=result.tracks(),
        frame=k,
        range_=args.range_ if args.range_ is not None else LOG_RANGE,
        title=title,
    )
    picture = render_picture(ax.get_figure(), fmt, dpi=args.dpi)
    with reading(out), mmio.atomic_write(out) as handle:
        handle.write(picture)
    print(f"written: {out}")
    return 0


def _moving_scores(truth, pred, ignore):
    """The moving points' IoU and counts over the frames with labels (NaN without)."""
    from mmreg.metrics import moving_iou

    if not truth:
        return {
            "frames_labelled": 0,
            "mos_iou": math.nan,
            "moving_points_true": math.nan,
            "moving_points_predicted": math.nan,
        }
    kept = [~i for i in ignore]
    return {
        "frames_labelled": len(truth),
        "mos_iou": moving_iou(truth, pred, ignore=ignore),
        "moving_points_true": sum(int((t & k).sum()) for t, k in zip(truth, kept, strict=True)),
        "moving_points_predicted": sum(int((p & k).sum()) for p, k in zip(pred, kept, strict=True)),
    }


def _pose_scores(translation, rotation):
    """Mean and largest relative pose errors (m and degrees; NaN without any)."""
    import numpy as np

    if not len(translation):
        return dict.fromkeys(("rpe_m_mean", "rpe_m_max", "rpe_deg_mean", "rpe_deg_max"), math.nan)
    return {
        "rpe_m_mean": float(np.mean(translation)),
        "rpe_m_max": float(np.max(translation)),
        "rpe_deg_mean": float(np.mean(rotation)),
        "rpe_deg_max": float(np.max(rotation)),
    }


# --------------------------------------------------------------------------- evaluate
def evaluate_log(result):
    """The scores of one log: ``{name: value}`` (NaN where not measured)."""
    import numpy as np

    from mmreg import io as mmio
    from mmreg.metrics import relative_pose_errors, tracking_scores

    sequence = result.sequence()
    root = Path(result.record["path"])
    labels = (root if root.is_dir() else root.parent) / "labels"
    truth, pred, ignore, true_ids, pred_ids = [], [], [], [], []
    instances = True
    for k, name in enumerate(result.names):
        path = labels / f"{name}.label"
        if not path.is_file():
            continue
        semantic, instance = result.labels(k)
        with reading(path):
            found = mmio.read_semantickitti_labels(path, n_points=len(semantic))
            moving, left_out = mmio.moving_from_labels(found.semantic, found.convention)
        truth.append(moving)
        pred.append(semantic == _MOVING)
        ignore.append(left_out)
        instances &= found.instance is not None
        if instances:
            true_ids.append(np.where(moving, found.instance, 0))
            pred_ids.append(np.where(semantic == _MOVING, instance, 0))
    scores = {"frames": len(result.names), **_moving_scores(truth, pred, ignore)}
    if instances and true_ids:
        found = tracking_scores(true_ids, pred_ids, ignore=ignore).summary()
        scores["objects_true"] = found["objects"]
        scores["objects_found_share"] = found["found_share"]
        scores["id_switches"] = found["id_switches"]
        scores["false_tracks_per_frame"] = found["false_tracks_per_frame"]
    with reading(root):  # a broken poses file names itself
        true_poses = getattr(sequence, "poses", None)
    translation, rotation = [], []
    if true_poses is not None:
        translation, rotation = relative_pose_errors(result.poses(), true_poses)
    scores.update(_pose_scores(translation, rotation))
    scores["poses_given"] = bool(result.record.get("row", {}).get("poses_given", False))
    if true_poses is None and not truth:
        raise CLIError(
            f"{result.name}: its log ({root}) has neither labels (labels/<frame>.label) nor "
            "poses to score against"
        )
    return scores


_LINES = [
    ("frames_labelled", "frames with labels", "d"),
    ("mos_iou", "moving-object IoU (LiDAR-MOS)", ".3f"),
    ("moving_points_true", "moving points, true", ",d"),
    ("moving_points_predicted", "moving points, found", ",d"),
    ("objects_true", "moving objects, true", "d"),
    ("objects_found_share", "object-frames found", ".0%"),
    ("id_switches", "ID switches", "d"),
    ("false_tracks_per_frame", "false tracks per frame", ".2f"),
    ("rpe_m_mean", "relative pose error, mean [m]", ".3f"),
    ("rpe_m_max", "relative pose error, max [m]", ".3f"),
    ("rpe_deg_mean", "relative pose error, mean [deg]", ".3f"),
    ("rpe_deg_max", "relative pose error, max [deg]", ".3f"),
]
_TABLE = [
    ("log", "log", ""),
    ("frames", "frames", "d"),
    ("pairs", "pairs", "d"),
    ("mos_iou", "MOS IoU", ".3f"),
    ("objects_found_share", "found", ".0%"),
    ("rpe_m_mean", "RPE [m]", ".3f"),
    ("rpe_deg_mean", "RPE [deg]", ".3f"),
]


def _text(value, fmt):
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    return format(value, fmt)


def evaluate_logs(args):
    """``mmreg evaluate`` of a run on logs: one log's lines, or a table of every log."""
    if args.truth is not None:
        raise CLIError(
            f"{args.pred_dir}: a run on logs is scored against its logs' own labels and "
            "poses; TRUTH does not apply"
        )
    results = open_log_results(args.pred_dir, log=args.job)
    rows = [{"log": r.name} | evaluate_log(r) for r in results]
    return print_scores(rows, args)


# --------------------------------------------------------------------------- --pairs runs
def pair_log_run(path):
    """The jobs of an 'mmreg run --pairs' of LiDAR logs (KITTI / SemanticKITTI sequences,
    bags, folders of sweep files), grouped by log: ``{log path: [job, ...]}``; None when
    ``path`` is no such run (a result directory, a run of correspondences or of
    Argoverse 2 logs, whose jobs carry their own truth)."""
    from mmreg._cli._results import is_run_folder, run_jobs
    from mmreg.runner import BrokenLogJob, SequenceSweepPairJob

    path = Path(path)
    if not path.is_dir() or not is_run_folder(path):
        return None
    with reading(path / "run.json"):
        configuration = json.loads((path / "run.json").read_text()).get("configuration")
    if not isinstance(configuration, dict) or not configuration.get("dataset"):
        return None
    jobs = [j for j in run_jobs(configuration, path) if not isinstance(j, BrokenLogJob)]
    if not jobs or not all(isinstance(j, SequenceSweepPairJob) for j in jobs):
        return None
    logs = {}
    for job in jobs:
        logs.setdefault(job.path, []).append(job)
    return logs


def _pair_static_motion(arrays):
    """The static world's motion of a pair job's result (4 x 4): its ``static_cluster``,
    else (results of earlier versions) its largest cluster that does not move."""
    import numpy as np

    rotations, translations = arrays["rotations"], arrays["translations"]
    static = int(arrays["static_cluster"]) if "static_cluster" in arrays else -1
    if static < 0:
        labels = np.asarray(arrays["labels"])
        counts = np.bincount(labels[labels >= 0], minlength=len(rotations)).astype(float)
        moving = arrays.get("moving")
        if moving is not None and len(moving) == len(counts):
            counts[np.asarray(moving, bool)] = -1.0
        static = int(np.argmax(counts)) if len(counts) else -1
    motion = np.eye(4)
    if static >= 0:
        motion[:3, :3], motion[:3, 3] = rotations[static], translations[static]
    return motion


def evaluate_pair_log(run, log, jobs):
    """The scores of one log of a --pairs run, every pair at once: the moving-object IoU
    of LiDAR-MOS over every pair's first frame against the log's labels (the rows in the
    moving clusters; the ego body and unlabelled points left out by the labels' own
    rules), and the relative pose error of every pair's static-world motion against the
    log's poses."""
    import numpy as np

    from mmreg import io as mmio
    from mmreg.datasets import open_sequence
    from mmreg.metrics import relative_pose_errors
    from mmreg.runner import read_job_result
    from mmreg.runner._logs import frame_names

    first = jobs[0]
    with reading(log):
        sequence = open_sequence(log, topic=first.topic, pattern=first.pattern)
    names = frame_names(sequence)
    root = Path(log)
    labels = (root if root.is_dir() else root.parent) / "labels"
    with reading(log):  # a broken poses file names itself
        true_poses = getattr(sequence, "poses", None)
    truth, pred, ignore = [], [], []
    translation, rotation = [], []
    done = 0
    for job in jobs:
        path = Path(run) / "jobs" / f"{job.name}.npz"
        found = read_job_result(path)
        if found is None:
            continue
        arrays, _ = found
        done += 1
        k = job.index
        label_path = labels / f"{names[k]}.label"
        if label_path.is_file():
            n = len(arrays["sweep_valid"]) if "sweep_valid" in arrays else None
            if n is None:
                with reading(log):
                    n = len(sequence[k].points)
            with reading(label_path):
                known = mmio.read_semantickitti_labels(label_path, n_points=n)
                moving, left_out = mmio.moving_from_labels(known.semantic, known.convention)
            found_moving = np.zeros(n, bool)
            rows = np.asarray(arrays["indices"], dtype=np.intp)
            ids = np.asarray(arrays["labels"])
            clusters = arrays.get("moving")
            if clusters is not None:
                clusters = np.asarray(clusters, bool)
                kept = ids >= 0
                found_moving[rows[kept]] = clusters[ids[kept]]
            truth.append(moving)
            pred.append(found_moving)
            ignore.append(left_out)
        if true_poses is not None:
            motion = np.linalg.inv(true_poses[k + 1]) @ true_poses[k]
            found_motion = _pair_static_motion(arrays)
            # Two-frame trajectories whose one step is each motion: relative_pose_errors
            # compares inv(P1) P0, the motion itself.
            errors = relative_pose_errors(
                np.stack([np.eye(4), np.linalg.inv(found_motion)]),
                np.stack([np.eye(4), np.linalg.inv(motion)]),
            )
            translation.append(float(errors[0][0]))
            rotation.append(float(errors[1][0]))
    if not done:
        raise CLIError(f"{run}: holds no finished job of {log}; run 'mmreg run' again")
    scores = {"pairs": done, **_moving_scores(truth, pred, ignore)}
    scores.update(_pose_scores(translation, rotation))
    scores["poses_given"] = bool(first.poses and true_poses is not None)
    if not translation and not truth:
        raise CLIError(
            f"{log}: has neither labels (labels/<frame>.label) nor poses to score the pairs "
            "of its run against; give TRUTH to score one job"
        )
    return scores


def evaluate_pair_logs(args, logs):
    """``mmreg evaluate`` of a --pairs run of logs: every pair of a log scored at once."""
    chosen = logs
    if args.job is not None:
        chosen = {log: [job for job in jobs if job.name == args.job] for log, jobs in logs.items()}
        chosen = {log: jobs for log, jobs in chosen.items() if jobs}
        if not chosen:
            names = [job.name for jobs in logs.values() for job in jobs]
            shown = ", ".join(names[:5]) + (", ..." if len(names) > 5 else "")
            raise CLIError(f"{args.pred_dir}: holds no job {args.job!r} (its jobs: {shown})")
    rows = []
    for log, jobs in chosen.items():
        name = Path(log).name
        rows.append({"log": name} | evaluate_pair_log(args.pred_dir, log, jobs))
    return print_scores(rows, args)


def print_scores(rows, args):
    """The scores of one log as lines, of several as a table, or as JSON."""
    if args.json:
        clean = [
            {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in row.items()}
            for row in rows
        ]
        print(json.dumps(clean if len(rows) > 1 else clean[0], indent=2))
        return 0
    if len(rows) > 1:
        spec = [c for c in _TABLE if any(c[0] in row for row in rows)]
        cells = [[name for _, name, _ in spec]]
        cells += [[_text(row.get(key), fmt) for key, _, fmt in spec] for row in rows]
        widths = [max(len(c[i]) for c in cells) for i in range(len(spec))]
        for number, cell in enumerate(cells):
            print("  ".join(c.rjust(w) for c, w in zip(cell, widths, strict=True)))
            if number == 0:
                print("  ".join("-" * w for w in widths))
        return 0
    (row,) = rows
    shown = [(k, n, f) for k, n, f in _LINES if k in row]
    width = max(len(name) for _, name, _ in shown)
    counted = plural(row["frames"], "frame") if "frames" in row else plural(row["pairs"], "pair")
    print(f"{'log':<{width}}  {row['log']} ({counted})")
    for key, name, fmt in shown:
        print(f"{name:<{width}}  {_text(row[key], fmt)}")
    if row["poses_given"] and not math.isnan(row["rpe_m_mean"]):
        print(
            "(the run started its ego motions from these poses: run with --no-poses for an "
            "independent comparison)"
        )
    return 0
