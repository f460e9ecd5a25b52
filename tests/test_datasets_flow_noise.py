"""Tests of corrupt_scene_flow: noise, gross errors in blobs, bleeding, switches."""

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt
from scipy.spatial import cKDTree

from mmreg.datasets._flow_noise import corrupt_scene_flow

HEIGHT, WIDTH = 60, 80
# Rectangles (rows, columns) on a background surface 0, each at its own depth.
RECTANGLES = {1: (slice(10, 25), slice(5, 25)), 2: (slice(10, 25), slice(25, 40)),
              3: (slice(35, 50), slice(50, 70))}  # fmt: skip
DEPTHS = {0: 20.0, 1: 5.0, 2: 8.0, 3: 12.0}
OFF = dict(noise=0.0, noise_depth=0.0, gross_error_fraction=0.0, bleeding_width=0)


def _rigid_flow(points, angle, translation):
    c, s = np.cos(angle), np.sin(angle)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return points @ rotation.T + translation - points


def toy_scene(height=HEIGHT, width=WIDTH):
    """Every pixel a point: background 0 and three rectangles, each a rigid motion."""
    image = np.zeros((height, width), dtype=int)
    for surface, box in RECTANGLES.items():
        image[box] = surface
    rows, cols = np.mgrid[:height, :width]
    pixels = np.column_stack([rows.ravel(), cols.ravel()])
    instance = image.ravel()
    depth = np.vectorize(DEPTHS.get)(instance).astype(float)
    focal = 50.0
    points = np.column_stack(
        [
            (pixels[:, 1] - width / 2) * depth / focal,
            (pixels[:, 0] - height / 2) * depth / focal,
            depth,
        ]
    )
    flow = np.zeros_like(points)
    motions = {0: (0.0, [0.0, 0.0, 0.0]), 1: (0.05, [1.0, 0.0, 0.2]),
               2: (-0.03, [0.0, 0.8, -0.5]), 3: (0.1, [-0.6, 0.3, 0.9])}  # fmt: skip
    for surface, (angle, translation) in motions.items():
        rows_of = instance == surface
        flow[rows_of] = _rigid_flow(points[rows_of], angle, np.array(translation))
    return points, flow, pixels, instance


def _corrupt(scene, **params):
    points, flow, pixels, instance = scene
    return corrupt_scene_flow(points, flow, pixels, instance, image_shape=(HEIGHT, WIDTH), **params)


def _large_scene(n=32768, seed=0):
    """32768 points at random pixels of a 540 x 960 image, four vertical surfaces."""
    rng = np.random.default_rng(seed)
    flat = rng.choice(540 * 960, size=n, replace=False)
    pixels = np.column_stack(np.unravel_index(flat, (540, 960)))
    instance = pixels[:, 1] // 240
    points = np.column_stack([rng.normal(size=(n, 2)), rng.uniform(5.0, 35.0, n)])
    flow = np.zeros((n, 3))
    flow[:, 0] = 0.5 * instance
    return points, flow, pixels, instance


@pytest.mark.parametrize("fraction", [0.05, 0.1, 0.3])
@pytest.mark.parametrize("blob_fraction", [0.0, 0.5, 1.0])
def test_gross_error_fraction_matches(fraction, blob_fraction):
    points, flow, pixels, instance = _large_scene()
    out = corrupt_scene_flow(
        points, flow, pixels, instance, image_shape=(540, 960), noise=0.0, noise_depth=0.0,
        bleeding_width=0, gross_error_fraction=fraction, blob_fraction=blob_fraction,
        gross_error_scale=2.0, random_state=0,
    )  # fmt: skip
    assert abs(out.outlier_mask.mean() - fraction) < 0.01
    error = np.linalg.norm(out.flow - flow, axis=1)
    # Offsets of magnitude 2 * U(0.5, 1.5), sqrt(2) times that in blobs; the rest untouched.
    assert np.all(error[out.outlier_mask] > 0.9) and np.all(error[out.outlier_mask] < 4.3)
    assert np.array_equal(out.flow[~out.outlier_mask], flow[~out.outlier_mask])


