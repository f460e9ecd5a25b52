"""Pose and per-point errors: known rotations, hand-computed weights, brute force, checks."""

import warnings

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.distance import cdist
from scipy.spatial.transform import Rotation
from sklearn.exceptions import UndefinedMetricWarning

from mmreg.datasets import make_scene
from mmreg.metrics import (
    chamfer_distance,
    ground_truth_poses,
    per_point_error,
    rotation_error,
    translation_error,
)


def motions(n, seed):
    rng = np.random.default_rng(seed)
    rotations = Rotation.random(n, random_state=seed).as_matrix().reshape(n, 3, 3)
    return rotations, rng.uniform(-3, 3, (n, 3))


def brute_force_match(labels_true, labels_pred, j):
    """True object (k >= 0) sharing most points with H_j; ties: smaller, then first point."""
    h = labels_pred == j
    candidates = []
    for k in np.unique(labels_true[labels_true >= 0]):
        g = labels_true == k
        shared = int(np.sum(h & g))
        if shared:
            candidates.append((-shared, int(g.sum()), int(np.argmax(g)), k))
    return min(candidates)[3] if candidates else None


def brute_force_pose_errors(labels_true, labels_pred, transforms_true, transforms_pred):
    rot_true, trans_true = transforms_true
    rot_pred, trans_pred = transforms_pred
    rot_errors, trans_errors = [], []
    for j in np.unique(labels_pred[labels_pred >= 0]):
        h = (labels_pred == j) & (labels_true >= 0)
        if not h.any():
            continue
        rot, trans = 0.0, 0.0
        for k in np.unique(labels_true[h]):
            weight = np.sum(h & (labels_true == k)) / h.sum()
            cos = (np.trace(rot_pred[j].T @ rot_true[k]) - 1) / 2
            rot += weight * np.degrees(np.arccos(np.clip(cos, -1, 1)))
            trans += weight * np.linalg.norm(trans_pred[j] - trans_true[k])
        rot_errors.append(rot)
        trans_errors.append(trans)
    return np.mean(rot_errors), np.mean(trans_errors)


def brute_force_chamfer(p, q):
    d = cdist(p, q)
    return 0.5 * (d.min(axis=1).mean() + d.min(axis=0).mean())


def brute_force_per_point(a, labels_true, labels_pred, transforms_true, transforms_pred):
    errors = []
    for j in np.unique(labels_pred[labels_pred >= 0]):
        k = brute_force_match(labels_true, labels_pred, j)
        if k is None:
            continue
        h, g = a[labels_pred == j], a[labels_true == k]
        moved_h = h @ transforms_pred[0][j].T + transforms_pred[1][j]
        moved_g = g @ transforms_true[0][k].T + transforms_true[1][k]
        errors.append(brute_force_chamfer(moved_h, moved_g))
    return np.mean(errors)


random_case = st.tuples(
    st.integers(2, 40),  # n
    st.integers(1, 4),  # true objects
    st.integers(1, 5),  # estimated clusters
    st.integers(0, 2**16),  # seed
)


def make_case(n, k_true, k_pred, seed):
    rng = np.random.default_rng(seed)
    labels_true = rng.integers(-1, k_true, n)
    labels_pred = rng.integers(-1, k_pred, n)
    labels_true[0], labels_pred[0] = 0, 0  # at least one scored pair
    a = rng.normal(size=(n, 3))
    return a, labels_true, labels_pred, motions(k_true, seed), motions(k_pred, seed + 1)


# ----------------------------------------------------------- ground-truth poses


def test_ground_truth_poses_recover_a_noiseless_scene():
    scene = make_scene(n_objects=3, n_points=300, outlier_fraction=0.2, random_state=0)
    rotations, translations = ground_truth_poses(scene.X, scene.labels)
    np.testing.assert_allclose(rotations, scene.rotations, atol=1e-10)
    np.testing.assert_allclose(translations, scene.translations, atol=1e-10)


