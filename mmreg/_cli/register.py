"""``mmreg register``: find the moving objects in a file of correspondences."""

import argparse
import contextlib
import hashlib
import math
import time
from pathlib import Path

from mmreg._cli._common import (
    CLIError,
    NoReturns,
    Steps,
    check_correspondences,
    check_labels,
    check_out,
    count_line,
    ego_body,
    format_table,
    input_record,
    load_npz,
    npy_bytes,
    one_line,
    plural,
    reading,
    render_png,
    reported_warnings,
    result_figure,
    summarize,
    sweep_residuals,
    write_result_dir,
)
from mmreg._cli._lidar_input import (
    check_points_for,
    check_sequence_options,
    check_time_range,
    file_timing,
    holds_points_only,
    interval_between,
    is_sequence,
    read_frames,
)

NAME = "register"
HELP = "find the moving objects, their motions and the outliers in correspondences"
DESCRIPTION = """\
Find every rigidly moving object in putative correspondences (a_i, b_i) between two
point clouds, with MultiModelRegistration, and write the result into a directory.

INPUT is one of
  - an (n, 6) array [a | b] in .npy, .npz, .csv or .txt (one correspondence per row:
    a_x a_y a_z b_x b_y b_z);
  - the a-points with --target (the b-points, one per a-point in the same order), --flow
    (an (n, 3) scene flow, b = a + flow) or --sweep (below): a point cloud (.ply, .pcd,
    .xyz), an (n, 3) array (.npy, .csv, .txt), or a LiDAR sweep: KITTI velodyne .bin
    (float32 x y z reflectance), nuScenes .pcd.bin (float32 x y z intensity ring),
    Argoverse 2 .feather (x y z, and offset_ns: the capture times);
  - a sequence: a ROS 1 .bag, a ROS 2 bag (its folder, .db3 or .mcap) with a
    sensor_msgs/PointCloud2 topic (--topic, needed when it holds several; needs
    pip install "mmreg[ros]"), a KITTI or SemanticKITTI sequence folder (velodyne/*.bin),
    an Argoverse 2 log (sensors/lidar/*.feather) or a folder of frame files (in name
    order; --pattern GLOB picks one kind when it holds several): --frame K (default 0)
    registers frame K (the a-points) against frame K+1 (the second sweep). The
    sequence's poses, where it has them, start the ego-motion ICP: a KITTI sequence's
    poses.txt with its calib.txt (the camera's poses), or a poses.txt alone, read as
    the LiDAR's own (as nuScenes-to-KITTI conversions write them; a warning says so).
--target, --flow and --sweep take every point format above too. Invalid LiDAR returns
(NaN or all-zero rows) are read as they are. Rows given as pairs (an (n, 6) array, or
--target) must pair each point with where it went: two LiDAR sweeps of the same size
stacked row by row (row i of one scan with row i of the other, the same ray, not the
same point) are refused; register those with --sweep.

--sweep S names the second sweep as its own points (any size, any order). With
correspondences (an array, or a cloud with --target or --flow) the default variant
finds the clusters and each moving cluster's motion is refined on S by robust
point-to-plane ICP (SweepRegistration); with a cloud INPUT alone the two raw sweeps are
registered (ego motion, then every island of INPUT aligned to S). --target keeps its
meaning: one b-point per a-point, in the same order.

Capture times (with --sweep): a spinning LiDAR takes a sweep's points over its whole
period, so a moving object is where it was when each point was taken (Argoverse 2's two
heads see a car about 50 ms apart: two copies of it in one sweep). --times T gives the
capture time of every point of INPUT (every row of correspondences), --sweep-times TS
that of every point of S, each in seconds after its own sweep's reference time (the time
its static world is compensated to; Argoverse 2: offset_ns * 1e-9), and --interval the
seconds between the two reference times (about 0.1 at 10 Hz). Two Argoverse 2 .feather
sweeps, and the frames of a sequence whose points carry capture times (a PointCloud2
field t, time, timestamp or offset_time; AV2's offset_ns), hand their times themselves,
with the interval from their timestamps (the .feather names, the messages' stamps) or
--interval. Else the three go together; T
and TS are an (n,) .npy or one number per line (.csv/.txt, an optional header), one per
point in the points' order, finite, and within 10 times --interval of zero (seconds, not
nanoseconds or absolute timestamps). With them the moving clusters are deskewed inside
the ICP on S (SweepRegistration); the static world and the scene flow's convention (each
point as captured, moved by its object's motion between the reference times) are as
without.

The interval between the frames comes from their own times where they have them (a
KITTI sequence's times.txt, a bag's header stamps, two .pcd files' absolute time field:
t, time, timestamp or offset_time), else from --interval, or --frame-rate HZ (its
inverse: nuScenes keyframes, 2 Hz); with it the table gives speeds in m/s.

Motion bounds (two raw sweeps): an object's motion relative to the static world must be
one a vehicle or a person can make. When the interval between the sweeps is known
(--interval or --frame-rate alone, capture times, or the frames' timestamps), no faster
than 50 m/s and no turn faster than 90 deg/s (360 deg/s for a cluster no longer than a
person, 1.2 m across); else no farther than --max-displacement. Always: no level sheet sliding along
itself (a sliver of terrain). A cluster that breaks a
bound is taken apart: its points rejoin the static world where its motion explains them,
else they are outliers. The lengths scale with --tau (5: metres). The table gives each
object's own displacement relative to the static world (the "moved" column: its
centroid's, not |t| about the sensor) and, with the interval, its speed.

Rows without a return (NaN, or several all-zero rows: a bag with is_dense false, an
organised .pcd, a KITTI scan) are left out of both sweeps with --sweep, counted in
run.json (n_no_return, n_sweep_no_return) and the printed line; labels.npy, X.npy and
clusters.ply hold the other rows, and indices.npy names the rows of INPUT they are.
Returns from the ego vehicle's own body (near the sensor, fixed in its frame) are
labelled -1 but are no outliers: counted apart (run.json's n_ego_body), flagged in
ego_body.npy and drawn pale blue around the sensor.

--init gives the initial clusters: "euclidean" (Euclidean clustering into --clusters
clusters, the default; with two raw sweeps the default is SweepRegistration's own start,
the sweeps' islands, which "euclidean" or "dbscan" replaces), "dbscan", a file of labels
(.npy, .csv or .txt: one integer per correspondence, negative for none) or a masks file
(.npz with arrays "masks", an (m, H, W) boolean stack or an H x W integer label image,
negative for none, e.g.
SegmentAnything's masks of the first image, and "pixels", the (n, 2) integer (column, row)
of each a-point in that image).

Written into --out: labels.npy (cluster of every correspondence, -1 for outliers),
motions.json (per cluster: label, 4x4 transform with b = R a + t, rotation, translation,
rotation_angle_deg, sigma, size, moving), summary.csv (one row per cluster), clusters.ply
(a-points coloured by cluster, outliers grey, and an int property 'label' per point: the
cluster, -1 for outliers, a scalar field in CloudCompare), result.png and run.json (input, options,
timings, and the input's absolute path and SHA-256, from which 'mmreg view' and 'mmreg
evaluate' read it again); with --save-input also X.npy, a copy of the correspondences.
The directory is written whole or not at all.

--out must be new, an empty folder, or (with --overwrite) an earlier result, which is
then replaced as a whole; a folder holding other files is never touched. This is checked
before any work. The default --out is INPUT's name + '-mmreg-' + 8 hex digits of the
input's full path, so different inputs never share it.

The largest cluster is taken for the background (the static world when the camera moves);
a cluster is "moving" when the background's motion would carry its a-points (the median
over them) more than 3 times the RMS residual of its inliers away from where its own
motion takes them (summary.csv: displacement_vs_background, residual_scale). Its inliers
are its correspondences within 3 robust standard deviations (from the median absolute
deviation) of its median residual, so wrong correspondences do not hide a moving object.
"""
EPILOG = """\
examples:
  mmreg register pairs.npy --out result
  mmreg register frame0.ply --target frame1.ply --init masks.npz --out result
  mmreg register frame0.ply --flow flow.npy --tau 1.0 -v
  mmreg register sweep0.ply --sweep sweep1.ply
  mmreg register sweep0.ply --flow flow.npy --sweep sweep1.ply
  mmreg register sweep0.ply --sweep sweep1.ply --times t0.npy --sweep-times t1.npy \
      --interval 0.1
  mmreg register 000000.bin --sweep 000001.bin
  mmreg register LOG/sensors/lidar/T0.feather --sweep LOG/sensors/lidar/T1.feather
  mmreg register drive.bag --topic /velodyne_points --frame 10
  mmreg register dataset/sequences/08 --frame 100
  mmreg register scans/ --pattern '*.bin' --frame 3
"""


