"""A frame of a tracked LiDAR log from above: tracks by id with their trails, the world grey.

:func:`plot_log_frame` draws one frame of a log in the log's frame (the first sensor
pose's, x and y as on a map), the window following the sensor: the static world in greys
by height, the points of every moving track in the track's own colour (the same id, the
same colour, in every frame), its id beside it and its trail (the centroids of the frames
before), the ego vehicle's body and the other unlabelled returns apart.
:func:`animate_log` joins such pictures into one animated GIF (Pillow: no ffmpeg).
"""

import numpy as np

from mmreg.plotting._style import _qualitative

# The ego body as the pictures of a pair draw it (pale blue).
from mmreg.plotting._sweep import _BODY_COLOR

__all__ = ["LOG_RANGE", "animate_log", "plot_log_frame", "track_color"]

#: Half width of the window around the sensor, by default [m].
LOG_RANGE = 50.0
# LiDAR-MOS classes of a ``.label`` file's lower 16 bits.
_MOVING, _STATIC = 251, 9
# The static world's greys by height above its ground (light road, darker walls).
_GROUND_GREY, _TALL_GREY, _TALL = 0.68, 0.22, 4.0
_UNLABELLED_COLOR = (0.15, 0.15, 0.15)
# tab10 without its grey, then tab20's light shades but the light blue of the ego body.
_PALETTE_SIZE = 16
_BODY_LIKE = 9


def track_color(track):
    """The colour of track ``track`` (an id ``>= 1``), the same in every picture.

    Examples
    --------
    >>> from mmreg.plotting._log import track_color
    >>> track_color(1) == track_color(1 + 16), len(track_color(2))
    (True, 3)
    """
    palette = np.delete(_qualitative(_PALETTE_SIZE + 1), _BODY_LIKE, axis=0)
    return tuple(float(c) for c in palette[(int(track) - 1) % _PALETTE_SIZE])


def _greys(z):
    if not len(z):
        return np.zeros(0)
    ground = np.percentile(z, 5.0)
    rise = np.clip((z - ground) / _TALL, 0.0, 1.0)
    return _GROUND_GREY + (_TALL_GREY - _GROUND_GREY) * rise


def _check_frame(points, semantic, instance, pose, body):
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] < 3:
        raise ValueError(f"points must have shape (n, 3); got {points.shape}.")
    n = len(points)
    semantic = np.asarray(semantic)
    instance = np.zeros(n, np.int64) if instance is None else np.asarray(instance)
    for name, values in (("semantic", semantic), ("instance", instance)):
        if values.shape != (n,) or values.dtype.kind not in "iu":
            raise ValueError(f"{name} must be {n} integers, one per point; got {values.shape}.")
    pose = np.asarray(pose, dtype=float)
    if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
        raise ValueError(f"pose must be a finite 4 x 4 matrix; got shape {pose.shape}.")
    if body is not None:
        body = np.asarray(body, dtype=bool)
        if body.shape != (n,):
            raise ValueError(f"body must have shape ({n},); got {body.shape}.")
    return points[:, :3], semantic.astype(np.int64), instance.astype(np.int64), pose, body


