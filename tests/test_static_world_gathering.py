"""What the static world would gather with each cluster: pruned pairs, same answer.

A background in pieces is named by the union of the pieces each cluster would gather
(``spanning_union``), which reads a test per pair of clusters. Bounds from the clusters'
sufficient statistics rule most pairs out; the pairs left are tested as before, so the
result must be that of testing every pair.
"""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from mmreg._array.moments import group_moments
from mmreg.em import _steps
from mmreg.em._static_world import spanning_union

D = 3


def _every_pair(models, min_motion):
    """The reference: both tests on every ordered pair of non-empty clusters."""
    k = len(models.sigmas)
    present = np.flatnonzero(models.moments.size > 0)
    i, j = np.repeat(present, len(present)), np.tile(present, len(present))
    i, j = i[i != j], j[i != j]
    members = np.eye(k, dtype=bool)
    if len(i):
        with_it = _steps._merge_ratio(models, np.column_stack([i, j]), D) < 1.0
        with_it |= _steps.motion_beyond_scatter(models, i, j) < min_motion
        members[i[with_it], j[with_it]] = True
    return members


def _random_models(seed, n_clusters, n_motions, extent, weighted, perturbed):
    """Clusters of random sizes and places, sharing ``n_motions`` motions (some nudged by
    a few centimetres: slow movers), fitted; ``perturbed``: some clusters keep a motion
    other than their least-squares one (the bounds' slack)."""
    rng = np.random.default_rng(seed)
    motions = [
        (Rotation.from_rotvec(rng.normal(scale=0.1, size=3)).as_matrix(), rng.normal(size=3))
        for _ in range(n_motions)
    ]
    sizes = rng.integers(0, 40, n_clusters)
    sizes[rng.random(n_clusters) < 0.1] = 0  # empty clusters
    a, b, labels = [], [], []
    for k, size in enumerate(sizes):
        rotation, translation = motions[rng.integers(n_motions)]
        if rng.random() < 0.3:
            translation = translation + rng.normal(scale=0.03, size=3)
        centre = rng.uniform(-extent, extent, 3)
        points = centre + rng.normal(size=(size, 3)) * rng.uniform(0.05, 3.0)
        noise = rng.uniform(0.001, 0.1)
        a.append(points)
        b.append(points @ rotation.T + translation + rng.normal(scale=noise, size=(size, 3)))
        labels.append(np.full(size, k))
    a, b, labels = np.vstack(a), np.vstack(b), np.concatenate(labels)
    scale = rng.uniform(0.5, 2.0, len(a)) if weighted else None
    models = _steps.fit_clusters(a, b, labels, n_clusters, 0.01, scale)
    if perturbed:
        nudged = rng.random(n_clusters) < 0.3
        turn = Rotation.from_rotvec(rng.normal(scale=0.01, size=(n_clusters, 3))).as_matrix()
        models.rotations[nudged] = turn[nudged] @ models.rotations[nudged]
        models.translations[nudged] += rng.normal(scale=0.05, size=(nudged.sum(), 3))
        models.squared_error = models.moments.squared_error(models.rotations, models.translations)
    return models


@given(
    seed=st.integers(0, 2**32 - 1),
    n_clusters=st.integers(1, 40),
    n_motions=st.integers(1, 6),
    extent=st.sampled_from([0.5, 5.0, 50.0, 500.0]),
    weighted=st.booleans(),
    perturbed=st.booleans(),
    min_motion=st.sampled_from([0.0, 0.02, 0.1, 0.5]),
)
def test_pruned_pairs_gather_what_every_pair_gathers(
    seed, n_clusters, n_motions, extent, weighted, perturbed, min_motion
):
    models = _random_models(seed, n_clusters, n_motions, extent, weighted, perturbed)
    expected = _every_pair(models, min_motion)
    np.testing.assert_array_equal(_steps.gathered_by_each(models, D, min_motion), expected)


