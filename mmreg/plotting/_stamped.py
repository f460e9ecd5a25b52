"""Many markers of one size in a few colours, stamped fast (a LiDAR sweep's 100k points).

A scatter draws every marker anew (Agg rasterises each disc: about half a second for a
sweep). :class:`StampedPoints` groups the points by colour and hands each group to the
renderer's ``draw_markers``, which rasterises the marker once and stamps it at every point:
a tenth of the time. Agg stamps at whole pixels; to keep a scatter's sub-pixel placement
(thin rings stay smooth lines, not dotted ones), the points are also grouped by their
offset within the pixel, in thirds, and each group's marker is shifted by that offset.
"""

import numpy as np
from matplotlib.artist import Artist, allow_rasterization
from matplotlib.markers import MarkerStyle
from matplotlib.path import Path
from matplotlib.transforms import Affine2D, IdentityTransform

# Sub-pixel offsets kept, per axis: a third of a pixel is as fine as the eye tells apart
# (and as a scatter draws it, up to a difference of 1.5 grey levels in 255 on average).
_PHASES = 3


class StampedPoints(Artist):
    """Points drawn as one marker each, of one size, by colour group (see the module).

    Parameters
    ----------
    xy : ndarray of shape (n, 2)
        In data coordinates (:meth:`matplotlib.axes.Axes.add_artist` gives the artist the
        axes' ``transData``).
    color_index : ndarray of shape (n,)
        The row of ``palette`` of every point.
    palette : array-like of shape (k, 3) or (k, 4)
        RGB(A) colours, drawn in this order: the points of a later colour are drawn over
        those of an earlier one (a painter's order by colour, e.g. greys by height).
    size : float
        Marker diameter in typographic points (``markersize`` of ``plot``).
    marker : str, default="o"
        A matplotlib marker; filled ones are filled in the colour, others stroked.
    linewidth : float, default=0.0
        Stroke width in points (0: a filled marker without an edge).
    **kwargs
        Artist properties (``zorder``, ``rasterized``, ...).

    Examples
    --------
    >>> import numpy as np
    >>> from matplotlib.figure import Figure
    >>> from mmreg.plotting._stamped import StampedPoints
    >>> ax = Figure().add_subplot()
    >>> xy = np.array([[0.2, 0.5], [0.4, 0.5], [0.6, 0.5]])
    >>> greys = [(0.7, 0.7, 0.7), (0.3, 0.3, 0.3)]  # the dark grey drawn over the light
    >>> points = ax.add_artist(StampedPoints(xy, [0, 1, 1], greys, 2.0))
    >>> points.get_offsets().shape
    (3, 2)
    """

    def __init__(self, xy, color_index, palette, size, *, marker="o", linewidth=0.0, **kwargs):
        super().__init__()
        self._xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        self._index = np.asarray(color_index, dtype=np.int64).reshape(len(self._xy))
        palette = np.asarray(palette, dtype=float).reshape(-1, np.shape(palette)[-1])
        if palette.shape[1] == 3:
            palette = np.hstack([palette, np.ones((len(palette), 1))])
        self._palette = palette
        self._size = float(size)
        self._marker = MarkerStyle(marker)
        self._linewidth = float(linewidth)
        self.set_in_layout(False)  # inside the axes: never widens the layout
        self._internal_update(kwargs)

    def get_offsets(self):
        """The points, as a scatter's ``get_offsets``."""
        return self._xy

    @allow_rasterization
    def draw(self, renderer):
        if not self.get_visible() or not len(self._xy):
            return
        pixels = self.get_transform().transform(self._xy)
        whole = np.round(pixels)
        # Agg stamps a marker at whole pixels: the rest of the position, in thirds, is
        # carried by the marker's own transform instead.
        phase = np.round((pixels - whole) * _PHASES).astype(np.int64) + _PHASES // 2 + 1
        side = _PHASES + 2
        key = (self._index * side + phase[:, 0]) * side + phase[:, 1]
        order = np.argsort(key, kind="stable")
        key = key[order]
        starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
        stops = np.r_[starts[1:], len(key)]

        gc = renderer.new_gc()
        self._set_gc_clip(gc)
        gc.set_alpha(self.get_alpha())
        gc.set_linewidth(self._linewidth)
        gc.set_url(self.get_url())
        gc.set_gid(self.get_gid())
        filled = self._marker.is_filled()
        diameter = renderer.points_to_pixels(self._size)
        shape = self._marker.get_transform() + Affine2D().scale(diameter)
        path = self._marker.get_path()
        shifted = {}
        renderer.open_group("stamped_points", self.get_gid())
        for start, stop in zip(starts, stops, strict=True):
            first = order[start]
            offset = (int(phase[first, 0]), int(phase[first, 1]))
            if offset not in shifted:
                centred = (np.array(offset) - _PHASES // 2 - 1) / _PHASES
                shifted[offset] = shape + Affine2D().translate(*centred)
            rgba = tuple(self._palette[self._index[first]])
            gc.set_foreground(rgba, isRGBA=True)
            renderer.draw_markers(
                gc,
                path,
                shifted[offset],
                Path(whole[order[start:stop]]),
                IdentityTransform(),
                rgba if filled else None,
            )
        renderer.close_group("stamped_points")
        gc.restore()
        self.stale = False
