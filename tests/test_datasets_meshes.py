"""Real meshes shipped with mmreg and ``make_scene(shapes="meshes")``."""

import hashlib
import re
from importlib import resources

import numpy as np
import pytest
from scipy.spatial import ConvexHull, cKDTree
from scipy.spatial.distance import cdist, pdist

from mmreg.datasets._meshes import MESH_NAMES, _neighbours, _surface_points, load_mesh_points
from mmreg.datasets._scene import SHAPES, make_scene

N_STORED = 2048


def diameter(points):
    return pdist(points[ConvexHull(points).vertices]).max()


def object_points(scene, k):
    return scene.a[scene.labels == k]


# -- the stored samples -------------------------------------------------------------------


def test_npz_holds_every_mesh_as_float32_samples():
    meshes = load_mesh_points()
    assert tuple(meshes) == MESH_NAMES
    assert len(MESH_NAMES) == len(set(MESH_NAMES)) == 16
    for name, points in meshes.items():
        assert points.shape == (N_STORED, 3), name
        assert points.dtype == np.float32, name
        assert np.isfinite(points).all(), name
        assert len(np.unique(points, axis=0)) == N_STORED, name


@pytest.mark.parametrize("name", MESH_NAMES)
def test_samples_are_centred_with_diameter_one(name):
    points = load_mesh_points(name).astype(np.float64)
    centre = (points.min(axis=0) + points.max(axis=0)) / 2
    np.testing.assert_allclose(centre, 0, atol=1e-6)
    assert abs(diameter(points) - 1) < 1e-5
    # Evenly spread: no sample farther than 0.1 from its nearest neighbour.
    gaps, _ = cKDTree(points).query(points, k=2)
    assert gaps[:, 1].max() < 0.1


def test_load_mesh_points_returns_copies():
    first = load_mesh_points("bunny")
    first[:] = 0
    assert np.abs(load_mesh_points("bunny")).max() > 0.1
    every = load_mesh_points()
    every["knot"][:] = 0
    assert np.abs(load_mesh_points()["knot"]).max() > 0.1


@pytest.mark.parametrize("name", ["teapot", "Bunny", "", 3])
def test_load_mesh_points_rejects_unknown_names(name):
    with pytest.raises(ValueError, match="name must be one of"):
        load_mesh_points(name)


def test_attribution_lists_every_mesh_with_licence_and_author():
    text = (
        resources.files("mmreg.datasets")
        .joinpath("data")
        .joinpath("meshes_ATTRIBUTION.md")
        .read_text(encoding="utf-8")
    )
    assert "libcgal-demo" in text
    rows = {}
    for line in text.splitlines():
        match = re.match(r"\| `([a-z_]+)` \| `([^`]+\.off)` \|(.*)\|(.*)\|(.*)\|$", line)
        if match:
            rows[match.group(1)] = match.groups()[1:]
    assert set(rows) == set(MESH_NAMES)
    for name, (_, _, licence, author) in rows.items():
        assert licence.strip() and author.strip(), name
        # CC0 1.0, except the Stanford Bunny, which keeps Stanford's terms.
        assert licence.strip().startswith("CC0") != (name == "bunny"), name
    assert "Stanford" in rows["bunny"][2]


# -- drawing points from the samples --------------------------------------------------------


def test_surface_points_subsets_the_samples_without_repeats():
    stored = load_mesh_points("elk").astype(np.float64)
    points = _surface_points("elk", 500, np.random.RandomState(0))
    assert points.shape == (500, 3)
    _, index = cKDTree(stored).query(points)
    assert len(np.unique(index)) == 500
    np.testing.assert_array_equal(points, stored[index])


def test_surface_points_beyond_the_samples_stay_between_neighbours():
    name, n = "pinion", 3 * N_STORED
    stored = load_mesh_points(name).astype(np.float64)
    points = _surface_points(name, n, np.random.RandomState(0))
    assert points.shape == (n, 3)
    assert len(np.unique(points, axis=0)) == n
    # Every stored sample once, then new points near them, never beyond the samples'
    # own spread: within half the longest neighbour segment of a sample.
    np.testing.assert_array_equal(np.unique(points[:N_STORED], axis=0), np.unique(stored, axis=0))
    longest = np.linalg.norm(stored[_neighbours(name)] - stored[:, None], axis=2).max()
    dist, _ = cKDTree(stored).query(points[N_STORED:])
    assert dist.max() <= 0.5 * longest + 1e-12
    assert longest < 0.1
    assert abs(diameter(points) - diameter(stored)) < 1e-9


