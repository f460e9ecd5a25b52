"""One colour scheme for every picture: the palette, the background, the legend, the views."""

import numpy as np

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
