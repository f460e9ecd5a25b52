"""``mmreg view``: redraw the picture of a result directory."""

import argparse
import json
from pathlib import Path

from mmreg._cli._common import (
    CLIError,
    check_labels,
    picture_format,
    plural,
    read_result_input,
    reading,
    render_picture,
    result_figure,
)
from mmreg._cli.register import VIEWS

NAME = "view"
HELP = "redraw the picture of a result directory"
DESCRIPTION = """\
Redraw the picture of a result directory (of "mmreg register" or "mmreg demo --out") from
its labels.npy, motions.json and correspondences (its X.npy, else the input file named in
its run.json, which must still hold the same correspondences), in the view the frame of
the points calls for (--frame, else read from where they lie, not from the sign of z): a
LiDAR sweep (z up, the sensor at the origin, points all around) from above, R metres
around the sensor (--range, default 50), the static world grey by height, each moving
cluster coloured in its oriented box with an arrow lengthened by the round factor the
legend states and its speed (m/s with --interval or run.json's, else metres per frame);
a camera frame (z along the view, every point in front) as a street, camera view and
bird's-eye view (the largest cluster, the background, in sand; outliers small and grey);
anything else in 3-D.
Written to --out, by default RESULT_DIR/result.png (replacing it); the format follows the
extension of --out (.png, .pdf, .svg, .eps, .jpg, ...). An existing --out other than
RESULT_DIR/result.png is replaced only with --overwrite.
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
    parser.add_argument("result_dir", metavar="RESULT_DIR", help="a result directory")
    parser.add_argument(
        "--out",
        metavar="PICTURE",
        default=None,
        help="picture to write, its format by its extension (default: RESULT_DIR/result.png)",
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

    folder = Path(args.result_dir)
    if not folder.is_dir():
        raise CLIError(f"{folder}: not a result directory (no such directory)")
    out = Path(args.out) if args.out is not None else folder / "result.png"
    fmt = picture_format(out)  # before any work
    if args.out is not None and not args.overwrite and out.exists():
        same = out.resolve() == (folder / "result.png").resolve()
        if not same:
            raise CLIError(f"{out}: exists; pass --overwrite to replace it")
    if out.is_dir():
        raise CLIError(f"{out}: is a folder; --out names the picture file")
    paths = {name: folder / name for name in ("labels.npy", "motions.json")}
    for path in paths.values():
        if not path.exists():
            raise CLIError(f"{path}: no such file (is {folder} a result directory?)")
    with reading(paths["labels.npy"]):
        labels = mmio.read_labels(paths["labels.npy"])
        labels = check_labels(labels, len(labels), paths["labels.npy"])
    X = read_result_input(folder, len(labels))
    with reading(paths["motions.json"]):
        motions = mmio.read_motions(paths["motions.json"])
    rotations, translations = motions["rotations"], motions["translations"]
    if len(rotations) < labels.max(initial=-1) + 1:
        raise CLIError(
            f"{paths['motions.json']}: {len(rotations)} motions for labels up to {labels.max()}"
        )
    title = args.title
    if title is None:
        n_moving = int(np.sum(motions["moving"])) if motions.get("moving") is not None else 0
        title = (
            f"{folder.name}: {len(X):,} correspondences -> {plural(len(rotations), 'cluster')} "
            f"({n_moving} moving), {int(np.sum(labels < 0)):,} outliers"
        )
    camera, interval = None, args.interval
    if (folder / "run.json").exists():  # the intrinsics and the interval, when it has them
        with reading(folder / "run.json"):
            run_record = json.loads((folder / "run.json").read_text())
        camera = run_record.get("camera")
        if interval is None:
            interval = run_record.get("interval")
    fig = result_figure(
        X,
        labels,
        (rotations, translations),
        moving=motions.get("moving"),
        view=args.view,
        title=title,
        camera=camera,
        frame=args.frame,
        interval=interval,
        range_=args.range_,
    )
    picture = render_picture(fig, fmt, dpi=args.dpi)
    with reading(out), mmio.atomic_write(out) as handle:
        handle.write(picture)
    print(f"written: {out}")
    return 0
