"""Fig. 1 of the paper: a street scene seen by the camera, points coloured by motion.

A GENERATED KITTI-like scene (mmreg.datasets.make_street: a driving camera, moving and
parked cars, buildings; scene flow with a network's errors, 10 % of them gross), drawn
at the pixels where the camera sees each a-point. Top: the ground truth, every moving car
in its own colour and the static world (parked cars included) in the background colour;
the gross flow errors in black. Below: the motions recovered by the paper's Algorithm 1
(Ours, tau = 5 m) and by mmreg's default, both from the SAM-like masks; each recovered
cluster takes the colour of the true motion it shares the most points with (one-to-one),
clusters matched to nothing get colours of their own, correspondences labelled as
outliers are black. As in the paper's Fig. 1, parked cars belong to the background.

Writes to --out: figure1.png and figure1.pdf.
"""

import sys
import warnings
from pathlib import Path

import matplotlib
import matplotlib.patches

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from _common import DEFAULT_OUT, add_formats_argument, make_parser, save_figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from scipy.optimize import linear_sum_assignment  # noqa: E402

from mmreg.datasets import make_street  # noqa: E402
from mmreg.init import PrecomputedMasks  # noqa: E402
from mmreg.methods import make_method  # noqa: E402
from mmreg.metrics import iou_score, objects_found  # noqa: E402

BACKGROUND = (0.80, 0.76, 0.68)
OUTLIER = (0.0, 0.0, 0.0)
CARS = ["#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2"]
SPARE = ["#17becf", "#bcbd22", "#7f7f7f", "#aec7e8", "#ffbb78", "#98df8a", "#c5b0d5"]
TAU = 5.0
QUICK = {"n_points": 3000, "image_size": (188, 621)}


