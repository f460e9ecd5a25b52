"""Fig. 2-style box plots (IoU, per-point, rotation and translation error per method).

The paper's Fig. 2 shows FlyingThings3D and KITTI, whose data cannot be shipped; this
script draws the same four panels for any results table written by ``paper/table1.py``
(one figure per experiment). Usage: ``python paper/figure_boxplots.py`` after
``python paper/table1.py``; writes ``paper/out/boxplots_experiment_<k>.png``.
"""

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402
import seaborn as sns  # noqa: E402

PANELS = {
    "iou": "IoU (higher is better)",
    "per_point_error": "Per-point error [m]",
    "rotation_error": "Rotation error [deg]",
    "translation_error": "Translation error [m]",
}


def draw(results, experiment):
    data = results[results["experiment"] == experiment]
    fig, axes = plt.subplots(1, len(PANELS), figsize=(4 * len(PANELS), 3.6))
    for ax, (column, title) in zip(axes, PANELS.items(), strict=True):
        sns.boxplot(data=data, x="method", y=column, hue="method", ax=ax, legend=False)
        ax.set_title(title)
        ax.set_xlabel("")
        ax.set_ylabel("")
        ax.tick_params(axis="x", labelrotation=35)
        if column != "iou" and (data[column] > 0).all():
            ax.set_yscale("log")
    fig.suptitle(f"Experiment {experiment}")
    fig.tight_layout()
    return fig


def main(argv=None):
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path(__file__).parent / "out",
        help="folder holding table1.csv (from table1.py); the PNGs are written there too",
    )
    args = parser.parse_args(argv)
    results = pd.read_csv(args.out / "table1.csv")
    for experiment in sorted(results["experiment"].unique()):
        path = args.out / f"boxplots_experiment_{experiment}.png"
        draw(results, experiment).savefig(path, dpi=120)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
