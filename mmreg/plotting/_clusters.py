"""Clusters in 3-D, from above or through the camera, with motion arrows."""

import numpy as np

from mmreg._array.frames import FRAMES, detect_frame
from mmreg._array.grouping import group_centroids
from mmreg.plotting._style import (
    VIEWS,
    _background_label,
    _check_labels,
    _check_points,
    _color_table,
    _legend,
    _ranked,
    _subsample,
)


def _check_camera(camera):
    if camera is None:
        return None
    get = camera.get if hasattr(camera, "get") else lambda k: getattr(camera, k, None)
    values = {k: get(k) for k in ("fx", "fy", "cx", "cy", "width", "height")}
    missing = [k for k, v in values.items() if v is None]
    if missing:
        raise ValueError(f"camera needs fx, fy, cx, cy, width and height; missing {missing}.")
    return {k: float(v) for k, v in values.items()}


def _project(points, view, camera, units):
    """2-D coordinates of ``points`` in a flat view, which of them are visible, axis labels."""
    visible = np.ones(len(points), dtype=bool)
    if view == "top":
        return points[:, :2], visible, (f"x [{units}]", f"y [{units}]")
    if points.shape[1] != 3:
        raise ValueError(f"view={view!r} needs 3-D points; got {points.shape[1]}-D.")
    if view == "bev":
        xy = points[:, [0, 2]]
        return xy, visible, (f"x, to the right [{units}]", f"z, ahead of the camera [{units}]")
    # camera
    depth = points[:, 2]
    visible = depth > 0
    safe = np.where(visible, depth, 1.0)
    uv = points[:, :2] / safe[:, np.newaxis]
    if camera is None:
        return uv, visible, ("x / z (right)", "y / z (down)")
    uv = uv * [camera["fx"], camera["fy"]] + [camera["cx"], camera["cy"]]
    return uv, visible, ("image column [pixels]", "image row [pixels]")


def _point_size(n, point_size, view):
    if point_size is not None:
        return float(point_size)
    scale = 6e4 if view == "camera" else 3e4  # an image is filled, a 3-D box is not
    return float(np.clip(scale / max(n, 1), 0.4, 20.0))


def _arrow_ends(a, labels, motions, ids, relative_to):
    """Centroid of each cluster's a-points and where its motion takes it."""
    rotations, translations = (np.asarray(m, dtype=float) for m in motions)
    ids = np.asarray(ids, dtype=np.intp)
    kept = ids[(ids >= 0) & (ids < len(rotations))]
    # Every centroid at once, not one pass over the points per cluster.
    with_motion = np.where(labels < len(rotations), labels, -1)
    starts = group_centroids(a, with_motion, len(rotations))[0][kept]
    ends = np.einsum("kij,kj->ki", rotations[kept], starts) + translations[kept]
    if relative_to is not None:  # back into the first frame by the background's motion
        ends = (ends - translations[relative_to]) @ rotations[relative_to]
    return starts, ends, kept.tolist()


def _new_axes(ax, view):
    if ax is not None:
        if view == "3d" and getattr(ax, "name", "") != "3d":
            raise ValueError("view='3d' needs a 3-D axes: fig.add_subplot(projection='3d').")
        return ax
    import matplotlib.pyplot as plt

    # Constrained layout keeps a legend beside a flat view inside the figure.
    fig = plt.figure(figsize=(7, 6), layout="constrained")
    return fig.add_subplot(projection="3d" if view == "3d" else None)


