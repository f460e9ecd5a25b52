"""Tests of the FlyingThings3D-like scene generator."""

import numpy as np
import pytest
from scipy.spatial.distance import pdist

from mmreg.datasets._camera import project
from mmreg.datasets._flying_things import PRIMITIVES, make_flying_things

SMALL = {"image_size": (135, 240), "n_points": 3000}
CLEAN = {"corruption": False, "sam_masks": False}


@pytest.fixture(scope="module")
def clean_scene():
    return make_flying_things(n_objects=6, **SMALL, **CLEAN, random_state=0)


def test_counts_and_shapes(clean_scene):
    scene = clean_scene
    n = SMALL["n_points"]
    assert scene.X.shape == (n, 6)
    assert scene.a.shape == scene.b.shape == scene.flow_clean.shape == (n, 3)
    assert scene.rotations.shape == (7, 3, 3)
    assert scene.translations.shape == (7, 3)
    assert scene.labels.min() >= 0 and scene.labels.max() <= 6
    np.testing.assert_array_equal(scene.instance_labels, scene.labels)
    assert scene.depth_image.shape == scene.instance_image.shape == (135, 240)
    # Pixels are distinct (column, row) pairs inside the image.
    assert len(np.unique(scene.pixels, axis=0)) == n
    assert scene.pixels[:, 0].max() < 240 and scene.pixels[:, 1].max() < 135
    assert scene.camera.fx == pytest.approx(1050 * 240 / 960)
    assert scene.masks is None
    assert not scene.outlier_mask.any()


def test_default_size_matches_paper():
    scene = make_flying_things(**CLEAN, random_state=1)
    assert scene.X.shape == (32768, 6)
    assert scene.depth_image.shape == (540, 960)
    np.testing.assert_allclose(
        scene.camera.K, [[1050, 0, 479.5], [0, 1050, 269.5], [0, 0, 1]], atol=1e-12
    )
    # The backdrop fills the rest of the image: every pixel sees a surface.
    assert np.all(scene.instance_image >= 0)
    # Several objects are seen, each covering only part of the image.
    assert len(np.unique(scene.labels)) >= 5
    assert np.mean(scene.labels == 0) < 0.95


def test_hidden_objects_keep_their_motion():
    # Many objects in a tiny image: some are hidden or out of view, yet all are counted.
    scene = make_flying_things(
        n_objects=30, n_points=200, image_size=(20, 36), **CLEAN, random_state=0
    )
    assert scene.rotations.shape == (31, 3, 3)
    assert len(np.unique(scene.labels)) < 31


