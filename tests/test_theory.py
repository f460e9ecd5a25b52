"""The checks of Definitions 1 and 2 against hand-made cases and brute-force references."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.distance import cdist

from mmreg._array.connectivity import min_gap_between
from mmreg._array.neighbors import connected_labels
from mmreg.datasets import make_scene
from mmreg.testing import (
    good_clusterings,
    ground_truth_scenes,
    rotations,
    scenes_with_good_clusterings,
)
from mmreg.theory import (
    is_good_clustering,
    is_tau_connected,
    satisfies_ground_truth,
    tau_components,
)

slow_data = settings(suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def same_partition(first, second):
    """Whether two label arrays group the points identically (up to renumbering)."""
    pairs = np.unique(np.column_stack([first, second]), axis=0)
    return len(pairs) == len(np.unique(first)) == len(np.unique(second))


def reference_components(points, tau, groups):
    """Radius-graph components (mmreg._array.neighbors), one group at a time."""
    labels = np.empty(len(points), dtype=np.intp)
    offset = 0
    for group in np.unique(groups):
        idx = np.flatnonzero(groups == group)
        n, comp = connected_labels(points[idx], tau)
        labels[idx] = comp + offset
        offset += n
    return offset, labels


# --- tau-connectivity -------------------------------------------------------------------


@st.composite
def point_sets(draw):
    d = draw(st.integers(1, 5))
    n = draw(st.integers(1, 60))
    # Integer lattices make many distances exactly equal to tau: the "<=" boundary. The
    # coordinates are small integers, so every squared distance is exact in floating point
    # and both implementations must agree there on any machine.
    lattice = draw(st.booleans())
    elements = st.integers(0, 4).map(float) if lattice else st.floats(0, 10, width=32)
    points = draw(arrays(float, (n, d), elements=elements))
    tau = float(draw(st.integers(1, 3))) if lattice else draw(st.floats(0.05, 4.0))
    groups = draw(arrays(np.int64, n, elements=st.integers(0, 2)))
    return points, tau, groups


@given(point_sets())
def test_tau_components_match_the_radius_graph(case):
    points, tau, groups = case
    n1, labels1 = tau_components(points, tau, groups)
    n2, labels2 = reference_components(points, tau, groups)
    assert n1 == n2
    assert same_partition(labels1, labels2)
    # Components never straddle groups.
    assert same_partition(labels1, np.column_stack([labels1, groups]) @ [1, 10**6])


def test_tau_components_on_a_dense_scene_with_a_large_tau():
    # tau = 1.5 on ~3,200 points per unit-size object: the radius graph would list about
    # 36 million pairs; the grid needs none of them.
    scene = make_scene(n_objects=7, random_state=0)
    n, labels = tau_components(scene.a, 1.5)
    assert n == 7
    assert same_partition(labels, scene.labels)


def test_is_tau_connected_basic_cases():
    line = np.column_stack([np.arange(5.0), np.zeros(5)])
    assert is_tau_connected(line, 1.0)
    assert not is_tau_connected(line, 0.999)
    assert is_tau_connected(line[:1], 0.1)
    assert is_tau_connected(np.zeros((0, 3)), 0.1)
    assert is_tau_connected(np.zeros((4, 3)), 1e-9)  # coincident points are joined


@pytest.mark.parametrize("tau", [0, -1.0, "1"])
def test_is_tau_connected_rejects_bad_tau(tau):
    with pytest.raises((ValueError, TypeError), match="tau"):
        is_tau_connected(np.zeros((3, 3)), tau)


@given(point_sets())
def test_min_gap_between_matches_brute_force(case):
    points, _, groups = case
    gap, pair = min_gap_between(points, groups)
    present = np.unique(groups)
    if len(present) < 2:
        assert gap == np.inf and pair is None
        return
    expected = min(
        cdist(points[groups == i], points[groups == j]).min()
        for i in present
        for j in present
        if i < j
    )
    assert gap == pytest.approx(expected, abs=1e-12)
    i, j = pair
    assert cdist(points[groups == i], points[groups == j]).min() == pytest.approx(gap, abs=1e-12)


# --- Definition 1 -------------------------------------------------------------------------


def mst_bottleneck(points):
    """Smallest tau making ``points`` tau-connected, by bisection on the radius graph."""
    distances = np.unique(cdist(points, points))
    lo, hi = 0, len(distances) - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if connected_labels(points, distances[mid])[0] == 1:
            hi = mid
        else:
            lo = mid + 1
    return distances[lo]


@slow_data
@given(ground_truth_scenes())
def test_ground_truth_report_matches_brute_force(scene):
    report = satisfies_ground_truth(scene.X, scene.labels, scene, scene.tau, scene.sigma)
    a, b, labels = scene.a, scene.b, scene.labels
    n_objects = labels.max() + 1
    assert report.n_objects == n_objects
    for j in range(n_objects):
        g = labels == j
        res = b[g] - a[g] @ scene.rotations[j].T - scene.translations[j]
        assert report.noise[j] == pytest.approx(np.abs(res).max(), abs=1e-12)
        assert report.pieces[j] == connected_labels(a[g], scene.tau)[0]
    gaps = [
        cdist(a[labels == i], a[labels == j]).min()
        for i in range(n_objects)
        for j in range(i + 1, n_objects)
    ]
    assert report.separation == pytest.approx(min(gaps, default=np.inf), abs=1e-12)
    if (labels < 0).any():
        outlier_gap = cdist(a[labels < 0], a[labels >= 0]).min()
        assert report.outlier_gap == pytest.approx(outlier_gap, abs=1e-12)
    assert report.bound == pytest.approx(np.linalg.norm(a, axis=1).max())


def test_ground_truth_report_on_make_scene_and_its_text():
    scene = make_scene(
        n_objects=3,
        n_points=3000,
        noise=0.02,
        noise_type="uniform",
        outlier_fraction=0.05,
        random_state=0,
    )
    report = satisfies_ground_truth(scene.X, scene.labels, scene, tau=0.5, sigma=0.02)
    assert report and report.holds and report.failures == ()
    text = str(report)
    assert text.startswith("Definition 1 (tau=0.5, sigma=0.02) holds:")
    for name in ("partition", "rigid", "noise", "connected", "separation", "bounded", "outliers"):
        assert f"[ok] {name}:" in text
    assert report["bounded"].holds
    with pytest.raises(KeyError, match="identifying"):
        report["identifying"]
    # An explicit bound B below max ||a|| fails only that condition.
    tight = satisfies_ground_truth(
        scene.X, scene.labels, scene, tau=0.5, sigma=0.02, bound=report.bound / 2
    )
    assert [c.name for c in tight.failures] == ["bounded"]
    # Transforms as a (rotations, translations) pair work the same.
    pair = satisfies_ground_truth(
        scene.X, scene.labels, (scene.rotations, scene.translations), tau=0.5, sigma=0.02
    )
    assert str(pair) == text


def test_ground_truth_finds_each_failure_by_name():
    # Two unit squares of 3 x 3 points, 2 apart along x, and one outlier.
    grid = np.array([[x, y, 0.0] for x in (0, 0.5, 1) for y in (0, 0.5, 1)])
    a = np.vstack([grid, grid + [3.0, 0, 0], [[1.5, 5, 0]]])
    labels = np.array([0] * 9 + [1] * 9 + [-1])
    rot = np.stack([np.eye(3), np.eye(3)])
    trans = np.array([[0.0, 0, 0], [1, 0, 0]])
    b = a + np.r_[np.zeros((9, 3)), np.tile([1.0, 0, 0], (9, 1)), [[0, 0, 0]]]
    X = np.hstack([a, b])

    def failing(**kw):
        args = dict(X=X, labels=labels, transforms=(rot, trans), tau=1.0, sigma=0.0) | kw
        return [c.name for c in satisfies_ground_truth(**args).failures]

    assert failing() == []
    assert failing(tau=2.5) == ["separation"]  # objects 2 apart: not "> tau"
    assert failing(tau=0.4) == ["connected"]  # grid step 0.5
    assert failing(tau=4.1) == ["separation", "outliers"]  # the outlier is 4.03 away
    noisy = X.copy()
    noisy[4, 3] += 0.1
    assert failing(X=noisy, sigma=0.05) == ["noise"]
    assert failing(X=noisy, sigma=0.1) == []
    flipped = rot.copy()
    flipped[1] = np.diag([1.0, 1.0, -1.0])
    assert "rigid" in failing(transforms=(flipped, trans))
    three = (np.stack([np.eye(3)] * 3), np.zeros((3, 3)))
    assert "partition" in failing(transforms=three)
    report = satisfies_ground_truth(X, labels, (rot, trans), tau=2.0, sigma=0)
    assert "objects 0 and 1 are 2 apart <= tau = 2" in str(report)


def test_ground_truth_rejects_malformed_input():
    scene = make_scene(n_objects=2, n_points=60, random_state=0)
    with pytest.raises(ValueError, match="only 2 motions"):
        satisfies_ground_truth(scene.X, scene.labels + 1, scene, tau=0.5, sigma=0)
    with pytest.raises(ValueError, match="shape"):
        satisfies_ground_truth(
            scene.X, scene.labels, (scene.rotations[:, :2], scene.translations), tau=0.5, sigma=0
        )
    with pytest.raises(TypeError, match="pair"):
        satisfies_ground_truth(scene.X, scene.labels, 3.0, tau=0.5, sigma=0)
    with pytest.raises(ValueError, match="even number of columns"):
        satisfies_ground_truth(scene.X[:, :5], scene.labels, scene, tau=0.5, sigma=0)
    with pytest.raises(ValueError, match="length"):
        satisfies_ground_truth(scene.X, scene.labels[:-1], scene, tau=0.5, sigma=0)
    with pytest.raises(ValueError, match="sigma"):
        satisfies_ground_truth(scene.X, scene.labels, scene, tau=0.5, sigma=-1)


@given(rotations())
def test_rotation_strategy_gives_proper_rotations(rotation):
    assert np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0)


# --- Definition 2 -------------------------------------------------------------------------


def reference_good_clustering(init, truth, a, tau):
    """Sizes, pieces and per-object |H*| / next, one cluster and object at a time."""
    clusters = np.unique(init[init >= 0])
    sizes = np.array([np.sum(init == k) for k in clusters])
    pieces = np.array([connected_labels(a[init == k], tau)[0] for k in clusters])
    ratios = []
    for obj in np.unique(truth[truth >= 0]):
        meeting = sorted(
            (np.sum(init == k) for k in np.unique(init[truth == obj]) if k >= 0), reverse=True
        )
        ratios.append(np.inf if len(meeting) == 1 else meeting[0] / meeting[1])
    return sizes, pieces, np.array(ratios)


@slow_data
@given(scenes_with_good_clusterings())
def test_good_clustering_report_matches_brute_force(pair):
    scene, clustering = pair
    report = is_good_clustering(
        clustering.labels, scene.labels, scene.X, scene.tau, clustering.alpha, clustering.m0
    )
    sizes, pieces, ratios = reference_good_clustering(
        clustering.labels, scene.labels, scene.a, scene.tau
    )
    np.testing.assert_array_equal(report.sizes, sizes)
    np.testing.assert_array_equal(report.pieces, pieces)
    np.testing.assert_allclose(report.ratios, ratios)
    assert report.max_alpha == ratios.min()
    assert report.n_clusters == len(sizes)
    assert report.n_objects == scene.labels.max() + 1


def test_good_clustering_hand_made_line():
    # One object: 12 points on a line, spacing 1; clusters of 8 and 4 consecutive points.
    a = np.column_stack([np.arange(12.0), np.zeros(12), np.zeros(12)])
    X = np.hstack([a, a])
    truth = np.zeros(12, dtype=int)
    init = np.repeat([5, 2], [8, 4])
    report = is_good_clustering(init, truth, X, tau=1.5, alpha=1.5, m0=4)
    assert report and report.max_alpha == 2.0 and report.max_m0 == 4
    assert "[ok] identifying" in str(report)

    def failing(labels=init, **kw):
        args = dict(tau=1.5, alpha=1.5, m0=4) | kw
        return [c.name for c in is_good_clustering(labels, truth, X, **args).failures]

    assert failing(alpha=2.5) == ["identifying"]  # 8 > 2.5 * 4 is false
    assert failing(m0=5) == ["size"]
    assert failing(tau=0.5) == ["connected"]
    interleaved = np.arange(12) % 2
    assert failing(interleaved, m0=1) == ["connected", "identifying"]
    unassigned = init.copy()
    unassigned[0] = -1
    assert failing(unassigned) == ["partition"]
    # alpha = 1 asks for a strictly largest cluster: a 6 / 6 tie fails.
    assert failing(np.repeat([0, 1], 6), alpha=1) == ["identifying"]
    assert failing(np.repeat([0, 1], [7, 5]), alpha=1) == []


def test_good_clustering_outlier_policies():
    # An object of 10 points on a line and 3 scattered outliers, far from it and each other.
    a = np.vstack(
        [
            np.column_stack([np.arange(10.0), np.zeros((10, 2))]),
            [[0, 50, 0], [0, 60, 0], [0, 70, 0]],
        ]
    )
    X = np.hstack([a, a])
    truth = np.r_[np.zeros(10, int), [-1, -1, -1]]
    unassigned = np.r_[np.zeros(10, int), [-1, -1, -1]]
    singletons = np.r_[np.zeros(10, int), [1, 2, 3]]
    together = np.r_[np.zeros(10, int), [1, 1, 1]]
    mixed = np.r_[np.zeros(10, int), [0, 1, 1]]

    def failing(labels, outliers):
        report = is_good_clustering(labels, truth, X, 1.0, 1.5, 2, outliers=outliers)
        return [c.name for c in report.failures]

    for labels in (unassigned, singletons, together):
        assert failing(labels, "exempt") == []
    assert failing(unassigned, "strict") == ["partition"]
    assert failing(singletons, "strict") == ["size"]
    assert failing(together, "strict") == ["connected"]
    assert set(failing(mixed, "exempt")) == {"connected", "pure"}


def test_good_clustering_rejects_malformed_input():
    X = np.zeros((6, 6))
    truth = np.zeros(6, int)
    with pytest.raises(ValueError, match="alpha"):
        is_good_clustering(truth, truth, X, 1.0, 0.5, 1)
    with pytest.raises(ValueError, match="m0"):
        is_good_clustering(truth, truth, X, 1.0, 1.5, 0)
    with pytest.raises(ValueError, match="outliers"):
        is_good_clustering(truth, truth, X, 1.0, 1.5, 1, outliers="ignore")
    with pytest.raises(ValueError, match="init_labels has length 5"):
        is_good_clustering(truth[:5], truth, X, 1.0, 1.5, 1)
    with pytest.raises(TypeError, match="integers"):
        is_good_clustering(truth + 0.5, truth, X, 1.0, 1.5, 1)


def test_checks_are_fast_on_100k_points():
    # Guards the O(n log n) claim; the radius graph at tau=1.5 would not finish.
    scene = make_scene(
        n_objects=7,
        n_points=100_000,
        noise=0.01,
        noise_type="uniform",
        outlier_fraction=0.05,
        random_state=0,
    )
    report = satisfies_ground_truth(scene.X, scene.labels, scene, tau=1.5, sigma=0.01)
    assert report, str(report)
    init = np.where(scene.labels >= 0, 2 * scene.labels + (scene.a[:, 2] > 0.3), -1)
    good = is_good_clustering(init, scene.labels, scene.X, 1.5, 1.0, 10)
    assert good["partition"] and good["connected"] and good["pure"] and good["size"]


def test_strategies_reject_impossible_requests():
    with pytest.raises(ValueError, match="gap_factor"):
        ground_truth_scenes(gap_factor=(1.0, 2.0))
    with pytest.raises(ValueError, match="m0"):
        scenes_with_good_clusterings(points_per_object=(10, 10), m0=(20, 30))
    scene = make_scene(n_objects=2, n_points=40, random_state=0)
    scene.tau = 0.5
    with pytest.raises(ValueError, match="smallest object has 20"):
        good_clusterings(scene, m0=(30, 40))
    with pytest.raises(ValueError, match="alpha"):
        good_clusterings(scene, alpha=(0.5, 2.0))
    with pytest.raises(ValueError, match="outliers"):
        good_clusterings(scene, outliers=("dropped",))