def plot_clusters(
    a,
    labels,
    *,
    b=None,
    ax=None,
    view="3d",
    motions=None,
    relative_to=None,
    camera=None,
    background="auto",
    label_names=None,
    title=None,
    units="m",
    legend=True,
    kind="cluster",
    point_size=None,
    max_points=60_000,
    random_state=0,
    colors=None,
    frame="auto",
):
    """Draw the a-points coloured by cluster, with optional motion arrows or b-points.

    Parameters
    ----------
    a : array-like of shape (n, 3)
        The a-points (``X[:, :3]``); 2-D points work with ``view="top"``.
    labels : array-like of shape (n,)
        Cluster of each correspondence (e.g. ``labels_``), ``-1`` for outliers.
    b : array-like of shape (n, 3), default=None
        The b-points, drawn faded in their cluster's colour.
    ax : matplotlib Axes, default=None
        Where to draw (a 3-D axes for ``view="3d"``); None: a new pyplot figure.
    view : {"3d", "top", "bev", "camera"}, default="3d"
        See the module's description.
    motions : (rotations, translations), default=None
        Arrays ``(K, 3, 3)`` and ``(K, 3)`` indexed by label (e.g. ``rotations_``,
        ``translations_``): an arrow from each cluster's centroid ``c`` to ``R c + t``.
    relative_to : int, default=None
        A label whose motion is undone at the arrows' heads (``R_0^T (R c + t - t_0)``),
        so they show each cluster's motion relative to that cluster (the background
        when the camera moves).
    camera : dict, default=None
        ``fx``, ``fy``, ``cx``, ``cy``, ``width``, ``height`` for ``view="camera"`` in
        pixels (e.g. ``make_street(...).camera``).
    background : {"auto", True, False}, default="auto"
        Whether the largest cluster is the background, drawn in the neutral
        :data:`BACKGROUND_COLOR`; ``"auto"``: when it holds at least 1.5 times the points
        of the second largest.
    label_names : dict, default=None
        ``{label: name}`` for the legend, e.g. ``{0: "static world"}``.
    kind : str, default="cluster"
        How the legend calls a cluster (e.g. ``"object"`` for the ground truth).
    title : str, default=None
    units : str, default="m"
        Unit of the coordinates, for the axis labels.
    legend : bool, default=True
        Whether to draw a legend: to the right of a flat view when the figure has a
        layout engine (the figures made here do), else in the upper left corner of the
        axes. It lists the largest clusters that fit the axes' height and sums up the
        rest as "and N more clusters".
    point_size : float, default=None
        Marker area in points^2; None: from the number of points.
    max_points : int or None, default=60000
        At most this many points are drawn (background and outliers thinned first).
    random_state : int, default=0
        Seeds the thinning.
    colors : dict, default=None
        ``{label: rgb}`` overriding the colours (used by :func:`plot_comparison`).
    frame : {"auto", "camera", "lidar"}, default="auto"
        The frame of the points, for ``view="bev"``: a camera's (seen from above is along
        y) or a z-up LiDAR's (along z, as ``"top"``); ``"auto"``: from where the points
        lie (a camera's when that does not show).

    Returns
    -------
    ax : matplotlib Axes

    See Also
    --------
    plot_street : Camera view and bird's-eye view of a driving scene, side by side.
    plot_comparison : Ground truth and estimate side by side, in matching colours.

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> from matplotlib.figure import Figure
    >>> from mmreg import MultiModelRegistration
    >>> from mmreg.datasets import make_scene
    >>> from mmreg.plotting import plot_clusters
    >>> scene = make_scene(n_objects=3, n_points=600, random_state=0)
    >>> est = MultiModelRegistration(init=scene.labels).fit(scene.X)
    >>> fig = Figure()
    >>> ax = plot_clusters(scene.a, est.labels_, ax=fig.add_subplot(projection="3d"),
    ...                    motions=(est.rotations_, est.translations_))
    >>> [text.get_text() for text in ax.get_legend().get_texts()]
    ['cluster 0 (200 pts)', 'cluster 1 (200 pts)', 'cluster 2 (200 pts)', 'arrow: motion']
    """
    if view not in VIEWS:
        raise ValueError(f"view must be one of {VIEWS}; got {view!r}.")
    if frame not in ("auto", *FRAMES):
        raise ValueError(f"frame must be 'auto', 'camera' or 'lidar'; got {frame!r}.")
    a = _check_points(a, "a")
    labels = _check_labels(labels, len(a))
    camera = _check_camera(camera)
    if view == "bev" and a.shape[1] == 3:
        if frame == "auto":
            frame = detect_frame(a)
        if frame == "lidar":  # z up: from above is along z
            view = "top"
    ax = _new_axes(ax, view)
    ids, _ = _ranked(labels)
    background_label = _background_label(labels, background)
    table = _color_table(labels, background)
    if colors is not None:
        table.update({int(k): np.asarray(v, dtype=float) for k, v in colors.items()})
    keep = _subsample(labels, background_label, max_points, random_state)
    size = _point_size(len(keep), point_size, view)

    # One scatter, drawn back to front: background, outliers, then the other clusters.
    rank = np.where(labels == background_label, 0, np.where(labels < 0, 1, 2))[keep]
    point_colors = np.array([table[label] for label in ids.tolist()] + [table[-1]])
    lookup = {label: i for i, label in enumerate(ids.tolist())}
    lookup[-1] = len(ids)
    index = np.array([lookup[label] for label in labels[keep].tolist()], dtype=np.intp)
    colors_kept = point_colors[index].reshape(-1, 3)
    sizes = np.where(labels[keep] < 0, 0.5 * size, size)
    extra = []
    if view == "3d":
        order = np.argsort(rank, kind="stable")
        pts = a[keep][order]
        # Draw in the order given (points, then arrows on top), not by depth, which
        # put whole point clouds over the arrows.
        ax.computed_zorder = False
        ax.scatter(
            pts[:, 0],
            pts[:, 1],
            pts[:, 2],
            c=colors_kept[order],
            s=sizes[order],
            linewidths=0,
            depthshade=False,
            zorder=1,
        )
        ax.set_xlabel(f"x [{units}]")
        ax.set_ylabel(f"y [{units}]")
        ax.set_zlabel(f"z [{units}]")
        if b is not None:
            b = _check_points(b, "b")
            pts = b[keep][order]
            ax.scatter(
                pts[:, 0],
                pts[:, 1],
                pts[:, 2],
                c=colors_kept[order],
                s=sizes[order] * 0.5,
                alpha=0.25,
                linewidths=0,
                depthshade=False,
                zorder=0,
            )
    else:
        xy, visible, (xlabel, ylabel) = _project(a, view, camera, units)
        shown = visible[keep]
        if view == "camera":  # painter's order: far points first
            order = np.lexsort((-a[keep, 2], rank))
        else:
            order = np.argsort(rank, kind="stable")
        order = order[shown[order]]
        pts = xy[keep][order]
        if b is not None:
            b = _check_points(b, "b")
            bxy, bvisible, _ = _project(b, view, camera, units)
            border = order[bvisible[keep][order]]
            ax.scatter(
                *bxy[keep][border].T,
                c=colors_kept[border],
                s=sizes[border] * 0.5,
                alpha=0.25,
                linewidths=0,
            )
        ax.scatter(*pts.T, c=colors_kept[order], s=sizes[order], linewidths=0)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_aspect("equal", adjustable="datalim" if view != "camera" else "box")
        if view == "camera":
            if camera is not None:
                ax.set_xlim(0, camera["width"])
                ax.set_ylim(camera["height"], 0)
            else:
                ax.invert_yaxis()
    if b is not None:
        from matplotlib.lines import Line2D

        extra.append(
            Line2D([], [], linestyle="none", marker="o", color="0.6", alpha=0.4, label="b-points")
        )
    heads = None
    if motions is not None:
        arrow, heads = _draw_arrows(ax, a, labels, motions, ids, relative_to, view, camera, units)
        extra.append(arrow)
    if view == "3d":
        _frame_3d(ax, a if heads is None else np.vstack([a, heads]))
    if legend:
        _legend(
            ax,
            labels,
            table,
            background_label,
            label_names,
            kind=kind,
            extra=[e for e in extra if e],
            # Beside a flat view; inside a 3-D one (layout engines leave it out there).
            **_legend_place(ax, view),
        )
    if title is not None:
        ax.set_title(title, fontsize=10)
    return ax


