"""``mmreg run``: process a whole dataset as independent jobs on Dask (resumable)."""

import importlib.util
import json
import shutil
import sys
import time
from pathlib import Path

from mmreg._cli._common import CLIError, one_line, plural, reading
from mmreg._cli.register import TAU_RULE, _positive_int, _seed, _tau, resolve_tau

NAME = "run"
HELP = "process a dataset (a folder of frames or files, Argoverse 2 logs) on Dask"
DESCRIPTION = """\
Run MultiModelRegistration on every job of DATASET, as independent tasks on a Dask
cluster: a LocalCluster on this machine by default, or the one at --scheduler.

DATASET is one of
  - an Argoverse 2 sensor log (a folder with sensors/lidar, annotations.feather, ...), or
    a folder of such logs: one job per consecutive sweep pair, the ground-truth flow as
    the correspondences (ground removed unless --keep-ground), scored against the truth;
  - a folder of frames (*.ply, *.pcd, *.xyz or (n, 3) *.npy, in name order): one job per
    consecutive pair, frame k+1 giving the b-point of every row of frame k (index-aligned
    clouds);
  - a folder of correspondence files ((n, 6) *.npy, *.npz, *.csv, *.txt): one job per
    file; an .npz may hold the truth too ('labels', 'flow'), then scored.

--pairs says what a pair of consecutive frames or sweeps is:
  - aligned (default): correspondences; frames must be index-aligned (same size, row i
    of frame k+1 matches row i of frame k); Argoverse 2: the ground-truth flow gives
    every point's match;
  - sweeps: two raw sweeps of any sizes and orders (real LiDAR frames), registered from
    the points alone: sweep k to sweep k+1 by SweepRegistration (ego motion and object
    motions by ICP, clusters by the --method variant). Argoverse 2 jobs are still scored
    against the ground-truth flow of sweep k. Not for correspondence files.

Capture times: with --pairs sweeps, an Argoverse 2 job hands the capture time of every
point (the sweep files' offset_ns, seconds after each sweep's timestamp) and the time
between the two sweeps to SweepRegistration, which moves each moving object's points back
to where the object was at its sweep's timestamp inside the ICP (deskewing: the two LiDAR
heads see a car about 50 ms apart, two copies of it within one sweep). Sweeps whose
offsets are all zero are registered without; --no-capture-times turns it off. The
summary's capture_times column says which jobs had them. Frames carry no times.

Written into --out: jobs/<job>.npz per job (labels, rotations, translations, sigmas,
flow, moving, meta), each whole or not at all; summary.parquet and summary.csv (one row
per job: sizes, clusters, timings, status, and the scores when the truth is known); and
run.json (the dataset and the options).

Run the same command again after an interruption (Ctrl-C, a crash, a lost worker): jobs
whose complete result is in --out are skipped. A job that fails is a row with its error;
the others go on, and the next run retries it (exit code 1 while any job fails).

--out must be new, an empty folder, or an earlier 'mmreg run' of the same dataset and
options (it is then resumed); a folder holding other files is never touched. Another
dataset or other options need --overwrite, which runs every job again.

With --scheduler, the workers must have mmreg installed and read DATASET at the same
path (a shared file system); the results come back to this machine.
"""
EPILOG = """\
examples:
  mmreg run /data/av2/sensor/val/0c6e62d7-bdfa-3061-8d3d-03b13aa21f68 --out val-0c6e
  mmreg run frames/ --out result --method robust --tau 1.5
  mmreg run lidar_frames/ --pairs sweeps --out result
  mmreg run /data/av2/sensor/val/0c6e62d7-bdfa-3061-8d3d-03b13aa21f68 --pairs sweeps
  mmreg run /data/av2/sensor/val/0c6e62d7-bdfa-3061-8d3d-03b13aa21f68 --pairs sweeps \
      --no-capture-times --out without-times
  mmreg run /data/av2/sensor/val --scheduler tcp://10.0.0.5:8786 --out val
"""

