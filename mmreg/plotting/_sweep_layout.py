"""The numbers behind a bird's-eye picture of a LiDAR sweep, apart from any drawing.

What to crop, how large a point is drawn, the outline of an object, how much its motion
arrow is lengthened and how its speed is written: pure functions of arrays, so the
picture's choices can be tested without rendering it.
"""

import numpy as np

from mmreg._array.unique_rows import unique_rows

# Arrow lengths, as shares of the window's width: the typical arrow is aimed at _TARGET,
# none is longer than _MAX, and one shorter than _MIN on screen is drawn at _MIN (a slow
# object's arrow would otherwise be hidden under its own head).
ARROW_MIN = 0.04
ARROW_TARGET = 0.08
ARROW_MAX = 0.2
# Occupancy cells for the density of points [m]: about a LiDAR's spacing at 20 m.
_CELL = 0.25
# Marker diameters [typographic points]: never a speck, never a blot.
_MIN_DIAMETER = 0.9
_MAX_DIAMETER = 3.0
# An object's outline is never smaller than this across [m]: a pedestrian of 3 points
# still shows.
MIN_BOX = 1.0


def in_window(xy, center, half_width):
    """Which points lie in the square ``center +- half_width`` (the crop)."""
    xy = np.asarray(xy, dtype=float)[:, :2]
    return np.all(np.abs(xy - np.asarray(center, dtype=float)) <= half_width, axis=1)


def marker_diameter(xy, points_per_metre):
    """A marker diameter (typographic points) under which a LiDAR's surfaces read as surfaces.

    Each point is given the side of the square it shares out of the area the points cover
    (occupied 25 cm cells), so that dense returns touch and fill a surface, and sparse far
    rings are not drawn as lone specks; clipped to [0.9, 3] points.
    """
    xy = np.asarray(xy, dtype=float)[:, :2]
    if not len(xy):
        return _MIN_DIAMETER
    cells = unique_rows(np.floor(xy / _CELL).astype(np.int64))
    share = np.sqrt(len(cells) * _CELL**2 / len(xy))  # metres per point, across
    return float(np.clip(share * points_per_metre, _MIN_DIAMETER, _MAX_DIAMETER))


def oriented_box(xy, min_size=MIN_BOX):
    """The smallest-area rectangle around 2-D points, at least ``min_size`` across.

    Rotating calipers over the convex hull: the best rectangle has a side along one of the
    hull's edges. Fewer than three points, or points on a line, get the rectangle along
    their principal direction.

    Returns
    -------
    corners : ndarray of shape (4, 2)
        Counter-clockwise.
    """
    from scipy.spatial import ConvexHull, QhullError

    xy = np.asarray(xy, dtype=float)[:, :2]
    try:
        hull = xy[ConvexHull(xy).vertices]
        edges = np.diff(np.vstack([hull, hull[:1]]), axis=0)
        angles = np.arctan2(edges[:, 1], edges[:, 0])
    except (QhullError, ValueError):  # < 3 points, or all on a line
        hull = xy
        centred = xy - xy.mean(axis=0)
        direction = np.linalg.svd(centred, full_matrices=False)[2][0] if len(xy) > 1 else [1, 0]
        angles = np.array([np.arctan2(direction[1], direction[0])])
    best = None
    for angle in angles:
        c, s = np.cos(angle), np.sin(angle)
        frame = np.array([[c, s], [-s, c]])  # rows: the box's axes
        local = hull @ frame.T
        low, high = local.min(axis=0), local.max(axis=0)
        area = np.prod(np.maximum(high - low, min_size))
        if best is None or area < best[0]:
            best = (area, frame, low, high)
    _, frame, low, high = best
    middle, half = (low + high) / 2, np.maximum(high - low, min_size) / 2
    local = middle + half * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
    return local @ frame


def nice_floor(value):
    """The largest of 1, 2, 5 times a power of ten not above ``value`` (> 0)."""
    power = 10.0 ** np.floor(np.log10(value))
    for step in (5.0, 2.0, 1.0):
        if step * power <= value * (1 + 1e-9):
            return step * power
    return power  # pragma: no cover - step 1 always fits


def arrow_scale(displacements, window):
    """By how much to lengthen motion arrows so that they show in a window ``window`` wide.

    The median displacement is drawn about 8 % of the window long, the largest at most
    20 %, rounded down to 1, 2 or 5 times a power of ten (so the legend states a round
    factor). Arrows still shorter than 4 % of the window are drawn at that length (see
    :func:`arrow_lengths`).

    Returns
    -------
    scale : float
        1.0 when there is no displacement.
    """
    d = np.asarray(displacements, dtype=float)
    d = d[np.isfinite(d) & (d > 0)]
    if not len(d):
        return 1.0
    target = ARROW_TARGET * window / np.median(d)
    ceiling = ARROW_MAX * window / d.max()
    return nice_floor(min(target, ceiling))


def arrow_lengths(displacements, scale, window):
    """Drawn length of every arrow and whether it was lengthened to the minimum."""
    drawn = np.asarray(displacements, dtype=float) * scale
    short = drawn < ARROW_MIN * window
    return np.where(short, ARROW_MIN * window, drawn), short


def speed_text(displacement, interval=None):
    """``'8.4 m/s'`` with the seconds between the sweeps, else ``'0.84 m/frame'``."""
    if interval is not None:
        return f"{displacement / interval:.1f} m/s"
    return f"{displacement:.2f} m/frame"