def _positive_float(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number; got {text!r}") from None
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"must be a finite positive number; got {text!r}")
    return value


def _voxel_size(text):
    if text.lower() in ("auto", "none"):
        return None if text.lower() == "none" else "auto"
    return _positive_float(text)


# --tau's default in both 'register' and 'run' (one rule): LiDAR sweeps in metres, sparse
# far from the sensor, need a wider gate than correspondences, for which the paper's 1.5
# holds (its objects, and the estimator's own default).
TAU_SWEEPS = 5.0
TAU_CORRESPONDENCES = 1.5
TAU_RULE = (
    f"'auto': {TAU_SWEEPS:g} for LiDAR sweeps (register --sweep, a LiDAR file or log or a "
    f"z-up sweep as INPUT; run: pairs of sweeps, the default for logs and frames), else "
    f"{TAU_CORRESPONDENCES:g} (correspondences, the paper's)"
)


def _is_lidar_input(args, points=None):
    """Whether INPUT is a LiDAR sweep, so that its points are in metres whatever else is
    given with it: by its format (KITTI, nuScenes, Argoverse 2, a bag or a sequence), or,
    for a cloud or an array, by its geometry (a z-up disc around the sensor)."""
    from mmreg._array.frames import detect_frame
    from mmreg.io._lidar import lidar_kind

    path = getattr(args, "input", None)
    if path is not None and (lidar_kind(path) is not None or is_sequence(path)):
        return True
    return points is not None and detect_frame(points) == "lidar"


def resolve_tau(tau, sweeps):
    """``tau`` as given, or for ``"auto"`` the default of :data:`TAU_RULE`."""
    if tau != "auto":
        return tau
    return TAU_SWEEPS if sweeps else TAU_CORRESPONDENCES


def _length(text):
    """A positive length, or ``auto``."""
    if text == "auto":
        return text
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a length or 'auto'; got {text!r}") from None
    if not (0 < value < float("inf")):
        raise argparse.ArgumentTypeError(f"must be a positive length or 'auto'; got {text}")
    return value


def _tau(text):
    if text.lower() in ("none", "auto"):
        return None if text.lower() == "none" else "auto"
    try:
        return _positive_float(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"expected a finite positive number, 'auto' or 'none'; got {text!r}"
        ) from None


