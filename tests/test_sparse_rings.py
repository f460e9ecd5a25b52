"""A sparse sensor's rings: a point between two rings of the next sweep is no sign of
motion, and a ring's neighbourhood (a line) has no normal to call it level.

Where rings lie far apart (a VLP-16's 2 degrees), each ring crosses a surface along a
curve that moves with the sensor; the spacing along a ring (a few centimetres) is no
measure across it. A track's claim reads the gap to the next ring there
(:func:`mmreg.sweeps._explained.across_rings`), so a car passing a 16-beam sensor keeps
its track.
"""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from mmreg import SequenceRegistration
from mmreg.datasets import make_lidar_sequence
from mmreg.sweeps._explained import EXPLAINED_SPACINGS, across_rings, spacing_ratio
from mmreg.sweeps._icp import SurfaceNormals


@settings(max_examples=30, deadline=None)
@given(
    gap=st.floats(0.2, 0.28),
    between=st.floats(0.25, 0.45),
    scale=st.sampled_from([0.01, 1.0, 100.0]),
    turn=st.floats(0.0, 2 * np.pi),
)
def test_a_point_between_two_rings_is_explained_and_one_beside_a_pole_is_not(
    gap, between, scale, turn
):
    # Two level rings on a wall, sampled every 2 cm, and an upright pole; any units, any
    # heading. A point a share ``between`` of the gap above the lower ring lies 2.5-6.3
    # spacings from it (the spacing along the ring), but within half the gap.
    x = np.arange(0.0, 3.0, 0.02)
    rings = np.concatenate([np.c_[x, 0 * x, 0 * x], np.c_[x, 0 * x, 0 * x + gap]])
    pole = np.c_[0 * x + 6.0, 0 * x, x]
    c, s = np.cos(turn), np.sin(turn)
    heading = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    sweep = np.vstack([rings, pole]) @ heading.T * scale
    points = np.array([[1.51, 0.0, between * gap], [6.0 + between * gap, 0.0, 1.51]])
    points = points @ heading.T * scale
    tree = cKDTree(sweep)
    normals = SurfaceNormals(sweep, tree, 10)
    answers = spacing_ratio(points, tree, sweep, normals)
    assert np.all(answers[0] > EXPLAINED_SPACINGS)
    ratio, nearest, _ = across_rings(points, answers, tree, sweep, normals, np.eye(3)[2])
    np.testing.assert_array_equal(nearest, answers[1])
    assert ratio[0] < 1.0  # within half the gap: between the rings
    assert ratio[1] == answers[0][1]  # an upright line: no next ring beside it


def test_a_car_passing_a_16_beam_sensor_keeps_its_track():
    # Car 3 of this log drives past the sensor for 15 frames. Read along the rings, its
    # claims failed until the last four frames: none of its points moved in frames 0-10.
    log = make_lidar_sequence(20, frame_rate=10.0, n_beams=16, n_azimuths=1024, random_state=1)
    est = SequenceRegistration(random_state=0).fit(log.frames, times=log.times)
    shares = []
    for k in range(11):
        car = (np.asarray(log.labels[k]) == 3) & np.asarray(log.moving[k])
        if car.sum() >= 50:  # seen: 50 points or more
            shares.append(est.moving_[k][car].mean())
    assert len(shares) >= 5
    # Most of its points move in all but the first of those frames (0.65-0.76 of them).
    assert sum(share > 0.5 for share in shares) >= len(shares) - 1
    # No other point moves where nothing does.
    for k in range(len(log.frames)):
        still = ~np.asarray(log.moving[k])
        assert est.moving_[k][still].mean() < 0.01