METHODS = ("sweep", "robust", "paper")
LAYOUTS = ("auto", "argoverse2", "frames", "correspondences")
PAIRS = ("aligned", "sweeps")
# What an 'mmreg run' folder holds at its top (jobs/ holds <job>.npz files).
RUN_FILES = ("run.json", "summary.parquet", "summary.csv", "jobs")


def add_arguments(parser):
    parser.add_argument("dataset", metavar="DATASET", help="a dataset folder (see above)")
    parser.add_argument(
        "--out",
        metavar="DIR",
        default=None,
        help="results folder (default: DATASET's name + '-mmreg-run', in the current directory)",
    )
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        default=None,
        help="address of a running Dask scheduler (tcp://host:8786); default: a "
        "LocalCluster on this machine",
    )
    parser.add_argument(
        "--n-workers",
        type=_positive_int,
        metavar="N",
        default=None,
        help="worker processes of the LocalCluster (default: one per core)",
    )
    parser.add_argument(
        "--method",
        choices=METHODS,
        default="sweep",
        help="the variant of MultiModelRegistration ('sweep': for LiDAR sweeps)",
    )
    parser.add_argument(
        "--tau",
        type=_tau,
        default="auto",
        help="distance gate, in the points' units; 'none' turns it off; " + TAU_RULE,
    )
    parser.add_argument("--max-iter", type=_positive_int, default=10, help="most EM iterations")
    parser.add_argument("--seed", type=_seed, default=0, help="random seed of every job")
    parser.add_argument("--layout", choices=LAYOUTS, default="auto", help="what DATASET holds")
    parser.add_argument(
        "--pairs",
        choices=PAIRS,
        default="aligned",
        help="what consecutive frames or sweeps are: 'aligned' correspondences (default; "
        "Argoverse 2: matched by the true flow) or raw 'sweeps' of any sizes and orders, "
        "registered from the points alone (see above)",
    )
    parser.add_argument(
        "--keep-ground", action="store_true", help="Argoverse 2: keep the ground points"
    )
    parser.add_argument(
        "--no-capture-times",
        dest="capture_times",
        action="store_false",
        help="Argoverse 2 with --pairs sweeps: do not deskew the moving objects by the "
        "points' capture times (offset_ns); register as if each sweep were taken at once",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="run every job again, replacing an earlier run at --out (never other files)",
    )
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress bar, no table")


def _configuration(args):
    """What the results in --out depend on (an earlier run resumes only if it matches)."""
    from mmreg import __version__

    return {
        "dataset": str(Path(args.dataset).resolve()),
        "layout": args.layout,
        "pairs": args.pairs,
        "drop_ground": not args.keep_ground,
        "capture_times": args.capture_times,
        "method": args.method,
        "tau": args.tau,
        "max_iter": args.max_iter,
        "seed": args.seed,
        "mmreg": __version__,
    }


def _foreign(out):
    """Names in ``out`` that an 'mmreg run' does not write."""
    names = sorted(p.name for p in out.iterdir() if p.name not in RUN_FILES)
    jobs = out / "jobs"
    if jobs.exists() and not jobs.is_dir():
        names.append("jobs")
    elif jobs.is_dir():
        names += [f"jobs/{p.name}" for p in jobs.iterdir() if p.suffix not in (".npz", ".tmp")]
    return names


