"""Fitting on one correspondence per voxel (``voxel_size``), then judging the rest."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mmreg import MultiModelRegistration
from mmreg._voxels import voxel_representatives
from mmreg.datasets import make_scene
from mmreg.metrics import iou_score


@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(0, 400),
    d=st.sampled_from([2, 3]),
    size=st.sampled_from([0.05, 0.3, 2.0]),
)
def test_the_first_point_of_every_occupied_voxel(seed, n, d, size):
    points = np.random.default_rng(seed).uniform(-3, 3, size=(n, d))
    rows = voxel_representatives(points, size)
    first = {}
    if n:
        cells = np.floor((points - points.min(axis=0)) / size).astype(int)
        for row, cell in enumerate(map(tuple, cells)):
            first.setdefault(cell, row)
    assert rows.tolist() == sorted(first.values())


def test_a_noiseless_scene_is_recovered_exactly_from_its_voxel_sample():
    scene = make_scene(random_state=0)
    full = MultiModelRegistration(random_state=0).fit(scene.X)
    sampled = MultiModelRegistration(voxel_size=0.1, random_state=0).fit(scene.X)
    fitted = sampled.init_labels_ >= 0
    assert fitted.sum() < len(scene.X) / 10  # the voxel sample: about 1,900 of 22,395
    assert iou_score(scene.labels, sampled.labels_) == 1.0
    assert sampled.n_clusters_ == full.n_clusters_ == 7
    flow = scene.X[:, 3:] - scene.X[:, :3]
    np.testing.assert_allclose(sampled.flow_, flow, atol=1e-9)
    assert np.mean(sampled.predict(scene.X) == sampled.labels_) == 1.0


def _world_with_a_slow_piece_and_a_car(rng):
    grid = np.stack(np.meshgrid(np.arange(0, 20, 0.1), np.arange(0, 20, 0.1)), -1)
    grid = grid.reshape(-1, 2)
    world = np.c_[grid + rng.uniform(-0.02, 0.02, grid.shape), rng.uniform(0, 0.02, len(grid))]
    car = rng.uniform([30, 0, 0], [34, 2, 1.5], size=(2000, 3))
    a = np.vstack([world, car])
    noise = rng.normal(scale=0.002, size=a.shape)
    b = a + noise + np.r_[np.zeros((len(world), 3)), np.tile([1.0, 0, 0], (len(car), 1))]
    # A patch of the world moves 3 cm more (15 times its noise, below min_motion): a
    # slow piece, reported with the static world but fitted with its own motion.
    patch = (world[:, 0] < 5) & (world[:, 1] < 5)
    b[: len(world)][patch] += [0.03, 0, 0]
    return np.hstack([a, b]), len(world), patch


def test_the_rows_left_out_of_a_slow_piece_stay_in_the_static_world():
    X, n_world, patch = _world_with_a_slow_piece_and_a_car(np.random.default_rng(0))
    est = MultiModelRegistration(tau=5.0, voxel_size=0.3, random_state=0).fit(X)
    assert (est.init_labels_ >= 0).sum() < len(X) / 4
    static = est.static_cluster_
    assert static >= 0
    # Judged by the static world's motion alone (predict), the patch is wrong...
    assert np.mean(est.predict(X[:n_world][patch]) < 0) > 0.9
    # ...but the voxel fit judged the rows it left out by the patch's own motion.
    np.testing.assert_array_equal(est.labels_[:n_world], static)
    assert np.all(est.labels_[n_world:] == est.labels_[n_world])
    assert est.moving_.tolist() == [i != static for i in range(est.n_clusters_)]
    assert est.weights_.sum() == pytest.approx(1.0)


def test_voxel_size_needs_a_robust_variant():
    X = make_scene(n_objects=2, n_points=200, random_state=0).X
    with pytest.raises(ValueError, match="voxel_size needs a robust variant"):
        MultiModelRegistration(variant="paper", voxel_size=0.1).fit(X)


def test_precomputed_init_labels_are_sampled_with_the_rows():
    scene = make_scene(n_objects=3, n_points=3000, random_state=1)
    est = MultiModelRegistration(init=scene.labels, voxel_size=0.1, random_state=0)
    est.fit(scene.X)
    fitted = est.init_labels_ >= 0
    assert 0 < fitted.sum() < len(scene.X)
    np.testing.assert_array_equal(est.init_labels_[fitted], scene.labels[fitted])
    assert iou_score(scene.labels, est.labels_) == 1.0
    with pytest.raises(ValueError, match="init labels"):
        MultiModelRegistration(init=scene.labels[:-1], voxel_size=0.1).fit(scene.X)
