"""A street scene from above: the clusters over the ground, as in the paper's Figure 2."""

from mmreg.plotting._clusters import _new_figure, plot_clusters
from mmreg.plotting._comparison import _use_constrained_layout
from mmreg.plotting._style import (
    _background_label,
    _check_labels,
    _check_points,
    _color_table,
    _legend,
)


def plot_street(
    a,
    labels,
    *,
    motions=None,
    camera=None,
    fig=None,
    title=None,
    label_names=None,
    max_points=60_000,
):
    """A driving scene: the camera's view and a bird's-eye view side by side.

    The points are in a camera frame (x right, y down, z forward: KITTI's convention,
    :func:`~mmreg.datasets.make_street`'s). The largest cluster is taken for the static
    world, and the arrows show the other clusters' motions relative to it (what a car
    drove between the frames, with the camera's own motion taken out).

    Parameters
    ----------
    a : array-like of shape (n, 3)
        The a-points, in the first camera's frame.
    labels : array-like of shape (n,)
        Cluster of each correspondence, ``-1`` for outliers.
    motions : (rotations, translations), default=None
        Per label, ``b = R a + t``; arrows relative to the largest cluster's motion.
    camera : dict, default=None
        Intrinsics (``fx``, ``fy``, ``cx``, ``cy``, ``width``, ``height``) for the camera
        view in pixels; None: normalised image coordinates.
    fig : matplotlib Figure, default=None
        Where to draw (it should be empty); None: a new pyplot figure, 13 x 5.5 inches.
    title : str, default=None
        Figure title.
    label_names : dict, default=None
        ``{label: name}`` for the legend.
    max_points : int or None, default=60000
        Drawn at most, per panel.

    Returns
    -------
    fig : matplotlib Figure

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> from matplotlib.figure import Figure
    >>> from mmreg.datasets import make_street
    >>> from mmreg.plotting import plot_street
    >>> scene = make_street(n_points=2000, corruption=False, sam_masks=False, random_state=0)
    >>> fig = plot_street(scene.a, scene.labels, camera=scene.camera,
    ...                   motions=(scene.rotations, scene.translations), fig=Figure())
    >>> [ax.get_title() for ax in fig.axes][:2]
    ["bird's-eye view (metres)", 'camera view (pixels)']
    """
    a = _check_points(a, "a")
    labels = _check_labels(labels, len(a))
    fig = _new_figure(fig, (13, 5.5))
    _use_constrained_layout(fig)
    grid = fig.add_gridspec(2, 2, width_ratios=[1.0, 2.4], height_ratios=[1.0, 0.55])
    bev = fig.add_subplot(grid[:, 0])
    cam = fig.add_subplot(grid[0, 1])
    key = fig.add_subplot(grid[1, 1])
    reference = _background_label(labels, True)
    options = {"label_names": label_names, "max_points": max_points, "background": True}
    plot_clusters(
        a,
        labels,
        ax=bev,
        view="bev",
        frame="camera",
        motions=motions,
        relative_to=reference,
        legend=False,
        title="bird's-eye view (metres)",
        **options,
    )
    bev.plot([0], [0], marker="^", color="black", markersize=8, linestyle="none")
    bev.annotate("camera", (0, 0), xytext=(6, -4), textcoords="offset points", fontsize=8)
    plot_clusters(
        a,
        labels,
        ax=cam,
        view="camera",
        camera=camera,
        legend=False,
        title="camera view" + (" (pixels)" if camera is not None else " (x / z, y / z)"),
        **options,
    )
    key.set_axis_off()
    extra = []
    if motions is not None:
        from matplotlib.lines import Line2D

        extra.append(
            Line2D(
                [],
                [],
                color="black",
                marker=">",
                label="arrow: motion between the frames,\nrelative to the background",
            )
        )
    _legend(
        key,
        labels,
        _color_table(labels, True),
        reference,
        label_names,
        extra=extra,
        loc="upper center",
        ncol=3,
    )
    if title is not None:
        fig.suptitle(title, fontsize=11)
    return fig
