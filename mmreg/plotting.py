"""Pictures of a registration: clusters in 3-D, from above, through the camera, side by side.

Every function draws the a-points coloured by cluster with one colour scheme: the largest
cluster (the static background, in a driving scene) in a neutral sand colour, the other
clusters in a qualitative palette by decreasing size, the outliers (label ``-1``) small
and grey. Functions draw into the ``ax`` or ``fig`` they are given, else into a new
:mod:`matplotlib.pyplot` figure, and return it; none calls ``plt.show``, so they are safe
under the Agg backend and in scripts that only save files.

Views (``view``):

* ``"3d"``: a 3-D scatter of ``(x, y, z)`` as given;
* ``"top"``: looking down the z axis, x to the right and y up;
* ``"bev"``: bird's-eye view of a camera frame (x right, y down, z forward, as in KITTI,
  FlyingThings3D and OpenCV): x to the right, z (distance ahead) up the page; of a z-up
  LiDAR frame (``frame="lidar"``, or detected as one): as ``"top"``;
* ``"camera"``: the points as a pinhole camera at the origin sees them; in pixels when
  ``camera`` gives the intrinsics (``fx``, ``fy``, ``cx``, ``cy``, ``width``, ``height``),
  else in normalised image coordinates ``(x / z, y / z)``.
"""

import numpy as np

from mmreg import _sweep_layout
from mmreg._frames import FRAMES, detect_frame, looks_down_minus_z
from mmreg._grouping import group_centroids

__all__ = [
    "BACKGROUND_COLOR",
    "OUTLIER_COLOR",
    "VIEWS",
    "cluster_colors",
    "cluster_palette",
    "plot_clusters",
    "plot_comparison",
    "plot_result",
    "plot_street",
    "plot_sweep",
]

VIEWS = ("3d", "top", "bev", "camera")
#: Colour of the largest cluster (the background): a light sand, neutral beside the palette.
BACKGROUND_COLOR = (0.80, 0.76, 0.68)
#: Colour of the outliers (label ``-1``).
OUTLIER_COLOR = (0.35, 0.35, 0.35)
_GREY_TAB10 = 7  # tab10's grey, left out: grey means outliers
_LEGEND_ENTRIES = 12
# background="auto": the largest cluster is the background when at least this many times
# larger than the second largest.
_BACKGROUND_RATIO = 1.5


def _qualitative(n):
    """``n`` distinct colours: tab10 without its grey, then tab20's light shades, then husl."""
    from matplotlib import colormaps

    tab10 = [c for i, c in enumerate(colormaps["tab10"].colors) if i != _GREY_TAB10]
    light = [c for i, c in enumerate(colormaps["tab20"].colors) if i % 2 and i != 15]
    colors = tab10 + light
    if n > len(colors):
        import seaborn as sns  # its import costs a second: only for the 18th colour on

        colors += sns.color_palette("husl", n - len(colors))
    return np.array(colors[:n], dtype=float).reshape(n, 3)


def cluster_palette(n_colors, *, background=True):
    """The colours of clusters ranked by size: background first, then the palette.

    Parameters
    ----------
    n_colors : int
        Number of clusters to colour.
    background : bool, default=True
        Whether the first (largest) cluster is the background, in :data:`BACKGROUND_COLOR`.

    Returns
    -------
    colors : ndarray of shape (n_colors, 3)
        RGB in ``[0, 1]``.

    Examples
    --------
    >>> from mmreg.plotting import BACKGROUND_COLOR, cluster_palette
    >>> colors = cluster_palette(4)
    >>> colors.shape, tuple(colors[0]) == BACKGROUND_COLOR
    ((4, 3), True)
    """
    n_colors = int(n_colors)
    if n_colors <= 0:
        return np.zeros((0, 3))
    if not background:
        return _qualitative(n_colors)
    return np.vstack([BACKGROUND_COLOR, _qualitative(n_colors - 1)])


def _check_labels(labels, n, name="labels"):
    labels = np.asarray(labels)
    if labels.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), one per a-point; got {labels.shape}.")
    integral = labels.dtype.kind in "iu" or (
        labels.dtype.kind == "f" and np.all(labels == np.round(labels))
    )
    if not integral:
        raise TypeError(f"{name} must be integers; got dtype {labels.dtype}.")
    return labels.astype(np.intp)