# -- make_scene(shapes="meshes") -------------------------------------------------------------


@pytest.mark.parametrize("n_objects, n_points", [(3, 900), (4, 4 * 3000 + 3), (7, 22395), (1, 50)])
def test_mesh_scene_has_requested_objects_and_points(n_objects, n_points):
    scene = make_scene(n_objects, n_points, shapes="meshes", object_size=3.0, random_state=1)
    assert scene.X.shape == (n_points, 6)
    counts = np.bincount(scene.labels)
    assert len(counts) == n_objects
    assert counts.max() - counts.min() <= 1
    assert scene.rotations.shape == (n_objects, 3, 3)
    assert scene.translations.shape == (n_objects, 3)
    assert len(scene.shapes) == n_objects
    assert len(set(scene.shapes)) == n_objects  # distinct meshes while there are enough
    assert set(scene.shapes) <= set(MESH_NAMES)


def test_more_objects_than_meshes_repeat_meshes():
    scene = make_scene(20, 20 * 40, shapes="meshes", random_state=0)
    assert len(scene.shapes) == 20
    assert set(scene.shapes) <= set(MESH_NAMES)
    assert len(set(scene.shapes)) < 20


@pytest.mark.parametrize("object_size", [0.5, 3.0])
def test_mesh_objects_are_object_size_across(object_size):
    # 3000 points per object: all 2048 samples are in, so the diameter is object_size.
    scene = make_scene(5, 5 * 3000, shapes="meshes", object_size=object_size, random_state=2)
    for k in range(5):
        assert abs(diameter(object_points(scene, k)) / object_size - 1) < 1e-6
    # 300 points per object: a subset, so at most object_size (measured: >= 0.9 of it).
    scene = make_scene(8, 8 * 300, shapes="meshes", object_size=object_size, random_state=3)
    for k in range(8):
        ratio = diameter(object_points(scene, k)) / object_size
        assert 0.8 < ratio < 1 + 1e-6


@pytest.mark.parametrize("separation", [1.6, 4.0])
def test_mesh_objects_and_outliers_are_separated(separation):
    scene = make_scene(
        8,
        4000,
        shapes="meshes",
        object_size=3.0,
        separation=separation,
        outlier_fraction=0.05,
        random_state=4,
    )
    for i in range(8):
        for j in range(i + 1, 8):
            gap = cdist(object_points(scene, i), object_points(scene, j)).min()
            assert gap > separation
    outliers = scene.a[scene.labels == -1]
    assert len(outliers) == 200
    assert cdist(outliers, scene.a[scene.labels >= 0]).min() > separation


@pytest.mark.parametrize("same_motion", [0, 1, 3])
def test_noiseless_mesh_scene_follows_its_motions(same_motion):
    scene = make_scene(
        7, 7000, shapes="meshes", object_size=3.0, same_motion=same_motion, random_state=5
    )
    R, t = scene.rotations[scene.labels], scene.translations[scene.labels]
    np.testing.assert_allclose(scene.b, np.einsum("nij,nj->ni", R, scene.a) + t, atol=1e-12)
    np.testing.assert_array_equal(scene.X, np.hstack([scene.a, scene.b]))
    for k in range(1, 1 + same_motion):
        np.testing.assert_array_equal(scene.rotations[k], scene.rotations[0])
        np.testing.assert_array_equal(scene.translations[k], scene.translations[0])
    distinct = {tuple(t) for t in scene.translations.tolist()}
    assert len(distinct) == 7 - same_motion


def test_noisy_mesh_scene_adds_noise_of_the_requested_scale():
    scene = make_scene(7, 7000, shapes="meshes", object_size=3.0, noise=0.03, random_state=6)
    R, t = scene.rotations[scene.labels], scene.translations[scene.labels]
    residual = scene.b - (np.einsum("nij,nj->ni", R, scene.a) + t)
    assert 0.028 < residual.std() < 0.032