def test_motions_reproduce_clean_flow_exactly(clean_scene):
    scene = clean_scene
    R, t = scene.rotations[scene.labels], scene.translations[scene.labels]
    moved = np.einsum("nij,nj->ni", R, scene.a) + t
    np.testing.assert_allclose(moved, scene.a + scene.flow_clean, rtol=0, atol=1e-9)
    np.testing.assert_allclose(scene.b, scene.a + scene.flow_clean, rtol=0, atol=1e-9)
    np.testing.assert_allclose(scene.X, np.hstack([scene.a, scene.b]))
    # Proper rotations, and every object really moves (3-20 degrees).
    eye = np.broadcast_to(np.eye(3), scene.rotations.shape)
    np.testing.assert_allclose(
        scene.rotations @ scene.rotations.transpose(0, 2, 1), eye, atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(scene.rotations), 1.0, atol=1e-12)
    relative = scene.rotations[1:] @ scene.rotations[0].T  # conjugate to the own motion
    angles = np.degrees(np.arccos(np.clip((np.trace(relative, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert np.all(angles >= 3 - 1e-6) and np.all(angles <= 20 + 1e-6)


def test_points_lie_on_visible_surfaces(clean_scene):
    scene = clean_scene
    cols, rows = scene.pixels.T
    # Depth of each a-point is the z-buffer's at its pixel, and it projects back there.
    np.testing.assert_array_equal(scene.a[:, 2], scene.depth_image[rows, cols])
    np.testing.assert_allclose(project(scene.a, scene.camera), scene.pixels, atol=1e-9)
    np.testing.assert_array_equal(scene.instance_labels, scene.instance_image[rows, cols])
    # Objects (centres 5-35 m deep, at most 4 m across) are in front of the backdrop
    # (45-60 m deep on the axis, tilted by at most 20 degrees: over 40 m in the view).
    assert scene.a[scene.labels > 0, 2].max() <= 37 + 1e-6
    assert scene.a[scene.labels > 0, 2].min() >= 3 - 1e-6
    assert scene.a[scene.labels == 0, 2].min() > 37
    assert np.all(scene.a[:, 2] > 2)


def test_objects_are_metres_across(clean_scene):
    # Every object lies in a ball of diameter 2-4 m: no two of its points are farther apart.
    scene = clean_scene
    for k in np.unique(scene.labels[scene.labels > 0]):
        points = scene.a[scene.labels == k][:400]
        assert pdist(points).max() < 4.0 + 1e-6


def test_density_falls_with_distance():
    # Points per pixel are uniform, so points per m^2 of surface fall as 1 / z^2: near
    # objects have many more points per m^2 than the far backdrop. A pixel at depth z
    # covers (z / f)^2 m^2 of a surface facing the camera.
    scene = make_flying_things(
        n_objects=8, n_points=20000, image_size=(270, 480), **CLEAN, random_state=3
    )
    z, depth, f = scene.a[:, 2], scene.depth_image, scene.camera.fx
    near_points = (scene.labels > 0) & (z < 15)
    near_pixels = (scene.instance_image > 0) & (depth < 15)
    far_points, far_pixels = scene.labels == 0, scene.instance_image == 0
    assert near_points.sum() > 100
    density_near = near_points.sum() / np.sum((depth[near_pixels] / f) ** 2)
    density_far = far_points.sum() / np.sum((depth[far_pixels] / f) ** 2)
    assert density_near > 4 * density_far


def test_gross_errors_match_corruption():
    corruption = {
        "gross_error_fraction": 0.2,
        "noise": 0.0,
        "noise_depth": 0.0,
        "bleeding_width": 0.0,
        "gross_error_scale": 2.0,
        "blob_fraction": 0.0,
    }
    scene = make_flying_things(
        n_objects=5, **SMALL, corruption=corruption, sam_masks=False, random_state=0
    )
    n = SMALL["n_points"]
    assert scene.outlier_mask.sum() == round(0.2 * n)
    error = np.linalg.norm(scene.b - scene.a - scene.flow_clean, axis=1)
    np.testing.assert_allclose(error[~scene.outlier_mask], 0.0, atol=1e-12)
    assert error[scene.outlier_mask].min() >= 0.5 * 2.0 - 1e-9
    assert error[scene.outlier_mask].max() <= 1.5 * 2.0 + 1e-9


def test_default_corruption_is_applied():
    scene = make_flying_things(n_objects=5, **SMALL, sam_masks=False, random_state=0)
    assert scene.outlier_mask.mean() == pytest.approx(0.1, abs=1e-3)
    inliers = ~scene.outlier_mask & ~scene.bled_mask
    error = np.linalg.norm(scene.flow - scene.flow_clean, axis=1)
    assert 0 < np.median(error[inliers]) < 0.5
    np.testing.assert_allclose(scene.flow, scene.b - scene.a)


def test_masks_cover_the_stated_fraction():
    scene = make_flying_things(n_objects=6, **SMALL, corruption=False, random_state=0)
    segmentations = np.array([m["segmentation"] for m in scene.masks])
    assert segmentations.shape[1:] == (135, 240)
    covered = segmentations.any(axis=0)
    valid = scene.instance_image >= 0
    assert covered[valid].mean() == pytest.approx(0.95, abs=0.01)
    assert not covered[~valid].any()
    # The backdrop is cut into several pieces, objects are masked too.
    assert len(scene.masks) > len(np.unique(scene.instance_image))


def test_deterministic_with_random_state():
    one = make_flying_things(n_objects=4, **SMALL, random_state=7)
    two = make_flying_things(n_objects=4, **SMALL, random_state=7)
    other = make_flying_things(n_objects=4, **SMALL, random_state=8)
    np.testing.assert_array_equal(one.X, two.X)
    np.testing.assert_array_equal(one.labels, two.labels)
    assert len(one.masks) == len(two.masks)
    for m1, m2 in zip(one.masks, two.masks, strict=True):
        np.testing.assert_array_equal(m1["segmentation"], m2["segmentation"])
    assert not np.array_equal(one.a, other.a)


@pytest.mark.parametrize("shape", PRIMITIVES)
def test_every_shape_renders(shape):
    scene = make_flying_things(
        n_objects=2, n_points=500, image_size=(54, 96), shapes=shape, **CLEAN, random_state=2
    )
    assert scene.X.shape == (500, 6)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"n_objects": -1}, "n_objects"),
        ({"n_objects": 2.5}, "n_objects"),
        ({"n_points": 0}, "n_points"),
        ({"n_points": 10**6}, "n_points"),
        ({"image_size": (0, 10)}, "image_size"),
        ({"image_size": 5}, "image_size"),
        ({"shapes": ("blob",)}, "shapes"),
        ({"shapes": ()}, "shapes"),
        ({"corruption": "yes"}, "corruption"),
        ({"corruption": {"bogus": 1}}, "corruption"),
        ({"corruption": {"random_state": 1}}, "corruption"),
        ({"sam_masks": "yes"}, "sam_masks"),
    ],
)
def test_bad_parameters_raise(kwargs, name):
    params = {"n_objects": 2, "n_points": 100, "image_size": (27, 48), **kwargs}
    with pytest.raises(ValueError, match=name):
        make_flying_things(**params, random_state=0)


def test_bundled_meshes_are_shapes(monkeypatch):
    # With bundled meshes (here a stand-in for mmreg.datasets._meshes), their names and
    # "meshes" are shapes; the objects keep the meshes' own proportions.
    import open3d as o3d

    from mmreg.datasets import _flying_things

    box = o3d.geometry.TriangleMesh.create_box(1.0, 0.2, 0.2)
    vertices = np.asarray(box.vertices) - [0.5, 0.1, 0.1]
    stand_in = {
        "rod": (vertices / (2 * np.linalg.norm(vertices, axis=1).max()), np.asarray(box.triangles))
    }
    monkeypatch.setattr(_flying_things, "_bundled_meshes", lambda: stand_in)
    for shapes in ("rod", "meshes", ("meshes", "sphere")):
        scene = make_flying_things(
            n_objects=3, n_points=500, image_size=(54, 96), shapes=shapes, **CLEAN, random_state=0
        )
        assert scene.X.shape == (500, 6)
    scene = make_flying_things(
        n_objects=3,
        n_points=20000,
        image_size=(270, 480),
        shapes="rod",
        **CLEAN,
        random_state=0,
    )
    # Rods 5 times longer than wide: their points spread along one direction (about 4
    # times more than across, as seen; a sphere or a cube would give about 1).
    ratios = []
    for k in (1, 2, 3):
        rod = scene.a[scene.labels == k]
        spread = np.linalg.svd(rod - rod.mean(axis=0), compute_uv=False)
        ratios.append(spread[0] / spread[1])
    assert np.median(ratios) > 2.5
    with pytest.raises(ValueError, match="shapes"):
        make_flying_things(
            n_objects=1, n_points=10, image_size=(27, 48), shapes="bunny", **CLEAN, random_state=0
        )


def test_still_objects_of_the_background_move_with_the_backdrop():
    scene = make_flying_things(n_objects=4, n_static=3, **SMALL, **CLEAN, random_state=3)
    background = scene.labels == 0
    # Backdrop and still objects: one motion group, one instance each, numbered after the
    # moving objects.
    pieces = np.unique(scene.instance_labels[background])
    assert pieces[0] == 0 and set(pieces[1:]) <= {5, 6, 7} and len(pieces) >= 2
    np.testing.assert_array_equal(scene.instance_labels[~background], scene.labels[~background])
    R, t = scene.rotations[0], scene.translations[0]
    np.testing.assert_allclose(scene.a[background] @ R.T + t, scene.b[background], atol=1e-9)
    assert scene.rotations.shape == (5, 3, 3)


def test_still_objects_leave_the_moving_ones_as_they_were():
    # The still objects are drawn after everything else: the moving objects' motions
    # (and the camera's) are those of the scene without them.
    plain = make_flying_things(n_objects=3, **SMALL, **CLEAN, random_state=5)
    with_still = make_flying_things(n_objects=3, n_static=2, **SMALL, **CLEAN, random_state=5)
    np.testing.assert_array_equal(with_still.rotations, plain.rotations)
    np.testing.assert_array_equal(with_still.translations, plain.translations)
    assert len(np.unique(with_still.instance_labels)) > len(np.unique(plain.instance_labels))
