"""EuclideanClustering: exact radius-graph components, the automatic radius, transform."""

import warnings

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.sparse.csgraph import connected_components
from scipy.spatial.distance import cdist

from mmreg._array.connectivity import cluster_components
from mmreg._array.neighbors import (
    NeighbourTable,
    minimum_spanning_forest,
    nearest_in_other_component,
    shortest_edges_between_components,
)
from mmreg.datasets import make_scene
from mmreg.init import EuclideanClustering, euclidean_clustering
from mmreg.init._euclidean import (
    _choose_radius,
    _complete_forest,
    _components,
    _GridPyramid,
    _knn_edges,
    _knn_forest,
    _nearest_in_other_group,
    _no_missing_edges,
    _pyramid_cell,
    _radius_for_count,
    _ZOrder,
)


def reference_labels(points, radius, min_cluster_size):
    """Euclidean clusters from the dense distance matrix: the definition itself."""
    adjacency = cdist(points, points) <= radius
    _, components = connected_components(adjacency, directed=False)
    sizes = np.bincount(components)
    return np.where(sizes[components] >= min_cluster_size, components, -1)


def same_partition(left, right):
    """Equal up to renumbering, with -1 meaning the same on both sides."""
    if not np.array_equal(left < 0, right < 0):
        return False
    keep = left >= 0
    pairs = np.unique(np.column_stack([left[keep], right[keep]]), axis=0)
    return len(pairs) == len(np.unique(left[keep])) == len(np.unique(right[keep]))