def _outlier_neighbour_share(mask_image):
    """Mean share of outliers among the 8 neighbours of each outlier pixel."""
    padded = np.pad(mask_image, 1)
    neighbours = sum(
        padded[1 + dr : 1 + dr + HEIGHT, 1 + dc : 1 + dc + WIDTH].astype(int)
        for dr in (-1, 0, 1)
        for dc in (-1, 0, 1)
        if (dr, dc) != (0, 0)
    )
    return neighbours[mask_image].mean() / 8


def test_blobs_are_spatially_coherent():
    scene = toy_scene()
    flow = scene[1]
    shares, cosines = {}, {}
    for blob_fraction in (0.0, 1.0):
        out = _corrupt(scene, noise=0.0, noise_depth=0.0, bleeding_width=0,
                       gross_error_fraction=0.1, blob_fraction=blob_fraction,
                       random_state=3)  # fmt: skip
        shares[blob_fraction] = _outlier_neighbour_share(out.outlier_mask.reshape(HEIGHT, WIDTH))
        # Errors of neighbouring outliers point alike in blobs, at random otherwise.
        errors = out.flow[out.outlier_mask] - flow[out.outlier_mask]
        errors /= np.linalg.norm(errors, axis=1, keepdims=True)
        where = np.column_stack(np.nonzero(out.outlier_mask.reshape(HEIGHT, WIDTH)))
        _, nearest = cKDTree(where).query(where, k=2)
        cosines[blob_fraction] = np.median(np.sum(errors * errors[nearest[:, 1]], axis=1))
    # Within a blob, no two errors are equal: no rigid motion hides in it.
    assert len(np.unique(np.round(errors, 9), axis=0)) == len(errors)
    # Two members of one blob: errors at 45 degrees to the mean, so cosines near 0.5.
    assert cosines[1.0] > 0.35 and abs(cosines[0.0]) < 0.2
    # Chance level is the outlier fraction, 0.1: isolated errors sit near it, blobs far above.
    assert shares[0.0] < 0.25
    assert shares[1.0] > 0.6


def test_noise_std_grows_with_depth_as_documented():
    n = 20000
    rng = np.random.default_rng(1)
    depth = np.repeat([4.0, 30.0], n)
    points = np.column_stack([rng.normal(size=(2 * n, 2)), depth])
    flow = np.zeros((2 * n, 3))
    pixels = np.zeros((2 * n, 2), dtype=int)
    instance = np.zeros(2 * n, dtype=int)
    out = corrupt_scene_flow(
        points, flow, pixels, instance, image_shape=(1, 1), noise=0.02, noise_depth=1e-4,
        gross_error_fraction=0.0, bleeding_width=0, random_state=0,
    )  # fmt: skip
    for z in (4.0, 30.0):
        expected = 0.02 + 1e-4 * z**2  # 0.0216 m and 0.11 m
        rows = depth == z
        assert np.allclose(out.noise_sigma[rows], expected)
        measured = out.flow[rows].std()
        assert abs(measured / expected - 1) < 0.05
    assert not out.outlier_mask.any() and not out.bled_mask.any()


def _distance_to_other_instance(instance):
    """Image distance from each pixel to the nearest pixel of another surface."""
    image = instance.reshape(HEIGHT, WIDTH)
    distance = np.zeros(image.shape)
    for surface in np.unique(image):  # four surfaces
        inside = image == surface
        distance[inside] = distance_transform_edt(inside)[inside]
    return distance.ravel()


def test_bleeding_touches_only_boundaries_and_takes_another_flow():
    scene = toy_scene()
    points, flow, pixels, instance = scene
    out = _corrupt(scene, **{**OFF, "bleeding_width": 2.0}, random_state=0)
    bled = out.bled_mask
    near = _distance_to_other_instance(instance)
    assert bled.any()
    assert np.all(near[bled] <= 2.0)
    # Every point next to another surface (all flows differ here) bleeds.
    assert np.all(bled[near <= 1.0])
    # Untouched points keep their flow exactly.
    assert np.array_equal(out.flow[~bled], flow[~bled])
    # A bled point carries the clean flow of a point of another surface within 2 pixels.
    for i in np.flatnonzero(bled):
        gap = np.hypot(*(pixels - pixels[i]).T)
        donors = (instance != instance[i]) & (gap <= 2.0)
        assert np.any(np.all(flow[donors] == out.flow[i], axis=1))


