"""A track's claim weighs its evidence against its counter-evidence one for one.

Near where a track should be lie the object and whatever stands beside it. The object's
motion explains the object and leaves the static things beside it unexplained (their
counter-evidence); the ego motion does the reverse. The claim stands when its evidence
exceeds its counter-evidence by ``min_evidence`` points. Weighed two for one, a car
passing a wall or a pole half its size lost its claim, and on a generated 10 Hz log a
car passing beside the sensor, whose side slides along itself, lost its track for the
rest of the log: one scan ring of that side fell between the next sweep's rings and
counted against its true motion.
"""

import numpy as np
from _surfaces import grid
from scipy.spatial import cKDTree

from mmreg.sweeps._icp import SurfaceNormals
from mmreg.tracking._evidence import track_claim

_SHIFT = 1.0  # m, along x


def _scene():
    """A floor, an upright face that moves by ``_SHIFT`` along its normal, and a static
    wall beside where it goes: 120 face points, 63 wall points."""
    floor = grid([-3.0, -3.0, 0.0], [8.0, 3.0, 0.0])
    face = grid([0.0, -0.55, 0.3], [0.0, 0.55, 1.2])
    wall = grid([2.5, 0.7, 0.3], [2.5, 1.3, 1.1])
    first = np.vstack([floor, face, wall])
    second = np.vstack([floor, face + [_SHIFT, 0.0, 0.0], wall])
    rows = np.arange(len(floor), len(first))
    face_rows, wall_rows = rows[: len(face)], rows[len(face) :]
    return first, second, face_rows, wall_rows


def _claim(first, second, near, tight, min_evidence):
    tree = cKDTree(second)
    start = np.eye(4)
    start[0, 3] = _SHIFT
    return track_claim(
        first,
        near,
        tight,
        [start],
        np.eye(4),
        (second, tree, SurfaceNormals(second, tree, 10)),
        0.002,
        max_distance=1.0,
        min_evidence=min_evidence,
    )


def test_a_moving_face_beside_a_static_wall_is_claimed():
    first, second, face, wall = _scene()
    near = np.concatenate([face, wall])
    # Evidence 120, counter-evidence 63: 57 more, against the 20 needed (two for one: -6).
    claim = _claim(first, second, near, face, min_evidence=20)
    assert claim is not None
    assert abs(claim.motion[0, 3] - _SHIFT) < 0.01
    np.testing.assert_array_equal(claim.rows, face)
    assert claim.evidence == len(face) - len(wall)


def test_counter_evidence_still_outweighs_too_little_evidence():
    first, second, face, wall = _scene()
    # Only the face's top row moves the claim (12 points) beside the whole wall (63).
    top = face[first[face, 2] > 1.15]
    claim = _claim(first, second, np.concatenate([top, wall]), top, min_evidence=6)
    assert claim is None
