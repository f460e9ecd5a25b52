"""``mmreg view``: redraw the picture of a result directory."""

import argparse
import json
from pathlib import Path

from mmreg._cli._common import (
    CLIError,
    picture_format,
    plural,
    reading,
    render_picture,
    result_figure,
)
from mmreg._cli._results import open_results
from mmreg._cli.register import VIEWS

NAME = "view"
HELP = "redraw the picture of a result directory, or of a job of 'mmreg run'"
DESCRIPTION = """\
Redraw the picture of RESULT: its a-points by cluster and an arrow per cluster for its
motion, in the view the frame of the points calls for (--frame, else read from where
they lie, not from the sign of z): a LiDAR sweep (z up, the sensor at the origin, points
all around) from above, R metres around the sensor (--range, default 50), the static
world grey by height, each moving cluster coloured in its oriented box with an arrow
lengthened by the round factor the legend states and its speed (m/s with --interval or
run.json's, else metres per frame); a camera frame (z along the view, every point in
front) as a street, camera view and bird's-eye view (the largest cluster, the
background, in sand; outliers small and grey); anything else in 3-D.

RESULT is one of
  - a result directory of "mmreg register" or "mmreg demo --out": its labels.npy,
    motions.json and correspondences (its X.npy, else the input files named in its
    run.json, which must still hold the same data; a moved or changed file is named);
  - an "mmreg run" folder: the job named by --job (needed when it holds several);
  - one job's file of a run, RUN/jobs/<job>.npz: its labels and motions, and its points
    loaded again from the run's dataset;
  - an "mmreg run" folder of a log (or of a folder of logs: --job names the log): the
    frame --at (default the last) from above in the log's frame (the first sensor
    pose's), the window following the sensor: the static world grey by height, each
    moving track in its colour with its id and its trail, unlabelled points (outliers,
    the ego body) as crosses; written to <frame>.png by default.

Written to --out, by default RESULT/result.png for a result directory (replacing it) and
<job>.png in the current folder for a job; the format follows the extension of --out
(.png, .pdf, .svg, .eps, .jpg, ...). Any other existing picture is replaced only with
--overwrite.
"""


def _dpi(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer; got {text!r}") from None
    if not 10 <= value <= 1200:
        raise argparse.ArgumentTypeError(f"must lie in [10, 1200] dots per inch; got {value}")
    return value


def _positive(unit):
    def parse(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number of {unit}; got {text!r}") from None
        if not (value > 0 and value < float("inf")):
            raise argparse.ArgumentTypeError(f"must be a positive number of {unit}; got {text}")
        return value

    return parse


_metres, _seconds = _positive("metres"), _positive("seconds")


def add_arguments(parser):
    parser.add_argument(
        "result_dir",
        metavar="RESULT",
        help="a result directory, an 'mmreg run' folder or one of its jobs/<job>.npz",
    )
    parser.add_argument(
        "--job",
        metavar="NAME",
        default=None,
        help="the job of an 'mmreg run' folder to draw (a run on a folder of logs: the log)",
    )
    parser.add_argument(
        "--at",
        metavar="FRAME",
        default=None,
        help="a run on logs: the frame to draw, by name (000012) or number (default: the last)",
    )
    parser.add_argument(
        "--out",
        metavar="PICTURE",
        default=None,
        help="picture to write, its format by its extension (default: RESULT/result.png, "
        "or <job>.png for a job)",
    )
    parser.add_argument(
        "--overwrite", action="store_true", help="replace an existing --out picture"
    )
    parser.add_argument(
        "--view",
        choices=VIEWS,
        default="auto",
        help="'street' (camera and bird's-eye views), 'bev' (from above: a z-up sweep's x-y, "
        "a camera frame's x-z) or one plotting view; 'auto': street for a camera frame, bev "
        "for a LiDAR frame, else 3d",
    )
    parser.add_argument(
        "--frame",
        choices=("auto", "camera", "lidar"),
        default="auto",
        help="frame of the points: 'camera' (z along the view, every point in front), "
        "'lidar' (z up, the sensor at the origin, points all around); 'auto': from where "
        "the points lie",
    )
    parser.add_argument(
        "--range",
        dest="range_",
        metavar="R",
        type=_metres,
        default=None,
        help="a LiDAR sweep from above: the square R metres around the sensor (default 50)",
    )
    parser.add_argument(
        "--interval",
        metavar="SECONDS",
        type=_seconds,
        default=None,
        help="seconds between the two sweeps, for speeds in m/s (default: run.json's, "
        "else speeds in metres per frame)",
    )
    parser.add_argument("--title", default=None, help="title of the picture")
    parser.add_argument("--dpi", type=_dpi, default=110, help="resolution, dots per inch")


def run(args):
    import numpy as np

    from mmreg import io as mmio
    from mmreg._cli._sequence_results import is_log_result, view_log

    if is_log_result(args.result_dir):
        return view_log(args)
    (result,) = open_results(args.result_dir, job=args.job)
    folder = Path(args.result_dir)
    own = folder / "result.png" if result.path.is_dir() else Path(f"{result.name}.png")
    out = Path(args.out) if args.out is not None else own
    fmt = picture_format(out)  # before any work
    if not args.overwrite and out.exists():
        same = result.path.is_dir() and out.resolve() == own.resolve()
        if not same:
            raise CLIError(f"{out}: exists; pass --overwrite to replace it")
    if out.is_dir():
        raise CLIError(f"{out}: is a folder; --out names the picture file")
    if result.rotations is None:
        raise CLIError(f"{folder / 'motions.json'}: no such file (is {folder} a result directory?)")
    labels = result.labels
    X = result.points()
    rotations, translations = result.rotations, result.translations
    title = args.title
    if title is None:
        moving = result.moving
        n_moving = int(np.sum(moving)) if moving is not None else 0
        what = "correspondences" if X.shape[1] == 6 and not result.derived else "points"
        body = np.zeros(len(labels), bool) if result.ego_body is None else result.ego_body
        title = (
            f"{result.name}: {len(X):,} {what} -> {plural(len(rotations), 'cluster')} "
            f"({n_moving} moving), {plural(int(np.sum((labels < 0) & ~body)), 'outlier')}"
            + (f", {int(body.sum()):,} on the ego vehicle's body" if body.any() else "")
        )
    interval = args.interval
    if interval is None and result.path.is_dir() and (result.path / "run.json").exists():
        with reading(result.path / "run.json"):  # the interval, when it has one
            interval = json.loads((result.path / "run.json").read_text()).get("interval")
    fig = result_figure(
        X,
        labels,
        (rotations, translations),
        moving=result.moving,
        view=args.view,
        title=title,
        camera=result.camera,
        frame=args.frame,
        interval=interval,
        range_=args.range_,
        ego_body=result.ego_body,
    )
    picture = render_picture(fig, fmt, dpi=args.dpi)
    with reading(out), mmio.atomic_write(out) as handle:
        handle.write(picture)
    print(f"written: {out}")
    return 0