def test_mesh_scene_is_reproducible_from_its_seed():
    first = make_scene(4, 9000, shapes="meshes", noise=0.01, outlier_fraction=0.1, random_state=7)
    again = make_scene(4, 9000, shapes="meshes", noise=0.01, outlier_fraction=0.1, random_state=7)
    for key in ("X", "labels", "rotations", "translations", "shapes"):
        np.testing.assert_array_equal(first[key], again[key])
    other = make_scene(4, 9000, shapes="meshes", noise=0.01, outlier_fraction=0.1, random_state=8)
    assert not np.array_equal(first.X, other.X)


def test_mesh_scene_draws_from_the_given_meshes_only():
    scene = make_scene(5, 1000, shapes=("bunny", "knot", "bunny"), random_state=0)
    assert set(scene.shapes) == {"bunny", "knot"}


@pytest.mark.parametrize(
    "shapes",
    ["mesh", "Meshes", "", "sphere", [], ["bunny", "teapot"], ["sphere"], 3, None, [1, 2]],
)
def test_bad_shapes_raise(shapes):
    with pytest.raises(ValueError, match="shapes must be"):
        make_scene(3, 300, shapes=shapes, random_state=0)


# -- the primitives are as before ---------------------------------------------------------------


def test_primitive_scene_names_its_shapes():
    scene = make_scene(7, 700, random_state=0)
    assert scene.shapes.tolist() == [SHAPES[k % len(SHAPES)] for k in range(7)]
    explicit = make_scene(7, 700, shapes="primitives", random_state=0)
    np.testing.assert_array_equal(explicit.X, scene.X)


# Recorded from make_scene before it had a `shapes` parameter; the full bytes of X, labels,
# rotations and translations were unchanged by it (sha256 prefixes 018076505bfbae93 for
# the default scene at random_state=0). Floats compare at 1e-12, so the test survives
# last-bit differences between platforms but no change in the random draws.
REFERENCE = {
    "default": (
        {"random_state": 0},
        "9260dda772f3615ce84efc0b5ea56b1afc58a29350e8695851f8944e56266e28",
        [
            32823.28439299501,
            43722.059547479446,
            43690.83385267149,
            -25671.355261318993,
            -6567.298339863218,
            14042.219505740473,
        ],
        [
            3.7179014471687104,
            3.0267251901859593,
            0.0873294340307355,
            -5.819702411500831,
            0.7634043986396879,
            0.8560912914612637,
        ],
        [
            [-1.6202537800618488, 0.4672552328621178, -1.4392103970598895],
            [1.8103413019676529, 0.41852581454456006, -1.8743229021172065],
            [0.6980737763614355, 1.6205194260062825, 1.3241727101004228],
            [1.8934539269372546, -1.4885642826503167, -1.0541390594240831],
            [-0.03511622007964865, 0.8487002116076452, 1.3103874349970894],
            [1.314726551397504, 0.03864561249747167, 0.4109862496988059],
            [-0.5772382600370363, 0.19325539711863327, -0.5188087911937771],
        ],
    ),
    "outliers and shared motion": (
        {
            "n_objects": 3,
            "n_points": 300,
            "noise": 0.01,
            "outlier_fraction": 0.1,
            "same_motion": 1,
            "random_state": 5,
        },
        "cf2a716244acd4359c9e1d475328a7110f4a8a8f7f251955bfb35881febf9a98",
        [
            663.073257029948,
            667.4382225375533,
            353.8242335117764,
            -2.127848765285488,
            551.9068690199242,
            79.38998799461726,
        ],
        [
            3.133553446634086,
            3.2320465571672625,
            3.0426693770495934,
            -0.5137664925653118,
            3.2738970002742245,
            1.5848630029703001,
        ],
        [
            [0.013087125302395197, -1.199302345719388, -1.4930527913105753],
            [0.013087125302395197, -1.199302345719388, -1.4930527913105753],
            [0.03212072880275274, 1.679783212768966, 1.3535868704858252],
        ],
    ),
}


@pytest.mark.parametrize("case", list(REFERENCE))
def test_primitive_scenes_are_unchanged(case):
    kwargs, labels_sha, column_sums, first_row, translations = REFERENCE[case]
    scene = make_scene(**kwargs)
    digest = hashlib.sha256(scene.labels.astype(np.int64).tobytes()).hexdigest()
    assert digest == labels_sha
    np.testing.assert_allclose(scene.X.sum(axis=0), column_sums, rtol=1e-12)
    np.testing.assert_allclose(scene.X[0], first_row, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(scene.translations, translations, rtol=1e-12, atol=1e-12)
