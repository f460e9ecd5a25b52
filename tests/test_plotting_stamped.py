"""StampedPoints: a sweep's points stamped where they are, in the painter's order of colours."""

import io

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from mmreg.plotting._stamped import StampedPoints

# A 100 x 100 pixel canvas whose data units are pixels (x right, y up).
SIDE = 100


def _axes():
    fig = Figure(figsize=(1, 1), dpi=SIDE)
    ax = fig.add_axes([0, 0, 1, 1])
    ax.set_xlim(0, SIDE)
    ax.set_ylim(0, SIDE)
    ax.axis("off")
    return fig, ax


def _pixels(fig):
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].astype(float)


def _ink_centre(fig):
    """The centre of the ink (darkness-weighted), in data units (x right, y up)."""
    ink = 255.0 - _pixels(fig).mean(axis=2)
    rows, columns = np.indices(ink.shape)
    # Agg draws display coordinate (x, y) at the centre of pixel column x, row SIDE - y.
    x = (ink * columns).sum() / ink.sum()
    y = (ink * (SIDE - rows)).sum() / ink.sum()
    return np.array([x, y]), ink.sum()


@pytest.mark.parametrize("where", [(40.3, 60.0), (40.0, 60.7), (40.9, 60.1), (40.2, 60.2)])
def test_a_point_is_stamped_within_a_fifth_of_a_pixel_of_where_it_is(where):
    fig, ax = _axes()
    ax.add_artist(StampedPoints([where], [0], [(0.0, 0.0, 0.0)], 3.0))
    stamped, ink = _ink_centre(fig)
    fig, ax = _axes()  # matplotlib's own markers, at whole pixels
    ax.plot(*np.transpose([where]), "o", markersize=3.0, markeredgewidth=0, color="black")
    plotted, plotted_ink = _ink_centre(fig)
    np.testing.assert_allclose(stamped, where, atol=0.2)
    # A marker of the same size: the same ink (a disc of 3 points, 4.2 pixels across).
    assert ink == pytest.approx(plotted_ink, rel=0.02)
    off = np.abs(np.subtract(where, np.round(where)))
    assert np.all(np.abs(plotted - where) >= off - 0.05)  # what stamping at pixels costs


def test_later_colours_are_drawn_over_earlier_ones_whatever_the_row_order():
    xy = [[50.0, 50.0], [50.0, 50.0], [20.0, 20.0]]
    palette = [(1.0, 0.0, 0.0), (0.0, 0.0, 1.0)]
    for index in ([0, 1, 0], [1, 0, 0]):
        fig, ax = _axes()
        ax.add_artist(StampedPoints(xy, index, palette, 6.0))
        image = _pixels(fig)
        # The pixel of (50, 50) is covered by both points: the one drawn last is blue.
        np.testing.assert_array_equal(image[SIDE - 50, 50], [0.0, 0.0, 255.0])
        lone = (0.0, 0.0, 255.0) if index[2] == 1 else (255.0, 0.0, 0.0)
        np.testing.assert_array_equal(image[SIDE - 20, 20], lone)


def test_each_point_is_drawn_in_its_palette_colour():
    levels = np.array([[51, 102, 153], [230, 128, 26], [0, 179, 77]])  # 8-bit, no rounding
    palette = levels / 255
    xy = np.array([[20.0, 20.0], [50.0, 50.0], [80.0, 30.0], [20.0, 80.0]])
    index = np.array([2, 0, 1, 0])
    fig, ax = _axes()
    artist = ax.add_artist(StampedPoints(xy, index, palette, 6.0))
    image = _pixels(fig)
    for (x, y), k in zip(xy.astype(int), index, strict=True):
        np.testing.assert_array_equal(image[SIDE - y, x], levels[k])
    np.testing.assert_array_equal(artist.get_offsets(), xy)
    # Nothing else is drawn: white away from the points.
    assert np.all(image[SIDE - 65, 65] == 255)


def test_an_unfilled_marker_is_stroked_and_points_outside_the_axes_are_clipped():
    fig = Figure(figsize=(2, 1), dpi=SIDE)
    ax = fig.add_axes([0, 0, 0.5, 1])  # the left half of the canvas
    ax.set_xlim(0, SIDE)
    ax.set_ylim(0, SIDE)
    ax.axis("off")
    xy = [[50.0, 50.0], [150.0, 50.0]]  # the second right of the axes
    ax.add_artist(StampedPoints(xy, [0, 0], [(0.0, 0.0, 0.0)], 8.0, marker="x", linewidth=1.0))
    image = _pixels(fig).mean(axis=2)
    assert image[SIDE - 50, 50] == 0  # the centre of the cross, where its strokes meet
    assert image[SIDE - 50, 47] == 255 and image[SIDE - 47, 50] == 255  # a cross, not a disc
    assert np.all(image[:, SIDE:] == 255)  # nothing drawn outside the axes


def test_vector_output_holds_the_points_as_one_picture_when_rasterised():
    points = np.random.default_rng(0).uniform(0, SIDE, (500, 2))
    svg = {}
    for rasterized in (False, True):
        fig, ax = _axes()
        ax.add_artist(
            StampedPoints(points, np.zeros(500, int), [(0.3, 0.3, 0.3)], 2.0, rasterized=rasterized)
        )
        buffer = io.BytesIO()
        fig.savefig(buffer, format="svg")
        svg[rasterized] = buffer.getvalue().decode()
    assert svg[False].count("<use ") == 500 and "<image " not in svg[False]
    assert svg[True].count("<use ") == 0 and svg[True].count("<image ") == 1
