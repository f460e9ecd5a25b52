"""Level surfaces are no evidence of a road user's motion, and the ground is not its.

A level motion slides a level surface along itself: its points say nothing of where it
went. A motion that keeps a sweep's ground rings where the sensor is explains them better
than the ego motion does, which lays them between the next sweep's rings; on a nuScenes
log such a ghost drove with the sensor for four frames. And the ground that the ground
segmentation left around a walker's feet joined its track (76-102 points a frame beside
its 50-60), until the track was mostly ground.
"""

import numpy as np
import pytest
from _surfaces import grid
from scipy.spatial import cKDTree

from mmreg.sweeps._icp import SurfaceNormals
from mmreg.tracking._evidence import track_claim
from mmreg.tracking._log import LogFrame, _off_the_ground

_UP = np.array([0.0, 0.0, 1.0])
_SHIFT = 1.5  # along x, m


def _upright_faces(low, high, step):
    """The four upright faces of a box, sampled every ``step``."""
    (x0, y0, z0), (x1, y1, z1) = low, high
    faces = [grid([x, y0, z0], [x, y1, z1], step) for x in (x0, x1)]
    faces += [grid([x0 + step, y, z0], [x1 - step, y, z1], step) for y in (y0, y1)]
    return np.vstack(faces)


def _claim(thing, rng, surface):
    """The claim of a shift by ``_SHIFT`` along x of ``thing`` above a floor, with or
    without the first sweep's normals."""
    floor = grid([-3.0, -3.0, 0.0], [6.0, 3.0, 0.0], 0.1)
    floor[:, 2] += rng.normal(0.0, 0.002, len(floor))
    first = np.vstack([floor, thing])
    second = np.vstack([floor, thing + [_SHIFT, 0.0, 0.0]])
    tree = cKDTree(second)
    target = (second, tree, SurfaceNormals(second, tree, 10))
    start = np.eye(4)
    start[0, 3] = _SHIFT
    near = np.arange(len(floor), len(first))
    return len(floor), track_claim(
        first,
        near,
        near,
        [start],
        np.eye(4),
        target,
        0.002,
        max_distance=1.0,
        min_evidence=20,
        up=_UP,
        surface=SurfaceNormals(first, cKDTree(first), 10) if surface else None,
    )


@pytest.mark.parametrize("seed", range(3))
def test_a_level_plate_sliding_along_itself_is_no_evidence(seed):
    # A plate 0.4 m above the floor moves 1.5 m along itself: only its level points
    # say so, 0.4 m (four spacings) above the floor where it was.
    plate = grid([0.0, 0.0, 0.4], [1.0, 1.0, 0.4], 0.1)
    _, claim = _claim(plate, np.random.default_rng(seed), surface=False)
    assert claim is not None and len(claim.shown) == len(plate)  # without the normals
    _, claim = _claim(plate, np.random.default_rng(seed), surface=True)
    assert claim is None


@pytest.mark.parametrize("seed", range(3))
def test_an_upright_body_is_still_claimed(seed):
    # The same shift of a walker-sized block's upright faces.
    walker = _upright_faces([0.0, 0.0, 0.2], [0.4, 0.4, 1.8], 0.1)
    n_floor, claim = _claim(walker, np.random.default_rng(seed), surface=True)
    assert claim is not None
    assert np.all(claim.rows >= n_floor)
    np.testing.assert_allclose(claim.motion[:3, 3], [_SHIFT, 0.0, 0.0], atol=1e-6)


def _frame(points):
    frame = LogFrame(index=0, points=points, valid=np.ones(len(points), bool), time=0.0)
    frame.up = _UP
    return frame


def test_the_ground_beneath_a_walker_is_left_out():
    ground = grid([-1.0, -1.0, 0.0], [1.4, 1.4, 0.0], 0.1)
    walker = _upright_faces([0.0, 0.0, 0.1], [0.4, 0.4, 1.7], 0.1)
    # A bonnet: a level part of the body 0.6 m above its lowest evidence.
    bonnet = grid([-1.0, 0.0, 0.7], [-0.5, 0.4, 0.7], 0.1)
    points = np.vstack([ground, walker, bonnet])
    rows = np.arange(len(points))
    is_walker = (rows >= len(ground)) & (rows < len(ground) + len(walker))
    # Its evidence: the walker's faces and a few ground points its shadow hid.
    shown = np.r_[rows[is_walker], rows[: len(ground) : 40]]
    kept = _off_the_ground(_frame(points), rows, shown, margin=0.25)
    assert set(kept.tolist()) == set(rows[len(ground) :].tolist())


def test_nothing_is_left_out_without_the_vertical_or_upright_evidence():
    ground = grid([-1.0, -1.0, 0.0], [1.0, 1.0, 0.0], 0.1)
    rows = np.arange(len(ground))
    frame = _frame(ground)
    # Only level evidence: nothing says where the body stands.
    assert _off_the_ground(frame, rows, rows, margin=0.25).tolist() == rows.tolist()
    frame.up = None
    assert _off_the_ground(frame, rows, rows[:10], margin=0.25).tolist() == rows.tolist()