def test_objects_flying_apart_test_no_pair():
    # Fifty objects 20 m apart, each moving away from the others by 5 % of its place (a
    # metre or more from each other): no two centroids stay as far apart, and no object's
    # motion carries another's centroid near where that one goes.
    rng = np.random.default_rng(0)
    grid = np.stack(np.meshgrid(np.arange(10), np.arange(5), [0]), axis=-1).reshape(-1, 3)
    a, b = [], []
    for centre in 20.0 * grid:
        points = centre + rng.uniform(-1, 1, (30, 3))
        a.append(points)
        b.append(points + 0.05 * centre + rng.normal(scale=0.01, size=points.shape))
    a, b = np.vstack(a), np.vstack(b)
    models = _steps.fit_clusters(a, b, np.repeat(np.arange(50), 30), 50, 0.01)
    assert len(_steps._pairs_that_may_gather(models, D, 0.1, np.arange(50))) == 0
    np.testing.assert_array_equal(_steps.gathered_by_each(models, D, 0.1), np.eye(50, dtype=bool))


def test_spanning_union_asks_for_the_pairs_only_in_a_camera_view():
    rng = np.random.default_rng(0)
    box = rng.uniform(-1, 1, (100, 3))
    asked = []

    def members():
        asked.append(True)
        matrix = np.eye(6, dtype=bool)
        matrix[0, 1] = matrix[1, 0] = True  # the backdrop's two pieces move alike
        return matrix

    around = np.vstack([box + [x, y, 0.0] for x, y in ((-5, 0), (5, 0), (0, 5), (0, -5))])
    around = np.vstack([around, box + [9.0, 9.0, 0.0], box + [-9.0, 9.0, 0.0]])
    labels = np.repeat(np.arange(6), 100)
    assert spanning_union(group_moments(around, around, labels, 6), members) == -1
    assert not asked
    # In a camera's view it reads them, as it reads an array.
    left = rng.uniform([-12, -3, 28], [-4, 3, 30], (100, 3))
    right = rng.uniform([4, -3, 28], [12, 3, 30], (100, 3))
    boxes = [box + [x, 0.0, 15.0] for x in (-8, -3, 3, 8)]
    seen = np.vstack([left, right, *boxes])
    moments = group_moments(seen, seen, labels, 6)
    assert spanning_union(moments, members) == spanning_union(moments, members()) == 0
    assert len(asked) == 2


def _objects(centres, rng):
    """Twenty boxes of 50 rows at ``centres``, each with a motion of its own, fitted."""
    a, b = [], []
    for centre in centres:
        points = centre + rng.uniform(-1, 1, (50, 3))
        turn = Rotation.from_rotvec(rng.normal(scale=0.05, size=3)).as_matrix()
        a.append(points)
        b.append((points - centre) @ turn.T + centre + rng.normal(size=3))
    a, b = np.vstack(a), np.vstack(b)
    labels = np.repeat(np.arange(len(centres)), 50)
    return _steps.fit_clusters(a, b, labels, len(centres), 0.01)


def test_the_static_world_tests_pairs_only_in_a_camera_view(monkeypatch):
    # Twenty objects, none a majority or spanning the scene: the static world looks for a
    # background in pieces, which only a camera's view can name.
    rng = np.random.default_rng(0)
    calls = []
    every_pair = _steps.gathered_by_each
    monkeypatch.setattr(
        _steps, "gathered_by_each", lambda *args: calls.append(1) or every_pair(*args)
    )
    angles = np.linspace(0, 2 * np.pi, 20, endpoint=False)
    around = np.column_stack([30 * np.cos(angles), 30 * np.sin(angles), np.zeros(20)])
    static = _steps.merge_static_world(_objects(around, rng), D, 0.01)[0]
    assert static == -1
    assert not calls
    ahead = np.column_stack([np.linspace(-30, 30, 20), np.zeros(20), np.full(20, 40.0)])
    _steps.merge_static_world(_objects(ahead, rng), D, 0.01)
    assert len(calls) == 1
