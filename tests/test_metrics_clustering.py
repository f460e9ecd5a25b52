"""IoU and misclassification error: hand-computed cases, brute force, invariances, checks."""

import itertools

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from sklearn.metrics import adjusted_rand_score as sklearn_ari

from mmreg.metrics import adjusted_rand_score, iou_score, misclassification_error, objects_found


def brute_force_iou(labels_true, labels_pred):
    """The paper's definition, one cluster at a time with Python sets."""
    labels_true, labels_pred = list(labels_true), list(labels_pred)
    rows = range(len(labels_true))
    true_sets = {k: {i for i in rows if labels_true[i] == k} for k in set(labels_true)}
    scores = []
    for j in set(labels_pred):
        h = {i for i in rows if labels_pred[i] == j}
        best = max(true_sets.values(), key=lambda g: (len(h & g), -len(g)))
        scores.append(len(h & best) / len(h | best))
    return sum(scores) / len(scores)


def brute_force_misclassification(labels_true, labels_pred):
    """Try every one-to-one matching of the smaller side into the larger."""
    classes_true = sorted(set(labels_true))
    classes_pred = sorted(set(labels_pred))
    counts = {
        (k, j): sum(1 for t, p in zip(labels_true, labels_pred, strict=True) if t == k and p == j)
        for k in classes_true
        for j in classes_pred
    }
    if len(classes_true) <= len(classes_pred):
        best = max(
            sum(counts[k, j] for k, j in zip(classes_true, perm, strict=True))
            for perm in itertools.permutations(classes_pred, len(classes_true))
        )
    else:
        best = max(
            sum(counts[k, j] for k, j in zip(perm, classes_pred, strict=True))
            for perm in itertools.permutations(classes_true, len(classes_pred))
        )
    return 1 - best / len(labels_true)


label_pairs = st.integers(1, 30).flatmap(
    lambda n: st.tuples(
        st.lists(st.integers(-1, 4), min_size=n, max_size=n),
        st.lists(st.integers(-1, 5), min_size=n, max_size=n),
    )
)


def relabel(labels, seed, keep_outliers=True):
    """Rename the clusters by a random permutation (``-1`` stays ``-1`` if asked)."""
    labels = np.asarray(labels)
    rng = np.random.default_rng(seed)
    classes = np.unique(labels[labels >= 0]) if keep_outliers else np.unique(labels)
    new = rng.permutation(100)[: len(classes)] + 10
    out = labels.copy()
    for old, fresh in zip(classes, new, strict=True):
        out[labels == old] = fresh
    return out


# ---------------------------------------------------------------- IoU, by hand


def test_iou_hand_computed_with_outliers():
    # H_0 = {0,1} -> G_0, 2/3; H_1 = {2,3,4} -> G_1 (2 shared), 2/3; H_-1 = {5} -> G_-1, 1.
    assert iou_score([0, 0, 0, 1, 1, -1], [0, 0, 1, 1, 1, -1]) == pytest.approx(7 / 9)


def test_iou_perfect_up_to_renumbering():
    assert iou_score([0, 0, 1, 1, 2, -1], [7, 7, 3, 3, 0, 1]) == 1.0


def test_iou_single_cluster_each_side():
    assert iou_score([0] * 5, [3] * 5) == 1.0
    assert iou_score([-1] * 5, [-1] * 5) == 1.0


def test_iou_worst_cases():
    # One estimated cluster over K equal objects: |G|/n = 1/K.
    assert iou_score(np.repeat(np.arange(4), 5), np.zeros(20, int)) == pytest.approx(1 / 4)
    # n singletons for one object: each has IoU 1/n.
    assert iou_score(np.zeros(8, int), np.arange(8)) == pytest.approx(1 / 8)


def test_iou_outliers_are_one_cluster_on_each_side():
    # Everything declared an outlier: one estimated cluster of 4, sharing 2 with G_0 and
    # 2 with the true outliers (both of size 2): 2/4 either way.
    assert iou_score([0, 0, -1, -1], [-1, -1, -1, -1]) == 0.5
    # The estimated outliers are scored as a cluster, and match the true outliers.
    assert iou_score([0, 0, -1, -1], [0, 0, -1, 0]) == pytest.approx((2 / 3 + 1 / 2) / 2)


def test_iou_empty_clusters_do_not_count():
    assert iou_score([0, 0, 1, 1], [0, 0, 5, 5]) == 1.0
    assert iou_score([0, 0, 9, 9], [0, 0, 1, 1]) == 1.0


def test_iou_ties_go_to_the_larger_iou():
    # H_0 = {2,3,4,5} shares 2 with G_0 (size 4) and 2 with G_1 (size 2): IoU 1/3 vs 1/2.
    assert iou_score([0, 0, 0, 0, 1, 1], [1, 1, 0, 0, 0, 0]) == pytest.approx(0.5)


