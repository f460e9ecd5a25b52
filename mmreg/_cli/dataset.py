"""``mmreg run``: process a whole dataset as independent jobs on Dask (resumable)."""

import argparse
import contextlib
import hashlib
import importlib.util
import json
import os
import sys
import time
from pathlib import Path

from mmreg._cli._common import CLIError, one_line, plural, reading
from mmreg._cli.register import (
    TAU_RULE,
    _positive_float,
    _positive_int,
    _seed,
    _tau,
    resolve_tau,
)

NAME = "run"
HELP = "process LiDAR logs (tracks per log) or a dataset of pairs on Dask"
DESCRIPTION = """\
Run the registration over DATASET as independent tasks: in this process by default
when a cluster would not pay (a single log, few jobs, no free core for a second worker:
see "Where the work runs" below), else on a Dask LocalCluster on this machine, or on the
cluster at --scheduler.

A LiDAR log (a ROS bag, a KITTI or SemanticKITTI sequence, an Argoverse 2 log, a folder
of frames) is registered by default as a whole by the sequence estimator
(SequenceRegistration): every moving object is tracked from frame to frame with one id.
A folder of logs (an Argoverse 2 split, KITTI's sequences/ or its root) runs one log per
task. Written into --out (for a folder of logs, into --out/<log>/):
  - labels/<frame>.label: one uint32 per row of every frame's file (rows that are no
    return too, 0), the last frame included, as the LiDAR-MOS tools read them: lower
    16 bits 251 moving, 9 static, 0 unlabelled (outliers, the ego vehicle's body, no
    return); upper 16 bits the track id (0 for the static world);
  - tracks.csv: one row per track and frame, in the log's frame (the first sensor
    pose's): track, frame, time_s, the centroid x_m, y_m, z_m, the box length_m,
    width_m, height_m, yaw_rad, the velocity vx_m_s, vy_m_s, vz_m_s, speed_m_s,
    yaw_rate_rad_s, points; where the log has no times and --frame-rate is not given,
    per frame: vx_m_frame, ..., yaw_rate_rad_frame;
  - poses.txt: the sensor's pose of every frame in KITTI's format (the first the
    identity), as evo reads it;
  - frames.csv: one row per frame (its file, time, points, moving points and objects,
    tracks, points of the static world and of the ego body, seconds);
  - with --pictures, pictures/<frame>.png (every frame from above: moving points by
    track id with the ids and trails, the static world grey) and pictures/animation.gif;
  - Argoverse 2 logs also: av2_scene_flow/<log>/<timestamp_ns>.feather at the top of
    --out, the flow of every point of each sweep but the last in the scene-flow
    challenge's format (is_dynamic: the points of moving tracks);
  - log.json (written last: a log is done once it is there) and run.json (the options
    and the timings); for a folder of logs, summary.csv (one row per log).
The log's poses (KITTI's poses.txt, Argoverse 2's ego poses) start each ego motion
unless --no-poses. The frames' times come from the log (KITTI's times.txt, a bag's
header stamps, Argoverse 2's names, a .pcd's absolute time field), else --frame-rate;
speeds are in m/s whenever they are known. Run again after an interruption: a finished
log whose files did not change is skipped; --pictures given to a finished log draws its
pictures from its files. The console shows the tracks and the frames (moving objects,
the static world's share, seconds per frame) of one log, a row per log of several; -v
every row, the warnings and where the work ran; -q only where the results went.
'mmreg evaluate' and 'mmreg view' read the result.

--pairs runs per-pair jobs instead, as below (also the default for a folder of
correspondence files, and with --flow); --ground, --method, --max-iter and --tau set the
sequence estimator's pair registration as theirs; --capture-times applies to pairs only.

Per-pair jobs: DATASET is one of
  - an Argoverse 2 log (a folder with sensors/lidar; annotations.feather, the ego poses
    and map/ are used when there: the test split and the LiDAR dataset have no
    annotations), or a folder of logs (a split): one job per consecutive sweep pair (N
    sweeps, N-1 jobs), scored against the truth where the log has annotations. A log
    of a split that cannot be read is a failed row; the others go on;
  - a KITTI odometry or SemanticKITTI sequence (a folder with velodyne/*.bin; its
    poses, where it has them, start each pair's ego-motion ICP: poses.txt with calib.txt,
    or a poses.txt alone, read as the LiDAR's own as nuScenes-to-KITTI conversions write
    them), a folder of sweep files (.bin, .pcd.bin), or a ROS bag (.bag, a ROS 2 bag
    folder, .db3, .mcap; --topic picks its PointCloud2 topic when it has several): one
    job per consecutive frame pair (rows that are NaN or all zero, no return, are left
    out);
  - a folder of KITTI sequences (sequences/ holding 00, 01, ..., or the root holding
    sequences/): the jobs of every sequence, named <sequence>_<frame>; a sequence that
    cannot be read is a failed row, the others go on;
  - a folder of frames (*.ply, *.pcd, *.xyz or (n, 3) *.npy, in name order; --pattern
    GLOB picks one kind when it holds several): one job per consecutive pair, two raw
    sweeps, or with --pairs aligned frame k+1 giving the b-point of every row of frame k
    (index-aligned clouds);
  - a folder of correspondence files ((n, 6) *.npy, *.npz, *.csv, *.txt): one job per
    file; an .npz may hold the truth too ('labels', 'flow'), then scored.

--pairs says what a job fits:
  - auto (a bare --pairs): sweeps for LiDAR logs and frames;
  - sweeps: two raw sweeps of any sizes and orders, registered from the points alone:
    sweep k to sweep k+1 by SweepRegistration (ego motion and object motions by ICP,
    clusters by the --method variant);
  - truth: an Argoverse 2 log's ground-truth flow as the correspondences. The fit sees
    the answer: its scores measure the clustering, not the flow; the summary's pairs
    column says 'truth' and the printed line says how many jobs were fed the truth;
  - aligned: index-aligned frames (row i of frame k+1 matches row i of frame k, as a
    simulation's particles at two times); two LiDAR scans of the same size stacked row
    by row (the same ray, not the same point) are refused, as they are no
    correspondences. On an Argoverse 2 log the same as truth.

--flow DIR refines a network's scene flow (ZeroFlow, DeFlow, an Argoverse 2 challenge
entry) on the second sweep: DIR/<log>/<timestamp_ns>.feather (or DIR/<timestamp_ns>.feather
for one log) with flow_tx_m, flow_ty_m, flow_tz_m, one row per point of the sweep as the
log holds it; each pair is fitted as SweepRegistration.fit([a | a + flow], sweep=next).

--ground says what becomes of the ground points of LiDAR logs, as in 'mmreg register':
  - auto (default): where the log has a map (Argoverse 2 logs with map/), the map's
    ground points go to the estimator when its fit takes them ('ground', 'sweep_ground'),
    else they are dropped as with drop; without a map (KITTI, bags, folders) Patchwork++
    finds the ground of a z-up sweep and it joins the static world;
  - keep: registered as ordinary points;
  - drop: left out of the fit (labelled -1, moving with the static world), by the map's
    rule where there is one, else as found by Patchwork++.
The summary's ground column says what was done (masks, dropped, found, kept) and
n_ground how many points of the first sweep were ground.

Capture times: an Argoverse 2 log or sweep pair (or a bag's, with a per-point time field)
hands the capture time of every point (the sweep files' offset_ns, seconds after each sweep's
timestamp) and the time between the two sweeps to SweepRegistration, which moves each
moving object's points back to where the object was at its sweep's timestamp inside the
ICP (deskewing). Sweeps whose offsets are all zero are registered without;
--no-capture-times turns it off. The summary's capture_times column says which jobs had
them, its ground column what became of the ground (masks, dropped, kept).

Written into --out: jobs/<job>.npz per job (labels, rotations, translations, sigmas,
flow, moving, static_cluster, indices: the rows of the first sweep's file the job
fitted, so that labels[k] and flow[k] belong to row indices[k]; meta), each whole or not
at all, compressed, labels as small integers and flows as float32, a sweep's flow of
every row only where it is not the fit's own (mmreg.runner.read_job_result restores it;
--full-arrays keeps every array whole);
av2_scene_flow/<log>/<timestamp_ns>.feather per Argoverse 2 job: the flow of every point
of the sweep in the scene-flow challenge's format (flow_tx_m, flow_ty_m, flow_tz_m,
is_dynamic; dropped ground and outliers move with the static world), ready for the
official evaluation; summary.parquet and summary.csv (one row per job: sizes, clusters,
timings, status, what it was fitted on, the static world's share, the fastest moving
object, and the scores when the truth is known); pictures/<job>.png with --pictures
(given to a finished run: the missing ones, drawn without fitting again); and run.json
(the dataset, the options and the timings). The console shows a table of the jobs
(points, moving objects, the static world's share, the fastest object in m/s where the
interval is known, seconds), -v every job and the warnings, -q only where the results
went. 'mmreg evaluate' scores a --pairs run of a LiDAR log against the log's own labels
and poses, every pair at once.

Run the same command again after an interruption (Ctrl-C, a crash, a lost worker): jobs
whose complete result is in --out are skipped. A job records the size and modification
time of every file it reads: one whose files changed since runs again (the summary's
changed_input column names the file, and a line says how many). A job that fails is a
row with its error; the others go on, and the next run retries it (exit code 1 while
any job fails).

--out must be new, an empty folder, or an earlier 'mmreg run' of the same dataset and
options (it is then resumed); a folder holding other files is never touched. Another
dataset or other options need --overwrite, which runs every job again, unless the
earlier run has no result at all (every job failed): that one is simply replaced.

With --scheduler, the workers must have mmreg installed and read DATASET at the same
path (a shared file system); the results come back to this machine.

Where the work runs: a Dask LocalCluster costs seconds to start (and every worker its
imports), and workers beside jobs that keep several threads busy only take cores from
them. By default the tasks run in this process unless at least two workers fit on the
free cores (the cores less the load of other processes, over each task's own threads,
the estimator's n_jobs) and, after the first task is timed here, the rest would take
this process at least twice the cluster's start longer than the workers. --n-workers N
starts N workers (0: in this process); run.json and -v say where it ran and why.
"""
EPILOG = """\
examples:
  mmreg run /data/kitti/dataset/sequences/08 --out kitti-08 --pictures
  mmreg run /data/av2/sensor/val --scheduler tcp://10.0.0.5:8786 --out val-tracks
  mmreg run scene-0006 --frame-rate 2 --out scene-0006   # nuScenes keyframes: 2 Hz
  mmreg run /data/kitti/odometry/sequences/08 --pairs --out kitti-08-pairs
  mmreg run /data/av2/sensor/test/0c6e62d7-bdfa-3061-8d3d-03b13aa21f68 --out test-0c6e
  mmreg run /data/av2/sensor/val --scheduler tcp://10.0.0.5:8786 --out val
  mmreg run /data/av2/sensor/val/0c6e62d7-bdfa-3061-8d3d-03b13aa21f68 --flow zeroflow/val
  mmreg run /data/av2/sensor/val/0c6e62d7-bdfa-3061-8d3d-03b13aa21f68 --pairs truth
  mmreg run /data/kitti/odometry/sequences/08 --out kitti-08
  mmreg run drive.bag --topic /velodyne_points --out drive
  mmreg run /data/kitti/odometry/sequences --out kitti-all
  mmreg run lidar_frames/ --out result
  mmreg run mixed_frames/ --pattern '*.bin' --out result
  mmreg run particles/ --pairs aligned --out result --method robust --tau 1.5
"""

