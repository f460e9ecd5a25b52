"""Table I as box plots: every measure of every run, one figure per experiment.

Reads table1.csv (written by paper/table1.py) from --out and draws, per experiment, the
paper's IoU, the share of the 7 objects found, the clusters reported and the per-point,
rotation and translation errors of every method, one dot per run. Errors at rounding
level (an exact answer) are drawn at that level and labelled "exact".

Writes to --out: table1_boxplots_exp<k>.png and .pdf.
"""

import sys
from pathlib import Path

import pandas as pd
from _common import DEFAULT_OUT, add_formats_argument, make_parser, save_figure
from _plots import box_figure

PANEL_COLUMNS = [
    "iou",
    "objects_found",
    "n_clusters",
    "per_point_error",
    "rotation_error",
    "translation_error",
]

TITLES = {
    "objects_found": ("Objects found (IoU >= 0.5)", "share of the 7", "higher is better"),
    "n_clusters": ("Clusters reported", "clusters (dashed: 7 objects)", "closer to dashed"),
}


def draw(results, out, formats="png,pdf"):
    """One figure per experiment of ``results`` (table1.csv); returns the paths."""
    paths = []
    for experiment, frame in results.groupby("experiment", sort=False):
        methods = list(dict.fromkeys(frame["method"]))
        title = (
            f"{frame['title'].iloc[0]}, on GENERATED PASCAL3D+-like scenes "
            f"(mmreg.datasets.make_scene: 7 objects, {int(frame['n_points'].median()):,} "
            f"correspondences): {frame['run'].nunique()} runs.\n"
            "Boxes: quartiles and median, whiskers 1.5 IQR; dots: one per run. "
            "Objects found: share of the 7 objects some cluster recovers with IoU >= 0.5."
        )
        frame = frame.assign(n_motions=7)
        fig = box_figure(frame, PANEL_COLUMNS, methods, title, ncols=3, titles=TITLES)
        stem = Path(out) / f"table1_boxplots_{experiment.split('-')[-1]}"
        paths += save_figure(fig, stem, formats=formats)
    return paths


def main(argv=None):
    parser = make_parser(__doc__)
    parser.add_argument(
        "--out",
        type=Path,
        default=DEFAULT_OUT,
        help="folder holding table1.csv (from table1.py); the figures are written there too",
    )
    add_formats_argument(parser)
    args = parser.parse_args(argv)
    source = args.out / "table1.csv"
    if not source.exists():
        raise SystemExit(f"error: {source} not found; run paper/table1.py --out {args.out} first")
    paths = draw(pd.read_csv(source), args.out, args.formats)
    print("wrote " + ", ".join(str(p) for p in paths), file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