def test_ground_truth_poses_n_objects_pads_with_identity():
    scene = make_scene(n_objects=2, n_points=100, random_state=0)
    rotations, translations = ground_truth_poses(scene.X, scene.labels, n_objects=4)
    assert rotations.shape == (4, 3, 3)
    np.testing.assert_array_equal(rotations[2:], np.stack([np.eye(3)] * 2))
    with pytest.raises(ValueError, match="too few"):
        ground_truth_poses(scene.X, scene.labels, n_objects=1)


# ------------------------------------------------------------ rotation errors


@pytest.mark.parametrize("angle", [0.0, 1e-4, 3.0, 45.0, 90.0, 179.0])
def test_rotation_error_of_known_rotations(angle):
    rotations, translations = motions(3, 0)
    axes = Rotation.random(3, random_state=1).as_rotvec()
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    offsets = Rotation.from_rotvec(np.radians(angle) * axes).as_matrix()
    labels = np.repeat(np.arange(3), 4)
    error = rotation_error(
        labels, labels, (rotations, translations), (rotations @ offsets, translations)
    )
    assert error == pytest.approx(angle, abs=1e-6)
    assert translation_error(
        labels, labels, (rotations, translations), (rotations @ offsets, translations)
    ) == pytest.approx(0.0, abs=1e-12)


def test_pose_errors_hand_computed_weights():
    eye = np.eye(3)
    rz90 = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    true = (np.stack([eye, rz90]), np.array([[0.0, 0, 0], [0, 0, 6]]))
    pred = (np.stack([eye, eye]), np.array([[0.0, 0, 0], [0, 0, 0]]))
    labels_true = [0, 0, 0, 1, 1, 1]
    labels_pred = [0, 0, 0, 0, 1, 1]
    # H_0: 3/4 of object 0 (0 deg, 0 m) and 1/4 of object 1 (90 deg, 6 m); H_1: object 1.
    assert rotation_error(labels_true, labels_pred, true, pred) == pytest.approx((22.5 + 90) / 2)
    assert translation_error(labels_true, labels_pred, true, pred) == pytest.approx((1.5 + 6) / 2)


def test_pose_errors_perfect_on_a_scene():
    scene = make_scene(n_objects=4, n_points=400, outlier_fraction=0.1, random_state=2)
    true = (scene.rotations, scene.translations)
    rng = np.random.default_rng(0)
    perm = rng.permutation(4)
    labels_pred = np.where(scene.labels >= 0, perm[scene.labels], -1)
    pred = (np.empty_like(scene.rotations), np.empty_like(scene.translations))
    pred[0][perm], pred[1][perm] = scene.rotations, scene.translations
    assert rotation_error(scene.labels, labels_pred, true, pred) == pytest.approx(0, abs=1e-6)
    assert translation_error(scene.labels, labels_pred, true, pred) == pytest.approx(0, abs=1e-12)


def test_pose_errors_skip_outliers_on_both_sides():
    true = (np.stack([np.eye(3)]), np.array([[0.0, 0, 0]]))
    pred = (np.stack([np.eye(3)] * 2), np.array([[2.0, 0, 0], [50, 0, 0]]))
    # H_0 meets object 0 on 2 points and the true outliers on 2: weight renormalised to 1.
    # H_1 holds only true outliers: not scored. The estimated outliers have no pose.
    labels_true = [0, 0, -1, -1, -1, 0]
    labels_pred = [0, 0, 0, 0, 1, -1]
    assert translation_error(labels_true, labels_pred, true, pred) == pytest.approx(2.0)


def test_pose_errors_undefined_without_any_match():
    true = (np.stack([np.eye(3)]), np.zeros((1, 3)))
    pred = (np.stack([np.eye(3)]), np.zeros((1, 3)))
    with pytest.warns(UndefinedMetricWarning, match="undefined"):
        assert np.isnan(rotation_error([0, 0, -1], [-1, -1, 0], true, pred))
    with pytest.warns(UndefinedMetricWarning, match="undefined"):
        assert np.isnan(translation_error([-1, -1], [0, 0], true, pred))