def _legend_place(ax, view):
    """Beside a flat view when a layout engine makes room for it, else inside the axes."""
    fig = ax.get_figure()
    has_layout = fig is not None and fig.get_layout_engine() is not None
    if view != "3d" and has_layout:
        return {"loc": "upper left", "bbox_to_anchor": (1.02, 1.0), "borderaxespad": 0.0}
    # Layout engines leave a 3-D axes' legend out: inside its (usually empty) corner.
    return {"loc": "upper left", "bbox_to_anchor": (0.0, 1.0), "borderaxespad": 0.0}


def _frame_3d(ax, points):
    """Limits holding ``points`` (and the arrows' heads), readable axes and ticks.

    An axis along which the points hardly extend (a flat scene) keeps at least a fifth
    of the largest extent, so its tick labels do not pile up; each axis has at most five
    ticks.
    """
    from matplotlib.ticker import MaxNLocator

    low, high = points.min(axis=0), points.max(axis=0)
    extent = high - low
    largest = float(extent.max()) if np.isfinite(extent).all() and extent.max() > 0 else 1.0
    extent = np.maximum(extent, 0.2 * largest)
    center = (low + high) / 2
    ax.set_xlim(center[0] - extent[0] / 2, center[0] + extent[0] / 2)
    ax.set_ylim(center[1] - extent[1] / 2, center[1] + extent[1] / 2)
    ax.set_zlim(center[2] - extent[2] / 2, center[2] + extent[2] / 2)
    ax.set_box_aspect(extent)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(nbins=5, min_n_ticks=2))
    ax.tick_params(labelsize=8)
    ax.zaxis.labelpad = 6