def _check_points(points, name):
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise ValueError(f"{name} must have shape (n, 3) (or (n, 2)); got {points.shape}.")
    return points


def _ranked(labels):
    """Cluster ids (not -1) by decreasing size (ties: smaller id first), and their sizes."""
    ids, sizes = np.unique(labels[labels >= 0], return_counts=True)
    order = np.lexsort((ids, -sizes))
    return ids[order], sizes[order]


def _background_label(labels, background):
    """The label drawn as the background, or None (see ``background`` of plot_clusters)."""
    if background not in ("auto", True, False):
        raise ValueError(f"background must be 'auto', True or False; got {background!r}.")
    ids, sizes = _ranked(labels)
    if not len(ids) or background is False:
        return None
    if background == "auto" and len(ids) > 1 and sizes[0] < _BACKGROUND_RATIO * sizes[1]:
        return None
    return int(ids[0])


def _color_table(labels, background="auto"):
    """``{label: rgb}`` for every cluster by decreasing size, ``-1`` included."""
    ids = _ranked(labels)[0]
    has_background = _background_label(labels, background) is not None
    table = dict(
        zip(ids.tolist(), cluster_palette(len(ids), background=has_background), strict=True)
    )
    table[-1] = np.array(OUTLIER_COLOR)
    return table


def cluster_colors(labels, *, background="auto"):
    """Colour of every point by its cluster, as the plots draw it.

    Parameters
    ----------
    labels : array-like of shape (n,)
        Cluster of each point, ``-1`` for outliers.
    background : {"auto", True, False}, default="auto"
        Whether the largest cluster is drawn in the neutral :data:`BACKGROUND_COLOR`;
        ``"auto"``: when it holds at least 1.5 times the points of the second largest.

    Returns
    -------
    colors : ndarray of shape (n, 3)
        RGB in ``[0, 1]``: ready for :func:`mmreg.io.write_point_cloud` or ``scatter``.

    Examples
    --------
    >>> from mmreg.plotting import OUTLIER_COLOR, cluster_colors
    >>> colors = cluster_colors([1, 1, 0, -1])
    >>> colors.shape, tuple(colors[3]) == OUTLIER_COLOR
    ((4, 3), True)
    """
    labels = np.asarray(labels)
    labels = _check_labels(labels, len(labels))
    table = _color_table(labels, background)
    # One gather from a palette indexed by label + 1 (row 0: the outliers' colour), not
    # a pass over the points per cluster.
    palette = np.zeros((max(table) + 2, 3))
    for label, color in table.items():
        palette[label + 1] = color
    return palette[np.maximum(labels, -1) + 1]


def _name(label, size, background_label, label_names, kind):
    if label_names is not None and label in label_names:
        return f"{label_names[label]} ({size:,} pts)"
    if label < 0:
        return f"outliers ({size:,} pts)"
    if label == background_label:
        return f"{kind} {label}: background ({size:,} pts)"
    return f"{kind} {label} ({size:,} pts)"