METHODS = ("sweep", "robust", "paper")
LAYOUTS = ("auto", "argoverse2", "sequence", "frames", "correspondences")
PAIRS = ("auto", "sweeps", "truth", "aligned")
GROUND = ("auto", "keep", "drop")
# What an 'mmreg run' folder holds at its top (jobs/ holds <job>.npz files).
RUN_FILES = (
    "run.json",
    "summary.parquet",
    "summary.csv",
    "jobs",
    "av2_scene_flow",
    "pictures",
)


def add_arguments(parser):
    parser.add_argument(
        "dataset", metavar="DATASET", help="a dataset folder or a ROS bag (see above)"
    )
    parser.add_argument(
        "--pictures",
        action="store_true",
        help="also draw every frame of a log from above, and its animation (pairs: every "
        "job's result) into OUT/pictures/",
    )
    parser.add_argument(
        "--out",
        metavar="DIR",
        default=None,
        help="results folder (default: DATASET's name + '-mmreg-run-' + 8 hex digits of "
        "its full path, in the current directory)",
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
        type=_workers,
        metavar="N",
        default=None,
        help="worker processes of a LocalCluster; 0: in this process, no cluster (default: "
        "in this process for one log or few jobs, else one worker per free core and the "
        "jobs' own threads, see above)",
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
        nargs="?",
        const="auto",
        default=None,
        type=_pairs,
        metavar="{" + ",".join(PAIRS) + "}",
        help="per-pair jobs instead of the sequence estimator: 'sweeps' (also bare --pairs "
        "or 'auto'), two raw sweeps; 'truth', an Argoverse 2 log's ground-truth flow (the "
        "fit sees the answer); 'aligned', index-aligned frames; see above (default: the "
        "sequence estimator on LiDAR logs and frames, pairs for correspondence files)",
    )
    parser.add_argument(
        "--voxel-size",
        type=_positive_float,
        metavar="V",
        default=None,
        help="logs: register one point per voxel of side V (the points' units; 0.1 for "
        "metres is a third faster on a 64-beam sensor and loses some objects); every point "
        "takes its voxel's labels (default: every point)",
    )
    parser.add_argument(
        "--jobs",
        type=_positive_int,
        metavar="N",
        default=2,
        help="logs: processes per log; 2 or more registers the pairs in a process of their "
        "own while this one keeps the tracks (the same results in 0.6-0.8 of the "
        "time), 1 runs both in one",
    )
    parser.add_argument(
        "--frame-rate",
        type=_positive_float,
        metavar="HZ",
        default=None,
        help="frames per second where the log's frames have no times (nuScenes keyframes: "
        "2): speeds in m/s, and the pairs' motions bounded (default: KITTI's times.txt, a "
        "bag's header stamps, a .pcd's absolute time field; without them, m per frame)",
    )
    parser.add_argument(
        "--no-poses",
        dest="poses",
        action="store_false",
        help="logs and pairs: do not start the ego motions from the log's poses (KITTI poses.txt, "
        "Argoverse 2 ego poses); register from the points alone, so that 'mmreg evaluate' "
        "compares the poses found with independent ones",
    )
    parser.add_argument(
        "--flow",
        metavar="DIR",
        default=None,
        help="Argoverse 2: refine this scene flow (DIR/<log>/<timestamp_ns>.feather, "
        "challenge layout) on the second sweep (see above)",
    )
    parser.add_argument(
        "--topic",
        metavar="TOPIC",
        default=None,
        help="a ROS bag's PointCloud2 topic (needed only when the bag has several)",
    )
    parser.add_argument(
        "--pattern",
        metavar="GLOB",
        default=None,
        help="a folder of frames or sweep files: the files that are frames (e.g. '*.bin'); "
        "needed when it holds frames of several kinds",
    )
    parser.add_argument(
        "--ground",
        choices=GROUND,
        default="auto",
        help="LiDAR logs' ground points, as in 'mmreg register': 'auto' hands the map's "
        "ground to an estimator that takes it (else as drop; no map: Patchwork++'s ground "
        "joins the static world), 'keep' registers them as any point, 'drop' leaves them "
        "out (the map's rule, else Patchwork++)",
    )
    parser.add_argument(
        "--keep-ground",
        dest="ground",
        action="store_const",
        const="keep",
        help="deprecated: the same as --ground keep",
    )
    parser.add_argument(
        "--no-capture-times",
        dest="capture_times",
        action="store_false",
        help="logs and sweep pairs (Argoverse 2, bags with per-point times): do not "
        "deskew the moving objects by the points' capture times; register as if each "
        "sweep were taken at once",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="run every job again, replacing an earlier run at --out (never other files)",
    )
    parser.add_argument(
        "--full-arrays",
        action="store_true",
        help="pairs: keep every array of a job whole in jobs/<job>.npz (float64 flow, "
        "int64 labels, the sweep's flow of every row) instead of the compact default "
        "(integers, float32, the sweep's flow only where it is not the fit's own)",
    )
    parser.add_argument(
        "--quiet",
        "-q",
        action="store_true",
        help="no progress bar, no table: only where the results went",
    )
    parser.add_argument(
        "--verbose",
        "-v",
        action="store_true",
        help="every row of the tables (no grouping), each job's or log's warnings, and where "
        "the work ran (this process or a cluster, and why) with its timings",
    )


