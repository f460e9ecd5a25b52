"""boundary_layers against a plain reading of its definition (all pairwise distances)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.distance import cdist

from mmreg._array.neighbors import NeighbourTable
from mmreg.em import _steps as robust_steps
from mmreg.em._steps import boundary_layers


def reference_layers(points, labels, n_clusters, spacing, thickness, exempt):
    layers = []
    distance = cdist(points, points)
    for cluster in range(n_clusters):
        mine = labels == cluster
        others = (labels >= 0) & ~mine
        if cluster == exempt or not mine.any():
            continue
        gaps = (
            distance[np.ix_(mine, others)].min(axis=1)
            if others.any()
            else np.full(mine.sum(), np.inf)
        )
        # The lower median, as the step takes it.
        median_gap = np.sort(gaps)[(mine.sum() - 1) // 2]
        typical = np.sort(spacing[mine])[(mine.sum() - 1) // 2]
        if median_gap <= thickness * typical:
            layers.append(cluster)
    return np.array(layers, dtype=np.intp)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(2, 300),
    n_clusters=st.integers(2, 7),
    gridded=st.booleans(),
    exempt=st.integers(-1, 6),
    thickness=st.sampled_from([0.5, 1.5, 3.0, 6.0]),
    every_row_labelled=st.booleans(),
)
def test_boundary_layers_match_the_definition(
    seed, n, n_clusters, gridded, exempt, thickness, every_row_labelled
):
    # Every row in a cluster and none exempt: the table is read in place, not copied.
    exempt = exempt if exempt < n_clusters and not every_row_labelled else -1
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(n, 3)) * rng.uniform(0.1, 5.0)
    if gridded:
        # Ties and duplicate points, as on a sampled grid.
        points = np.round(points, 1)
    labels = rng.integers(-1, n_clusters, size=n)
    # Spatially coherent clusters too, so that some are layers and some are not.
    half = points[:, 0] > np.median(points[:, 0])
    labels[half] = rng.integers(-1, n_clusters)
    if every_row_labelled:
        labels = np.where(labels >= 0, labels, rng.integers(0, n_clusters, size=n))
    spacing = NeighbourTable(points, k=2).distance[:, -1]
    # A table narrower than the default makes the widening path run.
    table = NeighbourTable(points, k=int(rng.integers(1, 6)))
    got = boundary_layers(
        points, labels, n_clusters, spacing, thickness=thickness, exempt=exempt, neighbours=table
    )
    expected = reference_layers(points, labels, n_clusters, spacing, thickness, exempt)
    np.testing.assert_array_equal(got, expected)
    # Rows taken in blocks (as at a million points) give the same layers.
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(robust_steps, "_BLOCK_ROWS", 7)
        blocked = boundary_layers(
            points,
            labels,
            n_clusters,
            spacing,
            thickness=thickness,
            exempt=exempt,
            neighbours=table,
        )
    np.testing.assert_array_equal(blocked, expected)


def test_a_layer_along_a_surface_is_found_and_an_object_beside_it_is_not():
    # A 20 x 20 grid (cluster 0), a one-row band along its edge with another motion
    # (cluster 1), and a 6 x 6 patch 5 spacings away (cluster 2).
    grid = np.stack(np.meshgrid(np.arange(20.0), np.arange(20.0)), -1).reshape(-1, 2)
    band = np.column_stack([np.arange(20.0), np.full(20, 20.0)])
    patch = np.stack(np.meshgrid(np.arange(6.0), np.arange(6.0)), -1).reshape(-1, 2) + [26.0, 0]
    points = np.vstack([grid, band, patch])
    labels = np.repeat([0, 1, 2], [len(grid), len(band), len(patch)])
    spacing = NeighbourTable(points, k=2).distance[:, -1]
    np.testing.assert_array_equal(boundary_layers(points, labels, 3, spacing), [1])


def test_stray_members_of_another_cluster_inside_an_object_do_not_make_it_a_layer():
    # A 10 x 10 patch (cluster 1) with five of its points labelled as the static world
    # (cluster 0), whose body lies 40 spacings away: the object is a layer along the
    # strays unless strays are ignored.
    patch = np.stack(np.meshgrid(np.arange(10.0), np.arange(10.0)), -1).reshape(-1, 2)
    body = np.stack(np.meshgrid(np.arange(20.0), np.arange(20.0)), -1).reshape(-1, 2) + 50.0
    points = np.vstack([patch, body])
    labels = np.repeat([1, 0], [len(patch), len(body)])
    labels[[11, 33, 45, 67, 88]] = 0
    spacing = NeighbourTable(points, k=2).distance[:, -1]
    table = NeighbourTable(points)
    assert 1 in boundary_layers(points, labels, 2, spacing, exempt=0, neighbours=table)
    assert 1 not in boundary_layers(
        points, labels, 2, spacing, exempt=0, neighbours=table, ignore_strays=True
    )
