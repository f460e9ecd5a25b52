"""A LiDAR sweep from above: the static world in greys, objects boxed, motions as arrows."""

import numpy as np

from mmreg._array.grouping import group_centroids
from mmreg.plotting import _sweep_layout
from mmreg.plotting._clusters import _arrow_ends, _legend_place
from mmreg.plotting._style import (
    _background_label,
    _check_labels,
    _check_points,
    _qualitative,
    _ranked,
)

#: Half width of the window of :func:`plot_sweep` around the sensor, by default [m].
SWEEP_RANGE = 50.0
# The static world's greys by height above the ground: light ground, darker as it rises
# (walls, poles, trees), so that a sweep reads as a map from above.
_GROUND_GREY, _TALL_GREY, _TALL = 0.74, 0.3, 4.0
_SWEEP_LEGEND_ENTRIES = 14
# The ego vehicle's own body: a pale blue under the sensor's mark, neither the static
# world's grey nor the outliers' black.
_BODY_COLOR = (0.55, 0.72, 0.9)


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


def _draw_static(ax, points, diameter):
    """The static points in greys by height, the higher drawn over the lower (the tops
    seen from above), each grey an 8-bit level so that a level is drawn at once."""
    from mmreg.plotting._stamped import StampedPoints

    levels = np.round(_static_greys(points[:, 2])[:, 0] * 255).astype(np.int64)
    # Darker is higher: the levels from light to dark are the painter's order.
    palette, index = np.unique(-levels, return_inverse=True)
    greys = -palette / 255
    ax.add_artist(
        StampedPoints(
            points[:, :2],
            index,
            np.repeat(greys[:, np.newaxis], 3, axis=1),
            diameter,
            rasterized=True,
            zorder=1,
        )
    )


def _draw_body(ax, points, diameter):
    """The ego vehicle's own body, pale blue, under the sensor's mark."""
    from mmreg.plotting._stamped import StampedPoints

    ax.add_artist(
        StampedPoints(
            points[:, :2],
            np.zeros(len(points), dtype=np.int64),
            [_BODY_COLOR],
            diameter,
            rasterized=True,
            zorder=2,
        )
    )


def _check_body(ego_body, n):
    """``ego_body`` as n bools (None: none)."""
    if ego_body is None:
        return np.zeros(n, dtype=bool)
    body = np.asarray(ego_body)
    if body.dtype != bool or body.shape != (n,):
        raise ValueError(
            f"ego_body must be one bool per point, shape ({n},); got {body.dtype} {body.shape}."
        )
    return body


def _draw_outliers(ax, points, diameter):
    """The outliers as black crosses, over the static world."""
    from mmreg.plotting._stamped import StampedPoints

    ax.add_artist(
        StampedPoints(
            points[:, :2],
            np.zeros(len(points), dtype=np.int64),
            [(0.0, 0.0, 0.0)],
            2.5 * diameter,
            marker="x",
            linewidth=0.5,
            rasterized=True,
            zorder=2,
        )
    )


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
    ego_body=None,
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
    ego_body : array-like of bool, default=None
        One per point: returns from the ego vehicle's own body (labelled -1, as
        :attr:`mmreg.SweepRegistration.ego_body_mask_` says), drawn pale blue around the
        sensor and counted apart, not as outliers.

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
    body = _check_body(ego_body, len(points))
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
    _draw_static(ax, points[static], diameter)
    if body.any():
        _draw_body(ax, points[window & body], diameter)
    outliers = np.flatnonzero(window & (labels < 0) & ~body)
    if len(outliers):
        _draw_outliers(ax, points[outliers], diameter)
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
        body,
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
    body,
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
    n_body = int(body.sum())
    if n_body:
        handles.append(
            Line2D(
                [],
                [],
                linestyle="none",
                marker="o",
                markersize=4,
                color=_BODY_COLOR,
                label=f"the ego vehicle's body ({n_body:,} pts)",
            )
        )
    n_out = int(np.sum((labels < 0) & ~body))
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