def check_run_out(out, configuration, *, overwrite):
    """Check ``out`` before any work; True when it holds an earlier run to resume."""
    out = Path(out)
    if not (out.exists() or out.is_symlink()):
        return False
    if not out.is_dir():
        raise CLIError(f"{out}: exists and is not a folder; choose another --out")
    try:
        entries = list(out.iterdir())
    except OSError as error:
        raise CLIError(f"{out}: cannot be read: {one_line(error.strerror or error)}") from None
    if not entries:
        return False
    foreign = _foreign(out)
    if foreign:
        shown = ", ".join(foreign[:3]) + (", ..." if len(foreign) > 3 else "")
        raise CLIError(
            f"{out}: is a folder holding files that 'mmreg run' did not write ({shown}); it "
            "is left as it is: choose another --out"
        )
    if overwrite:
        return False
    earlier = None
    with reading(out / "run.json"):
        if (out / "run.json").exists():
            earlier = json.loads((out / "run.json").read_text()).get("configuration")
    if earlier != configuration:
        raise CLIError(
            f"{out}: holds the results of another dataset or other options; pass --overwrite "
            "to replace them, or choose another --out"
        )
    return True


def _estimator(args):
    from mmreg import MultiModelRegistration, SweepRegistration

    estimator = MultiModelRegistration(
        variant=args.method, tau=args.tau, max_iter=args.max_iter, random_state=args.seed
    )
    if args.pairs == "sweeps":
        estimator = SweepRegistration(estimator, random_state=args.seed)
    return estimator


def run(args):
    from mmreg import io as mmio
    from mmreg.runner import (
        Argoverse2PairJob,
        Argoverse2SweepPairJob,
        dataset_jobs,
        run_dataset,
    )

    if importlib.util.find_spec("distributed") is None:
        raise CLIError("'mmreg run' needs dask.distributed: pip install 'mmreg[dask]'")
    if args.out is None:
        args.out = f"{Path(args.dataset).resolve().name}-mmreg-run"
    out = Path(args.out)
    with reading(args.dataset):  # a listing of the dataset: no job is loaded yet
        jobs = dataset_jobs(
            args.dataset,
            layout=args.layout,
            drop_ground=not args.keep_ground,
            pairs=args.pairs,
            capture_times=args.capture_times,
        )
    lidar = args.pairs == "sweeps" or any(
        isinstance(job, (Argoverse2PairJob, Argoverse2SweepPairJob)) for job in jobs
    )
    args.tau = resolve_tau(args.tau, lidar)
    configuration = _configuration(args)
    resuming = check_run_out(out, configuration, overwrite=args.overwrite)  # before any work
    try:
        if args.overwrite and (out / "jobs").is_dir():
            shutil.rmtree(out / "jobs")  # only result files, checked above
        out.mkdir(parents=True, exist_ok=True)
        record = {"configuration": configuration, "jobs": len(jobs)}
        with mmio.atomic_write(out / "run.json", "w") as handle:
            handle.write(json.dumps(record, indent=2) + "\n")
    except OSError as error:
        raise CLIError(f"{out}: cannot be written: {one_line(error.strerror or error)}") from None
    start = time.perf_counter()
    summary = run_dataset(
        jobs,
        _estimator(args),
        out,
        scheduler=args.scheduler,
        n_workers=args.n_workers,
        progress=not args.quiet,
    )
    elapsed = time.perf_counter() - start
    failed = summary[summary["status"] != "done"]
    resumed = int(summary["resumed"].sum())
    if not args.quiet:
        print(
            f"{plural(len(summary), 'job')}: {len(summary) - len(failed):,} done"
            + (f" ({resumed:,} from an earlier run)" if resuming and resumed else "")
            + f", {len(failed):,} failed, {elapsed:.1f} s"
        )
        scores = ("iou", "moving_found", "epe3d", "epe_moving", "epe_static")
        scores = [c for c in scores if c in summary]
        if scores:
            means = summary[scores].mean(numeric_only=True)
            print("mean " + ", ".join(f"{name} {value:.3f}" for name, value in means.items()))
        print(f"written: {out}/ (jobs/, summary.parquet, summary.csv, run.json)")
    if len(failed):
        first = failed.iloc[0]
        print(
            f"mmreg: error: {plural(len(failed), 'job')} failed, e.g. {first['job']}: "
            f"{first['error']} (see {out}/summary.csv; run again to retry them)",
            file=sys.stderr,
        )
        return 1
    return 0
