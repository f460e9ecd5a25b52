"""mmreg.sweeps._ego_motion.ego_motion: two raw sweeps' rigid motion, from the identity."""

import functools
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
from _surfaces import area_weighted_box
from hypothesis import given
from hypothesis import strategies as st

from mmreg.sweeps._ego_motion import ego_motion, layout_origin
from mmreg.sweeps._icp import rotation_vectors_to_matrices

ROOT = Path(__file__).resolve().parent.parent
SCALE = 5.0  # metres, LiDAR's tau

# A courtyard (metres, z up) on a 40 x 30 m ground (z = 0): four walls of different
# heights, two parked cars, a kiosk, a pole and a low building; ``(centre, size)`` of
# axis-aligned boxes.
GROUND = (40.0, 30.0)
BOXES = [
    ((0.0, 16.0, 5.0), (40.0, 2.0, 10.0)),
    ((0.0, -16.0, 4.0), (40.0, 2.0, 8.0)),
    ((21.0, 0.0, 6.0), (2.0, 30.0, 12.0)),
    ((-21.0, 0.0, 3.0), (2.0, 30.0, 6.0)),
    ((6.0, 5.0, 1.0), (4.5, 1.8, 2.0)),
    ((-8.0, -5.0, 1.0), (4.5, 1.8, 2.0)),
    ((12.0, -8.0, 2.5), (5.0, 4.0, 5.0)),
    ((-13.0, 9.0, 1.5), (3.0, 6.0, 3.0)),
    ((3.0, -10.0, 3.0), (0.4, 0.4, 6.0)),
]


def courtyard(n, rng):
    """``n`` points drawn independently on the courtyard's surfaces."""
    area = [GROUND[0] * GROUND[1]]
    area += [2 * (s[0] * s[1] + s[1] * s[2] + s[0] * s[2]) for _, s in BOXES]
    counts = rng.multinomial(n, np.array(area) / np.sum(area))
    ground = rng.uniform(-0.5, 0.5, (counts[0], 3)) * [*GROUND, 0.0]
    boxes = [area_weighted_box(c, s, k, rng) for (c, s), k in zip(BOXES, counts[1:], strict=True)]
    return np.vstack([ground, *boxes])


def sweeps(rotation_vector, translation, n=20000, m=25000, random_state=0):
    """Two independent samplings; the second seen after the motion (noiseless)."""
    rng = np.random.default_rng(random_state)
    rotation = rotation_vectors_to_matrices(np.array([rotation_vector]))[0]
    a = courtyard(n, rng)
    sweep = courtyard(m, rng) @ rotation.T + translation
    return a, sweep, rotation, np.asarray(translation, dtype=float)


def angle_deg(r1, r2):
    return np.degrees(np.arccos(np.clip((np.trace(r1 @ r2.T) - 1) / 2, -1.0, 1.0)))


@pytest.mark.parametrize(
    "rotation_vector, translation",
    [
        # 0.1 s at 10 m/s: 1 m on, 1 degree of yaw.
        ([0.0, 0.0, np.deg2rad(1.0)], [-1.0, 0.05, 0.0]),
        # 0.5 s: 4.5 m on, 4 degrees of yaw, a degree of roll and pitch.
        ([np.deg2rad(1.0), np.deg2rad(-1.0), np.deg2rad(4.0)], [-4.5, 0.6, 0.1]),
    ],
)
def test_recovers_small_and_large_motions_from_the_identity(rotation_vector, translation):
    a, sweep, rotation, translation = sweeps(rotation_vector, translation)
    found_rotation, found_translation, sigma = ego_motion(a, sweep, scale=SCALE)
    # Independent samplings of planes: within a fiftieth of the 0.25 m voxels.
    assert angle_deg(found_rotation, rotation) < 0.02
    assert np.linalg.norm(found_translation - translation) < 0.005
    assert 0 <= sigma < 0.005


def test_a_moved_copy_is_recovered_to_the_convergence_tolerance():
    rng = np.random.default_rng(1)
    a = courtyard(20000, rng)
    rotation = rotation_vectors_to_matrices(np.array([[0.01, 0.0, 0.05]]))[0]
    translation = np.array([3.0, -1.0, 0.2])
    sweep = a[rng.permutation(len(a))] @ rotation.T + translation
    found_rotation, found_translation, sigma = ego_motion(a, sweep, scale=SCALE)
    assert angle_deg(found_rotation, rotation) < 0.005
    assert np.linalg.norm(found_translation - translation) < 0.001
    assert sigma < 0.001


