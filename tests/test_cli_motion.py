"""mmreg._array.motion: the static world and which clusters move, by robust statistics."""

import numpy as np
import pytest

from mmreg._array.motion import MOVING_FACTOR, motion_statistics, moving_clusters, static_cluster


def _turn(degrees):
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _scene(n_wrong, *, degrees=15.0, shift=1.0, noise=0.02, seed=0):
    """A static ground (label 0), a car (1) turned and moved, a static box (2)."""
    rng = np.random.default_rng(seed)
    ground = rng.uniform([-15, -15, 0], [15, 15, 0.2], (2000, 3))
    car = rng.uniform([-2, -1, 0.3], [2, 1, 1.8], (400, 3)) + [5, 3, 0]
    box = rng.uniform([-1, -1, 0], [1, 1, 2], (300, 3)) + [-6, 4, 0]
    a = np.vstack([ground, car, box])
    labels = np.repeat([0, 1, 2], [len(ground), len(car), len(box)])
    center = car.mean(axis=0)
    rotations = np.stack([np.eye(3), _turn(degrees), np.eye(3)])
    car_shift = center - _turn(degrees) @ center + [shift, 0, 0]
    translations = np.array([[0, 0, 0], car_shift, [0, 0, 0]])
    b = np.einsum("nij,nj->ni", rotations[labels], a) + translations[labels]
    b += rng.normal(0, noise, b.shape)
    for label in (1, 2):  # wrong correspondences, metres off
        wrong = np.flatnonzero(labels == label)[:n_wrong]
        b[wrong] += rng.uniform(-15, 15, (len(wrong), 3))
    return a, b, labels, rotations, translations


def _old_rule(a, b, labels, rotations, translations):
    """The former rule: mean displacement > 3 x RMS residual (outliers inflate the RMS)."""
    moving = []
    for j in range(len(rotations)):
        pts = a[labels == j]
        own = pts @ rotations[j].T + translations[j]
        rms = np.sqrt(np.mean(np.sum((own - b[labels == j]) ** 2, axis=1)))
        gap = np.linalg.norm(own - (pts @ rotations[0].T + translations[0]), axis=1).mean()
        moving.append(j != 0 and gap > 3 * rms)
    return np.array(moving)


def test_static_cluster_is_the_largest():
    assert static_cluster([2, 2, 0, 1, 1, 1, -1]) == 1
    assert static_cluster(np.array([3, 3, 5, 5])) == 3  # ties: the smallest label
    assert static_cluster([-1, -1, -3]) == -1
    assert static_cluster(np.array([], dtype=int)) == -1


@pytest.mark.parametrize("n_wrong", [0, 40, 120])
def test_moving_car_with_wrong_correspondences_is_moving(n_wrong):
    a, b, labels, rotations, translations = _scene(n_wrong)
    moving = moving_clusters(a, b, labels, rotations, translations, static_cluster(labels))
    assert moving.tolist() == [False, True, False]
    displacement, scale = motion_statistics(a, b, labels, rotations, translations, 0)
    # Far from the cut-off: the car clearly moves, the box clearly does not.
    assert displacement[1] > 5 * MOVING_FACTOR * scale[1]
    assert displacement[2] < 0.2 * MOVING_FACTOR * scale[2]


def test_the_old_rule_missed_the_car():
    a, b, labels, rotations, translations = _scene(120)
    assert _old_rule(a, b, labels, rotations, translations).tolist() == [False, False, False]


def test_noiseless_clusters_are_well_posed():
    a, b, labels, rotations, translations = _scene(0, noise=0.0)
    moving = moving_clusters(a, b, labels, rotations, translations, 0)
    assert moving.tolist() == [False, True, False]
    _, scale = motion_statistics(a, b, labels, rotations, translations, 0)
    assert np.all(scale > 0)


def test_no_static_cluster_and_empty_clusters():
    a, b, labels, rotations, translations = _scene(0)
    assert not moving_clusters(a, b, labels, rotations, translations, -1).any()
    labels = labels.copy()
    labels[labels == 2] = -1  # cluster 2 has no points left
    moving = moving_clusters(a, b, labels, rotations, translations, 0)
    assert moving.tolist() == [False, True, False]
    displacement, scale = motion_statistics(a, b, labels, rotations, translations, 0)
    assert np.isnan(displacement[2]) and np.isnan(scale[2])


def test_matches_a_loop_over_clusters():
    """The vectorised statistics equal a plain per-cluster computation."""
    rng = np.random.default_rng(3)
    n, k = 500, 6
    a, b = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    labels = rng.integers(-1, k, n)
    rotations = np.stack([_turn(d) for d in rng.uniform(0, 90, k)])
    translations = rng.normal(size=(k, 3))
    displacement, scale = motion_statistics(a, b, labels, rotations, translations, 2)
    for j in range(k):
        pts, bs = a[labels == j], b[labels == j]
        own = pts @ rotations[j].T + translations[j]
        r = np.linalg.norm(own - bs, axis=1)
        mad = np.median(np.abs(r - np.median(r)))
        inliers = r <= np.median(r) + 3 * 1.4826 * mad
        assert scale[j] == pytest.approx(np.sqrt(np.mean(r[inliers] ** 2)))
        gap = np.linalg.norm(own - (pts @ rotations[2].T + translations[2]), axis=1)
        assert displacement[j] == (0.0 if j == 2 else pytest.approx(np.median(gap)))


def test_bad_shapes():
    a = np.zeros((4, 3))
    with pytest.raises(ValueError, match="same shape"):
        moving_clusters(a, np.zeros((3, 3)), np.zeros(4, int), np.eye(3)[None], np.zeros((1, 3)), 0)
    with pytest.raises(ValueError, match="labels go up to 1"):
        moving_clusters(a, a, np.array([0, 1, 0, 1]), np.eye(3)[None], np.zeros((1, 3)), 0)


@pytest.mark.parametrize("n_groups", [7, 40_000])  # the int16 radix path and the other
def test_group_median_is_the_median_of_each_group(n_groups):
    from mmreg._array.motion import _group_median

    rng = np.random.default_rng(n_groups)
    groups = rng.integers(0, n_groups, 60_000)
    values = rng.integers(0, 50, 60_000).astype(float)  # many ties
    got = _group_median(values, groups, n_groups + 2)  # the last two groups are empty
    expected = [
        np.median(values[groups == g]) if np.any(groups == g) else np.nan
        for g in range(n_groups + 2)
    ]
    np.testing.assert_array_equal(got, expected)
