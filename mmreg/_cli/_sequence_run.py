"""``mmreg run`` on LiDAR logs: the sequence estimator over each log, and what it prints.

The work is :func:`mmreg.runner._logs.run_logs`'s; here are the estimator the options
ask for, the checks of ``--out`` before any work, ``run.json`` and the console tables.
"""

import json
import math
import shutil
import sys
import time
from pathlib import Path

from mmreg._cli._common import CLIError, one_line, plural, reading

__all__ = ["foreign_names", "holds_results", "remove_results", "run_sequences"]

# What an 'mmreg run' folder holds at its top: the pair jobs' files and a log's.
TOP_FILES = (
    "run.json",
    "summary.parquet",
    "summary.csv",
    "jobs",
    "av2_scene_flow",
    "pictures",
    "labels",
    "tracks.csv",
    "poses.txt",
    "frames.csv",
    "log.json",
)
_LOG_FILES = ("labels", "tracks.csv", "poses.txt", "frames.csv", "log.json", "pictures")
# The tables on the console: at most this many rows of tracks and of frames.
_TRACK_ROWS = 20
_FRAME_ROWS = 40


def _temporary(name):
    """An atomic write's temporary file, left by a crash (``.<name>.<random>.tmp``)."""
    return name.startswith(".") and name.endswith(".tmp")


def _is_log_folder(path):
    """A folder of one log's results (only the files a log writes)."""
    try:
        names = [p.name for p in path.iterdir()]
    except OSError:
        return False
    return bool(names) and all(n in _LOG_FILES or _temporary(n) for n in names)


def foreign_names(out):
    """Names in ``out`` that an 'mmreg run' (pairs or logs) does not write."""
    out = Path(out)
    names = []
    for path in sorted(out.iterdir()):
        if path.name in TOP_FILES or _temporary(path.name):
            continue
        if path.is_dir() and _is_log_folder(path):
            continue
        names.append(path.name)
    jobs = out / "jobs"
    if jobs.exists() and not jobs.is_dir():
        names.append("jobs")
    elif jobs.is_dir():
        names += [f"jobs/{p.name}" for p in jobs.iterdir() if p.suffix not in (".npz", ".tmp")]
    return names


def holds_results(out):
    """Whether ``out`` holds a result of a pair job or a log (an earlier run whose jobs all
    failed holds none: a run with other options may replace it)."""
    out = Path(out)
    jobs = out / "jobs"
    if jobs.is_dir() and any(p.suffix == ".npz" for p in jobs.iterdir()):
        return True
    if (out / "log.json").is_file():
        return True
    return any(p.is_dir() and (p / "log.json").is_file() for p in out.iterdir())


def remove_results(out):
    """Remove every result file of an earlier run in ``out`` (checked: nothing foreign)."""
    out = Path(out)
    for path in out.iterdir():
        if path.name == "run.json":
            continue
        if path.is_dir() and (path.name in TOP_FILES or _is_log_folder(path)):
            shutil.rmtree(path)
        elif path.name in TOP_FILES or _temporary(path.name):
            path.unlink()


def _estimator(args):
    """The sequence estimator of the options; its own pair estimator unless they ask for
    another (--method, --max-iter, --ground); --tau is the sequence's and its pairs'."""
    from mmreg import MultiModelRegistration, SequenceRegistration
    from mmreg.estimators._sequence import default_pair_estimator

    pair = None
    tau = 5.0 if args.tau is None else args.tau
    inner = args.method != "sweep" or args.max_iter != 10
    if inner or args.ground != "auto":
        params = {"tau": tau, "ground": args.ground}
        if inner:  # a multi-model estimator asked for by name
            params["estimator"] = MultiModelRegistration(
                variant=args.method, tau=args.tau, max_iter=args.max_iter, random_state=args.seed
            )
        # Seeded by the sequence, a new seed for every pair.
        pair = default_pair_estimator(**params)
    return SequenceRegistration(
        pair,
        tau=tau,
        frame_rate=args.frame_rate,
        voxel_size=getattr(args, "voxel_size", None),
        n_jobs=getattr(args, "jobs", None),
        random_state=args.seed,
    )


def _configuration(args):
    from mmreg import __version__

    return {
        "dataset": str(Path(args.dataset).resolve()),
        "kind": "logs",
        "layout": args.layout,
        "topic": args.topic,
        "pattern": args.pattern,
        "ground": args.ground,
        "method": args.method,
        "tau": args.tau,
        "max_iter": args.max_iter,
        "seed": args.seed,
        "frame_rate": args.frame_rate,
        "voxel_size": getattr(args, "voxel_size", None),
        "poses": args.poses,
        "mmreg": __version__,
    }


