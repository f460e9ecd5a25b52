"""What a sweep could see: its returns as a range image, and which places it had hidden.

A point that the second sweep does not explain is evidence that it moved only where that
sweep could have seen it: behind a car that drove in front of it, a static wall is simply
not there to be seen. :class:`RangeView` keeps the nearest return in every direction (a
cell of the sweep's own angular spacing, from its sensor at the origin); a place is
hidden when a return in its direction is clearly nearer than it.
"""

import numpy as np

from mmreg._array.neighbors import lookup_tree

__all__ = ["RangeView"]

# Directions sampled for the sweep's angular spacing.
_SAMPLE = 4000
# A cell is this many angular spacings wide.
_CELLS_PER_SPACING = 2.0


def _angles(points):
    horizontal = np.hypot(points[:, 0], points[:, 1])
    return (
        np.arctan2(points[:, 1], points[:, 0]),
        np.arctan2(points[:, 2], horizontal),
        np.linalg.norm(points, axis=1),
    )


class RangeView:
    """The nearest return of a sweep in every direction, from its sensor at the origin.

    Parameters
    ----------
    sweep : ndarray of shape (m, 3)
        In its sensor's frame.

    Examples
    --------
    A wall 10 m ahead; a place 12 m ahead behind it is hidden, one 8 m ahead is not.

    >>> import numpy as np
    >>> from mmreg.tracking._visibility import RangeView
    >>> y, z = np.meshgrid(np.linspace(-3, 3, 121), np.linspace(-1, 1, 41))
    >>> wall = np.stack([np.full(y.size, 10.0), y.ravel(), z.ravel()], axis=1)
    >>> view = RangeView(wall)
    >>> view.hidden(np.array([[12.0, 0.1, 0.0], [8.0, 0.1, 0.0]]), margin=0.5).tolist()
    [True, False]
    """

    def __init__(self, sweep):
        azimuth, elevation, distance = _angles(sweep)
        rng = np.random.default_rng(0)
        sample = rng.choice(len(sweep), min(_SAMPLE, len(sweep)), replace=False)
        flat = np.column_stack([azimuth * np.cos(elevation), elevation])
        gap, _ = lookup_tree(flat).query(flat[sample], k=2)  # distances alone are read
        spacing = float(np.median(gap[:, 1]))
        self.cell = max(_CELLS_PER_SPACING * spacing, 1e-6)
        self.n_azimuth = int(np.ceil(2 * np.pi / self.cell)) + 1
        keys = self._keys(azimuth, elevation)
        order = np.argsort(keys, kind="stable")
        keys, distance = keys[order], distance[order]
        starts = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
        self.keys = keys[starts]
        self.nearest = np.minimum.reduceat(distance, starts)

    def _keys(self, azimuth, elevation, d_azimuth=0, d_elevation=0):
        column = np.floor((azimuth + np.pi) / self.cell).astype(np.int64) + d_azimuth
        column %= self.n_azimuth
        row = np.floor((elevation + np.pi / 2) / self.cell).astype(np.int64) + d_elevation
        return row * self.n_azimuth + column

    def nearest_return(self, points):
        """The nearest return in each point's direction and the cells around it (inf
        where the sweep has none)."""
        azimuth, elevation, _ = _angles(points)
        best = np.full(len(points), np.inf)
        for d_azimuth in (-1, 0, 1):
            for d_elevation in (-1, 0, 1):
                keys = self._keys(azimuth, elevation, d_azimuth, d_elevation)
                at = np.searchsorted(self.keys, keys)
                found = at < len(self.keys)
                found[found] &= self.keys[at[found]] == keys[found]
                best[found] = np.minimum(best[found], self.nearest[at[found]])
        return best

    def hidden(self, points, margin):
        """Whether a return of the sweep lies more than ``margin`` nearer than each point,
        in its direction: the sweep could not have seen it."""
        return self.nearest_return(points) < np.linalg.norm(points, axis=1) - margin