def match_colours(truth, labels, truth_colours):
    """A colour per label: the true motion it overlaps most (one-to-one), else a spare."""
    ids = np.unique(labels[labels >= 0])
    true_ids = np.unique(truth[truth >= 0])
    overlap = np.array(
        [[np.sum((labels == p) & (truth == t)) for p in ids] for t in true_ids], dtype=float
    )
    colours = {-1: OUTLIER}
    spare = iter(SPARE * (len(ids) // len(SPARE) + 1))
    rows, cols = linear_sum_assignment(-overlap) if overlap.size else ([], [])
    matched = {
        ids[c]: truth_colours[true_ids[r]] for r, c in zip(rows, cols, strict=True) if overlap[r, c]
    }
    for label in ids:
        colours[label] = matched.get(label) or next(spare)
    return colours


def draw_panel(ax, pixels, labels, colours, image_size, title):
    """The a-points at their pixels, coloured by label; outliers small and black."""
    height, width = image_size
    order = np.argsort(labels >= 0)  # outliers first, under the clusters
    rgb = np.array([matplotlib.colors.to_rgb(colours[label]) for label in labels[order]])
    sizes = np.where(labels[order] < 0, 0.8, 2.2)
    ax.scatter(
        pixels[order, 0],
        pixels[order, 1],
        c=rgb,
        s=sizes,
        linewidths=0,
        rasterized=True,
        antialiased=False,
    )
    ax.set_xlim(0, width)
    ax.set_ylim(height, 0)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_facecolor("white")
    ax.set_title(title, fontsize=10, loc="left")


def outline_parked_cars(ax, scene):
    """A dashed box and the word "parked" around every parked car in view."""
    parked = np.flatnonzero(~np.asarray(scene.moving, dtype=bool)) + 1  # instance ids
    for instance in parked:
        pixels = scene.pixels[scene.instance_labels == instance]
        if len(pixels) < 10:
            continue
        (left, top), (right, bottom) = pixels.min(axis=0) - 4, pixels.max(axis=0) + 4
        ax.add_patch(
            matplotlib.patches.Rectangle(
                (left, top),
                right - left,
                bottom - top,
                fill=False,
                linestyle="--",
                linewidth=0.9,
                edgecolor="black",
            )
        )
        ax.text(left, top - 3, "parked", fontsize=7, va="bottom")


def run(seed=4, quick=False):
    """The scene and the labels of the ground truth, Ours and mmreg."""
    kwargs = QUICK if quick else {}
    scene = make_street(random_state=seed, **kwargs)
    init = PrecomputedMasks(scene.masks, scene.pixels).fit(scene.X).labels_
    truth = np.where(scene.outlier_mask, -1, scene.labels)
    fits = {}
    for name, label in (("ours", "Ours (Algorithm 1)"), ("mmreg", "mmreg")):
        estimator = make_method(name, tau=TAU, init=init, random_state=0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fits[label] = estimator.fit(scene.X)
    return scene, truth, fits


def draw(scene, truth, fits):
    """Ground truth above the recovered motions, one panel each."""
    image_size = scene.depth_image.shape
    moving = np.unique(truth[truth > 0])
    truth_colours = {0: BACKGROUND, -1: OUTLIER}
    truth_colours.update({k: CARS[(k - 1) % len(CARS)] for k in moving})
    parked = int((~np.asarray(scene.moving, dtype=bool)).sum())
    n_panels = 1 + len(fits)
    width = 12.0
    fig, axes = plt.subplots(
        n_panels,
        1,
        figsize=(width, n_panels * width * image_size[0] / image_size[1] + 1.6),
        layout="constrained",
    )
    draw_panel(
        axes[0],
        scene.pixels,
        truth,
        truth_colours,
        image_size,
        f"Ground truth: {len(moving)} moving cars in colour; the static world, "
        f"{parked} parked cars included, in the background colour; "
        f"{int((truth < 0).sum()):,} gross flow errors in black",
    )
    outline_parked_cars(axes[0], scene)
    for ax, (label, fitted) in zip(axes[1:], fits.items(), strict=True):
        labels = np.asarray(fitted.labels_)
        found = objects_found(truth, labels, objects=moving)
        draw_panel(
            ax,
            scene.pixels,
            labels,
            match_colours(truth, labels, truth_colours),
            image_size,
            f"{label}: {fitted.n_clusters_} motions reported (truth: {len(moving) + 1}), "
            f"{found * len(moving):.0f} of {len(moving)} moving cars found, IoU with gross "
            f"errors as outliers {iou_score(truth, labels):.2f}; "
            f"{int((labels < 0).sum()):,} labelled outliers (black)",
        )
    handles = [
        Line2D([], [], marker="o", linestyle="", color=BACKGROUND, label="static world"),
        *[
            Line2D([], [], marker="o", linestyle="", color=truth_colours[k], label=f"car {k}")
            for k in moving
        ],
        Line2D([], [], marker="o", linestyle="", color=OUTLIER, label="gross error / outlier"),
        Line2D(
            [],
            [],
            marker="o",
            linestyle="",
            color=SPARE[0],
            label="clusters matching no true motion (any other colour)",
        ),
    ]
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), frameon=False)
    fig.suptitle(
        f"Fig. 1 reproduced on a GENERATED KITTI-like street (mmreg.datasets.make_street, "
        f"{len(scene.X):,} correspondences), seen from the camera.\nEach point is drawn "
        "at its pixel in the first frame; tau = 5 m; initial clusters from SAM-like masks.",
        fontsize=10.5,
        x=0.01,
        ha="left",
    )
    return fig


def main(argv=None):
    parser = make_parser(__doc__)
    parser.add_argument("--seed", type=int, default=4, help="random_state of make_street")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="folder for the figure")
    parser.add_argument("--quick", action="store_true", help="a small scene, for tests")
    add_formats_argument(parser)
    args = parser.parse_args(argv)
    fig = draw(*run(args.seed, args.quick))
    paths = save_figure(fig, args.out / "figure1", dpi=110, formats=args.formats)
    print("wrote " + ", ".join(str(p) for p in paths), file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