def test_ray_cast_street_sweeps_half_a_second_apart():
    """Raw LiDAR sweeps of a street (5 m and 4 degrees further on, cars driving)."""
    path = ROOT / "benchmarks" / "_lidar_street.py"
    spec = importlib.util.spec_from_file_location("_lidar_street", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["_lidar_street"] = module
    spec.loader.exec_module(module)
    pair = module.street_sweeps(dt=0.5, speed=10.0, yaw_rate=8.0, random_state=0)
    found_rotation, found_translation, _ = ego_motion(pair.a, pair.sweep, scale=SCALE)
    assert angle_deg(found_rotation, pair.rotation) < 0.3
    assert np.linalg.norm(found_translation - pair.translation) < 0.02


@functools.cache
def _unscaled():
    a, sweep, _, _ = sweeps([0.0, 0.01, 0.03], [-2.0, 0.5, 0.0], n=5000, m=6000)
    return a, sweep, ego_motion(a, sweep, scale=SCALE, max_displacement=6.0)


@given(st.floats(min_value=-3.0, max_value=3.0))
def test_scaled_points_and_lengths_give_the_same_motion(log10_scale):
    s = 10.0**log10_scale
    a, sweep, (rotation, translation, sigma) = _unscaled()
    scaled = ego_motion(a * s, sweep * s, scale=SCALE * s, max_displacement=6.0 * s)
    np.testing.assert_allclose(scaled[0], rotation, rtol=0, atol=1e-9)
    np.testing.assert_allclose(scaled[1] / s, translation, rtol=0, atol=1e-9)
    np.testing.assert_allclose(scaled[2] / s, sigma, rtol=1e-6)


def test_order_and_sizes_of_the_sweeps_do_not_matter():
    a, sweep, _, _ = sweeps([0.0, 0.0, 0.03], [-2.0, 0.5, 0.0], n=5000, m=9000)
    rotation, translation, _ = ego_motion(a, sweep, scale=SCALE)
    rng = np.random.default_rng(2)
    shuffled = ego_motion(a[rng.permutation(len(a))], sweep[rng.permutation(len(sweep))], scale=5)
    np.testing.assert_allclose(shuffled[0], rotation, atol=1e-9)
    np.testing.assert_allclose(shuffled[1], translation, atol=1e-9)


@given(
    st.floats(min_value=-3.0, max_value=3.0),
    st.lists(st.floats(min_value=-1e6, max_value=1e6), min_size=3, max_size=3),
)
def test_any_two_layouts_are_one_voxel_grid(log10_scale, offset):
    """Two point sets anywhere are laid out on one grid (their origins a whole number of
    fine voxels apart), near their points, in proportion to the scale."""
    scale = 10.0**log10_scale
    rng = np.random.default_rng(0)
    first = rng.uniform(-50, 50, (200, 3)) * scale
    second = first + np.asarray(offset) * scale
    o1, o2 = layout_origin(first, scale), layout_origin(second, scale)
    voxels = (o2 - o1) / (scale / 20)
    np.testing.assert_allclose(voxels, np.round(voxels), rtol=0, atol=1e-6 * np.abs(voxels).max())
    assert np.all(np.abs(o2 - second.mean(axis=0)) <= 26 * scale)
    np.testing.assert_allclose(layout_origin(first * 2, scale * 2), 2 * o1, rtol=1e-12, atol=0)


def test_sweeps_far_from_their_frame_s_origin_give_the_same_motion():
    """A map frame's coordinates (tens of kilometres off): the motion found there puts
    the points where the sensor frame's does, and where the truth does (both within a
    millimetre; the voxels fall elsewhere on the surfaces)."""
    a, sweep, true_rotation, true_translation = sweeps([0.0, 0.01, 0.03], [-2.0, 0.5, 0.0])
    rotation, translation, _ = ego_motion(a, sweep, scale=SCALE)
    far = np.array([31_415.9, -27_182.8, 141.4])
    found_rotation, found_translation, _ = ego_motion(a + far, sweep + far, scale=SCALE)
    # Where each motion puts the points (far off, a turn's error is a shift).
    moved = (a + far) @ found_rotation.T + found_translation - far
    near = a @ rotation.T + translation
    assert np.linalg.norm(moved - near, axis=1).max() < 0.005
    truth = a @ true_rotation.T + true_translation
    assert np.linalg.norm(moved - truth, axis=1).max() < 0.005


def test_the_caller_s_sweep_normals_give_the_same_answer():
    from scipy.spatial import cKDTree

    from mmreg.sweeps._icp import SurfaceNormals

    a, sweep, _, _ = sweeps([0.0, 0.0, 0.03], [-2.0, 0.5, 0.0], n=5000, m=6000)
    alone = ego_motion(a, sweep, scale=SCALE)
    given_normals = SurfaceNormals(sweep, cKDTree(sweep), 10)
    reused = ego_motion(a, sweep, scale=SCALE, sweep_normals=given_normals)
    np.testing.assert_array_equal(reused[0], alone[0])
    np.testing.assert_array_equal(reused[1], alone[1])
    assert reused[2] == alone[2]
    with pytest.raises(ValueError, match="sweep_normals must be None or the SurfaceNormals"):
        ego_motion(sweep, a, scale=SCALE, sweep_normals=given_normals)


def test_residual_scale_is_the_first_sweep_s_noise():
    rng = np.random.default_rng(3)
    a = courtyard(20000, rng)
    sweep = courtyard(200000, rng)
    noise = 0.02
    _, _, sigma = ego_motion(a + rng.normal(0.0, noise, a.shape), sweep, scale=SCALE)
    assert 0.8 * noise < sigma < 1.2 * noise


@pytest.mark.parametrize(
    "points, sweep, kwargs, message",
    [
        (np.zeros((50, 2)), None, {}, r"points must be an array of shape \(n, 3\)"),
        (None, np.zeros(30), {}, r"sweep must be an array of shape \(n, 3\)"),
        (np.full((50, 3), np.nan), None, {}, "points has NaN or infinite"),
        (np.zeros((5, 3)), None, {}, "points needs at least 10 points"),
        (np.array([["a"] * 3] * 20), None, {}, "points must hold real numbers"),
        (None, None, {"scale": 0.0}, "scale must be a positive finite length"),
        (None, None, {"scale": np.nan}, "scale must be a positive finite length"),
        (None, None, {"scale": True}, "scale must be a positive finite length"),
        (None, None, {"max_displacement": -1.0}, "max_displacement must be a positive"),
        (None, None, {"max_iter": 0}, "max_iter must be a positive integer"),
        (None, None, {"workers": 1.5}, "workers must be a positive integer"),
        (None, None, {"scale": 1e-4}, "is scale=0.0001 in the points' units"),
        (None, None, {"scale": 1e4}, "voxels of scale / 20"),
    ],
)
def test_bad_input_is_refused(points, sweep, kwargs, message):
    a, b, _, _ = sweeps([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], n=2000, m=2000)
    kwargs = {"scale": SCALE, **kwargs}
    with pytest.raises(ValueError, match=message):
        ego_motion(a if points is None else points, b if sweep is None else sweep, **kwargs)


def test_robust_stage_is_not_pulled_by_moving_objects():
    """Boxes of which two drive off (a third of the surface): the robust stage's kernel
    leaves them out (GICP alone is several centimetres off)."""
    rng = np.random.default_rng(2)
    boxes = [((0.0, 0.0, 0.0), (12.0, 8.0, 0.4)), ((-4.0, 3.0, 1.5), (3.0, 1.0, 2.6))]
    boxes += [((4.0, -2.0, 1.2), (1.0, 2.5, 2.0))]
    cars = [((0.0, -1.0, 0.9), (4.0, 1.8, 1.4)), ((3.0, 2.5, 0.9), (1.8, 4.0, 1.4))]
    ego = rotation_vectors_to_matrices(np.array([[0.0, 0.0, 0.01]]))[0], np.array([0.3, 0, 0])
    car_motions = [(np.eye(3), np.array([1.0, 0.2, 0.0])), (np.eye(3), np.array([0.1, 0.9, 0.0]))]

    def sample(k):
        static = [area_weighted_box(c, s, 3000, rng) for c, s in boxes]
        moving = [area_weighted_box(c, s, 2000, rng) for c, s in cars]
        if k:
            static = [p @ ego[0].T + ego[1] for p in static]
            moving = [
                (p @ R.T + t) @ ego[0].T + ego[1]
                for p, (R, t) in zip(moving, car_motions, strict=True)
            ]
        return np.vstack(static + moving)

    a, sweep = sample(0), sample(1)
    rotation, translation, _ = ego_motion(a, sweep, scale=2.0, robust=True)
    assert angle_deg(rotation, ego[0]) < 0.01
    assert np.linalg.norm(translation - ego[1]) < 1e-3
