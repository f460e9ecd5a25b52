"""Pictures of the synthetic scene families, for docs/datasets.md.

Writes ``docs/img/scene.png``, ``docs/img/flying_things.png`` and ``docs/img/street.png``:
the a-points coloured by their ground truth (seen from the camera for the rendered
families) next to the simulated SegmentAnything masks.

Usage: ``python scripts/plot_datasets.py [--out DIR] [--seed N]``.
"""

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.ndimage import distance_transform_edt  # noqa: E402

from mmreg.datasets import make_scene  # noqa: E402
from mmreg.datasets._flying_things import make_flying_things  # noqa: E402
from mmreg.datasets._street import make_street  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "docs" / "img"


def _colours(n, rng):
    """``n`` distinct bright colours (background grey first), RGB in [0, 1]."""
    base = plt.get_cmap("tab20")(np.arange(20))[:, :3]
    base = np.delete(base, [14, 15], axis=0)  # no greys: grey is the background
    base = np.vstack([base[0::2], base[1::2]])  # the saturated tab20 shades first
    extra = rng.uniform(0.15, 0.95, size=(max(0, n - len(base)), 3))
    return np.vstack([[[0.72, 0.72, 0.72]], base, extra])[:n]


def _points_panel(ax, scene, labels, title, rng, outliers=True):
    """The a-points seen from the camera, by ``labels`` (0: grey by depth), outliers black.

    Each point is drawn at its pixel and spread to the pixels nearer to it than to any
    other point, up to 1.5 times the mean gap between points (so surfaces read as surfaces and the
    sparser far regions stay visibly sparser); pixels without a surface stay white.
    """
    colours = _colours(labels.max() + 1, rng)
    point_colours = colours[labels]
    # The background in greys, lighter with depth, so its structure shows.
    depth = scene.a[:, 2]
    shade = (depth - depth.min()) / max(np.ptp(depth), 1e-12)
    point_colours[labels == 0] = (0.35 + 0.5 * shade[labels == 0])[:, np.newaxis]
    if outliers:
        point_colours[scene.outlier_mask] = 0.0
    cols, rows = scene.pixels.T
    height, width = scene.instance_image.shape
    owner = np.full((height, width), -1)
    owner[rows, cols] = np.arange(len(labels))
    valid = scene.instance_image >= 0
    gap = np.sqrt(np.count_nonzero(valid) / len(labels))
    distance, (near_rows, near_cols) = distance_transform_edt(owner < 0, return_indices=True)
    nearest = owner[near_rows, near_cols]
    image = np.ones((height, width, 3))
    shown = valid & (distance <= 1.5 * gap)
    image[shown] = point_colours[nearest[shown]]
    ax.imshow(image, interpolation="nearest")
    _image_axes(ax, scene.camera, title)


def _masks_panel(ax, scene, title, rng):
    """The SAM-like masks painted smallest on top, in random colours; uncovered black."""
    height, width = scene.instance_image.shape
    image = np.zeros((height, width, 3))
    order = np.argsort([-m["area"] for m in scene.masks])
    colours = rng.uniform(0.2, 1.0, size=(len(scene.masks), 3))
    for index in order:  # one pass per mask
        image[scene.masks[index]["segmentation"]] = colours[index]
    image[scene.instance_image < 0] = 1.0  # no surface: white
    ax.imshow(image, interpolation="nearest")
    _image_axes(ax, scene.camera, title)


def _image_axes(ax, camera, title):
    ax.set_xlim(-0.5, camera.width - 0.5)
    ax.set_ylim(camera.height - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title, fontsize=10)


def plot_scene(out, seed):
    scene = make_scene(
        n_objects=7,
        n_points=22395,
        noise=0.03,
        outlier_fraction=0.05,
        object_size=3.0,
        shapes="meshes",
        random_state=seed,
    )
    rng = np.random.RandomState(seed)
    colours = _colours(scene.labels.max() + 2, rng)[1:]
    fig = plt.figure(figsize=(11, 5))
    for index, (points, title) in enumerate(
        [(scene.a, "a-points by object (outliers black)"), (scene.b, "b-points after the motions")]
    ):
        ax = fig.add_subplot(1, 2, index + 1, projection="3d")
        inlier = scene.labels >= 0
        ax.scatter(*points[inlier].T, c=colours[scene.labels[inlier]], s=1.5, linewidths=0)
        ax.scatter(*points[~inlier].T, c="k", s=0.8, linewidths=0)
        ax.set_title(title, fontsize=10)
        ax.set_box_aspect(np.ptp(scene.a, axis=0))
    fig.suptitle(
        "make_scene(shapes='meshes'): 7 real meshes 3 m across, 22,395 correspondences, "
        "noise 0.03 m, 5 % outliers "
        "(no image, so no masks)",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(out / "scene.png", dpi=110)
    plt.close(fig)


def plot_flying_things(out, seed):
    scene = make_flying_things(random_state=seed)
    rng = np.random.RandomState(seed)
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.2))
    _points_panel(
        axes[0],
        scene,
        scene.labels,
        f"{len(scene.labels):,} a-points by motion group (backdrop grey, gross errors black)",
        rng,
    )
    _masks_panel(axes[1], scene, f"{len(scene.masks)} SAM-like masks (uncovered black)", rng)
    fig.suptitle("make_flying_things: 10 objects 2-4 m across at 5-35 m, 960 x 540", fontsize=11)
    fig.tight_layout()
    fig.savefig(out / "flying_things.png", dpi=110)
    plt.close(fig)


def plot_street(out, seed):
    scene = make_street(n_cars=7, n_moving=3, random_state=seed)
    rng = np.random.RandomState(seed)
    fig, axes = plt.subplots(3, 1, figsize=(12, 11.5))
    _points_panel(
        axes[0],
        scene,
        scene.labels,
        f"{len(scene.labels):,} a-points by motion group: background and parked cars grey, "
        f"{scene.moving.sum()} moving cars coloured, gross errors black",
        np.random.RandomState(seed),
    )
    _points_panel(
        axes[1],
        scene,
        scene.instance_labels,
        f"instances (the paper's ground truth): every car its own, {len(scene.moving)} cars",
        np.random.RandomState(seed),
        outliers=False,
    )
    _masks_panel(
        axes[2], scene, f"{len(scene.masks)} SAM-like masks (uncovered black, no depth white)", rng
    )
    fig.suptitle("make_street: KITTI camera 1242 x 375, depth capped at 35 m", fontsize=11)
    fig.tight_layout()
    fig.savefig(out / "street.png", dpi=100)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT, help="output folder (docs/img)")
    parser.add_argument("--seed", type=int, default=0, help="random_state of every scene")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    plot_scene(args.out, args.seed)
    plot_flying_things(args.out, args.seed)
    plot_street(args.out, args.seed)


if __name__ == "__main__":
    main()
