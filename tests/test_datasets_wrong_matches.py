import numpy as np
import pytest

from mmreg.datasets import add_wrong_correspondences, make_scene


@pytest.fixture(scope="module")
def scene():
    return make_scene(n_objects=3, n_points=2000, random_state=0)


@pytest.mark.parametrize("fraction", [0.05, 0.1, 0.3])
def test_moves_the_requested_share_by_the_requested_distance(scene, fraction):
    X, y = add_wrong_correspondences(scene.X, scene.labels, fraction, random_state=1)
    moved = np.linalg.norm(X[:, 3:] - scene.X[:, 3:], axis=1)
    wrong = y == -1
    assert wrong.sum() == round(fraction * len(X))
    assert np.all((moved[wrong] >= 0.5) & (moved[wrong] <= 1.5))
    assert np.array_equal(X[~wrong], scene.X[~wrong])
    assert np.array_equal(X[:, :3], scene.X[:, :3])
    assert np.array_equal(y[~wrong], scene.labels[~wrong])


def test_inputs_are_not_modified_and_seeds_reproduce(scene):
    before = scene.X.copy()
    first = add_wrong_correspondences(scene.X, scene.labels, random_state=3)
    second = add_wrong_correspondences(scene.X, scene.labels, random_state=3)
    generator = add_wrong_correspondences(
        scene.X, scene.labels, random_state=np.random.default_rng(3)
    )
    assert np.array_equal(scene.X, before)
    assert np.array_equal(first[0], second[0]) and np.array_equal(first[1], second[1])
    assert generator[0].shape == first[0].shape


def test_two_dimensional_correspondences():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(50, 4))
    X2, y = add_wrong_correspondences(X, np.zeros(50, dtype=int), 0.2, random_state=0)
    assert (y == -1).sum() == 10
    assert np.array_equal(X2[:, :2], X[:, :2])


def test_zero_fraction_is_a_copy(scene):
    X, y = add_wrong_correspondences(scene.X, scene.labels, 0.0)
    assert np.array_equal(X, scene.X) and X is not scene.X
    assert np.array_equal(y, scene.labels)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"fraction": 1.5}, "fraction"),
        ({"fraction": -0.1}, "fraction"),
        ({"distance": (2.0, 1.0)}, "distance"),
        ({"labels": np.zeros(3)}, "labels"),
        ({"X": np.zeros((10, 5))}, "shape"),
    ],
)
def test_bad_input(scene, kwargs, match):
    args = {"X": scene.X, "labels": scene.labels, **kwargs}
    with pytest.raises(ValueError, match=match):
        add_wrong_correspondences(**args)