def plot_log_frame(
    points,
    semantic,
    instance=None,
    pose=None,
    *,
    tracks=None,
    frame=None,
    body=None,
    range_=LOG_RANGE,
    title=None,
    ax=None,
):
    """Draw one frame of a tracked log from above, in the log's frame.

    Parameters
    ----------
    points : array-like of shape (n, 3)
        The frame's points in its sensor's frame (z up); rows that are NaN or all zero
        (no return) are left out.
    semantic : array-like of int, shape (n,)
        LiDAR-MOS classes: 251 moving, 9 static, 0 unlabelled (outliers, the ego
        vehicle's body, invalid returns), as :func:`mmreg.io.semantickitti_mos_labels`
        gives them.
    instance : array-like of int, shape (n,), optional
        The track id of each point (0: none).
    pose : array-like of shape (4, 4), optional
        The sensor's pose in the log's frame (``x_log = pose @ x_sensor``); None: the
        identity.
    tracks : pandas.DataFrame, optional
        The tracks' centroids in the log's frame, columns ``track``, ``frame``, ``x``,
        ``y``: the rows of frames up to ``frame`` draw each track's trail; the tracks
        with moving points in this frame (or a row at ``frame``) are drawn.
    frame : int, optional
        This frame's number in ``tracks``.
    body : array-like of bool, shape (n,), optional
        The ego vehicle's body, drawn apart from the other unlabelled points.
    range_ : float, default=50.0
        Half width of the square window around the sensor.
    title : str, optional
    ax : matplotlib Axes, optional
        Drawn into; None: a new (non-pyplot) Figure.

    Returns
    -------
    ax : matplotlib Axes

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.plotting._log import plot_log_frame
    >>> points = np.array([[5.0, 0, -1.7], [8, 1, 0], [8, 2, 0], [0, 0, 0]])
    >>> ax = plot_log_frame(points, [9, 251, 251, 0], [0, 3, 3, 0], np.eye(4))
    >>> [t.get_text() for t in ax.texts]
    ['3']
    """
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    from mmreg.plotting._stamped import StampedPoints

    pose = np.eye(4) if pose is None else pose
    points, semantic, instance, pose, body = _check_frame(points, semantic, instance, pose, body)
    if not (np.isfinite(range_) and range_ > 0):
        raise ValueError(f"range_ must be a positive number; got {range_!r}.")
    if ax is None:
        ax = Figure(figsize=(7.0, 7.4), layout="constrained").add_subplot()
    valid = np.all(np.isfinite(points), axis=1) & np.any(points != 0, axis=1)
    world = points @ pose[:3, :3].T + pose[:3, 3]
    centre = pose[:2, 3]
    inside = valid & np.all(np.abs(world[:, :2] - centre) <= range_, axis=1)
    per_metre = 7.0 * 72.0 / (2.0 * range_)
    size = float(np.clip(0.09 * per_metre, 0.6, 3.0))
    moving = inside & (semantic == _MOVING)
    static = inside & (semantic != _MOVING) & (semantic != 0)
    unlabelled = inside & (semantic == 0)
    is_body = np.zeros(len(points), bool) if body is None else body & inside
    unlabelled &= ~is_body
    # The static world, the higher drawn over the lower (tops seen from above).
    levels = np.round(_greys(points[static, 2]) * 255).astype(np.int64)
    palette, index = np.unique(-levels, return_inverse=True)
    greys = np.repeat((-palette / 255.0)[:, None], 3, axis=1)
    ax.add_artist(StampedPoints(world[static, :2], index, greys, size, rasterized=True, zorder=1))
    for mask, color, marker, zorder in (
        (unlabelled, _UNLABELLED_COLOR, "x", 2),
        (is_body, _BODY_COLOR, "o", 3),
    ):
        if mask.any():
            ax.add_artist(
                StampedPoints(
                    world[mask, :2],
                    np.zeros(int(mask.sum()), np.int64),
                    [color],
                    1.6 * size,
                    marker=marker,
                    linewidth=0.4,
                    rasterized=True,
                    zorder=zorder,
                )
            )
    ids = np.unique(instance[moving])
    ids = ids[ids > 0]
    shown = set(ids.tolist())
    if tracks is not None and frame is not None and len(tracks):
        shown |= set(tracks.loc[tracks["frame"] == frame, "track"].astype(int).tolist())
    for track in sorted(shown):
        color = track_color(track)
        mine = moving & (instance == track)
        if mine.any():
            ax.add_artist(
                StampedPoints(
                    world[mine, :2],
                    np.zeros(int(mine.sum()), np.int64),
                    [color],
                    max(2.5 * size, 2.0),
                    rasterized=True,
                    zorder=4,
                )
            )
        trail = None
        if tracks is not None and frame is not None:
            rows = tracks[(tracks["track"] == track) & (tracks["frame"] <= frame)]
            trail = rows.sort_values("frame")[["x", "y"]].to_numpy(float)
        if trail is not None and len(trail) > 1:
            ax.plot(trail[:, 0], trail[:, 1], "-", color=color, lw=1.2, alpha=0.9, zorder=5)
            ax.plot(trail[:-1, 0], trail[:-1, 1], ".", color=color, ms=3, zorder=5)
        where = world[mine, :2].mean(axis=0) if mine.any() else None
        if where is None and trail is not None and len(trail):
            where = trail[-1]
        if where is not None and np.all(np.abs(where - centre) <= range_):
            ax.text(
                where[0] + 0.012 * range_,
                where[1] + 0.012 * range_,
                str(track),
                color=color,
                fontsize=8,
                fontweight="bold",
                zorder=6,
                clip_on=True,
            )
    heading = pose[:2, 0] / max(np.linalg.norm(pose[:2, 0]), 1e-12)
    side = np.array([-heading[1], heading[0]])
    s = range_ / 60.0
    tip, back = centre + 1.6 * s * heading, centre - s * heading
    ax.fill(*np.array([tip, back + s * side, back - s * side]).T, color="black", zorder=7)
    ax.set_xlim(centre[0] - range_, centre[0] + range_)
    ax.set_ylim(centre[1] - range_, centre[1] + range_)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m] (the log's frame: the first sensor pose)")
    ax.set_ylabel("y [m]")
    legend = [
        Line2D([], [], ls="", marker="o", color=(0.55,) * 3, label="static world"),
        Line2D([], [], ls="", marker="o", color=track_color(1), label="moving: track id"),
        Line2D([], [], ls="", marker="x", color=_UNLABELLED_COLOR, label="unlabelled"),
    ]
    if body is not None:
        legend.append(Line2D([], [], ls="", marker="o", color=_BODY_COLOR, label="ego body"))
    legend.append(Line2D([], [], ls="", marker=">", color="black", label="sensor"))
    ax.legend(handles=legend, loc="upper left", fontsize=7, framealpha=0.85)
    if title is not None:
        ax.set_title(title, fontsize=9)
    return ax


def animate_log(pictures, *, seconds_per_frame=0.2, width=640):
    """One animated GIF of pictures (PNG bytes), in order, each ``seconds_per_frame``.

    Made with Pillow (no ffmpeg): each picture is scaled to ``width`` pixels and reduced
    to an adaptive 256-colour palette.

    Parameters
    ----------
    pictures : sequence of bytes
        PNG images.
    seconds_per_frame : float, default=0.2
    width : int, default=640

    Returns
    -------
    gif : bytes

    Examples
    --------
    >>> import io
    >>> from PIL import Image
    >>> from mmreg.plotting._log import animate_log
    >>> frames = []
    >>> for shade in (0, 255):
    ...     buffer = io.BytesIO()
    ...     Image.new("RGB", (20, 10), (shade, 0, 0)).save(buffer, format="PNG")
    ...     frames.append(buffer.getvalue())
    >>> gif = Image.open(io.BytesIO(animate_log(frames, width=10)))
    >>> gif.n_frames, gif.size
    (2, (10, 5))
    """
    import io

    from PIL import Image

    if not len(pictures):
        raise ValueError("animate_log needs at least one picture.")
    images = []
    for png in pictures:
        image = Image.open(io.BytesIO(png)).convert("RGB")
        height = max(1, round(image.height * width / image.width))
        image = image.resize((int(width), height), Image.Resampling.LANCZOS)
        images.append(image.convert("P", palette=Image.Palette.ADAPTIVE, colors=256))
    buffer = io.BytesIO()
    images[0].save(
        buffer,
        format="GIF",
        save_all=True,
        append_images=images[1:],
        duration=max(20, round(1000 * seconds_per_frame)),
        loop=0,
        optimize=False,
    )
    return buffer.getvalue()