def _pairs(text):
    if text not in PAIRS:
        raise argparse.ArgumentTypeError(
            f"invalid choice: {text!r} (choose from {', '.join(PAIRS)}; a bare --pairs goes "
            "after DATASET)"
        )
    return text


def _workers(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number; got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 (in this process) or more; got {value}")
    return value


def _configuration(args):
    """What the results in --out depend on (an earlier run resumes only if it matches)."""
    from mmreg import __version__

    return {
        "dataset": str(Path(args.dataset).resolve()),
        "layout": args.layout,
        "pairs": args.pairs,
        "ground": args.ground,
        "topic": args.topic,
        "flow": None if args.flow is None else str(Path(args.flow).resolve()),
        "capture_times": args.capture_times,
        "method": args.method,
        "tau": args.tau,
        "max_iter": args.max_iter,
        "seed": args.seed,
        "mmreg": __version__,
    } | {
        key: value
        for key, value in (
            ("pattern", getattr(args, "pattern", None)),
            ("frame_rate", getattr(args, "frame_rate", None)),
            ("poses", None if getattr(args, "poses", True) else False),
            ("full_arrays", getattr(args, "full_arrays", False) or None),
        )
        if value is not None
    }


def _foreign(out):
    """Names in ``out`` that an 'mmreg run' (of pairs or of logs) does not write."""
    from mmreg._cli._sequence_run import foreign_names

    return foreign_names(out)


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
        if not _holds_results(out):  # every job failed: nothing to keep
            return False
        raise CLIError(
            f"{out}: holds the results of another dataset or other options; pass --overwrite "
            "to replace them, or choose another --out"
        )
    return True


def _holds_results(out):
    """Whether ``out`` holds a job's or a log's result (an earlier run whose jobs all
    failed does not: it may be replaced by a run with other options, such as an error's
    advice)."""
    from mmreg._cli._sequence_run import holds_results

    return holds_results(out)


def _estimator(args, jobs):
    from mmreg import MultiModelRegistration, SweepRegistration
    from mmreg.runner import _SWEEP_JOBS

    estimator = MultiModelRegistration(
        variant=args.method, tau=args.tau, max_iter=args.max_iter, random_state=args.seed
    )
    if any(isinstance(job, _SWEEP_JOBS) for job in jobs):
        estimator = SweepRegistration(estimator, random_state=args.seed)
    return estimator


@contextlib.contextmanager
def _missing_reader():
    """A reader's missing package (rosbags for a bag) is one line naming the install."""
    try:
        yield
    except ImportError as error:
        raise CLIError(one_line(error)) from None


def default_out(args):
    """``<DATASET's name>-mmreg-run-<8 hex digits of its full path>``: never shared."""
    path = str(Path(args.dataset).resolve())
    digest = hashlib.sha256(path.encode("utf-8", "surrogateescape")).hexdigest()[:8]
    name = Path(os.path.abspath(args.dataset)).name or Path(path).name  # as the user has it
    return f"{name}-mmreg-run-{digest}"


def run(args):
    from mmreg import io as mmio
    from mmreg._cli._lidar_input import option_words
    from mmreg.runner import (
        _SWEEP_JOBS,
        Argoverse2PairJob,
        dataset_jobs,
        run_dataset,
    )

    if importlib.util.find_spec("distributed") is None:
        raise CLIError("'mmreg run' needs dask.distributed: pip install 'mmreg[dask]'")
    if args.out is None:
        args.out = default_out(args)
    out = Path(args.out)
    if args.pairs is None and args.flow is None:  # a log, or a folder of logs?
        from mmreg._cli._sequence_run import run_sequences
        from mmreg.runner._logs import NotALogError, log_jobs

        try:
            with reading(args.dataset), _missing_reader(), option_words():
                logs = log_jobs(
                    args.dataset,
                    layout=args.layout,
                    topic=args.topic,
                    pattern=args.pattern,
                    poses=args.poses,
                    capture_times=args.capture_times,
                )
        except CLIError as error:
            if not isinstance(error.__cause__, NotALogError):
                raise
        else:
            args.tau = resolve_tau(args.tau, True)
            return run_sequences(args, logs)
    if args.pairs is None:
        args.pairs = "auto"
    # A listing: no job is loaded yet.
    with reading(args.dataset), _missing_reader(), option_words():
        jobs = dataset_jobs(
            args.dataset,
            layout=args.layout,
            ground=args.ground,
            pairs=args.pairs,
            capture_times=args.capture_times,
            flow=args.flow,
            topic=args.topic,
            pattern=args.pattern,
            frame_rate=args.frame_rate,
            poses=args.poses,
        )
    lidar = args.pairs == "sweeps" or any(
        isinstance(job, (*_SWEEP_JOBS, Argoverse2PairJob)) for job in jobs
    )
    args.tau = resolve_tau(args.tau, lidar)
    configuration = _configuration(args)
    resuming = check_run_out(out, configuration, overwrite=args.overwrite)  # before any work
    try:
        if args.overwrite:  # only result files, checked above
            from mmreg._cli._sequence_run import remove_results

            if out.is_dir():
                remove_results(out)
        out.mkdir(parents=True, exist_ok=True)
        record = {"configuration": configuration, "jobs": len(jobs)}
        with mmio.atomic_write(out / "run.json", "w") as handle:
            handle.write(json.dumps(record, indent=2) + "\n")
    except OSError as error:
        raise CLIError(f"{out}: cannot be written: {one_line(error.strerror or error)}") from None
    start = time.perf_counter()
    summary = run_dataset(
        jobs,
        _estimator(args, jobs),
        out,
        scheduler=args.scheduler,
        n_workers=args.n_workers,
        progress=not args.quiet,
        pictures=args.pictures,
        full_arrays=args.full_arrays,
    )
    elapsed = time.perf_counter() - start
    plan = summary.attrs.get("plan", {})
    record["timings"] = _timings(summary, elapsed, plan)
    try:
        with mmio.atomic_write(out / "run.json", "w") as handle:
            handle.write(json.dumps(record, indent=2, default=str) + "\n")
    except OSError as error:
        raise CLIError(f"{out}: cannot be written: {one_line(error.strerror or error)}") from None
    failed = summary[summary["status"] != "done"]
    resumed = int(summary["resumed"].sum())
    if not args.quiet:
        print_jobs(summary, verbose=args.verbose)
        print(
            f"{plural(len(summary), 'job')}: {len(summary) - len(failed):,} done"
            + (f" ({resumed:,} from an earlier run)" if resuming and resumed else "")
            + f", {len(failed):,} failed, {elapsed:.1f} s"
            + f" ({where_line(plan)})"
        )
        if args.verbose:
            print_plan(plan, record["timings"])
        fed = int(summary["pairs"].eq("truth").sum()) if "pairs" in summary else 0
        if fed:
            print(
                f"{plural(fed, 'job')} fitted on the ground-truth flow (--pairs truth): the "
                "fit saw the answer; its scores measure the clustering, not the flow"
            )
        scores = ("iou", "moving_found", "epe3d", "epe_moving", "epe_static")
        scores = [c for c in scores if c in summary]
        if scores:
            means = summary[scores].mean(numeric_only=True)
            print("mean " + ", ".join(f"{name} {value:.3f}" for name, value in means.items()))
        changed = summary.get("changed_input")
        changed = summary[changed.astype(bool)] if changed is not None else changed
        if changed is not None and len(changed):
            first = changed.iloc[0]
            print(
                f"{plural(len(changed), 'job')} run again: a file read changed since the "
                f"earlier run (e.g. {first['job']}: {first['changed_input']})"
            )
        redrawn = plan.get("redrawn", 0)
        if redrawn:
            print(f"{plural(redrawn, 'picture')} of finished jobs drawn (--pictures)")
    print(f"written: {_written(out)}")
    if len(failed):
        first = failed.iloc[0]
        print(
            f"mmreg: error: {plural(len(failed), 'job')} failed, e.g. {first['job']}: "
            f"{first['error']} (see {out}/summary.csv; run again to retry them)",
            file=sys.stderr,
        )
        return 1
    return 0


def _written(out):
    """The run's folder and everything it holds, by name."""
    parts = []
    if (out / "jobs").is_dir():
        n = sum(1 for _ in (out / "jobs").glob("*.npz"))
        parts.append(f"jobs/ ({plural(n, 'job')})")
    if (out / "av2_scene_flow").is_dir():
        parts.append("av2_scene_flow/")
    if (out / "pictures").is_dir():
        n = sum(1 for _ in (out / "pictures").glob("*.png"))
        parts.append(f"pictures/ ({plural(n, 'picture')})")
    parts += ["summary.parquet", "summary.csv", "run.json"]
    return f"{out}/ ({', '.join(parts)})"


def _seconds(value):
    import math

    return None if value is None or (isinstance(value, float) and math.isnan(value)) else value


def _timings(summary, elapsed, plan):
    """run.json's timings: the whole run, where it ran, and the jobs' seconds."""
    done = summary[(summary["status"] == "done") & ~summary["resumed"].astype(bool)]
    load = float(done["load_s"].sum()) if "load_s" in done else 0.0
    fit = float(done["fit_s"].sum()) if "fit_s" in done else 0.0
    return {
        "total_s": elapsed,
        "where": plan.get("where"),
        "workers": plan.get("workers"),
        "why": plan.get("why"),
        "cluster_start_s": plan.get("start_s", 0.0),
        "jobs_run": int(len(done)),
        "jobs_resumed": int(summary["resumed"].astype(bool).sum()),
        "load_s": load,
        "fit_s": fit,
        "s_per_job": _seconds((load + fit) / len(done)) if len(done) else None,
    }


def where_line(plan):
    """Where the work ran, in a few words."""
    where = plan.get("where", "this process")
    if where == "this process":
        return "in this process"
    if where == "local cluster":
        return f"on {plural(plan.get('workers') or 0, 'worker')}"
    return f"on {where}"


def print_plan(plan, timings):
    """-v: where the work ran and why, and its seconds."""
    line = f"ran {where_line(plan)}"
    if plan.get("why"):
        line += f" ({plan['why']})"
    if plan.get("start_s"):
        line += f"; the cluster took {plan['start_s']:.1f} s to start"
    print(line)
    parts = [
        f"{k.removesuffix('_s')} {v:.1f} s"
        for k, v in timings.items()
        if k in ("load_s", "fit_s") and v is not None
    ]
    if parts:
        print("seconds: " + ", ".join(parts) + f", {timings['total_s']:.1f} s in all")


# Rows of the jobs' table at most; more are grouped (every n-th job's range).
_JOB_ROWS = 40


def print_jobs(summary, *, verbose=False):
    """The jobs as a short table: points, moving objects, the static world's share of the
    returns, the fastest moving object, seconds; groups of jobs when there are many
    (every job with ``verbose``), then each job's warnings with ``verbose``."""
    import math

    from mmreg._cli._sequence_run import table

    done = summary[summary["status"] == "done"]
    if not len(done):
        return
    unit = "m/s"
    if "speed_unit" in done and done["speed_unit"].eq("m/frame").any():
        unit = "m/frame" if done["speed_unit"].eq("m/frame").all() else "m/s or m/frame"
    step = 1 if verbose else max(1, math.ceil(len(done) / _JOB_ROWS))
    rows = []
    for first in range(0, len(done), step):
        block = done.iloc[first : first + step]
        name = str(block["job"].iloc[0]) + ("" if step == 1 else f"-{block['job'].iloc[-1]}")
        digits = 0 if step == 1 else 1
        speed = block["max_speed"].max() if "max_speed" in block else math.nan
        share = block["static_share"].mean() if "static_share" in block else math.nan
        rows.append(
            [
                name,
                f"{block['n'].mean():,.0f}",
                f"{block['n_moving'].clip(lower=0).mean():.{digits}f}",
                "n/a" if math.isnan(share) else f"{share:.0%}",
                "n/a" if math.isnan(speed) else f"{speed:.1f}",
                f"{block['fit_s'].mean():.2f}",
            ]
        )
    label = "job" if step == 1 else f"jobs (by {step})"
    print(f"{label}s:" if step == 1 else f"{label}:")
    header = ["job", "points", "moving objects", "static world", f"fastest [{unit}]", "fit [s]"]
    print(table(header, rows))
    print_warnings(summary["job"], summary, verbose=verbose)


def print_warnings(names, summary, *, verbose=False):
    """Each warning once, with the jobs (or logs) that gave it: every one with
    ``verbose``, else those that say the input is not in the points' units or their
    sensor's frame (the results are wrong, as they stand)."""
    column = "warnings" if verbose else "input_warnings"
    if column in summary:
        _print_warnings(names, summary[column])


def _print_warnings(names, warnings):
    """-v: each warning once, with the jobs (or logs) that gave it."""
    by_text = {}
    for name, text in zip(names, warnings, strict=True):
        if isinstance(text, str) and text:
            by_text.setdefault(text, []).append(str(name))
    for text, which in by_text.items():
        shown = which[0] if len(which) == 1 else f"{which[0]} and {len(which) - 1} more"
        print(f"{shown}: warning: {text}")
