"""scattered_clusters and adjacent_pairs against plain readings of their definitions."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from mmreg._array.neighbors import NeighbourTable
from mmreg.em._steps import adjacent_pairs, scattered_clusters


def reference_scattered(labels, n_clusters, table, exempt):
    """One row at a time: a member is a stray when fewer than a quarter of its first
    ``min(k - 1, cluster size - 1)`` listed neighbours share its cluster."""
    strays = np.zeros(n_clusters, dtype=int)
    sizes = np.bincount(labels[labels >= 0], minlength=n_clusters)
    for row, cluster in enumerate(labels):
        if cluster < 0 or cluster == exempt:
            continue
        depth = min(table.k - 1, sizes[cluster] - 1)
        if depth == 0:
            continue
        listed = labels[table.index[row, 1 : 1 + depth]]
        strays[cluster] += 4 * np.count_nonzero(listed == cluster) < depth
    judged = np.arange(n_clusters) != exempt
    return np.flatnonzero(judged & (2 * strays > sizes))


@settings(max_examples=80, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 200),
    n_clusters=st.integers(1, 12),
    k=st.integers(2, 17),
    exempt=st.integers(-1, 11),
    every_row_labelled=st.booleans(),
)
def test_scattered_clusters_match_the_definition(
    seed, n, n_clusters, k, exempt, every_row_labelled
):
    # Every row in a cluster and none exempt: the table is read in place, not copied.
    # Small clusters (fewer members than the table lists) count to their own size.
    exempt = exempt if exempt < n_clusters and not every_row_labelled else -1
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(n, 3))
    # Clusters of all sizes, some spatially coherent (bodies) and some scattered.
    labels = np.where(rng.random(n) < 0.5, np.digitize(points[:, 0], [-0.5, 0.5]) % n_clusters, -1)
    labels = np.where(labels >= 0, labels, rng.integers(-1, n_clusters, size=n))
    if every_row_labelled:
        labels = np.where(labels >= 0, labels, rng.integers(0, n_clusters, size=n))
    table = NeighbourTable(points, k=k)
    np.testing.assert_array_equal(
        scattered_clusters(labels, n_clusters, table, exempt=exempt),
        reference_scattered(labels, n_clusters, table, exempt),
    )


@settings(max_examples=80, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 300),
    n_clusters=st.integers(1, 9),
    tau=st.sampled_from([0.3, 1.0, 2.5]),
)
def test_adjacent_pairs_are_the_clusters_that_share_a_cell(seed, n, n_clusters, tau):
    rng = np.random.default_rng(seed)
    points = rng.uniform(-3.0, 3.0, size=(n, 3))
    labels = rng.integers(-1, n_clusters, size=n)
    # The cells as the step draws them; the pairs from a dictionary of their labels.
    kept = labels >= 0
    expected = set()
    if kept.any():
        low = points[kept].min(axis=0)
        cells = np.floor((points[kept] - low) / (tau / np.sqrt(3))).astype(int)
        members = {}
        for cell, label in zip(map(tuple, cells), labels[kept], strict=True):
            members.setdefault(cell, set()).add(int(label))
        for found in members.values():
            expected |= {(i, j) for i in found for j in found if i < j}
    got = adjacent_pairs(points, labels, n_clusters, tau)
    assert got.dtype == np.intp and got.shape[1] == 2
    # Ascending, as np.unique would list them: merging breaks ties in this order.
    assert [tuple(pair) for pair in got] == sorted(expected)
