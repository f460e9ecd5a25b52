"""Tests of the KITTI-like street scene generator."""

import numpy as np
import pytest

from mmreg.datasets._camera import project
from mmreg.datasets._street import SURFACE_KINDS, make_street

SMALL = {"image_size": (94, 310), "n_points": 3000}
CLEAN = {"corruption": False, "sam_masks": False}


@pytest.fixture(scope="module")
def clean_scene():
    return make_street(n_cars=6, n_moving=3, **SMALL, **CLEAN, random_state=0)


def test_counts_and_shapes(clean_scene):
    scene = clean_scene
    n = SMALL["n_points"]
    assert scene.X.shape == (n, 6)
    assert scene.rotations.shape == (4, 3, 3)
    assert scene.translations.shape == (4, 3)
    np.testing.assert_array_equal(scene.moving, [True, True, True, False, False, False])
    assert scene.labels.min() >= 0 and scene.labels.max() <= 3
    assert scene.instance_labels.min() >= 0 and scene.instance_labels.max() <= 6
    assert set(scene.surface_kinds) <= set(SURFACE_KINDS)
    assert np.sum(scene.surface_kinds == "car") == 6
    assert scene.depth_image.shape == scene.instance_image.shape == (94, 310)
    assert len(np.unique(scene.pixels, axis=0)) == n
    assert scene.masks is None


def test_default_scene_is_kitti_like():
    scene = make_street(**CLEAN, random_state=1)
    assert scene.X.shape == (16384, 6)
    assert scene.depth_image.shape == (375, 1242)
    np.testing.assert_allclose(
        scene.camera.K, [[721.5377, 0, 609.5593], [0, 721.5377, 172.854], [0, 0, 1]], atol=1e-9
    )
    assert len(scene.moving) == 5 and 1 <= scene.moving.sum() <= 4
    # Depth is capped at 35 m; the sky and the far street are invalid pixels.
    assert scene.a[:, 2].max() <= 35.0
    valid = scene.instance_image >= 0
    assert 0.3 < valid.mean() < 0.99
    assert not valid[0].all()  # the top row sees sky or far surfaces
    # The road is 1.65 m below the camera, flat.
    road = scene.surface_kinds[scene.surface_labels] == "road"
    assert road.sum() > 1000
    np.testing.assert_allclose(scene.a[road, 1], 1.65, atol=1e-4)


def test_parked_cars_share_the_background_motion(clean_scene):
    scene = clean_scene
    car = scene.instance_labels > 0
    moving_point = car & scene.moving[np.maximum(scene.instance_labels - 1, 0)]
    parked_point = car & ~moving_point
    assert parked_point.any() and moving_point.any()
    np.testing.assert_array_equal(scene.labels[parked_point], 0)
    np.testing.assert_array_equal(scene.labels[~car], 0)
    # A moving car's motion group is its instance id.
    np.testing.assert_array_equal(scene.labels[moving_point], scene.instance_labels[moving_point])


def test_motions_reproduce_clean_flow_exactly(clean_scene):
    scene = clean_scene
    R, t = scene.rotations[scene.labels], scene.translations[scene.labels]
    moved = np.einsum("nij,nj->ni", R, scene.a) + t
    np.testing.assert_allclose(moved, scene.a + scene.flow_clean, rtol=0, atol=1e-9)
    np.testing.assert_allclose(scene.b, scene.a + scene.flow_clean, rtol=0, atol=1e-9)


def test_background_moves_by_the_inverse_ego_motion(clean_scene):
    scene = clean_scene
    ego_rotation, ego_translation = scene.ego_motion
    np.testing.assert_allclose(scene.rotations[0], ego_rotation.T, atol=1e-12)
    np.testing.assert_allclose(scene.translations[0], -ego_rotation.T @ ego_translation)
    # The camera drives forward 0.5-1.2 m: the world comes towards it, and turns only
    # about the vertical axis.
    static = scene.labels == 0
    forward = -scene.flow_clean[static, 2]
    assert 0.4 < np.median(forward) < 1.3
    np.testing.assert_allclose(scene.flow_clean[static, 1], 0.0, atol=1e-9)
    # The ego speed is 5-12 m/s (KITTI records at 10 Hz).
    world_speed = np.linalg.norm(ego_translation) / 0.1
    assert 5 - 1e-9 <= world_speed <= 12 + 1e-9