def _draw_arrows(ax, a, labels, motions, ids, relative_to, view, camera, units):
    """Arrows from each cluster's centroid to where its motion takes it, over the points.

    Arrows shorter than 1 % of the extent of the drawing are left out (a static cluster
    relative to the background, say). Returns the legend handle (None if no arrow shows)
    and, in 3-D, the arrows' heads (to frame the drawing; None otherwise).
    """
    from matplotlib import patheffects
    from matplotlib.lines import Line2D

    starts, ends, kept = _arrow_ends(a, labels, motions, ids.tolist(), relative_to)
    if view == "3d":
        extent = float(np.max(np.ptp(a, axis=0)))
        p, q = starts, ends
    else:
        xy, visible, _ = _project(a, view, camera, units)
        extent = float(np.max(np.ptp(xy[visible], axis=0))) if visible.any() else 0.0
        p, visible_p, _ = _project(starts, view, camera, units)
        q, visible_q, _ = _project(ends, view, camera, units)
        p, q = p[visible_p & visible_q], q[visible_p & visible_q]
    long_enough = np.linalg.norm(q - p, axis=1) > 0.01 * extent
    p, q = p[long_enough], q[long_enough]
    if not len(p):
        return None, None
    # A white halo keeps a black arrow visible over dark clusters.
    halo = [patheffects.withStroke(linewidth=3.0, foreground="white")]
    if view == "3d":
        d = q - p
        ax.quiver(
            *p.T,
            *d.T,
            color="black",
            linewidth=1.4,
            arrow_length_ratio=0.2,
            zorder=10,
            path_effects=halo,
        )
    else:
        for s, e in zip(p, q, strict=True):
            ax.annotate(
                "",
                xy=e,
                xytext=s,
                arrowprops={
                    "arrowstyle": "-|>",
                    "color": "black",
                    "lw": 1.2,
                    "mutation_scale": 9,
                    "shrinkA": 0,
                    "shrinkB": 0,
                    "path_effects": halo,
                },
                zorder=10,
            )
    what = "motion relative to the background" if relative_to is not None else "motion"
    handle = Line2D([], [], color="black", marker=">", label=f"arrow: {what}")
    return handle, (q if view == "3d" else None)


def _new_figure(fig, figsize):
    if fig is not None:
        return fig
    import matplotlib.pyplot as plt

    return plt.figure(figsize=figsize)