@st.composite
def point_sets(draw):
    """Small clouds of a few blobs, with some points repeated exactly."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    d = draw(st.integers(1, 3))
    n_blobs = draw(st.integers(1, 5))
    n = draw(st.integers(2, 120))
    centers = rng.uniform(-5, 5, size=(n_blobs, d))
    points = centers[rng.integers(n_blobs, size=n)] + rng.normal(scale=0.5, size=(n, d))
    n_copies = draw(st.integers(0, min(5, n - 1)))
    points[:n_copies] = points[n - n_copies :]
    return points


@given(
    points=point_sets(),
    n_clusters=st.integers(1, 12),
    min_cluster_size=st.integers(1, 4),
    n_neighbors=st.sampled_from([1, 2, 6]),
)
def test_auto_radius_gives_exactly_the_radius_graph_components(
    points, n_clusters, min_cluster_size, n_neighbors
):
    # n_neighbors=1 misses most radius-graph edges, so the repair and the Boruvka
    # completion are exercised; the clusters must be exact whatever it is.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        labels, radius = euclidean_clustering(
            points,
            n_clusters=n_clusters,
            min_cluster_size=min_cluster_size,
            n_neighbors=n_neighbors,
        )
    assert same_partition(labels, reference_labels(points, radius, min_cluster_size))
    # Numbered 0..K-1 in order of first point.
    firsts = [np.flatnonzero(labels == j)[0] for j in range(labels.max() + 1)]
    assert firsts == sorted(firsts)


@given(points=point_sets(), radius=st.floats(0, 3), min_cluster_size=st.integers(1, 4))
def test_explicit_radius_matches_definition(points, radius, min_cluster_size):
    labels, used = euclidean_clustering(points, radius=radius, min_cluster_size=min_cluster_size)
    assert used == radius
    assert same_partition(labels, reference_labels(points, radius, min_cluster_size))


@given(points=point_sets(), n_clusters=st.integers(1, 10))
def test_count_is_met_when_reachable(points, n_clusters):
    # With min_cluster_size=1 every component counts, and their number falls one by one
    # as the radius grows, from n (distinct points) to 1.
    n_distinct = len(np.unique(points, axis=0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        labels, _ = euclidean_clustering(points, n_clusters=n_clusters, min_cluster_size=1)
    assert labels.max() + 1 == min(n_clusters, n_distinct)


def test_minimum_spanning_forest_is_single_linkage():
    rng = np.random.default_rng(0)
    points = rng.normal(size=(60, 2))
    dist = cdist(points, points)
    i, j = np.triu_indices(60, 1)
    forest, lengths = minimum_spanning_forest(60, np.column_stack([i, j]), dist[i, j])
    assert forest.shape == (59, 2) and np.all(np.diff(lengths) >= 0)
    for radius in np.quantile(lengths, [0.2, 0.5, 0.9]):
        _, expected = connected_components(dist <= radius, directed=False)
        keep = lengths <= radius
        adjacency = np.zeros((60, 60), dtype=bool)
        adjacency[forest[keep, 0], forest[keep, 1]] = True
        _, got = connected_components(adjacency, directed=False)
        assert same_partition(got, expected)


def test_minimum_spanning_forest_keeps_zero_length_and_shortest_repeat():
    edges = np.array([[0, 1], [1, 0], [1, 2], [2, 1], [2, 3]])
    lengths = np.array([0.0, 0.0, 5.0, 2.0, 1.0])
    forest, forest_lengths = minimum_spanning_forest(4, edges, lengths)
    assert forest_lengths.tolist() == [0.0, 1.0, 2.0]
    assert sorted(map(sorted, forest.tolist())) == [[0, 1], [1, 2], [2, 3]]


@pytest.mark.parametrize("n_clusters", [8, 30, 60])
def test_cluster_count_on_scene(n_clusters):
    scene = make_scene(n_objects=4, n_points=3000, noise=0.01, random_state=3)
    init = EuclideanClustering(n_clusters=n_clusters, min_cluster_size=4).fit(scene.X)
    assert init.n_clusters_ == n_clusters
    assert same_partition(init.labels_, reference_labels(scene.a, init.radius_, 4))
    # Each cluster lies inside one object, and is tau-connected for any tau >= radius_.
    clustered = init.labels_ >= 0
    pairs = np.unique(np.column_stack([init.labels_, scene.labels])[clustered], axis=0)
    assert len(pairs) == n_clusters
    pieces = cluster_components(scene.a, init.labels_, init.radius_)
    assert np.all(pieces == 1)


def test_fewer_clusters_than_separated_objects():
    # The k-NN graph falls apart into the objects: the forest must be completed.
    scene = make_scene(n_objects=5, n_points=1000, random_state=0)
    init = EuclideanClustering(n_clusters=2, min_cluster_size=1).fit(scene.X)
    assert init.n_clusters_ == 2
    assert init.radius_ > 2.0  # the objects are more than `separation` apart
    assert same_partition(init.labels_, reference_labels(scene.a, init.radius_, 1))


def test_unreachable_count_warns_and_uses_best_radius():
    points = np.array([[0.0], [1.0], [3.0], [6.0]])
    X = np.hstack([points, points])
    with pytest.warns(UserWarning, match="No radius tried gives n_clusters=3"):
        init = EuclideanClustering(n_clusters=3, min_cluster_size=2).fit(X)
    # Never more than one component of two points: the largest radius with one is used.
    assert init.n_clusters_ == 1
    assert init.labels_.tolist() == [0, 0, 0, 0]


def test_small_components_are_unassigned():
    points = np.array([[0.0, 0], [0.1, 0], [0.2, 0], [3, 0], [3.1, 0], [9, 9]])
    X = np.hstack([points, points])
    init = EuclideanClustering(radius=0.5, min_cluster_size=3).fit(X)
    assert init.labels_.tolist() == [0, 0, 0, -1, -1, -1]
    assert init.n_clusters_ == 1 and init.radius_ == 0.5


def test_single_point_and_coincident_points():
    X = np.zeros((1, 6))
    assert EuclideanClustering(min_cluster_size=1).fit(X).labels_.tolist() == [0]
    assert EuclideanClustering(min_cluster_size=2).fit(X).labels_.tolist() == [-1]
    X = np.zeros((5, 6))
    init = EuclideanClustering(n_clusters=3, min_cluster_size=1)
    with pytest.warns(UserWarning, match="No radius"):
        assert init.fit(X).labels_.tolist() == [0] * 5


def test_transform_is_membership_and_assigns_new_points():
    scene = make_scene(n_objects=3, n_points=600, random_state=0)
    init = EuclideanClustering(n_clusters=10, min_cluster_size=5)
    membership = init.fit_transform(scene.X)
    assert membership.shape == (600, init.n_clusters_)
    assert membership.format == "csr"
    expected = np.zeros((600, init.n_clusters_))
    rows = np.flatnonzero(init.labels_ >= 0)
    expected[rows, init.labels_[rows]] = 1
    np.testing.assert_array_equal(membership.toarray(), expected)
    np.testing.assert_array_equal(init.transform(scene.X).toarray(), expected)
    # A new point next to a clustered one joins its cluster; one far away joins none.
    i = rows[0]
    near = scene.X[[i]].copy()
    near[0, 0] += 0.1 * init.radius_
    far = scene.X[[i]] + 100.0
    new = init.transform(np.vstack([near, far])).toarray()
    assert new[0].tolist() == expected[i].tolist()
    assert new[1].sum() == 0


def test_bad_input():
    X = make_scene(n_objects=2, n_points=50, random_state=0).X
    with pytest.raises(ValueError, match="even number of columns"):
        EuclideanClustering().fit(X[:, :5])
    with pytest.raises(ValueError, match="n_clusters or radius"):
        EuclideanClustering(n_clusters=None).fit(X)
    with pytest.raises(ValueError, match="n_clusters"):
        EuclideanClustering(n_clusters=0).fit(X)
    with pytest.raises(ValueError, match="radius"):
        EuclideanClustering(radius=-1.0).fit(X)
    with pytest.raises(ValueError, match="max_radius"):
        EuclideanClustering(max_radius=0.0).fit(X)
    init = EuclideanClustering(n_clusters=2).fit(X)
    with pytest.raises(ValueError, match="features"):
        init.transform(X[:, :4])


@given(
    seed=st.integers(0, 2**32 - 1),
    n_components=st.sampled_from([2, 3, 7, 70]),
    max_distance=st.sampled_from([np.inf, 0.5, 2.0]),
)
def test_nearest_in_other_component_matches_brute_force(seed, n_components, max_distance):
    rng = np.random.default_rng(seed)
    points = rng.uniform(0, 10, size=(150, 3))
    components = rng.integers(0, n_components, size=150) * 3  # need not be compact
    if len(np.unique(components)) < 2:
        return
    sources = np.sort(rng.choice(150, size=40, replace=False))
    dist = cdist(points, points)
    dist[components[:, None] == components[None, :]] = np.inf
    for given_sources, expected_sources in ((None, np.arange(150)), (sources, sources)):
        source, target, lengths = nearest_in_other_component(
            points, components, max_distance=max_distance, sources=given_sources
        )
        nearest = dist[expected_sources].min(axis=1)
        within = expected_sources[nearest <= max_distance]
        np.testing.assert_array_equal(source, within)
        np.testing.assert_allclose(lengths, dist[within].min(axis=1))
        np.testing.assert_allclose(dist[source, target], lengths)


@given(seed=st.integers(0, 2**32 - 1), n_components=st.sampled_from([2, 5, 70]))
def test_shortest_edges_between_components_matches_brute_force(seed, n_components):
    rng = np.random.default_rng(seed)
    centers = rng.uniform(0, 20, size=(n_components, 3))
    components = np.arange(200) % n_components
    points = centers[components] + rng.normal(size=(200, 3))
    edges, lengths = shortest_edges_between_components(points, components)
    dist = cdist(points, points)
    dist[components[:, None] == components[None, :]] = np.inf
    expected = [dist[components == c].min() for c in range(n_components)]
    np.testing.assert_allclose(lengths, expected)
    np.testing.assert_array_equal(components[edges[:, 0]], np.arange(n_components))
    np.testing.assert_allclose(
        np.linalg.norm(points[edges[:, 0]] - points[edges[:, 1]], axis=1), lengths
    )


def sequential_squared_distances(a, b):
    """Squared distances summed axis by axis, in order: what a KD-tree query computes."""
    total = np.zeros(np.broadcast_shapes(a.shape, b.shape)[:-1])
    for axis in range(a.shape[-1]):
        total = total + (a[..., axis] - b[..., axis]) ** 2
    return total


def knn_forest(points, n_neighbors):
    from scipy.spatial import cKDTree

    edges, lengths, reach = _knn_edges(points, cKDTree(points), n_neighbors, 1)
    forest, forest_lengths = minimum_spanning_forest(len(points), edges, lengths)
    return forest, forest_lengths, reach


@given(points=point_sets(), n_neighbors=st.sampled_from([1, 2, 6]))
def test_knn_forest_is_the_spanning_forest_of_the_knn_edges(points, n_neighbors):
    from scipy.spatial import cKDTree

    tree = cKDTree(points)
    forest, lengths, reach = _knn_forest(points, tree, n_neighbors, 1)
    expected, expected_lengths, expected_reach = knn_forest(points, n_neighbors)
    np.testing.assert_array_equal(lengths, expected_lengths)
    np.testing.assert_array_equal(reach, expected_reach)
    n = len(points)
    for length in np.unique(lengths):
        assert same_partition(
            _components(n, forest[lengths <= length]),
            _components(n, expected[expected_lengths <= length]),
        )


def single_linkage_between_trees(points, trees):
    """Lengths of the minimum spanning tree of the trees, each pair of trees weighted by
    its closest pair of points: what Boruvka steps on the true distances add."""
    from scipy.sparse.csgraph import minimum_spanning_tree

    n_trees = trees.max() + 1
    squared = sequential_squared_distances(points[:, None, :], points[None, :, :])
    gaps = np.full((n_trees, n_trees), np.inf)
    np.minimum.at(gaps, (trees[:, None], trees[None, :]), np.sqrt(squared))
    np.fill_diagonal(gaps, 0)
    # csgraph reads zero as no edge: coincident points of two trees travel as the tiniest.
    weights = np.where(gaps == 0, np.finfo(float).tiny, gaps)
    np.fill_diagonal(weights, 0)
    tree = minimum_spanning_tree(weights)
    return np.sort(np.where(tree.data <= np.finfo(float).tiny, 0.0, tree.data))


@given(points=point_sets(), n_neighbors=st.sampled_from([1, 2]), target=st.integers(1, 6))
def test_completion_is_the_single_linkage_between_trees(points, n_neighbors, target):
    # The k-NN forest falls apart into trees; completing it adds the minimum spanning
    # tree between them on the true distances, as Boruvka steps would.
    n = len(points)
    forest, forest_lengths, reach = knn_forest(points, n_neighbors)
    trees = _components(n, forest)
    if trees.max() == 0:
        return
    layout = _ZOrder(points, _pyramid_cell(reach))

    def zorder():  # the caller makes it on demand
        return layout

    full, full_lengths, whole, _ = _complete_forest(points, forest, forest_lengths, zorder, 1, 1)
    assert whole and len(full) == n - 1
    np.testing.assert_array_equal(full_lengths, np.sort(full_lengths))
    added = list(full_lengths)
    for length in forest_lengths:
        added.remove(length)
    expected = single_linkage_between_trees(points, trees)
    np.testing.assert_allclose(np.sort(added), expected, rtol=1e-12, atol=1e-300)
    # Completed only until target components remain: the same forest up to there.
    part, part_lengths, _, _ = _complete_forest(points, forest, forest_lengths, zorder, target, 1)
    if target >= n:
        return
    limit = full_lengths[n - 1 - target]
    np.testing.assert_array_equal(
        part_lengths[part_lengths <= limit], full_lengths[full_lengths <= limit]
    )
    assert same_partition(
        _components(n, part[part_lengths <= limit]), _components(n, full[full_lengths <= limit])
    )


@given(
    points=point_sets(),
    n_groups=st.integers(2, 6),
    radius=st.floats(0.05, 5),
    big_labels=st.booleans(),
    seed=st.integers(0, 2**32 - 1),
)
def test_nearest_in_other_group_matches_brute_force(points, n_groups, radius, big_labels, seed):
    rng = np.random.default_rng(seed)
    n = len(points)
    # Groups by blob half the time, at random otherwise; on a subset of the points.
    groups = rng.integers(0, n_groups, size=n) * (100_000 if big_labels else 1)
    subset = np.sort(rng.choice(n, size=max(2, n // 2), replace=False))
    zorder = _ZOrder(points, float(rng.uniform(0.01, 1)))
    pyramid = _GridPyramid(zorder, groups[subset], radius, subset=subset)
    source, target, lengths = _nearest_in_other_group(pyramid, radius)
    sub, sub_groups = points[subset], groups[subset]
    squared = sequential_squared_distances(sub[:, None, :], sub[None, :, :])
    squared[sub_groups[:, None] == sub_groups[None, :]] = np.inf
    bound = np.nextafter(radius, np.inf)
    nearest = squared.min(axis=1)
    expected = np.flatnonzero(nearest < bound * bound)
    np.testing.assert_array_equal(np.sort(source), expected)
    order = np.argsort(source)
    source, target, lengths = source[order], target[order], lengths[order]
    np.testing.assert_array_equal(lengths, np.sqrt(nearest[expected]))
    np.testing.assert_array_equal(squared[source, target], nearest[expected])


@given(
    points=point_sets(),
    decimals=st.sampled_from([None, 1]),
    n_clusters=st.integers(1, 12),
    min_cluster_size=st.integers(1, 4),
    n_neighbors=st.sampled_from([1, 2, 6]),
)
def test_partial_completion_chooses_as_the_full_one(
    points, decimals, n_clusters, min_cluster_size, n_neighbors
):
    # The forest is completed only as far as the choice of the radius looks; completing
    # it all must not change the radius nor the clusters. Points on a 0.1 grid give
    # equal lengths and lengths one float apart, where a choice looks furthest.
    if decimals is not None:
        points = np.round(points, decimals)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        args = (points, n_clusters, min_cluster_size, n_neighbors, 1)
        radius, components, reached = _radius_for_count(*args)
        full_radius, full_components, full_reached = _radius_for_count(*args, complete_all=True)
    assert radius == full_radius and reached == full_reached
    assert same_partition(components, full_components)


@given(
    seed=st.integers(0, 2**32 - 1),
    n_objects=st.integers(2, 12),
    n_clusters=st.integers(1, 6),
    spread=st.floats(0.05, 1.5),
)
def test_no_missing_edges_after_completion_holds(seed, n_objects, n_clusters, spread):
    # Objects whose k-NN trees fall apart: after the completion, the shortcut that skips
    # the search for missing edges may answer only when no pair of points within the
    # radius joins two components (brute force), and it answers on well-separated ones.
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-20, 20, size=(n_objects, 3))
    points = (centres[:, None, :] + rng.normal(scale=spread, size=(n_objects, 12, 3))).reshape(
        -1, 3
    )
    n = len(points)
    forest, forest_lengths, reach = knn_forest(points, 2)
    layout = _ZOrder(points, _pyramid_cell(reach))
    longest = forest_lengths[-1]
    full, full_lengths, whole, completed_to = _complete_forest(
        points, forest, forest_lengths, lambda: layout, 1, 1
    )
    assert whole
    radius, components, _ = _choose_radius(n, full, full_lengths, n_clusters, 1)
    answer = _no_missing_edges(full_lengths, longest, np.inf, radius)
    across = components[:, None] != components[None, :]
    joined_pairs = np.any((cdist(points, points) <= np.nextafter(radius, np.inf)) & across)
    assert not (answer and joined_pairs)
    # The answer needs the forest before the completion whole at the radius, and it is
    # given whenever that holds with no forest length just above the radius.
    assert answer == (
        longest <= radius
        and not np.any((full_lengths > radius) & (full_lengths <= np.nextafter(radius, np.inf)))
    )
    # A completion that stopped short of the radius proves nothing.
    assert not _no_missing_edges(full_lengths, longest, radius / 2, radius)


@given(
    points=point_sets(),
    n_clusters=st.integers(1, 12),
    min_cluster_size=st.integers(1, 4),
    cut=st.floats(0.1, 0.9),
)
def test_choice_from_kept_states_is_the_choice_from_scratch(
    points, n_clusters, min_cluster_size, cut
):
    # The components found by one choice, kept below a length, give a later choice on a
    # forest that changed only above it exactly what that choice finds from scratch.
    n = len(points)
    forest, lengths, _ = knn_forest(points, 2)
    states = {}
    _choose_radius(n, forest, lengths, n_clusters, min_cluster_size, states)
    if not len(lengths):
        return
    # Change the forest above a length: drop its longer edges (as a replaced forest would).
    shortest = lengths[int(cut * (len(lengths) - 1))]
    kept = {t: state for t, state in states.items() if t < shortest}
    changed = lengths < shortest
    if not changed.any():
        return
    args = (n, forest[changed], lengths[changed], n_clusters, min_cluster_size)
    fresh = _choose_radius(*args)
    reused = _choose_radius(*args, kept)
    assert (fresh is None) == (reused is None)
    if fresh is not None:
        assert fresh[0] == reused[0] and fresh[2] == reused[2]
        np.testing.assert_array_equal(fresh[1], reused[1])


def test_many_far_apart_objects():
    # The k-NN graph falls apart into 60 objects, fewer clusters are asked: the single
    # linkage between objects is completed only as far as needed, then checked.
    rng = np.random.default_rng(0)
    centres = np.stack(np.meshgrid(*[np.arange(4) * 6.0] * 3), axis=-1).reshape(-1, 3)[:60]
    points = (centres[:, None, :] + rng.normal(scale=0.3, size=(60, 15, 3))).reshape(-1, 3)
    for n_clusters, min_cluster_size in [(10, 4), (25, 15), (59, 1)]:
        labels, radius = euclidean_clustering(
            points, n_clusters=n_clusters, min_cluster_size=min_cluster_size
        )
        assert same_partition(labels, reference_labels(points, radius, min_cluster_size))
        assert labels.max() + 1 == n_clusters


def test_max_radius_keeps_far_apart_objects_apart():
    # 60 objects 6 m apart (gaps between them of at least 3 m): 10 clusters need gaps of
    # 6 m; capped at 2 m, every object is a cluster of its own, exactly the components
    # of the radius graph at the cap. A cap above the chosen radius changes nothing.
    rng = np.random.default_rng(0)
    centres = np.stack(np.meshgrid(*[np.arange(4) * 6.0] * 3), axis=-1).reshape(-1, 3)[:60]
    points = (centres[:, None, :] + rng.normal(scale=0.3, size=(60, 15, 3))).reshape(-1, 3)
    objects = np.repeat(np.arange(60), 15)
    X = np.hstack([points, points])
    uncapped = EuclideanClustering(10).fit(X)
    assert uncapped.n_clusters_ == 10 and uncapped.radius_ > 5.0
    capped = EuclideanClustering(10, max_radius=2.0).fit(X)
    assert capped.radius_ == 2.0 and capped.n_clusters_ == 60
    assert same_partition(capped.labels_, objects)
    assert same_partition(capped.labels_, reference_labels(points, 2.0, 4))
    wide = EuclideanClustering(10, max_radius=2 * uncapped.radius_).fit(X)
    assert wide.radius_ == uncapped.radius_
    np.testing.assert_array_equal(wide.labels_, uncapped.labels_)


@pytest.mark.parametrize("n_neighbors", [1, 2, 6])
def test_many_small_trees(n_neighbors):
    # With one or two neighbours the k-NN forest is hundreds of small trees: the single
    # linkage between them is completed in stages; the result is the same as completing
    # it all at once, and exact.
    rng = np.random.default_rng(2)
    centres = rng.uniform(0, 60, size=(40, 3))
    points = (centres[:, None, :] + rng.normal(scale=0.5, size=(40, 20, 3))).reshape(-1, 3)
    args = (points, 10, 4, n_neighbors, 1)
    radius, components, reached = _radius_for_count(*args)
    assert (radius, reached) == _radius_for_count(*args, complete_all=True)[::2]
    assert same_partition(components, _radius_for_count(*args, complete_all=True)[1])
    labels, used = euclidean_clustering(points, n_clusters=10, n_neighbors=n_neighbors)
    assert used == radius and labels.max() + 1 == 10
    assert same_partition(labels, reference_labels(points, radius, 4))


def test_unreachable_count_after_partial_completion():
    # 30 far-apart blobs of 5 points: no radius gives 10 components of 30 points; the
    # partly completed forest cannot say which radius gives the most, so it is completed.
    rng = np.random.default_rng(1)
    centres = rng.uniform(0, 100, size=(30, 3))
    points = (centres[:, None, :] + rng.normal(scale=0.2, size=(30, 5, 3))).reshape(-1, 3)
    with pytest.warns(UserWarning, match="No radius tried gives n_clusters=10"):
        labels, radius = euclidean_clustering(points, n_clusters=10, min_cluster_size=30)
    assert same_partition(labels, reference_labels(points, radius, 30))


def test_gaps_rounded_to_adjacent_floats():
    # 0.3 - 0.1 and 0.5 - 0.3 round to adjacent floats: no float lies between them, and
    # the midpoint between the two merge lengths used to be the upper one, so that the
    # missing-edge repair found the same edge forever (n_neighbors=1) or the clusters
    # were not those of the radius (n_neighbors>=2).
    points = np.array([[0.1], [0.3], [0.5]])
    for n_neighbors in (1, 2, 6):
        labels, radius = euclidean_clustering(
            points, n_clusters=2, min_cluster_size=1, n_neighbors=n_neighbors
        )
        assert labels.tolist() == [0, 0, 1]
        assert radius == 0.3 - 0.1
        assert same_partition(labels, reference_labels(points, radius, 1))


def test_closest_pair_on_the_bounding_boxes():
    # Two pairs of points on a line: the closest pair between them is the gap of their
    # bounding boxes, which the box-pruned Boruvka step of _neighbors rounds away (it
    # then finds no edge and the completion never ended).
    points = np.array([[-2.5], [-2.0], [2.1], [2.6]])
    labels, radius = euclidean_clustering(points, n_clusters=1, min_cluster_size=1, n_neighbors=1)
    assert labels.tolist() == [0, 0, 0, 0]
    assert same_partition(labels, reference_labels(points, radius, 1))


@pytest.mark.filterwarnings("ignore:No radius tried")
@given(
    seed=st.integers(0, 2**32 - 1),
    n_clusters=st.sampled_from([1, 5, 40]),
    lattice=st.booleans(),
)
def test_a_neighbour_table_read_instead_of_the_query_gives_the_same_clusters(
    seed, n_clusters, lattice
):
    # On a lattice many neighbours are equidistant, and the table (16 per point) may
    # list other ones among them than the init's own 7-neighbour query: the single
    # linkage, the radius and so the clusters are the same.
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0, 30, size=(12, 3))
    points = (centres[:, None] + rng.normal(scale=1.0, size=(12, 40, 3))).reshape(-1, 3)
    if lattice:
        points = np.round(points * 2) / 2
    expected = euclidean_clustering(points, n_clusters=n_clusters)
    got = euclidean_clustering(points, n_clusters=n_clusters, neighbours=NeighbourTable(points))
    np.testing.assert_array_equal(got[0], expected[0])
    assert got[1] == expected[1]
