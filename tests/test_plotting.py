"""Pictures of registrations: colours, views, legends, and no window ever opened."""

import io

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from PIL import Image  # noqa: E402

from mmreg.datasets import make_scene, make_street  # noqa: E402
from mmreg.plotting import (  # noqa: E402
    BACKGROUND_COLOR,
    OUTLIER_COLOR,
    VIEWS,
    cluster_colors,
    cluster_palette,
    plot_clusters,
    plot_comparison,
    plot_street,
)


@pytest.fixture(scope="module")
def street():
    return make_street(
        n_cars=4,
        n_moving=2,
        n_points=3000,
        image_size=(150, 496),
        corruption=False,
        sam_masks=False,
        random_state=0,
    )


@pytest.fixture(scope="module")
def scene():
    return make_scene(n_objects=3, n_points=600, outlier_fraction=0.05, random_state=0)


def _png_std(fig):
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=60)
    with Image.open(buffer) as image:
        return np.asarray(image.convert("L"), dtype=float).std()


def _drawn(ax):
    """Number of points in the axes' scatter collections."""
    return sum(len(c.get_offsets()) for c in ax.collections)


def test_palette_background_first_and_no_grey():
    colors = cluster_palette(25)
    assert tuple(colors[0]) == BACKGROUND_COLOR
    assert len(np.unique(np.round(colors, 4), axis=0)) == 25
    saturation = colors[1:].max(axis=1) - colors[1:].min(axis=1)
    assert np.all(saturation > 0.05)  # nothing grey, grey means outliers
    assert cluster_palette(0).shape == (0, 3)
    assert tuple(cluster_palette(3, background=False)[0]) != BACKGROUND_COLOR


def test_colors_follow_cluster_size_not_label_value():
    labels = np.array([5] * 10 + [2] * 3 + [-1] * 2 + [9] * 1)
    colors = cluster_colors(labels)
    assert tuple(colors[0]) == BACKGROUND_COLOR  # label 5 is the largest
    assert tuple(colors[13]) == OUTLIER_COLOR
    np.testing.assert_allclose(colors[10], cluster_palette(3)[1])
    # Renumbering the clusters does not change the colours.
    np.testing.assert_allclose(cluster_colors(np.where(labels >= 0, labels + 100, -1)), colors)


def test_colors_are_each_clusters_colour_in_the_table():
    rng = np.random.default_rng(0)
    labels = rng.integers(-1, 40, 5000)
    labels[:100] = rng.integers(-9, -1, 100)  # any negative label is an outlier
    colors = cluster_colors(labels, background=False)
    assert np.all(colors[labels < 0] == OUTLIER_COLOR)
    ids, sizes = np.unique(labels[labels >= 0], return_counts=True)
    by_size = ids[np.lexsort((ids, -sizes))]
    palette = cluster_palette(len(ids), background=False)
    for rank, label in enumerate(by_size):
        assert np.all(colors[labels == label] == palette[rank])
    assert cluster_colors(np.array([], dtype=int)).shape == (0, 3)


def test_auto_background_needs_a_clearly_largest_cluster():
    even = np.repeat([0, 1, 2], 10)
    assert not np.any(np.all(cluster_colors(even) == BACKGROUND_COLOR, axis=1))
    assert np.all(cluster_colors(even, background=True)[:10] == BACKGROUND_COLOR)


@pytest.mark.parametrize("view", VIEWS)
def test_every_view_draws_every_point(scene, view):
    fig = Figure()
    ax = fig.add_subplot(projection="3d" if view == "3d" else None)
    a = scene.a + [0, 0, 10]  # in front of the camera for view="camera"
    assert plot_clusters(a, scene.labels, ax=ax, view=view, title="t") is ax
    assert _drawn(ax) == len(a)
    assert ax.get_title() == "t"
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert texts[-1].startswith("outliers") and len(texts) == 4
    assert _png_std(fig) > 0


def test_motions_draw_one_arrow_per_moving_cluster(scene):
    fig = Figure()
    ax = fig.add_subplot()
    motions = (scene.rotations, scene.translations)
    plot_clusters(scene.a, scene.labels, ax=ax, view="top", motions=motions, b=scene.b)
    arrows = [c for c in ax.get_children() if isinstance(c, matplotlib.text.Annotation)]
    assert len(arrows) == 3
    assert _drawn(ax) == 2 * len(scene.a)  # a- and b-points
    assert "b-points" in [t.get_text() for t in ax.get_legend().get_texts()]


def test_thinning_keeps_the_objects(street):
    fig = Figure()
    ax = fig.add_subplot()
    plot_clusters(street.a, street.labels, ax=ax, view="bev", max_points=500)
    moving = int(np.sum(street.labels > 0))
    assert moving < 250 and _drawn(ax) == 500
    colors = ax.collections[0].get_facecolors()[:, :3]
    assert np.sum(np.any(np.abs(colors - BACKGROUND_COLOR) > 1e-6, axis=1)) == moving


def test_camera_view_in_pixels(street):
    fig = Figure()
    ax = fig.add_subplot()
    plot_clusters(street.a, street.labels, ax=ax, view="camera", camera=street.camera)
    assert ax.get_xlim() == (0, street.camera["width"])
    assert ax.get_ylim() == (street.camera["height"], 0)  # rows down, as an image
    offsets = ax.collections[0].get_offsets()
    assert np.all((offsets >= -1) & (offsets <= [street.camera["width"], 150]))


def test_street_has_both_views_and_a_key(street):
    fig = plot_street(
        street.a,
        street.labels,
        camera=street.camera,
        fig=Figure(),
        motions=(street.rotations, street.translations),
        title="street",
    )
    titles = [ax.get_title() for ax in fig.axes]
    assert titles[:2] == ["bird's-eye view (metres)", "camera view (pixels)"]
    assert fig.axes[2].get_legend() is not None
    assert fig.get_suptitle() == "street"
    assert _png_std(fig) > 0