def test_bleeding_between_equal_flows_changes_nothing():
    points, flow, pixels, instance = toy_scene()
    flow = np.tile([0.3, -0.1, 0.2], (len(points), 1))
    out = corrupt_scene_flow(
        points, flow, pixels, instance, image_shape=(HEIGHT, WIDTH),
        **{**OFF, "bleeding_width": 3.0},
    )  # fmt: skip
    assert not out.bled_mask.any()
    assert np.array_equal(out.flow, flow)


@pytest.mark.parametrize("bleeding_width", [0, None])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_everything_off_returns_an_unchanged_copy(bleeding_width, dtype):
    points, flow, pixels, instance = toy_scene()
    flow = flow.astype(dtype)
    out = corrupt_scene_flow(
        points, flow, pixels, instance, image_shape=(HEIGHT, WIDTH),
        **{**OFF, "bleeding_width": bleeding_width}, random_state=0,
    )  # fmt: skip
    assert out.flow.dtype == flow.dtype
    assert out.flow.tobytes() == flow.tobytes()
    assert not np.shares_memory(out.flow, flow)
    assert not out.outlier_mask.any() and not out.bled_mask.any()
    assert np.all(out.noise_sigma == 0)


def test_defaults_corrupt_every_way():
    scene = toy_scene()
    out = _corrupt(scene, random_state=0)
    assert abs(out.outlier_mask.mean() - 0.1) < 0.01
    assert out.bled_mask.any()
    assert not np.any(out.bled_mask & out.outlier_mask)
    assert np.all(out.noise_sigma > 0.01)


def test_random_state_makes_it_deterministic():
    scene = toy_scene()
    first = _corrupt(scene, random_state=7)
    again = _corrupt(scene, random_state=np.random.RandomState(7))
    other = _corrupt(scene, random_state=8)
    for key in ("flow", "outlier_mask", "bled_mask", "noise_sigma"):
        assert np.array_equal(first[key], again[key])
    assert not np.array_equal(first.flow, other.flow)
    assert not np.array_equal(first.outlier_mask, other.outlier_mask)


@pytest.mark.parametrize(
    "params, error, match",
    [
        ({"noise": -0.1}, ValueError, "noise"),
        ({"noise_depth": -1e-4}, ValueError, "noise_depth"),
        ({"noise": "big"}, TypeError, "noise"),
        ({"gross_error_fraction": 1.5}, ValueError, "gross_error_fraction"),
        ({"blob_fraction": -0.2}, ValueError, "blob_fraction"),
        ({"gross_error_scale": -1.0}, ValueError, "gross_error_scale"),
        ({"gross_error_scale": 0.0}, ValueError, "gross_error_scale"),
        ({"bleeding_width": -1}, ValueError, "bleeding_width"),
        ({"bleeding_width": np.nan}, ValueError, "bleeding_width"),
        ({"image_shape": (0, WIDTH)}, ValueError, "image_shape"),
        ({"image_shape": 60}, ValueError, "image_shape"),
    ],
)
def test_bad_parameters_raise(params, error, match):
    points, flow, pixels, instance = toy_scene()
    params = {"image_shape": (HEIGHT, WIDTH), **params}
    with pytest.raises(error, match=match):
        corrupt_scene_flow(points, flow, pixels, instance, **params)


def test_bad_arrays_raise():
    points, flow, pixels, instance = toy_scene()
    shape = (HEIGHT, WIDTH)
    with pytest.raises(ValueError, match=r"\(row, column\)"):
        corrupt_scene_flow(points, flow, pixels[:, ::-1], instance, image_shape=shape)
    with pytest.raises(TypeError, match="pixels"):
        corrupt_scene_flow(points, flow, pixels + 0.5, instance, image_shape=shape)
    with pytest.raises(ValueError, match="flow"):
        corrupt_scene_flow(points, flow[:-1], pixels, instance, image_shape=shape)
    with pytest.raises(ValueError, match="points"):
        corrupt_scene_flow(points[:, :2], flow, pixels, instance, image_shape=shape)
    with pytest.raises(ValueError, match="instance"):
        corrupt_scene_flow(points, flow, pixels, instance - 1, image_shape=shape)
    with pytest.raises(TypeError, match="instance"):
        corrupt_scene_flow(points, flow, pixels, instance * 1.0, image_shape=shape)