@given(random_case)
def test_pose_errors_match_brute_force(case):
    _, labels_true, labels_pred, true, pred = make_case(*case)
    expected = brute_force_pose_errors(labels_true, labels_pred, true, pred)
    assert rotation_error(labels_true, labels_pred, true, pred) == pytest.approx(
        expected[0], abs=1e-6
    )
    assert translation_error(labels_true, labels_pred, true, pred) == pytest.approx(
        expected[1], abs=1e-10
    )


@given(random_case, st.integers(0, 2**16))
def test_errors_invariant_to_renumbering(case, seed):
    a, labels_true, labels_pred, true, pred = make_case(*case)
    X = np.hstack([a, a])
    rng = np.random.default_rng(seed)
    perm_true = rng.permutation(len(true[0]))
    perm_pred = rng.permutation(len(pred[0]))
    new_true = np.where(labels_true >= 0, perm_true[labels_true], -1)
    new_pred = np.where(labels_pred >= 0, perm_pred[labels_pred], -1)
    moved_true = (np.empty_like(true[0]), np.empty_like(true[1]))
    moved_true[0][perm_true], moved_true[1][perm_true] = true
    moved_pred = (np.empty_like(pred[0]), np.empty_like(pred[1]))
    moved_pred[0][perm_pred], moved_pred[1][perm_pred] = pred
    for metric in (rotation_error, translation_error):
        assert metric(new_true, new_pred, moved_true, moved_pred) == pytest.approx(
            metric(labels_true, labels_pred, true, pred), abs=1e-9
        )
    assert per_point_error(X, new_true, new_pred, moved_true, moved_pred) == pytest.approx(
        per_point_error(X, labels_true, labels_pred, true, pred), abs=1e-9
    )


# ----------------------------------------------------------- chamfer distance


@given(st.integers(1, 30), st.integers(1, 30), st.integers(1, 4), st.integers(0, 2**16))
def test_chamfer_matches_brute_force(n_p, n_q, d, seed):
    rng = np.random.default_rng(seed)
    p, q = rng.normal(size=(n_p, d)), rng.normal(size=(n_q, d)) + 0.5
    assert chamfer_distance(p, q) == pytest.approx(brute_force_chamfer(p, q), rel=1e-12)
    assert chamfer_distance(p, q) == pytest.approx(chamfer_distance(q, p), rel=1e-12)


def test_chamfer_hand_computed():
    # P -> Q: 0 and 1; Q -> P: 0, 1 and 3: (0.5 + 4/3) / 2.
    p = [[0.0, 0], [1, 0]]
    q = [[0.0, 0], [2, 0], [4, 0]]
    assert chamfer_distance(p, q) == pytest.approx((0.5 + 4 / 3) / 2)
    assert chamfer_distance(p, p) == 0.0


def test_chamfer_rejects_mismatched_dimensions():
    with pytest.raises(ValueError, match="same dimension"):
        chamfer_distance(np.zeros((2, 3)), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="NaN|infinity"):
        chamfer_distance([[np.nan, 0]], [[0.0, 0]])


# ------------------------------------------------------------ per-point error


def test_per_point_error_hand_computed():
    a = np.array([[0.0, 0, 0], [1, 0, 0], [5, 0, 0], [6, 0, 0]])
    X = np.hstack([a, a])
    identity = (np.stack([np.eye(3)] * 2), np.zeros((2, 3)))
    shift = (np.stack([np.eye(3)] * 2), np.array([[0.0, 0, 0], [0, 3, 0]]))
    labels = [0, 0, 1, 1]
    assert per_point_error(X, labels, [1, 1, 0, 0], identity, identity) == 0.0
    # Object 1 moved 3 m off: its Chamfer distance is 3, the mean over objects 1.5.
    assert per_point_error(X, labels, labels, identity, shift) == pytest.approx(1.5)
    # One estimated object for both: moved by identity, matched to object 0 (tie, first
    # point); P -> Q: 0, 0, 4, 5; Q -> P: 0, 0.
    one = (np.stack([np.eye(3)]), np.zeros((1, 3)))
    assert per_point_error(X, labels, [0, 0, 0, 0], identity, one) == pytest.approx(9 / 8)


