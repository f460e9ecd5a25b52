"""The raw-sweep path's shortcuts give what the plain computations give, bit for bit."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial import cKDTree

from mmreg._array.unique_rows import prefix_counts, unique_rows
from mmreg.sweeps._icp import SurfaceNormals, multi_body_icp


@settings(max_examples=60, deadline=None)
@given(
    rows=st.integers(0, 40).flatmap(
        lambda n: arrays(
            np.int64,
            (n, 3),
            elements=st.one_of(
                st.integers(-3, 3),
                st.integers(-(2**62), 2**62),  # the second cannot pack
            ),
        )
    )
)
def test_unique_rows_is_numpy_s_unique_over_rows(rows):
    expected = np.unique(rows, axis=0, return_index=True, return_inverse=True, return_counts=True)
    found = unique_rows(rows, return_index=True, return_inverse=True, return_counts=True)
    assert found[0].dtype == rows.dtype
    for mine, numpy_s in zip(found, expected, strict=True):
        np.testing.assert_array_equal(mine, np.ravel(numpy_s) if mine.ndim == 1 else numpy_s)
    np.testing.assert_array_equal(unique_rows(rows), expected[0])


def test_unique_rows_packs_columns_of_many_values():
    rng = np.random.default_rng(0)
    rows = np.column_stack(
        [rng.integers(0, 500, 5000), rng.integers(-60, 60, (5000, 3)), rng.integers(0, 9, 5000)]
    )
    rows = np.vstack([rows, rows[:700]])  # repeated rows
    unique, counts = unique_rows(rows, return_counts=True)
    expected, expected_counts = np.unique(rows, axis=0, return_counts=True)
    np.testing.assert_array_equal(unique, expected)
    np.testing.assert_array_equal(counts, expected_counts)


@settings(max_examples=30, deadline=None)
@given(
    points=arrays(np.float64, (30, 3), elements=st.sampled_from([0.0, 0.25, 1.0, 2.5, 7.0])),
    first=st.lists(st.integers(0, 29), max_size=10),
    second=st.lists(st.integers(0, 29), min_size=1, max_size=40),
)
def test_spacing_is_the_distance_to_the_nearest_other_point(points, first, second):
    """Spacings read off the normals' neighbourhoods (``first`` asked for normals
    before) or found on their own are those of a k = 2 query, duplicates included."""
    tree = cKDTree(points)
    normals = SurfaceNormals(points, tree, 10)
    normals(np.array(first, dtype=np.intp))
    index = np.array(second, dtype=np.intp)
    expected = tree.query(points[index], k=2)[0][:, 1]
    np.testing.assert_array_equal(normals.spacing(index), expected)
    np.testing.assert_array_equal(normals.spacing(index[::-1]), expected[::-1])


def test_icp_without_the_final_measurement_moves_the_same():
    rng = np.random.default_rng(1)

    def corner(n):
        p = rng.uniform(0, 2, (n, 3))
        p[np.arange(n), rng.integers(0, 3, n)] = 0.0
        return p

    a = np.vstack([corner(800), corner(800) + [5.0, 0.0, 0.0]])
    labels = np.repeat([0, 1], 800)
    target = np.vstack([corner(5000) + [0.1, 0.0, 0.0], corner(5000) + [5.0, 0.1, 0.05]])
    start = np.broadcast_to(np.eye(3), (2, 3, 3)), np.zeros((2, 3))
    for max_iter in (0, 3, 30):
        kwargs = dict(max_distance=0.5, max_iter=max_iter)
        measured = multi_body_icp(a, labels, *start, target, **kwargs)
        quick = multi_body_icp(a, labels, *start, target, measure=False, **kwargs)
        np.testing.assert_array_equal(quick.rotations, measured.rotations)
        np.testing.assert_array_equal(quick.translations, measured.translations)
        assert quick.n_iter == measured.n_iter
    np.testing.assert_allclose(measured.translations, [[0.1, 0, 0], [0.0, 0.1, 0.05]], atol=0.02)


def test_threads_of_the_icp_queries_change_nothing():
    """The estimator's n_jobs also threads the ICPs' queries: the same answer, bit for bit."""
    from mmreg import MultiModelRegistration, SweepRegistration
    from mmreg.datasets import make_lidar_sweeps

    scene = make_lidar_sweeps(n_moving=2, n_parked=1, n_beams=16, n_azimuths=512, random_state=0)
    fits = [
        SweepRegistration(
            MultiModelRegistration(variant="sweep", tau=5.0, n_jobs=n_jobs), random_state=0
        ).fit(scene.a, sweep=scene.sweep)
        for n_jobs in (None, 2)
    ]
    np.testing.assert_array_equal(fits[0].labels_, fits[1].labels_)
    np.testing.assert_array_equal(fits[0].flow_, fits[1].flow_)
    assert fits[0].n_clusters_ >= 2  # the static world and at least one car


@settings(max_examples=60, deadline=None)
@given(
    rows=st.integers(0, 40).flatmap(
        lambda n: arrays(
            np.int64,
            (n, 4),
            elements=st.one_of(st.integers(-3, 3), st.integers(-(2**62), 2**62)),
        )
    ),
    width=st.integers(1, 3),
)
def test_prefix_counts_count_distinct_rows_per_prefix(rows, width):
    """Each distinct prefix, counted once per distinct full row it begins (as the
    translation histogram counts a voter once per bin)."""
    found, counts = prefix_counts(rows, width)
    distinct = {tuple(row) for row in rows.tolist()}
    expected = sorted({row[:width] for row in distinct})
    assert found.dtype == rows.dtype
    assert [tuple(row) for row in found.tolist()] == expected
    assert counts.tolist() == [sum(row[:width] == p for row in distinct) for p in expected]