def test_cars_are_car_sized(clean_scene):
    scene = clean_scene
    for car in np.unique(scene.instance_labels[scene.instance_labels > 0]):
        points = scene.a[scene.instance_labels == car]
        # On the road (y = 1.65 down from the camera), at most 1.6 m high, about 4 m long.
        assert points[:, 1].max() <= 1.65 + 1e-4
        assert points[:, 1].min() >= 1.65 - 1.6 - 1e-4
        assert np.ptp(points[:, [0, 2]], axis=0).max() < 5.0


def test_points_lie_on_visible_surfaces(clean_scene):
    scene = clean_scene
    cols, rows = scene.pixels.T
    np.testing.assert_array_equal(scene.a[:, 2], scene.depth_image[rows, cols])
    np.testing.assert_allclose(project(scene.a, scene.camera), scene.pixels, atol=1e-9)
    np.testing.assert_array_equal(scene.instance_labels, scene.instance_image[rows, cols])
    np.testing.assert_array_equal(scene.surface_labels, scene.surface_image[rows, cols])
    assert np.all(scene.depth_image[scene.surface_image < 0] == 0)


def test_density_falls_with_distance():
    # On the road (a plane below the camera), points per m^2 fall with distance: count
    # the points of the camera's lane (|x| < 1.5 m, no cars) in 4 m stretches.
    scene = make_street(n_cars=0, n_points=20000, **CLEAN, random_state=2)
    road = scene.surface_kinds[scene.surface_labels] == "road"
    x, z = scene.a[:, 0], scene.a[:, 2]
    lane = road & (np.abs(x) < 1.5)
    near = np.sum(lane & (z > 6) & (z < 10)) / (3.0 * 4.0)
    far = np.sum(lane & (z > 24) & (z < 28)) / (3.0 * 4.0)
    assert far > 0
    assert near > 4 * far


def test_gross_errors_match_corruption():
    corruption = {"gross_error_fraction": 0.25, "noise": 0.0, "noise_depth": 0.0}
    scene = make_street(n_cars=4, **SMALL, corruption=corruption, sam_masks=False, random_state=0)
    assert scene.outlier_mask.sum() == round(0.25 * SMALL["n_points"])
    error = np.linalg.norm(scene.b - scene.a - scene.flow_clean, axis=1)
    assert np.all(error[scene.outlier_mask] > 0.1)
    clean = ~scene.outlier_mask & ~scene.bled_mask
    np.testing.assert_allclose(error[clean], 0.0, atol=1e-12)


def test_masks_cover_the_stated_fraction():
    scene = make_street(n_cars=4, **SMALL, corruption=False, random_state=0)
    segmentations = np.array([m["segmentation"] for m in scene.masks])
    covered = segmentations.any(axis=0)
    valid = scene.instance_image >= 0
    assert covered[valid].mean() == pytest.approx(0.95, abs=0.01)
    assert not covered[~valid].any()  # no mask on the sky or beyond 35 m
    # The road is cut into several masks.
    road = scene.surface_image == np.flatnonzero(scene.surface_kinds == "road")[0]
    on_road = [np.mean(s[road]) for s in segmentations]
    assert sum(share > 0.05 for share in on_road) >= 2


def test_deterministic_with_random_state():
    one = make_street(**SMALL, random_state=5)
    two = make_street(**SMALL, random_state=5)
    other = make_street(**SMALL, random_state=6)
    np.testing.assert_array_equal(one.X, two.X)
    np.testing.assert_array_equal(one.instance_labels, two.instance_labels)
    np.testing.assert_array_equal(one.moving, two.moving)
    assert len(one.masks) == len(two.masks)
    assert not np.array_equal(one.a, other.a)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"n_cars": -1}, "n_cars"),
        ({"n_moving": 5, "n_cars": 3}, "n_moving"),
        ({"n_moving": -1}, "n_moving"),
        ({"n_points": 0}, "n_points"),
        ({"n_points": 10**7}, "n_points"),
        ({"image_size": (94,)}, "image_size"),
        ({"corruption": 0.1}, "corruption"),
        ({"corruption": {"bogus": 1}}, "corruption"),
        ({"sam_masks": None}, "sam_masks"),
    ],
)
def test_bad_parameters_raise(kwargs, name):
    params = {"n_points": 100, "image_size": (47, 155), **kwargs}
    with pytest.raises(ValueError, match=name):
        make_street(**params, random_state=0)