def test_per_point_error_perfect_on_a_noisy_scene():
    scene = make_scene(n_objects=3, n_points=300, noise=0.05, outlier_fraction=0.1, random_state=4)
    true = (scene.rotations, scene.translations)
    assert per_point_error(scene.X, scene.labels, scene.labels, true, true) == 0.0
    # Horn's poses on noisy data are close to, but not exactly, the true ones.
    fitted = ground_truth_poses(scene.X, scene.labels)
    error = per_point_error(scene.X, scene.labels, scene.labels, true, fitted)
    assert 0.0 < error < 0.05


def test_per_point_error_outliers():
    a = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [9, 9, 9]])
    X = np.hstack([a, a])
    true = (np.stack([np.eye(3)]), np.zeros((1, 3)))
    pred = (np.stack([np.eye(3)] * 2), np.zeros((2, 3)))
    # The estimated outlier row is not an object; H_1 = the true outlier is not scored.
    assert per_point_error(X, [0, 0, 0, -1], [0, 0, -1, 1], true, pred) == pytest.approx(
        brute_force_chamfer(a[:2], a[:3])
    )
    # A true outlier inside an estimated object is moved with it and penalised.
    assert per_point_error(X, [0, 0, 0, -1], [0, 0, 0, 0], true, pred) == pytest.approx(
        brute_force_chamfer(a, a[:3])
    )
    with pytest.warns(UndefinedMetricWarning, match="undefined"):
        assert np.isnan(per_point_error(X, [0, 0, 0, -1], [-1, -1, -1, 0], true, pred))


@given(random_case)
def test_per_point_error_matches_brute_force(case):
    a, labels_true, labels_pred, true, pred = make_case(*case)
    X = np.hstack([a, a + 1.0])
    expected = brute_force_per_point(a, labels_true, labels_pred, true, pred)
    assert per_point_error(X, labels_true, labels_pred, true, pred) == pytest.approx(
        expected, rel=1e-10
    )


def test_per_point_error_on_a_paper_sized_scene():
    scene = make_scene(n_objects=7, n_points=22395, noise=0.03, random_state=0)
    labels_pred = np.random.default_rng(0).integers(0, 100, len(scene.labels))
    fitted = ground_truth_poses(scene.X, labels_pred)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        error = per_point_error(
            scene.X, scene.labels, labels_pred, (scene.rotations, scene.translations), fitted
        )
    assert np.isfinite(error) and error > 0


# ----------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("transforms", "error", "match"),
    [
        (np.zeros((2, 3, 3)), TypeError, "pair"),
        ((np.zeros((2, 3)), np.zeros((2, 3))), ValueError, r"\(K, d, d\)"),
        ((np.zeros((2, 3, 3)), np.zeros((3, 3))), ValueError, "translations"),
        ((np.zeros((1, 3, 3)), np.zeros((1, 3))), ValueError, "only 1 motions"),
        ((np.full((2, 3, 3), np.nan), np.zeros((2, 3))), ValueError, "NaN"),
        ((np.zeros((2, 2, 2)), np.zeros((2, 2))), ValueError, "2-D motions"),
    ],
)
def test_bad_transforms_raise(transforms, error, match):
    labels = [0, 0, 1, 1]
    good = (np.stack([np.eye(3)] * 2), np.zeros((2, 3)))
    X = np.zeros((4, 6))
    with pytest.raises(error, match=match):
        per_point_error(X, labels, labels, good, transforms)
    if "2-D" not in match:
        with pytest.raises(error, match=match):
            rotation_error(labels, labels, good, transforms)


def test_bad_correspondences_raise():
    good = (np.stack([np.eye(3)] * 2), np.zeros((2, 3)))
    labels = [0, 0, 1, 1]
    with pytest.raises(ValueError, match="3 correspondences"):
        per_point_error(np.zeros((3, 6)), labels, labels, good, good)
    with pytest.raises(ValueError, match="even number of columns"):
        per_point_error(np.zeros((4, 5)), labels, labels, good, good)
    with pytest.raises(ValueError, match="NaN|infinity"):
        per_point_error(np.full((4, 6), np.nan), labels, labels, good, good)
    with pytest.raises(ValueError, match="different lengths"):
        translation_error(labels, labels[:3], good, good)