def _seed(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer; got {text!r}") from None
    if not 0 <= value < 2**32:
        raise argparse.ArgumentTypeError(f"must lie in [0, 2**32 - 1]; got {value}")
    return value


def _n_jobs(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer; got {text!r}") from None
    if value == 0:
        raise argparse.ArgumentTypeError("must be a positive count, or -1 for every core; got 0")
    return value


def _positive_int(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer; got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1; got {value}")
    return value


def _count(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer; got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be at least 0; got {value}")
    return value


VIEWS = ("auto", "street", "3d", "top", "bev", "camera")


def add_arguments(parser):
    """Every option of ``mmreg register``, in the groups its help shows."""
    _add_input(parser)
    _add_sweep_options(parser)
    _add_fit_options(parser)
    _add_output_options(parser)


def _add_input(parser):
    parser.add_argument(
        "input",
        metavar="INPUT",
        help="correspondences, the a-points, or a sequence (a ROS bag or a folder)",
    )
    source = parser.add_mutually_exclusive_group()
    source.add_argument(
        "--target", metavar="B", help="b-points, one per a-point (any point file, see above)"
    )
    source.add_argument("--flow", metavar="F.npy", help="scene flow, (n, 3): b = a + flow")
    parser.add_argument(
        "--sweep",
        metavar="S",
        help="the second sweep as its own points (any point file, any size, any order): "
        "refines the motions on it, or, with points alone as INPUT, registers the two raw "
        "sweeps",
    )


def _add_sweep_options(parser):
    sweeps = parser.add_argument_group(
        "two sweeps", "lengths in the units of the points; 'auto' derives them from --tau"
    )
    sweeps.add_argument(
        "--ground",
        choices=("auto", "keep", "drop"),
        default="auto",
        help="two raw sweeps: the ground found in a z-up sweep joins the static world "
        "(auto), is registered like any point (keep), or is left out and labelled -1 (drop)",
    )
    sweeps.add_argument(
        "--max-distance",
        type=_length,
        default="auto",
        help="an ICP matches a point to the second sweep only within this distance "
        "(auto: tau / 5, 1 m for LiDAR)",
    )
    sweeps.add_argument(
        "--island-radius",
        type=_length,
        default="auto",
        help="two raw sweeps: points this close share an island (auto: tau / 10)",
    )
    sweeps.add_argument(
        "--max-displacement",
        type=_length,
        default="auto",
        help="two raw sweeps: the largest motion of an object relative to the static world "
        "between the sweeps (auto: 0.6 tau, 3 m for LiDAR: 30 m/s at 10 Hz)",
    )
    sequence = parser.add_argument_group(
        "sequences", "INPUT a ROS bag, a KITTI sequence, an Argoverse 2 log or a folder of frames"
    )
    sequence.add_argument(
        "--frame",
        type=_count,
        default=None,
        metavar="K",
        help="register frame K against frame K+1 (default 0)",
    )
    sequence.add_argument(
        "--topic",
        default=None,
        help="the bag's sensor_msgs/PointCloud2 topic (needed when it holds several)",
    )
    sequence.add_argument(
        "--pattern",
        metavar="GLOB",
        default=None,
        help="a folder of frame files: the files that are frames (e.g. '*.bin'); needed "
        "when it holds frames of several kinds",
    )
    timing = parser.add_argument_group(
        "capture times", "with --sweep, all three together (see above): deskew moving objects"
    )
    timing.add_argument(
        "--times",
        metavar="T",
        help="capture time of every point of INPUT, in seconds after its sweep's reference "
        "time: (n,) .npy or one column .csv/.txt",
    )
    timing.add_argument(
        "--sweep-times",
        metavar="TS",
        help="capture time of every point of --sweep, in seconds after its reference time",
    )
    timing.add_argument(
        "--interval",
        type=_positive_float,
        metavar="SECONDS",
        help="seconds between the two sweeps' reference times (e.g. 0.1 at 10 Hz); alone, "
        "it bounds the objects' speeds and turns (see above)",
    )
    timing.add_argument(
        "--frame-rate",
        type=_positive_float,
        metavar="HZ",
        default=None,
        help="frames per second, where the frames have no times of their own (nuScenes "
        "keyframes: 2): the interval 1/HZ, for speeds in m/s and the motion bounds",
    )


def _add_fit_options(parser):
    parser.add_argument(
        "--init",
        default=None,
        metavar="INIT",
        help="euclidean (default; two raw sweeps: their islands), dbscan, LABELS "
        "(.npy/.csv/.txt) or MASKS.npz (masks + pixels)",
    )
    parser.add_argument(
        "--clusters",
        type=_positive_int,
        default=100,
        help="number of initial clusters of --init euclidean",
    )
    parser.add_argument(
        "--eps",
        type=_positive_float,
        default=None,
        help="neighbourhood radius of --init dbscan, in the units of the points (default: "
        "4 times the median distance between nearest a-points)",
    )
    parser.add_argument(
        "--tau",
        type=_tau,
        default="auto",
        help="distance gate in the units of the points (metres); 'none' turns it off; " + TAU_RULE,
    )
    parser.add_argument(
        "--ego-motion",
        metavar="T",
        default=None,
        help="the static world's known motion from the first frame to the second (odometry, "
        "poses), b = R a + t: a 4x4 matrix in a .npy or 4 rows of 4 numbers in a .txt/.csv; "
        "two raw sweeps start their ego ICP from it, a flow's static world is what moves "
        "with it",
    )
    parser.add_argument(
        "--min-cluster-size", type=_positive_int, default=4, help="smallest cluster kept"
    )
    parser.add_argument("--max-iter", type=_count, default=10, help="most EM iterations")
    parser.add_argument(
        "--voxel-size",
        type=_voxel_size,
        default="auto",
        metavar="V",
        help="fit on one correspondence per voxel of side V (units of the points) and "
        "judge the others by the fitted clusters; 'auto' (default): inputs above 50,000 "
        "rows on a sample of about 25,000, smaller ones whole; 'none': every row",
    )
    parser.add_argument(
        "--paper",
        action="store_true",
        help="the paper's Algorithm 1 exactly (variant='paper') instead of the default",
    )
    parser.add_argument("--seed", type=_seed, default=0, help="random seed")
    parser.add_argument(
        "--n-jobs",
        type=_n_jobs,
        default=1,
        help="threads of the k-d tree queries of the initial clustering, the EM and, with "
        "--sweep, the ICPs (MultiModelRegistration's n_jobs; -1: every core)",
    )


def _add_output_options(parser):
    parser.add_argument(
        "--out",
        metavar="DIR",
        default=None,
        help="result directory (default: INPUT's name + '-mmreg-' + 8 hex digits of its "
        "path, in the current directory)",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an earlier result directory at --out (never a folder of other files)",
    )
    parser.add_argument(
        "--save-input",
        action="store_true",
        help="also write X.npy, a copy of the correspondences (else 'mmreg view' and "
        "'evaluate' read INPUT again, which must then stay where it is, unchanged)",
    )
    parser.add_argument(
        "--view",
        choices=VIEWS,
        default="auto",
        help="result.png: 'street' (camera and bird's-eye views, for points in a camera "
        "frame: x right, y down, z forward), 'bev' (from above) or one plotting view; "
        "'auto': street for a camera frame, bev for a z-up LiDAR sweep, else 3d",
    )
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress bar, no table")
    parser.add_argument(
        "--verbose", "-v", action="count", default=0, help="print the EM's iterations"
    )


def _check_size(values, args, what="points"):
    """values unchanged, or a CLIError when INPUT gives fewer than --min-cluster-size."""
    if len(values) < args.min_cluster_size:
        raise CLIError(
            f"{args.input}: {len(values)} {what}, fewer than --min-cluster-size "
            f"{args.min_cluster_size}: no cluster is possible"
        )
    return values


def _read_sequence_input(args, other):
    """Frame K's points (with --target/--flow: its correspondences); frame K+1 becomes the
    second sweep, and the frames' capture times and stamps the capture-time arguments."""
    import numpy as np

    sequence, first, second = read_frames(args)
    args.sweep_points = second.points
    args.input_times, args.sweep_file_times = first.times, second.times
    if args.interval is None:
        args.sweep_interval = interval_between(first.timestamp, second.timestamp, args.input)
    args.frames = {"frame": first.index, "topic": getattr(sequence, "topic", None)}
    args.frames["sources"] = [first.source, second.source]
    if getattr(args, "ego_motion", None) is None and other is None:
        with reading(args.input):  # the poses (a KITTI poses.txt): the ego ICP's start
            if getattr(sequence, "poses", None) is not None:
                motion = sequence.ego_motion(first.index, second.index)
                args.sequence_ego_motion = (motion[:3, :3], motion[:3, 3])
                args.frames["ego_motion_from"] = "poses"
    a = _check_size(first.points, args)
    if other is None:
        return a
    path = args.target if args.target is not None else args.flow
    from mmreg.io._correspondences import _read_points

    with reading(path):
        values = _read_points(path, "the b-points" if args.target else "the flow")
    if len(values) != len(a):
        raise CLIError(f"{path}: {len(values):,} rows for the {len(a):,} points of {first.source}")
    X = np.hstack([a, values if args.target is not None else a + values])
    X = check_correspondences(X, path)
    if args.target is not None:
        check_rows(X, args, f"{first.source} and --target {args.target}")
    return X


def check_rows(X, args, where):
    """A CLIError when the rows of X are two LiDAR sweeps stacked row by row (row i of one
    scan with row i of the other) rather than points and where they went."""
    from mmreg._validation import NotCorrespondencesError
    from mmreg.sweeps._stacked_rows import check_rows_follow_motion

    target = getattr(args, "target", None)
    if target is not None:
        advice = f"Register two sweeps as sweeps: --sweep {target} instead of --target."
    else:
        advice = "Register two sweeps as sweeps: mmreg register SWEEP0 --sweep SWEEP1."
    try:
        check_rows_follow_motion(X[:, :3], X[:, 3:], where=where, advice=advice)
    except NotCorrespondencesError as error:
        raise CLIError(one_line(error)) from None


def read_input(args):
    """The (n, 6) correspondences of INPUT (with --target or --flow), or its (n, 3) points."""
    from mmreg import io as mmio

    other = "--target" if args.target is not None else "--flow" if args.flow is not None else None
    check_sequence_options(args)
    if is_sequence(args.input):
        return _read_sequence_input(args, other)
    points = holds_points_only(args.input)
    sweep = getattr(args, "sweep", None)
    if points and other is None and sweep is not None:
        with reading(args.input):
            a, args.input_times = mmio.read_point_cloud(args.input, times=True)
        return _check_size(a, args)
    if points and other is None and Path(args.input).exists():
        raise CLIError(
            f"{args.input}: holds only the a-points; give the b-points with --target B, the "
            "scene flow with --flow F.npy or the second sweep with --sweep S"
        )
    if not points and other is not None and Path(args.input).is_file():
        check_points_for(args.input, other)
    with reading(args.input, args.target, args.flow):
        try:
            X = mmio.read_correspondences(args.input, target=args.target, flow=args.flow)
        except ValueError as error:
            if args.target is not None and "index-aligned" in str(error):
                raise CLIError(
                    f"{args.target}: --target needs one b-point per a-point of {args.input}, "
                    "in the same order, but the sizes differ; for a second sweep of any "
                    "size and order use --sweep"
                ) from None
            raise
    X = _check_size(check_correspondences(X, args.input), args, "correspondences")
    if args.flow is None and sweep is None:  # rows given as pairs: are they?
        where = args.input if args.target is None else f"{args.input} and --target {args.target}"
        check_rows(X, args, where)
    return X


def read_masks(path, n):
    """PrecomputedMasks from an .npz holding ``masks`` and ``pixels``."""
    from mmreg.init import PrecomputedMasks

    with reading(path):
        with contextlib.nullcontext(load_npz(path, "masks")) as data:
            names = list(data.keys())
            missing = [k for k in ("masks", "pixels") if k not in names]
            if missing:
                raise CLIError(
                    f"{path}: a masks file needs arrays 'masks' and 'pixels'; it holds {names}"
                )
            masks, pixels = data["masks"], data["pixels"]
        if masks.ndim not in (2, 3):
            raise CLIError(
                f"{path}: 'masks' must be an (m, H, W) boolean stack or an H x W label image; "
                f"got shape {masks.shape}"
            )
        if pixels.ndim != 2 or pixels.shape[1] != 2:
            raise CLIError(f"{path}: 'pixels' must have shape (n, 2); got {pixels.shape}")
        if len(pixels) != n:
            raise CLIError(f"{path}: {len(pixels)} pixels for {n} correspondences")
        return PrecomputedMasks(masks, pixels)


def init_name(args, X):
    """What ``--init`` named, or the default it stands for (two raw sweeps, ``X`` of
    shape (n, 3): their islands)."""
    if args.init is not None:
        return str(args.init)
    return "islands" if X.shape[1] == 3 else "euclidean"


def make_init(args, n):
    """The ``init`` of the estimator: an initialiser or an array of labels."""
    from mmreg import io as mmio
    from mmreg.init import DBSCANClustering, EuclideanClustering

    n_jobs = getattr(args, "n_jobs", None)
    if args.init in (None, "euclidean"):
        return EuclideanClustering(n_clusters=args.clusters, n_jobs=n_jobs)
    if args.init == "dbscan":
        return DBSCANClustering(eps=getattr(args, "eps", None), n_jobs=n_jobs)
    path = Path(args.init)
    if path.suffix.lower() == ".npz":
        return read_masks(path, n)
    if not path.exists():
        raise CLIError(f"{path}: no such file (--init takes euclidean, dbscan or a file)")
    with reading(path):
        labels = mmio.read_labels(path)
    return check_labels(labels, n, path)


def read_ego_motion(args):
    """``(R, t)`` of ``--ego-motion``, or None; one clear line when the file is not one."""
    path = getattr(args, "ego_motion", None)
    if path is None:
        return None
    import numpy as np

    from mmreg._validation import check_ego_motion
    from mmreg.io._arrays import _load_npy, _load_text_table
    from mmreg.io._checks import _check_readable

    path = Path(path)
    with reading(path):
        _check_readable(path, "--ego-motion")
        matrix = _load_npy(path) if path.suffix.lower() == ".npy" else _load_text_table(path)
    matrix = np.asarray(matrix, dtype=float)
    if matrix.shape != (4, 4) or not np.allclose(matrix[3], [0, 0, 0, 1]):
        raise CLIError(
            f"{path}: --ego-motion takes a 4x4 homogeneous matrix (last row 0 0 0 1); got "
            f"an array of shape {matrix.shape}"
            + ("" if matrix.shape != (4, 4) else f" whose last row is {matrix[3].tolist()}")
        )
    try:
        return check_ego_motion(matrix, 3)
    except ValueError as error:
        raise CLIError(f"{path}: {one_line(error)}") from None


def read_sweep(args):
    """The second sweep's points (--sweep, or a sequence's next frame), or None.

    A file's capture times (an Argoverse 2 .feather's) and timestamp (its name) are kept
    in ``args`` for :func:`read_capture_times`.
    """
    from mmreg import io as mmio
    from mmreg.io import _lidar as _lidar_files

    if getattr(args, "sweep_points", None) is not None:  # a sequence's frame K+1
        return args.sweep_points
    sweep = getattr(args, "sweep", None)
    if sweep is None:
        return None
    if args.paper:
        raise CLIError("--sweep refines the default variant's motions; drop --paper")
    with reading(sweep):
        points, args.sweep_file_times = mmio.read_point_cloud(sweep, times=True)
    # Two Argoverse 2 sweeps: the seconds between them from their names, in integer ns.
    first, second = (_lidar_files.av2_timestamp_ns(p) for p in (args.input, sweep))
    if first is not None and second is not None and getattr(args, "interval", None) is None:
        if second <= first:
            raise CLIError(
                f"{sweep}: its timestamp ({second} ns) is not after that of {args.input} "
                f"({first} ns); give --interval"
            )
        args.sweep_interval = (second - first) * 1e-9
    if getattr(args, "interval", None) is None and getattr(args, "sweep_interval", None) is None:
        # Two .pcd files with an absolute time field: the seconds between their stamps.
        first_stamp = _pcd_stamp(args.input)
        second_stamp = _pcd_stamp(sweep) if first_stamp is not None else None
        if second_stamp is not None:
            args.sweep_interval = interval_between(first_stamp, second_stamp, sweep)
            args.stamped_interval = True
    return points


def _frame_rate_interval(args, sweep, *, before):
    """--frame-rate's interval, where the frames give none (their stamps win): set as
    --interval for two sweeps or a sequence (it bounds the motions); for correspondences
    True, to be set after the capture-time checks (their speeds only)."""
    rate = getattr(args, "frame_rate", None)
    if rate is None or getattr(args, "interval", None) is not None:
        return False
    if getattr(args, "sweep_interval", None) is not None:
        return False  # the frames' own stamps
    if sweep is not None or is_sequence(args.input):
        args.interval = 1.0 / rate
        return False
    return True


def _pcd_stamp(path):
    """A .pcd file's timestamp (its absolute time field), else None."""
    from mmreg.io._correspondences import _read_point_file

    if path is None or Path(path).suffix.lower() != ".pcd" or not Path(path).is_file():
        return None
    with reading(path):
        return _read_point_file(path, "the points", stamp=True)[3]


_TIME_OPTIONS = (("times", "--times"), ("sweep_times", "--sweep-times"), ("interval", "--interval"))


def _files_carry_times(args):
    """Whether INPUT and its second sweep may hold capture times themselves (read later)."""
    from mmreg.io import _lidar as _lidar_files

    if is_sequence(args.input):
        return True
    paths = (args.input, getattr(args, "sweep", None))
    return all(p is not None and _lidar_files.lidar_kind(p) == "feather" for p in paths)


def check_time_options(args):
    """The capture-time options come all three, and with --sweep; a CLIError otherwise.

    --interval alone is the interval of sweeps that hold their own capture times.
    """
    given = [flag for name, flag in _TIME_OPTIONS if getattr(args, name, None) is not None]
    if not given:
        return
    # --interval alone: the interval of sweeps that hold their own capture times, or of
    # two sweeps without (it bounds the objects' motions: a speed, a turn rate).
    if given == ["--interval"] and (getattr(args, "sweep", None) or _files_carry_times(args)):
        return
    if getattr(args, "sweep", None) is None and not is_sequence(args.input):
        raise CLIError(
            f"{', '.join(given)}: capture times deskew the moving objects in the ICP on the "
            "second sweep; give it with --sweep"
        )
    missing = [flag for name, flag in _TIME_OPTIONS if getattr(args, name, None) is None]
    if missing:
        raise CLIError(
            "--times, --sweep-times and --interval go together (the capture time of every "
            "point of both sweeps and the seconds between them); missing " + " and ".join(missing)
        )


def _read_times(path, n, what, interval):
    from mmreg import io as mmio

    with reading(path):
        times = mmio.read_times(path)
    if len(times) != n:
        raise CLIError(f"{path}: {len(times):,} capture times for the {n:,} points of {what}")
    return check_time_range(times, interval, path)


def read_capture_times(args, n, m):
    """``fit``'s ``times``, ``sweep_times`` and ``interval`` from the options, or ``{}``.

    ``n``: points (rows) of INPUT; ``m``: points of the second sweep.
    """
    check_time_options(args)
    if getattr(args, "times", None) is None:
        interval = getattr(args, "interval", None) or getattr(args, "sweep_interval", None)
        where = getattr(args, "sweep", None) or getattr(args, "input", None)
        timing = file_timing(
            getattr(args, "input_times", None),
            getattr(args, "sweep_file_times", None),
            interval,
            where,
        )
        # No capture times: the interval bounds the motions, when --interval or a
        # sequence's stamps give it (two files' names alone are no frame rate: an AV2
        # name is a timestamp only in a real log, whose sweeps carry their times).
        source = getattr(args, "input", None)
        known = (
            getattr(args, "interval", None) is not None
            or getattr(args, "stamped_interval", False)
            or (source is not None and is_sequence(source))
        )
        if not timing and interval is not None and known:
            args.interval = interval  # for run.json and the speeds of the picture
            return {"interval": interval}
        if timing:
            args.interval = timing["interval"]  # for run.json
            args.file_times = True
        return timing
    second = getattr(args, "sweep", None) or f"frame {getattr(args, 'frame', None) or 0} + 1"
    return {
        "times": _read_times(args.times, n, args.input, args.interval),
        "sweep_times": _read_times(args.sweep_times, m, second, args.interval),
        "interval": args.interval,
    }


def _fit(X, init, args, steps, sweep=None, timing=None):
    from mmreg import MultiModelRegistration, SweepRegistration
    from mmreg.init import initial_labels

    voxel_size = getattr(args, "voxel_size", None)
    if X.shape[1] == 6 and voxel_size is None:
        # Every row fitted: the initial clusters are a step of their own.
        with steps.step("initial clusters"), reading(args.init), reported_warnings():
            labels = initial_labels(init, X, random_state=args.seed)
    else:
        # Two raw sweeps: the correspondences, and so the clusters, come later. A voxel
        # fit ("auto" included) clusters its own sample.
        labels = init
    estimator = MultiModelRegistration(
        tau=resolve_tau(args.tau, sweep is not None or _is_lidar_input(args, X[:, :3])),
        min_cluster_size=args.min_cluster_size,
        max_iter=args.max_iter,
        init=labels,
        variant="paper" if args.paper else "sweep",
        voxel_size=voxel_size,
        random_state=args.seed,
        n_jobs=getattr(args, "n_jobs", None),
        verbose=args.verbose,
    )
    if sweep is not None:
        # Two raw sweeps start from their islands unless --init names a clustering.
        raw_init = "islands" if args.init is None else "estimator"
        estimator = SweepRegistration(
            estimator,
            raw_init=raw_init,
            ground=getattr(args, "ground", "auto"),
            max_distance=getattr(args, "max_distance", "auto"),
            island_radius=getattr(args, "island_radius", "auto"),
            max_displacement=getattr(args, "max_displacement", "auto"),
            random_state=args.seed,
        )
    params = {} if sweep is None else {"sweep": sweep} | (timing or {})
    ego = read_ego_motion(args)
    if ego is None and sweep is not None and X.shape[1] == 3:
        ego = getattr(args, "sequence_ego_motion", None)  # a sequence's poses
    if ego is not None:
        if sweep is not None and X.shape[1] != 3:
            raise CLIError(
                "--ego-motion goes with two raw sweeps (points and --sweep) or with "
                "correspondences alone, not with both a flow and --sweep"
            )
        params["ego_motion"] = ego
    deskewed = bool(timing) and timing.get("times") is not None
    name = "EM" if sweep is None else "EM and ICP on --sweep" + (" (deskewed)" if deskewed else "")
    with steps.step(name), reported_warnings():
        estimator.fit(X, **params)
    if voxel_size is not None and X.shape[1] == 6:
        # The initial clusters of the fit (a wrapped estimator's, with --sweep).
        fitted = getattr(estimator, "estimator_", estimator)
        labels = getattr(fitted, "init_labels_", labels)
    n_initial = int(labels.max(initial=-1)) + 1 if hasattr(labels, "max") else 0
    return estimator, n_initial


def _workers(args):
    """Threads of a k-d tree query: --n-jobs (-1: every core), else 1."""
    n_jobs = getattr(args, "n_jobs", None)
    return 1 if n_jobs is None else n_jobs


def _params(estimator):
    """The estimator's parameters for run.json (a wrapped estimator's own, beside)."""
    params = estimator.get_params(deep=False)
    inner = params.pop("estimator", None)
    if inner is None:
        return params
    return inner.get_params(deep=False) | {"sweep_registration": params}


def register(
    X, init, args, *, input_name, steps, extra_run=None, extra_files=None, title=None, camera=None
):
    """Fit, summarise, draw and write the result directory ``args.out`` (if not None).

    ``title`` (of the picture) may hold ``{found}``: the numbers of clusters, moving
    clusters and outliers.

    Returns ``(estimator, summary, fit_seconds, n_initial_clusters)``.
    """
    import numpy as np

    from mmreg._validation import NotCorrespondencesError

    start = time.perf_counter()
    init_used = init_name(args, X)
    sweep = read_sweep(args)
    pairs_only = _frame_rate_interval(args, sweep, before=True)
    timing = read_capture_times(args, len(X), None if sweep is None else len(sweep))
    if pairs_only:  # correspondences: the interval gives their speeds only
        args.interval = 1.0 / args.frame_rate
    no_returns = None
    if sweep is not None:  # rows with no return (NaN, the origin) are dropped, and counted
        no_returns = NoReturns(X, sweep)
        sweep_name = getattr(args, "sweep", None) or f"frame {getattr(args, 'frame', 0) or 0} + 1"
        X, sweep, timing = no_returns.apply(X, sweep, timing, input_name, sweep_name)
    args.no_returns = no_returns
    try:
        estimator, n_initial = _fit(X, init, args, steps, sweep, timing)
    except NotCorrespondencesError as error:
        raise CLIError(f"{input_name}: {one_line(error)}") from None
    elapsed = time.perf_counter() - start
    residuals = moving = None
    # The ego vehicle's own body (labelled -1) is no outlier: counted and drawn apart.
    body = ego_body(estimator, len(X))
    n_outliers = int(estimator.outlier_mask_.sum()) - int(body.sum())
    if sweep is not None:  # what is written: the first sweep and where its points move
        X = np.hstack([X[:, :3], X[:, :3] + estimator.flow_])
        # Its b-points are its own flow, so |R a + t - b| is 0: the residual is the
        # distance from each moved point to the second sweep.
        residuals = sweep_residuals(X[:, :3], estimator.flow_, sweep, _workers(args))
        moving = estimator.moving_
    with steps.step("summary and picture"):
        summary = summarize(
            X,
            estimator.labels_,
            estimator.rotations_,
            estimator.translations_,
            estimator.sigmas_,
            residuals=residuals,
            moving=moving,
            interval=getattr(args, "interval", None),
        )
        motions = (estimator.rotations_, estimator.translations_)
        n_moving = int(summary["moving"].sum())
        found = f"{plural(estimator.n_clusters_, 'cluster')} ({n_moving} moving), " + count_line(
            estimator, len(X)
        )
        if title is None:
            what = "points" if sweep is not None else "correspondences"
            title = f"{Path(str(input_name)).name}: {len(X):,} {what} -> {found}"
        else:
            title = title.format(found=found)
        png = None
        if args.out is not None:
            figure = result_figure(
                X,
                estimator.labels_,
                motions,
                moving=summary["moving"].to_numpy(),
                view=args.view,
                title=title,
                camera=camera,
                interval=getattr(args, "interval", None),
                ego_body=body if body.any() else None,
            )
            png = render_png(figure)
    if args.out is not None:
        run = {
            "input": input_name,
            "target": getattr(args, "target", None),
            "flow": getattr(args, "flow", None),
            "sweep": getattr(args, "sweep", None),
            "times": getattr(args, "times", None),
            "sweep_times": getattr(args, "sweep_times", None),
            "interval": getattr(args, "interval", None),
            # The capture times came with the points (offset_ns, a PointCloud2 field).
            "file_times": getattr(args, "file_times", False),
            "init": init_used,
            "initial_clusters": n_initial,
            "estimator": _params(estimator) | {"init": init_used},
            "n_jobs": getattr(args, "n_jobs", None),
            "n_correspondences": len(X),
            "n_clusters": estimator.n_clusters_,
            "n_moving": n_moving,
            "n_outliers": n_outliers,
            "n_ego_body": int(body.sum()),
            "n_iter": estimator.n_iter_,
            "converged": bool(estimator.converged_),
            "fit_seconds": round(elapsed, 3),
        } | (extra_run or {})
        extra_files = dict(extra_files or {})
        if body.any():  # for "mmreg view": the body drawn apart
            extra_files["ego_body.npy"] = npy_bytes(body)
        if no_returns is not None:
            run |= no_returns.record()
            if no_returns.n:  # the rows of INPUT that labels.npy and X.npy hold
                extra_files["indices.npy"] = npy_bytes(np.flatnonzero(no_returns.keep))
        if camera is not None:  # for "mmreg view": the camera view in pixels
            run["camera"] = {k: camera[k] for k in ("fx", "fy", "cx", "cy", "width", "height")}
        with steps.step(f"writing {args.out}"):
            write_result_dir(
                args.out,
                X,
                estimator.labels_,
                estimator.rotations_,
                estimator.translations_,
                estimator.sigmas_,
                summary,
                png,
                run,
                extra_files,
                overwrite=getattr(args, "overwrite", False),
                # No input file, or (with --sweep) what is written is not the input but
                # the first sweep and where its points move: keep X for view/evaluate.
                save_input=getattr(args, "save_input", True) or sweep is not None,
            )
    return estimator, summary, elapsed, n_initial


# The table printed: (column of the summary, header, format). "moved": the object's own
# displacement (its centroid's, relative to the background), not |t| about the sensor;
# "speed" only when the interval between the frames is known.
TABLE = [
    ("label", "cluster", ""),
    ("size", "points", ",d"),
    ("rotation_angle_deg", "rotation [deg]", ".3f"),
    ("displacement", "moved", ".3f"),
    ("speed", "speed [m/s]", ".3g"),
    ("residual_scale", "residual", ".3g"),
    ("displacement_vs_background", "vs background", ".3f"),
    ("moving", "moving", ""),
]


def default_out(args):
    """``<INPUT's name>-mmreg-<8 hex digits>``: a name no other input (or partner) shares."""
    paths = [args.input, getattr(args, "target", None), getattr(args, "flow", None)]
    paths += [getattr(args, name, None) for name in ("sweep", "times", "sweep_times")]
    key = "\0".join(str(Path(p).resolve()) for p in paths if p is not None)
    stem = Path(args.input).stem
    if is_sequence(args.input):  # one result per frame (and topic, and pattern)
        frame = getattr(args, "frame", None) or 0
        key += f"\0{frame}\0{getattr(args, 'topic', None)}"
        if getattr(args, "pattern", None) is not None:
            key += f"\0{args.pattern}"
        stem += f"-frame{frame}"
    digest = hashlib.sha256(key.encode("utf-8", "surrogateescape")).hexdigest()[:8]
    return f"{stem}-mmreg-{digest}"


def run(args):
    start = time.perf_counter()  # the whole command: reading, imports, fit, writing
    if args.out is None:
        args.out = default_out(args)
    check_out(args.out, overwrite=args.overwrite)  # before any work
    if getattr(args, "frame_rate", None) is not None and args.interval is not None:
        raise CLIError("--interval and --frame-rate say the same (seconds = 1 / HZ); give one")
    check_time_options(args)
    check_sequence_options(args)
    if args.paper and getattr(args, "voxel_size", None) not in (None, "auto"):
        raise CLIError("--voxel-size samples the default variant's fit; drop --paper")
    with Steps(5, quiet=args.quiet, verbose=args.verbose) as steps:
        with steps.step(f"reading {args.input}"):
            X = read_input(args)
            init = make_init(args, len(X))
            if X.shape[1] == 3 and not hasattr(init, "fit"):
                raise CLIError(
                    f"{args.init}: two raw sweeps have no correspondences yet to label; "
                    "use --init euclidean or dbscan"
                )
        record = input_record(X, args.input, args.target, args.flow)
        if getattr(args, "frames", None) is not None:
            record |= args.frames
        estimator, summary, elapsed, _ = register(
            X, init, args, input_name=args.input, steps=steps, extra_run=record
        )
    if not args.quiet:
        moving = summary["moving"].map({True: "yes", False: "no"})
        table = summary.assign(moving=moving.where(~summary["background"], "background"))
        print(
            f"{len(estimator.labels_):,} {'points' if X.shape[1] == 3 else 'correspondences'}: "
            f"{plural(estimator.n_clusters_, 'cluster')}, "
            f"{count_line(estimator, len(estimator.labels_), getattr(args, 'no_returns', None))}, "
            f"{plural(estimator.n_iter_, 'iteration')}, "
            f"{time.perf_counter() - start:.2f} s (the fit {elapsed:.2f} s)"
        )
        spec = [row for row in TABLE if row[0] != "speed" or table["speed"].notna().any()]
        print(format_table(table, spec))
        print(f"written: {args.out}/ (labels.npy motions.json summary.csv clusters.ply result.png)")
    return 0
