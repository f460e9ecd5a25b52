"""Two raw sweeps: a cluster must show its motion at a place the static world was not."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from mmreg import SweepRegistration
from mmreg.datasets import make_lidar_sweeps
from mmreg.metrics import objects_found
from mmreg.sweeps._icp import SurfaceNormals
from mmreg.sweeps._new_places import MIN_NEW_PLACE, new_place_shares


def _grid(x, z, y=0.0, step=0.05):
    """A wall in the plane ``y`` over the ranges ``x`` and ``z``, sampled every ``step``."""
    gx, gz = np.meshgrid(np.arange(*x, step), np.arange(*z, step), indexing="ij")
    return np.column_stack([gx.ravel(), np.full(gx.size, y), gz.ravel()])


def _target(sweep):
    tree = cKDTree(sweep)
    return sweep, tree, SurfaceNormals(sweep, tree, 10)


def test_a_strip_slid_down_a_wall_shows_no_new_place():
    # The second sweep sees the wall up to 2.5 m only (its top left the field of
    # view); the first sweep's top strip, which the ego motion leaves unexplained, is
    # slid down by 0.5 m by its own ICP: it lands on wall the first sweep held.
    wall = _grid((0.0, 6.0), (0.0, 2.5))
    strip = _grid((0.0, 6.0), (2.5, 3.0))
    box = _grid((2.0, 3.0), (0.0, 1.0), y=-2.0)  # an object moved by 0.5 m along x
    a = np.vstack([wall, strip, box])
    sweep = np.vstack([wall + [0.02, 0.0, 0.02], box + [0.5, 0.0, 0.0]])
    labels = np.repeat([0, 1, 2], [len(wall), len(strip), len(box)])
    translations = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -0.5], [0.5, 0.0, 0.0]])
    motions = (np.stack([np.eye(3)] * 3), translations)
    shares = new_place_shares(a, labels, motions, 0, 0.005, _target(sweep))
    assert shares[1] == 0.0
    # A face seen flat on that slides along itself is on its plane at rest: the ego
    # motion explains it, and it shows nothing either.
    assert shares[2] == 0.0


def test_a_box_moved_by_half_its_size_shows_new_places():
    # A 1 m box moved 0.5 m along x: its face x = 1 lands in free space.
    s = np.arange(0.0, 1.0, 0.04)
    face = np.array([[1.0, v, w] for v in s for w in s])
    side = np.array([[u, 0.0, w] for u in s for w in s])
    box = np.vstack([face, side])
    wall = np.array([[x, 3.0, z] for x in np.arange(-2, 4, 0.05) for z in np.arange(0, 2, 0.05)])
    a = np.vstack([wall, box])
    sweep = np.vstack([wall, box + [0.5, 0.0, 0.0]])
    labels = np.r_[np.zeros(len(wall), int), np.ones(len(box), int)]
    motions = (np.stack([np.eye(3)] * 2), np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0]]))
    shares = new_place_shares(a, labels, motions, 0, 0.005, _target(sweep))
    # The face (half the box) lands where nothing was; the side slides along itself.
    assert shares[1] > 2 * MIN_NEW_PLACE


@pytest.mark.parametrize(
    ("interval", "seed", "beams"),
    [(0.1, 3, 32), (0.5, 1, 32), (0.1, 0, 64), (0.5, 2, 64)],
)
def test_generated_streets_call_no_static_piece_moving(interval, seed, beams):
    # Pairs where a pole or a building's edge, seen by other rings from the second
    # place, was slid up or down by its own ICP and called moving; with 64 beams, a
    # single column of points (a pole, the edge of a building seen through a gap)
    # matched onto another one (a line of points is no evidence of motion).
    scene = make_lidar_sweeps(interval=interval, n_beams=beams, n_azimuths=1024, random_state=seed)
    est = SweepRegistration(random_state=0).fit(scene.a, sweep=scene.sweep)
    static = scene.labels == 0
    for cluster in np.flatnonzero(est.moving_):
        assert static[est.labels_ == cluster].mean() < 0.5
    cars = [k for k in range(1, scene.labels.max() + 1) if (scene.labels == k).sum() >= 50]
    assert objects_found(scene.labels, est.labels_, objects=cars, min_iou=0.5) == 1.0


def test_shares_do_not_depend_on_the_frame_of_the_sensor():
    # The sensor turned by 20 degrees and drove 3 m on between the sweeps (the static
    # world's motion): the box still shows new places, the strip slid down the wall
    # none, whichever frame each sweep is written in. (Each sweep jittered by a
    # millimetre: a grid's equidistant neighbours would leave the nearest to rounding.)
    rng = np.random.default_rng(0)
    wall = _grid((0.0, 6.0), (0.0, 2.5))
    strip = _grid((0.0, 6.0), (2.5, 3.0))
    box = _grid((2.0, 3.0), (0.0, 1.0), y=-2.0)
    face = _grid((0.0, 1.0), (0.0, 1.0))[:, [1, 0, 2]] + [3.0, -3.0, 0.0]  # across x
    a = np.vstack([wall, strip, box, face])
    a += rng.normal(0.0, 1e-3, a.shape)
    c, s = np.cos(np.radians(20)), np.sin(np.radians(20))
    ego = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.array([3.0, -1.0, 0.2])
    second = np.vstack([wall, box + [0.5, 0.0, 0.0], face + [0.5, 0.0, 0.0]])
    second += rng.normal(0.0, 1e-3, second.shape)
    sweep = second @ ego[0].T + ego[1]
    labels = np.repeat([0, 1, 2, 2], [len(wall), len(strip), len(box), len(face)])
    rotations = np.stack([ego[0]] * 3)
    moves = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -0.5], [0.5, 0.0, 0.0]])
    motions = (rotations, moves @ ego[0].T + ego[1])
    shares = new_place_shares(a, labels, motions, 0, 0.005, _target(sweep))
    still = new_place_shares(
        a, labels, (np.stack([np.eye(3)] * 3), moves), 0, 0.005, _target(second)
    )
    assert shares[1] == still[1] == 0.0
    assert shares[2] == still[2] > 2 * MIN_NEW_PLACE