def _write_record(out, record):
    from mmreg import io as mmio

    with mmio.atomic_write(out / "run.json", "w") as handle:
        handle.write(json.dumps(record, indent=2, default=str) + "\n")


def run_sequences(args, jobs):
    """Run the sequence estimator over the logs ``jobs`` (see ``mmreg run --help``)."""
    from mmreg.runner._logs import run_logs

    out = Path(args.out)
    configuration = _configuration(args)
    from mmreg._cli.dataset import check_run_out

    resuming = check_run_out(out, configuration, overwrite=args.overwrite)
    if not resuming and out.is_dir():  # another run's results, or --overwrite: replaced
        remove_results(out)
    record = {"configuration": configuration, "logs": [job.name for job in jobs]}
    try:
        out.mkdir(parents=True, exist_ok=True)
        _write_record(out, record)
    except OSError as error:
        raise CLIError(f"{out}: cannot be written: {one_line(error.strerror or error)}") from None
    start = time.perf_counter()
    summary = run_logs(
        jobs,
        _estimator(args),
        out,
        scheduler=args.scheduler,
        n_workers=args.n_workers,
        progress=not args.quiet,
        pictures=args.pictures,
    )
    elapsed = time.perf_counter() - start
    plan = summary.attrs.get("plan", {})
    record["timings"] = {
        "total_s": elapsed,
        "where": plan.get("where"),
        "workers": plan.get("workers"),
        "why": plan.get("why"),
        "cluster_start_s": plan.get("start_s", 0.0),
        "logs": {
            row["log"]: {
                key: row[key]
                for key in ("frames", "load_s", "fit_s", "s_per_frame", "resumed")
                if key in row and not _missing(row[key])
            }
            for row in summary.to_dict("records")
        },
    }
    _write_record(out, record)
    failed = summary[summary["status"] != "done"]
    single = len(jobs) == 1 and not getattr(jobs[0], "folder", "")
    verbose = getattr(args, "verbose", False)
    if not args.quiet:
        if single and not len(failed):
            _print_log(out, summary.iloc[0], elapsed, resuming, plan, verbose)
        else:
            _print_logs(summary, elapsed, resuming, plan)
        from mmreg._cli.dataset import print_plan, print_warnings

        if verbose:
            print_plan(plan, {"total_s": elapsed})
        print_warnings(summary["log"], summary, verbose=verbose)
        if plan.get("redrawn"):
            print(f"{plural(plan['redrawn'], 'log')}' pictures drawn from the finished results")
    print(f"written: {_written(out, jobs, single)}")
    if len(failed):
        first = failed.iloc[0]
        where = f" (see {out}/summary.csv; run again to retry them)" if not single else ""
        print(
            f"mmreg: error: {plural(len(failed), 'log')} failed, e.g. {first['log']}: "
            f"{first['error']}{where}",
            file=sys.stderr,
        )
        return 1
    return 0


def _missing(value):
    return value is None or (isinstance(value, float) and math.isnan(value))


def _written(out, jobs, single):
    parts = []
    if single:
        n = sum(1 for _ in (out / "labels").glob("*.label")) if (out / "labels").is_dir() else 0
        parts.append(f"labels/ ({plural(n, 'frame')})")
        parts += ["tracks.csv", "poses.txt", "frames.csv"]
        if (out / "pictures").is_dir():
            parts.append("pictures/ (one per frame, animation.gif)")
    else:
        parts.append("<log>/ (labels/, tracks.csv, poses.txt, frames.csv)")
        parts.append("summary.csv")
    if (out / "av2_scene_flow").is_dir():
        parts.append("av2_scene_flow/")
    parts.append("run.json")
    return f"{out}/ ({', '.join(parts)})"


def table(header, rows):
    """Right-aligned columns under a ruled header."""
    cells = [header] + rows
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    lines = []
    for number, cell in enumerate(cells):
        lines.append("  ".join(c.rjust(w) for c, w in zip(cell, widths, strict=True)))
        if number == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _number(value, fmt):
    return "n/a" if _missing(value) else format(value, fmt)