def _legend_rows(ax, fontsize, ncol=1):
    """How many legend rows fit in the height of ``ax`` (at least 3)."""
    fig = ax.get_figure()
    height = ax.get_position().height * fig.get_figheight() * 72.0  # points
    row = fontsize * 1.55  # a marker row and matplotlib's label spacing
    return max(3, int((height - 2 * fontsize) // row)) * max(1, ncol)


def _legend(ax, labels, table, background_label, label_names, *, kind="cluster", extra=(), **kw):
    """A legend of the largest clusters that fits the axes; the rest as "and N more"."""
    from matplotlib.lines import Line2D

    fontsize = 7
    ids, sizes = _ranked(labels)
    entries = list(zip(ids.tolist(), sizes.tolist(), strict=True))
    n_out = int(np.sum(labels < 0))
    room = min(_LEGEND_ENTRIES, _legend_rows(ax, fontsize, kw.get("ncol", 1)))
    room -= len(extra) + (1 if n_out else 0)
    if len(entries) > room:  # one row for "and N more"
        room = max(room - 1, 1)
    shown, rest = entries[:room], entries[room:]
    if n_out:
        shown.append((-1, n_out))
    handles = [
        Line2D(
            [],
            [],
            linestyle="none",
            marker="o",
            markersize=6 if label >= 0 else 4,
            color=table[label],
            label=_name(label, size, background_label, label_names, kind),
        )
        for label, size in shown
    ]
    if rest:
        handles.append(
            Line2D(
                [],
                [],
                linestyle="none",
                label=f"and {len(rest)} more {kind}s ({sum(s for _, s in rest):,} pts)",
            )
        )
    handles.extend(extra)
    return ax.legend(handles=handles, fontsize=fontsize, framealpha=0.85, **kw)


def _subsample(labels, background_label, max_points, random_state):
    """Indices to draw: every object point while they fit in half the budget, then the rest."""
    n = len(labels)
    if max_points is None or n <= max_points:
        return np.arange(n)
    rng = np.random.default_rng(random_state)
    objects = np.flatnonzero((labels >= 0) & (labels != background_label))
    others = np.flatnonzero((labels < 0) | (labels == background_label))
    if len(objects) > max_points // 2:
        objects = rng.choice(objects, max_points // 2, replace=False)
    budget = max_points - len(objects)
    if len(others) > budget:
        others = rng.choice(others, budget, replace=False)
    return np.sort(np.concatenate([objects, others]))


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


def _use_constrained_layout(fig):
    if fig.get_layout_engine() is None:
        fig.set_layout_engine("constrained")


def _matched_colors(labels_true, labels_pred):
    """Colours of the true clusters, and of the predicted ones by their matched true cluster.

    Predicted clusters are matched one-to-one to true clusters (most shared points,
    Hungarian method); a matched cluster takes its true cluster's colour, an unmatched
    one a colour of its own.
    """
    from scipy.optimize import linear_sum_assignment

    true_ids, _ = _ranked(labels_true)
    pred_ids, _ = _ranked(labels_pred)
    true_table = _color_table(labels_true, True)
    if not len(true_ids) or not len(pred_ids):
        return true_table, _color_table(labels_pred, True)
    t_index = {label: i for i, label in enumerate(true_ids.tolist())}
    p_index = {label: i for i, label in enumerate(pred_ids.tolist())}
    both = (labels_true >= 0) & (labels_pred >= 0)
    overlap = np.zeros((len(true_ids), len(pred_ids)))
    np.add.at(
        overlap,
        (
            np.array([t_index[v] for v in labels_true[both].tolist()], dtype=np.intp),
            np.array([p_index[v] for v in labels_pred[both].tolist()], dtype=np.intp),
        ),
        1.0,
    )
    rows, cols = linear_sum_assignment(-overlap)
    pred_table = {-1: np.array(OUTLIER_COLOR)}
    matched = {}
    for r, c in zip(rows, cols, strict=True):
        if overlap[r, c] > 0:
            matched[int(pred_ids[c])] = true_table[int(true_ids[r])]
    spare = iter(_qualitative(len(true_ids) + len(pred_ids))[max(len(true_ids) - 1, 0) :])
    for label in pred_ids.tolist():
        pred_table[label] = matched[label] if label in matched else next(spare)
    return true_table, pred_table


def plot_comparison(
    a,
    labels_true,
    labels_pred,
    *,
    view="3d",
    camera=None,
    fig=None,
    titles=("ground truth", "estimate"),
    title=None,
    max_points=60_000,
):
    """Ground truth and estimated clusters side by side, a match in the same colour.

    Each estimated cluster is matched one-to-one to the true object it shares the most
    points with (Hungarian method) and drawn in that object's colour; unmatched clusters
    get colours of their own, so a split object shows as two colours on the right.

    Parameters
    ----------
    a : array-like of shape (n, 3)
        The a-points.
    labels_true, labels_pred : array-like of shape (n,)
        True and estimated clusters, ``-1`` for outliers.
    view : {"3d", "top", "bev", "camera"}, default="3d"
    camera : dict, default=None
        Intrinsics for ``view="camera"``.
    fig : matplotlib Figure, default=None
        Where to draw (empty); None: a new pyplot figure.
    titles : (str, str), default=("ground truth", "estimate")
    title : str, default=None
        Figure title.
    max_points : int or None, default=60000

    Returns
    -------
    fig : matplotlib Figure

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> from matplotlib.figure import Figure
    >>> from mmreg import MultiModelRegistration
    >>> from mmreg.datasets import make_scene
    >>> from mmreg.plotting import plot_comparison
    >>> scene = make_scene(n_objects=3, n_points=600, random_state=0)
    >>> est = MultiModelRegistration(init=scene.labels).fit(scene.X)
    >>> fig = plot_comparison(scene.a, scene.labels, est.labels_, view="top", fig=Figure())
    >>> len(fig.axes)
    2
    """
    if view not in VIEWS:
        raise ValueError(f"view must be one of {VIEWS}; got {view!r}.")
    a = _check_points(a, "a")
    labels_true = _check_labels(labels_true, len(a), "labels_true")
    labels_pred = _check_labels(labels_pred, len(a), "labels_pred")
    wide = view == "camera"
    fig = _new_figure(fig, (12, 7.5) if wide else (12, 5.5))
    _use_constrained_layout(fig)
    true_table, pred_table = _matched_colors(labels_true, labels_pred)
    projection = "3d" if view == "3d" else None
    shape = (2, 1) if wide else (1, 2)
    panels = [
        (labels_true, true_table, titles[0], "object"),
        (labels_pred, pred_table, titles[1], "cluster"),
    ]
    for i, (labels, table, name, kind) in enumerate(panels):
        ax = fig.add_subplot(*shape, i + 1, projection=projection)
        plot_clusters(
            a,
            labels,
            ax=ax,
            view=view,
            camera=camera,
            colors=table,
            background=True,
            kind=kind,
            title=name,
            max_points=max_points,
        )
    if title is not None:
        fig.suptitle(title, fontsize=11)
    return fig


#: Half width of the window of :func:`plot_sweep` around the sensor, by default [m].
SWEEP_RANGE = 50.0
# The static world's greys by height above the ground: light ground, darker as it rises
# (walls, poles, trees), so that a sweep reads as a map from above.
_GROUND_GREY, _TALL_GREY, _TALL = 0.74, 0.3, 4.0
_SWEEP_LEGEND_ENTRIES = 14


def _static_reference(labels, moving, n_clusters):
    """The static world, reference of the motions: the largest cluster ``moving`` leaves
    still (the largest of all when ``moving`` is None or leaves none still)."""
    ids, _ = _ranked(labels)
    if moving is not None:
        still = ~np.asarray(moving, dtype=bool).ravel()[:n_clusters]
        candidates = [k for k in ids.tolist() if k < len(still) and still[k]]
        if candidates:
            return candidates[0]
    return _background_label(labels, True)


def _moving_flags(moving, n_clusters, reference):
    """One bool per cluster: the given ``moving``, else every cluster but the reference."""
    if moving is None:
        flags = np.ones(n_clusters, dtype=bool)
    else:
        flags = np.asarray(moving, dtype=bool).ravel()
        if len(flags) < n_clusters:
            raise ValueError(
                f"moving must have one entry per cluster, at least {n_clusters}; got {len(flags)}."
            )
        flags = flags[:n_clusters].copy()
    if reference is not None:
        flags[reference] = False
    return flags


def _static_greys(z):
    """Grey of every static point by its height above the ground (the 5th percentile)."""
    if not len(z):
        return np.zeros((0, 3))
    ground = np.percentile(z, 5.0)
    rise = np.clip((z - ground) / _TALL, 0.0, 1.0)
    grey = _GROUND_GREY + (_TALL_GREY - _GROUND_GREY) * rise
    return np.repeat(grey[:, np.newaxis], 3, axis=1)


def _sweep_axes(ax):
    if ax is not None:
        return ax
    from matplotlib.figure import Figure

    # Not a pyplot figure: a runner writing a picture per job leaks none.
    fig = Figure(figsize=(11.5, 8.0), layout="constrained")
    return fig.add_subplot()


def _points_per_metre(ax, half_width):
    """Typographic points per metre across the (square) axes."""
    fig = ax.get_figure()
    box = ax.get_position()
    side = min(box.width * fig.get_figwidth(), box.height * fig.get_figheight())
    if fig.get_layout_engine() is not None:  # constrained layout gives the legend its room
        side = min(side, 0.62 * fig.get_figwidth(), 0.9 * fig.get_figheight())
    return side * 72.0 / (2.0 * half_width)


def _sensor(ax, center, half_width):
    from matplotlib.patches import Polygon

    size = half_width / 90.0
    ax.add_patch(
        Polygon(
            [
                (center[0] + 1.4 * size, center[1]),
                (center[0] - size, center[1] + size),
                (center[0] - size, center[1] - size),
            ],
            closed=True,
            color="black",
            zorder=12,
        )
    )


def plot_sweep(
    points,
    labels,
    motions=None,
    *,
    moving=None,
    interval=None,
    range_=SWEEP_RANGE,
    center=(0.0, 0.0),
    ax=None,
    title=None,
    label_names=None,
    max_points=300_000,
    random_state=0,
):
    """A LiDAR sweep from above: the static world in grey, moving objects outlined, arrows.

    The points are in a z-up frame with the sensor at ``center`` (x forward, y left: ROS,
    Argoverse 2, KITTI's Velodyne). The picture is the square ``center +- range_`` seen
    from above: the static world in greys by height above the ground (light ground,
    darker walls, poles and trees), each moving cluster in its own colour inside its
    oriented bounding box, with an arrow from its centroid along its motion relative to the
    static world. Arrows are lengthened by one round factor so that the typical one shows
    (the legend says by how much, and a slow object's arrow is drawn at least 4 % of the
    window long); the legend gives each object's speed, in m/s when ``interval`` is known,
    else in metres per frame. Markers are sized by the density of the points, so that a
    surface reads as a surface.

    Parameters
    ----------
    points : array-like of shape (n, 3)
        The points of the first sweep (the a-points), z up.
    labels : array-like of shape (n,)
        Cluster of every point, ``-1`` for outliers. The largest cluster (of those not
        ``moving``) is the static world, the reference of every motion.
    motions : (rotations, translations), default=None
        Arrays ``(K, 3, 3)`` and ``(K, 3)`` indexed by label (``b = R a + t``): the arrows
        and speeds. None: outlines only.
    moving : array-like of bool, default=None
        One per cluster (as in ``mmreg register``'s summary): the moving clusters are
        coloured, the others drawn with the static world, the largest of which is the
        reference of the motions. None: every cluster but the largest is moving.
    interval : float, default=None
        Seconds between the two sweeps: speeds in m/s (else in metres per frame) and the
        arrows' legend in seconds of travel.
    range_ : float, default=50.0
        Half width of the window [m].
    center : (float, float), default=(0.0, 0.0)
        Centre of the window, the sensor's position.
    ax : matplotlib Axes, default=None
        Where to draw (the legend goes to its right); None: a new
        :class:`matplotlib.figure.Figure` of 11.5 x 8 inches (not a pyplot figure: save it
        with ``fig.savefig``).
    title : str, default=None
    label_names : dict, default=None
        ``{label: name}`` for the legend (e.g. ``{3: "bus"}``).
    max_points : int or None, default=300000
        At most this many static points are drawn (thinned at random beyond).
    random_state : int, default=0
        Seeds the thinning.

    Returns
    -------
    fig : matplotlib Figure

    See Also
    --------
    plot_street : The same for a camera's frame: camera view and bird's-eye view.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.plotting import plot_sweep
    >>> rng = np.random.default_rng(0)
    >>> ground = np.c_[rng.uniform(-40, 40, (4000, 2)), np.zeros(4000)]
    >>> car = np.c_[rng.uniform(10, 14, (200, 1)), rng.uniform(2, 4, (200, 1)),
    ...             rng.uniform(0, 1.5, (200, 1))]
    >>> points, labels = np.vstack([ground, car]), np.r_[np.zeros(4000, int), np.ones(200, int)]
    >>> rotations = np.stack([np.eye(3)] * 2)
    >>> translations = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])  # 1 m in 0.1 s
    >>> fig = plot_sweep(points, labels, (rotations, translations), interval=0.1)
    >>> [t.get_text() for t in fig.axes[0].get_legend().get_texts()][1]
    'cluster 1: 10.0 m/s (200 pts)'
    """
    points = _check_points(points, "points")
    if points.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3); got {points.shape}.")
    labels = _check_labels(labels, len(points))
    range_ = float(range_)
    if not (np.isfinite(range_) and range_ > 0):
        raise ValueError(f"range_ must be a positive number of metres; got {range_!r}.")
    if interval is not None and not (np.isfinite(interval) and interval > 0):
        raise ValueError(f"interval must be a positive number of seconds; got {interval!r}.")
    center = np.asarray(center, dtype=float).reshape(2)
    ax = _sweep_axes(ax)
    n_clusters = int(labels.max(initial=-1)) + 1
    reference = _static_reference(labels, moving, n_clusters)
    if motions is not None and len(motions[0]) < n_clusters:
        raise ValueError(f"motions must have one per cluster, {n_clusters}; got {len(motions[0])}.")
    flags = _moving_flags(moving, n_clusters, reference)
    is_moving = np.zeros(len(labels), dtype=bool)
    is_moving[labels >= 0] = flags[labels[labels >= 0]]
    window = _sweep_layout.in_window(points, center, range_)

    # Objects: the moving clusters by decreasing size; shown when their centroid is in view.
    ids, sizes = _ranked(labels)
    objects = [(k, s) for k, s in zip(ids.tolist(), sizes.tolist(), strict=True) if flags[k]]
    centroids = group_centroids(points, labels, max(n_clusters, 1))[0]
    shown = [
        (k, s) for k, s in objects if _sweep_layout.in_window(centroids[[k]], center, range_)[0]
    ]
    colors = dict(zip([k for k, _ in objects], _qualitative(len(objects)), strict=True))
    displacement = {}
    if motions is not None and shown:
        starts, ends, kept = _arrow_ends(points, labels, motions, [k for k, _ in shown], reference)
        displacement = dict(zip(kept, ends - starts, strict=True))

    # The static world (and the non-moving clusters, and the outliers apart), then objects.
    ppm = _points_per_metre(ax, range_)
    static = np.flatnonzero(window & ~is_moving & (labels >= 0))
    if max_points is not None and len(static) > max_points:
        rng = np.random.default_rng(random_state)
        static = np.sort(rng.choice(static, max_points, replace=False))
    diameter = _sweep_layout.marker_diameter(points[static], ppm)
    static = static[np.argsort(points[static, 2], kind="stable")]  # the tops seen from above
    ax.scatter(
        *points[static, :2].T,
        c=_static_greys(points[static, 2]),
        s=diameter**2,
        linewidths=0,
        rasterized=True,
        zorder=1,
    )
    outliers = np.flatnonzero(window & (labels < 0))
    if len(outliers):
        ax.scatter(
            *points[outliers, :2].T,
            color="black",
            s=(2.5 * diameter) ** 2,
            marker="x",
            linewidths=0.5,
            rasterized=True,
            zorder=2,
        )
    # One round factor for every arrow, from their lengths seen from above.
    scale = _sweep_layout.arrow_scale(
        [np.linalg.norm(d[:2]) for d in displacement.values()], 2 * range_
    )
    _draw_objects(ax, points, labels, shown, colors, displacement, diameter, range_, scale)

    ax.grid(True, color="0.88", lw=0.6, zorder=0)
    ax.set_axisbelow(True)
    _sensor(ax, center, range_)
    ax.set_xlim(center[0] - range_, center[0] + range_)
    ax.set_ylim(center[1] - range_, center[1] + range_)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.tick_params(labelsize=8)
    _sweep_legend(
        ax,
        labels,
        flags,
        reference,
        shown,
        objects,
        colors,
        displacement,
        scale,
        interval,
        range_,
        label_names,
    )
    if title is not None:
        ax.set_title(title, fontsize=10)
    return ax.get_figure()


def _draw_objects(ax, points, labels, shown, colors, displacement, diameter, range_, scale):
    """Each moving object's points, oriented box, arrow (lengthened by scale) and its id."""
    from matplotlib import patheffects
    from matplotlib.patches import FancyArrowPatch, Polygon

    window = 2 * range_
    halo = [patheffects.withStroke(linewidth=2.6, foreground="white")]
    for label, _ in shown:
        color = colors[label]
        xy = points[labels == label, :2]
        ax.scatter(
            *xy.T,
            color=color,
            s=max(1.8 * diameter, 2.0) ** 2,
            linewidths=0,
            rasterized=True,
            zorder=4,
        )
        corners = _sweep_layout.oriented_box(xy, max(_sweep_layout.MIN_BOX, 0.012 * window))
        ax.add_patch(
            Polygon(
                corners, closed=True, facecolor=(*color, 0.15), edgecolor=color, lw=1.3, zorder=3
            )
        )
        start = xy.mean(axis=0)
        if label in displacement:
            d = displacement[label]
            length = float(np.linalg.norm(d[:2]))
            if length > 0:
                drawn = _sweep_layout.arrow_lengths([length], scale, window)[0][0]
                end = start + d[:2] / length * drawn
                ax.add_patch(
                    FancyArrowPatch(
                        start,
                        end,
                        arrowstyle="-|>",
                        mutation_scale=11,
                        color="black",
                        lw=1.4,
                        shrinkA=0,
                        shrinkB=0,
                        path_effects=halo,
                        zorder=10,
                    )
                )
        top = corners[np.argmax(corners[:, 1])]
        ax.annotate(  # the legend's name for it
            f"{label}",
            top,
            xytext=(3, 3),
            textcoords="offset points",
            fontsize=7,
            color="black",
            path_effects=halo,
            zorder=11,
            clip_on=True,
        )


def _sweep_legend(
    ax,
    labels,
    flags,
    reference,
    shown,
    objects,
    colors,
    displacement,
    scale,
    interval,
    range_,
    label_names,
):
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    label_names = label_names or {}
    static_labels = [k for k in _ranked(labels)[0].tolist() if not flags[k]]
    n_static = int(np.isin(labels, static_labels).sum())
    others = [k for k in static_labels if k != reference]
    what = "static world" + (f" and {len(others)} static clusters" if others else "")
    handles = [Patch(color=(0.6, 0.6, 0.6), label=f"{what} ({n_static:,} pts),\n  darker = higher")]
    room = _SWEEP_LEGEND_ENTRIES - 4
    listed = shown[:room] if len(shown) <= room else shown[: room - 1]
    for label, size in listed:
        name = label_names.get(label, f"cluster {label}")
        if label in displacement:
            speed = float(np.linalg.norm(displacement[label]))
            name += f": {_sweep_layout.speed_text(speed, interval)}"
        handles.append(
            Patch(
                facecolor=(*colors[label], 0.35),
                edgecolor=colors[label],
                label=f"{name} ({size:,} pts)",
            )
        )
    rest = shown[len(listed) :]
    if rest:
        handles.append(
            Patch(
                color="none", label=f"and {len(rest)} more moving ({sum(s for _, s in rest):,} pts)"
            )
        )
    beyond = len(objects) - len(shown)
    if beyond:
        handles.append(Patch(color="none", label=f"{beyond} moving beyond {range_:g} m, not drawn"))
    n_out = int(np.sum(labels < 0))
    if n_out:
        handles.append(
            Line2D(
                [],
                [],
                linestyle="none",
                marker="x",
                color="black",
                label=f"outliers ({n_out:,} pts)",
            )
        )
    if displacement:
        if interval is not None:
            arrow = f"arrow: travel in {scale * interval:.2g} s (motion x{scale:g})"
        else:
            arrow = f"arrow: motion between the sweeps x{scale:g}"
        lengths = np.array([np.linalg.norm(d[:2]) for d in displacement.values()])
        lengths = lengths[lengths > 0]  # no arrow at all for these
        if np.any(_sweep_layout.arrow_lengths(lengths, scale, 2 * range_)[1]):
            arrow += f",\n  at least {_sweep_layout.ARROW_MIN * 2 * range_:.2g} m long"
        handles.append(Line2D([], [], color="black", marker=">", label=arrow))
    handles.append(
        Line2D([], [], linestyle="none", marker=">", color="black", markersize=7, label="sensor")
    )
    ax.legend(
        handles=handles,
        fontsize=8,
        framealpha=0.9,
        **_legend_place(ax, "bev"),
    )


#: Views of :func:`plot_result`: ``"auto"``, ``"street"`` and those of :func:`plot_clusters`.
RESULT_VIEWS = ("auto", "street", *VIEWS)


def _turned_to_opencv(points, motions):
    """Points and motions of an OpenGL camera (y up, looking down -z) in OpenCV's frame.

    A half turn about x, ``D = diag(1, -1, -1)``: ``a -> D a`` and ``R, t -> D R D, D t``
    (``b = R a + t`` becomes ``D b = (D R D)(D a) + D t``).
    """
    flip = np.array([1.0, -1.0, -1.0])
    if motions is not None:
        rotations, translations = (np.asarray(m, dtype=float) for m in motions)
        motions = (rotations * flip[:, np.newaxis] * flip[np.newaxis, :], translations * flip)
    return points * flip, motions


def plot_result(
    points,
    labels,
    motions=None,
    *,
    moving=None,
    view="auto",
    frame="auto",
    camera=None,
    interval=None,
    range_=None,
    title=None,
):
    """The picture of a registration in the view that suits the frame of its points.

    The frame decides: a LiDAR sweep (z up, the sensor at the origin, points all around)
    is drawn from above by :func:`plot_sweep`; a camera's frame (z along the view, every
    point in front) as a street by :func:`plot_street` (an OpenGL camera looking down -z
    turned into OpenCV's frame first); anything else in 3-D. The frame is read from where
    the points lie, never from the sign of z alone (a LiDAR frame on the ground has
    z > 0 everywhere), unless ``frame`` names it.

    Parameters
    ----------
    points : array-like of shape (n, 3)
        The a-points.
    labels : array-like of shape (n,)
        Cluster of every point, ``-1`` for outliers; the largest is the static world.
    motions : (rotations, translations), default=None
        Per label, ``b = R a + t``: the arrows (relative to the static world).
    moving : array-like of bool, default=None
        One per cluster: which clusters move (e.g. ``mmreg register``'s summary).
    view : {"auto", "street", "3d", "top", "bev", "camera"}, default="auto"
        ``"auto"``: from the frame as above; ``"bev"``: from above (along z for every
        frame but a camera's); the others as :func:`plot_clusters` draws them.
    frame : {"auto", "camera", "lidar"}, default="auto"
    camera : dict, default=None
        Intrinsics for the camera view in pixels (see :func:`plot_street`).
    interval : float, default=None
        Seconds between the two sweeps: speeds in m/s in a LiDAR picture.
    range_ : float, default=None
        Half width of a LiDAR picture's window [m]; None: 50.
    title : str, default=None

    Returns
    -------
    fig : matplotlib Figure
        Not a pyplot figure: save it with ``fig.savefig``.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.plotting import plot_result
    >>> rng = np.random.default_rng(0)
    >>> azimuth, distance = rng.uniform(-np.pi, np.pi, 3000), rng.uniform(3, 40, 3000)
    >>> sweep = np.c_[distance * np.cos(azimuth), distance * np.sin(azimuth),
    ...               rng.uniform(0.1, 3.0, 3000)]  # z > 0 everywhere: still a LiDAR
    >>> fig = plot_result(sweep, np.zeros(3000, dtype=int))
    >>> fig.axes[0].get_xlabel(), fig.axes[0].get_ylabel()
    ('x [m]', 'y [m]')
    """
    from matplotlib.figure import Figure

    if view not in RESULT_VIEWS:
        raise ValueError(f"view must be one of {RESULT_VIEWS}; got {view!r}.")
    if frame not in ("auto", *FRAMES):
        raise ValueError(f"frame must be 'auto', 'camera' or 'lidar'; got {frame!r}.")
    points = _check_points(points, "points")
    labels = _check_labels(labels, len(points))
    if frame == "auto":
        frame = detect_frame(points) if points.shape[1] == 3 else None
    if view == "auto":
        view = {"camera": "street", "lidar": "bev"}.get(frame, "3d")
    if view == "bev" and frame != "camera":
        fig = Figure(figsize=(11.5, 8.0), layout="constrained")
        plot_sweep(
            points,
            labels,
            motions,
            moving=moving,
            interval=interval,
            range_=SWEEP_RANGE if range_ is None else range_,
            ax=fig.add_subplot(),
        )
        if title is not None:
            fig.suptitle(title, fontsize=11)
        return fig
    if frame == "camera" and view in ("street", "bev", "camera") and looks_down_minus_z(points):
        points, motions = _turned_to_opencv(points, motions)
    reference = _background_label(labels, True)
    names = None
    if moving is not None:
        names = {
            j: f"cluster {j}: " + ("background" if j == reference else "moving" if m else "static")
            for j, m in enumerate(np.asarray(moving, dtype=bool).tolist())
        }
    if view == "street":
        fig = Figure(figsize=(13, 5.8))
        plot_street(
            points,
            labels,
            motions=motions,
            camera=camera,
            fig=fig,
            title=title,
            label_names=names,
        )
        return fig
    fig = Figure(figsize=(10, 7), layout="constrained")
    ax = fig.add_subplot(projection="3d" if view == "3d" else None)
    # The largest cluster is the reference of "moving": drawn as the background, and the
    # arrows show the motions relative to it (none for a cluster moving with it).
    plot_clusters(
        points,
        labels,
        ax=ax,
        view=view,
        motions=motions,
        relative_to=reference,
        camera=camera,
        label_names=names,
        background=True,
        frame=frame or "auto",
    )
    if title is not None:
        fig.suptitle(title, fontsize=11)
    return fig