def test_iou_several_estimated_clusters_may_share_an_object():
    # Both halves match the same object: 2/4 each, not a one-to-one matching.
    assert iou_score([0, 0, 0, 0, 1], [0, 0, 1, 1, 2]) == pytest.approx((0.5 + 0.5 + 1) / 3)


@given(label_pairs)
def test_iou_matches_brute_force(pair):
    labels_true, labels_pred = pair
    assert iou_score(labels_true, labels_pred) == pytest.approx(
        brute_force_iou(labels_true, labels_pred), abs=1e-12
    )


@given(label_pairs, st.integers(0, 2**16))
def test_iou_invariant_to_renumbering(pair, seed):
    labels_true, labels_pred = pair
    expected = iou_score(labels_true, labels_pred)
    renamed = iou_score(relabel(labels_true, seed), relabel(labels_pred, seed + 1))
    assert renamed == pytest.approx(expected, abs=1e-12)


@given(label_pairs)
def test_iou_in_unit_interval(pair):
    score = iou_score(*pair)
    assert 0.0 < score <= 1.0


# ------------------------------------------------------- misclassification error


def test_misclassification_hand_computed():
    assert misclassification_error([0, 0, 1, 1], [0, 0, 0, 1]) == 0.25
    # Surplus estimated cluster: best matching 0->0, 1->1 covers 4 of 6.
    assert misclassification_error([0, 0, 0, 1, 1, 1], [0, 0, 2, 1, 1, 2]) == pytest.approx(2 / 6)


def test_misclassification_perfect_and_worst():
    assert misclassification_error([0, 0, 1, -1], [4, 4, -1, 2]) == 0.0
    assert misclassification_error(np.zeros(10, int), np.arange(10)) == pytest.approx(0.9)
    assert misclassification_error(np.arange(10), np.zeros(10, int)) == pytest.approx(0.9)


def test_misclassification_outliers_are_a_class():
    # -1 matched to -1 like any other cluster; here only the last row is wrong.
    assert misclassification_error([0, 0, -1, -1], [0, 0, -1, 0]) == 0.25


@given(label_pairs)
def test_misclassification_matches_brute_force(pair):
    labels_true, labels_pred = pair
    assert misclassification_error(labels_true, labels_pred) == pytest.approx(
        brute_force_misclassification(labels_true, labels_pred), abs=1e-12
    )


@given(label_pairs, st.integers(0, 2**16))
def test_misclassification_invariant_to_renumbering(pair, seed):
    labels_true, labels_pred = pair
    expected = misclassification_error(labels_true, labels_pred)
    renamed = misclassification_error(
        relabel(labels_true, seed, keep_outliers=False),
        relabel(labels_pred, seed + 1, keep_outliers=False),
    )
    assert renamed == pytest.approx(expected, abs=1e-12)


def test_adjusted_rand_is_sklearns():
    assert adjusted_rand_score is sklearn_ari
    assert adjusted_rand_score([0, 0, -1, -1], [1, 1, 0, 0]) == 1.0


# ------------------------------------------------------------------ validation


@pytest.mark.parametrize("metric", [iou_score, misclassification_error])
@pytest.mark.parametrize(
    ("labels_true", "labels_pred", "error", "match"),
    [
        ([0, 1, 1], [0, 1], ValueError, "different lengths"),
        ([[0, 1]], [0, 1], ValueError, "1-D"),
        ([0, 1], [[0, 1]], ValueError, "1-D"),
        ([0.0, np.nan], [0, 1], ValueError, "NaN"),
        ([0, 1], [0.5, 1], TypeError, "integers"),
        (["a", "b"], [0, 1], TypeError, "integers"),
        ([], [], ValueError, "empty"),
        (3, [0], ValueError, "1-D"),
    ],
)
def test_bad_labels_raise(metric, labels_true, labels_pred, error, match):
    with pytest.raises(error, match=match):
        metric(labels_true, labels_pred)


def test_integer_valued_floats_are_accepted():
    assert iou_score([0.0, 0.0, 1.0], [1, 1, 0]) == 1.0


def test_objects_found_against_a_brute_force_count():
    rng = np.random.default_rng(0)
    for _ in range(50):
        truth = rng.integers(-1, 4, 60)
        pred = rng.integers(-1, 5, 60)
        expected = []
        for k in np.unique(truth[truth >= 0]):
            g = truth == k
            ious = [(g & (pred == j)).sum() / (g | (pred == j)).sum() for j in range(5)]
            expected.append(max(ious) >= 0.5)
        assert objects_found(truth, pred) == pytest.approx(np.mean(expected))


def test_objects_found_counts_the_objects_asked_for():
    truth = np.repeat([0, 1, 2], [80, 10, 10])
    one_cluster = np.zeros(100, dtype=int)
    # The paper's IoU rewards one big cluster; no moving object is found in it.
    assert iou_score(truth, one_cluster) == pytest.approx(0.8)
    assert objects_found(truth, one_cluster, objects=[1, 2]) == 0.0
    assert objects_found(truth, truth, objects=[1, 2]) == 1.0
    assert np.isnan(objects_found(truth, truth, objects=[]))