def test_comparison_matches_colours(scene):
    # The estimate: the true objects renumbered, and 50 points of object 1 split off.
    pred = np.where(scene.labels >= 0, 2 - scene.labels, -1)
    split = np.flatnonzero(scene.labels == 1)[:50]
    pred[split] = 7
    fig = plot_comparison(scene.a, scene.labels, pred, view="top", fig=Figure())
    left, right = fig.axes
    true_colors = np.round(left.collections[0].get_facecolors()[:, :3], 6)
    pred_colors = np.round(right.collections[0].get_facecolors()[:, :3], 6)
    palette_true = {tuple(c) for c in true_colors}
    new = [tuple(c) for c in pred_colors if tuple(c) not in palette_true]
    assert len(set(new)) == 1 and len(new) == len(split)  # only the split-off part is new
    assert left.get_title() == "ground truth" and right.get_title() == "estimate"
    assert left.get_legend().get_texts()[0].get_text().startswith("object ")


def test_nothing_goes_to_pyplot_when_given_a_figure(scene):
    before = plt.get_fignums()
    plot_comparison(scene.a, scene.labels, scene.labels, fig=Figure())
    assert plt.get_fignums() == before
    ax = plot_clusters(scene.a, scene.labels, view="top")  # no ax: a pyplot figure
    assert plt.get_fignums() == [*before, ax.figure.number]
    plt.close(ax.figure)


def test_bad_arguments(scene):
    with pytest.raises(ValueError, match="view must be one of"):
        plot_clusters(scene.a, scene.labels, view="side")
    with pytest.raises(ValueError, match="shape"):
        plot_clusters(scene.a, scene.labels[:-1], ax=Figure().add_subplot(), view="top")
    with pytest.raises(ValueError, match="3-D axes"):
        plot_clusters(scene.a, scene.labels, ax=Figure().add_subplot(), view="3d")
    with pytest.raises(ValueError, match="camera needs"):
        plot_clusters(
            scene.a, scene.labels, ax=Figure().add_subplot(), view="camera", camera={"fx": 1.0}
        )


# --------------------------------------------------------------------------- readability
def _forty_blocks():
    rng = np.random.default_rng(0)
    centers = rng.uniform(-30, 30, (40, 3))
    a = np.repeat(centers, 30, axis=0) + rng.uniform(-1, 1, (1200, 3))
    labels = np.repeat(np.arange(40), 30)
    labels[:60] = 0  # one cluster clearly the largest
    return a, labels


def _extent(artist, fig):
    return artist.get_window_extent(fig.canvas.get_renderer())


def test_3d_arrows_are_drawn_over_the_points(scene):
    """Depth sorting drew whole point clouds over the arrows: now arrows come last."""
    fig = Figure()
    ax = fig.add_subplot(projection="3d")
    plot_clusters(scene.a, scene.labels, ax=ax, motions=(scene.rotations, scene.translations))
    assert ax.computed_zorder is False
    points = [c for c in ax.collections if len(np.atleast_2d(c.get_offsets())) > 1]
    arrows = [c for c in ax.collections if c not in points]
    assert arrows and points
    assert min(c.get_zorder() for c in arrows) > max(c.get_zorder() for c in points)


def test_3d_tick_labels_of_a_flat_scene_do_not_overlap():
    rng = np.random.default_rng(1)
    a = np.column_stack([rng.uniform(-5, 5, (500, 2)), np.zeros(500)])  # z = 0: flat
    labels = (a[:, 0] > 2).astype(int)
    fig = plt.figure(figsize=(10, 7))
    try:
        ax = plot_clusters(a, labels, ax=fig.add_subplot(projection="3d"))
        fig.canvas.draw()
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            low, high = sorted(axis.get_view_interval())
            drawn = [  # the labels of the last draw, within the axis' limits
                tick.label1
                for tick in axis.majorTicks
                if low <= tick.get_loc() <= high and tick.label1.get_text()
            ]
            boxes = [_extent(label, fig) for label in drawn]
            assert len(boxes) >= 2
            for i, first in enumerate(boxes):
                for second in boxes[i + 1 :]:
                    assert not first.overlaps(second), [label.get_text() for label in drawn]
    finally:
        plt.close(fig)


@pytest.mark.parametrize("view", ["top", "3d"])
def test_a_legend_of_forty_clusters_fits_the_figure(view):
    a, labels = _forty_blocks()
    ax = plot_clusters(a, labels, view=view)  # a new pyplot figure
    fig = ax.get_figure()
    try:
        fig.canvas.draw()
        legend = ax.get_legend()
        texts = [t.get_text() for t in legend.get_texts()]
        assert texts[-1].startswith("and ") and "more clusters" in texts[-1]
        shown = len(texts) - 1
        assert int(texts[-1].split()[1]) == len(np.unique(labels)) - shown
        box, frame = _extent(legend, fig), fig.bbox
        assert box.x0 >= frame.x0 and box.x1 <= frame.x1
        assert box.y0 >= frame.y0 and box.y1 <= frame.y1
    finally:
        plt.close(fig)


def test_a_legend_in_a_short_axes_lists_what_fits():
    a, labels = _forty_blocks()
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = Figure(figsize=(6, 1.6), layout="constrained")
    FigureCanvasAgg(fig)
    ax = plot_clusters(a, labels, ax=fig.add_subplot(), view="top")
    fig.canvas.draw()
    legend = ax.get_legend()
    assert _extent(legend, fig).height <= fig.bbox.height
    assert len(legend.get_texts()) < 12
