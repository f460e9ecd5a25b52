"""The picture of a result: the sweep view for LiDAR, the cluster view otherwise."""

import numpy as np

from mmreg._array.frames import FRAMES, detect_frame, looks_down_minus_z
from mmreg.plotting._clusters import plot_clusters
from mmreg.plotting._street import plot_street
from mmreg.plotting._style import VIEWS, _background_label, _check_labels, _check_points
from mmreg.plotting._sweep import SWEEP_RANGE, plot_sweep

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
    ego_body=None,
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
    ego_body : array-like of bool, default=None
        One per point: the ego vehicle's own body, drawn apart from the outliers in a
        LiDAR picture (see :func:`plot_sweep`).

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
            ego_body=ego_body,
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