def _print_log(out, row, elapsed, resuming, plan=None, verbose=False):
    """One log: its tracks and frames as tables (every row with ``verbose``), then one
    line of totals."""
    import pandas as pd

    from mmreg._cli.dataset import where_line
    from mmreg.runner._logs import read_log_record

    record = read_log_record(out) or {}
    unit = record.get("velocity_unit") or row.get("velocity_unit") or "m/s"
    with reading(out / "tracks.csv"):
        tracks = pd.read_csv(out / "tracks.csv")
    with reading(out / "frames.csv"):
        frames = pd.read_csv(out / "frames.csv", dtype={"name": str})
    speed = next((c for c in tracks.columns if c.startswith("speed_")), None)
    if len(tracks):
        grouped = tracks.groupby("track")
        by_track = pd.DataFrame(
            {
                "frames": grouped["frame"].count(),
                "first": grouped["frame"].min(),
                "last": grouped["frame"].max(),
                "speed": grouped[speed].mean() if speed else math.nan,
                "points": grouped["points"].mean(),
            }
        ).sort_values(["frames", "first"], ascending=[False, True])
        shown = by_track if verbose else by_track.head(_TRACK_ROWS)
        print(
            f"tracks ({len(by_track)}"
            + (f", the {len(shown)} seen longest" if len(by_track) > len(shown) else "")
            + "):"
        )
        rows = [
            [
                str(track),
                str(int(r["frames"])),
                f"{frames['name'].iloc[int(r['first'])]}",
                f"{frames['name'].iloc[int(r['last'])]}",
                _number(r["speed"], ".1f"),
                f"{r['points']:.0f}",
            ]
            for track, r in shown.iterrows()
        ]
        header = ["track", "frames", "first", "last", f"speed [{unit}]", "points"]
        print(table(header, rows))
    else:
        print("tracks: none")
    step = 1 if verbose else max(1, math.ceil(len(frames) / _FRAME_ROWS))
    static = _static_shares(frames)
    label = "frame" if step == 1 else f"frames (by {step})"
    rows = []
    for first in range(0, len(frames), step):
        block = frames.iloc[first : first + step]
        name = block["name"].iloc[0] + ("" if step == 1 else f"-{block['name'].iloc[-1]}")
        rows.append(
            [
                name,
                f"{block['points'].mean():,.0f}",
                f"{block['moving_points'].mean():,.0f}",
                f"{block['moving_objects'].mean():.{0 if step == 1 else 1}f}",
                f"{block['tracks'].mean():.{0 if step == 1 else 1}f}",
                _number(static[first : first + step].mean(), ".0%"),
                f"{block['fit_s'].mean():.2f}",
            ]
        )
    print(f"{label}s:" if step == 1 else f"{label}:")
    header = [
        "frame", "points", "moving points", "moving objects", "tracks", "static world",
        "fit [s]",
    ]  # fmt: skip
    print(table(header, rows))
    again = " (from an earlier run)" if resuming and bool(row.get("resumed")) else ""
    print(
        f"{plural(int(row['frames']), 'frame')}, {plural(int(row['tracks']), 'track')}, "
        f"{row['moving_objects_per_frame']:.1f} moving objects per frame, "
        f"{_number(row['s_per_frame'], '.2f')} s per frame{again}; {elapsed:.1f} s in all "
        f"({where_line(plan or {})})"
    )


def _static_shares(frames):
    """The static world's share of each frame's returns (the ego vehicle's body left
    out); NaN for frames.csv of earlier versions, which lack the counts."""
    import numpy as np

    if "static_points" not in frames:
        return np.full(len(frames), np.nan)
    body = frames.get("ego_body_points", 0)
    seen = (frames["returns"] - body).clip(lower=1)
    return (frames["static_points"] / seen).to_numpy(float)


def _print_logs(summary, elapsed, resuming, plan=None):
    """Several logs: one row each, then one line of totals."""
    from mmreg._cli.dataset import where_line

    rows = []
    for row in summary.to_dict("records"):
        done = row["status"] == "done"
        rows.append(
            [
                str(row["log"]),
                row["status"] + (" (earlier)" if done and row.get("resumed") else ""),
                _number(row.get("frames"), ".0f") if done else "",
                _number(row.get("tracks"), ".0f") if done else "",
                _number(row.get("moving_objects_per_frame"), ".1f") if done else "",
                _number(row.get("s_per_frame"), ".2f") if done else "",
            ]
        )
    header = ["log", "status", "frames", "tracks", "moving/frame", "s/frame"]
    print(table(header, rows))
    failed = int((summary["status"] != "done").sum())
    resumed = int(summary["resumed"].fillna(False).astype(bool).sum())
    print(
        f"{plural(len(summary), 'log')}: {len(summary) - failed:,} done"
        + (f" ({resumed:,} from an earlier run)" if resuming and resumed else "")
        + f", {failed:,} failed, {elapsed:.1f} s ({where_line(plan or {})})"
    )
    changed = summary.get("changed_input")
    if changed is not None:
        changed = summary[changed.astype(bool)]
        if len(changed):
            first = changed.iloc[0]
            print(
                f"{plural(len(changed), 'log')} run again: a file read changed since the "
                f"earlier run (e.g. {first['log']}: {first['changed_input']})"
            )
