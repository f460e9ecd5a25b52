"""Values sorted within groups, each group's middle values and the medians built on them,
and each group's bounding box and centroid."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from mmreg._array.grouping import (
    group_bounds,
    group_centroids,
    middle_values,
    sorted_within_groups,
    unique_sorted,
)
from mmreg._array.motion import _group_median
from mmreg.em._steps import group_median


@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.sampled_from([1, 7, 500]),
    n_groups=st.sampled_from([1, 3, 40, 40_000]),
    ties=st.booleans(),
)
def test_the_order_of_a_lexsort_and_lower_medians(seed, n, n_groups, ties):
    rng = np.random.default_rng(seed)
    values = rng.normal(size=n)
    if ties:
        values = np.round(values)
    groups = rng.integers(n_groups, size=n)
    sorted_values, starts, counts = sorted_within_groups(values, groups, n_groups)
    np.testing.assert_array_equal(sorted_values, values[np.lexsort((values, groups))])
    np.testing.assert_array_equal(counts, np.bincount(groups, minlength=n_groups))
    np.testing.assert_array_equal(starts, np.cumsum(counts) - counts)
    labels = np.where(rng.random(n) < 0.2, -1, groups)  # some in no group
    expected = [
        np.sort(values[labels == g])[(np.sum(labels == g) - 1) // 2]
        if np.any(labels == g)
        else np.nan
        for g in range(min(n_groups, 50))
    ]
    np.testing.assert_array_equal(group_median(values, labels, n_groups)[:50], expected)


@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.sampled_from([1, 8, 129, 3000]),
    n_groups=st.sampled_from([1, 2, 5, 300]),
    kind=st.sampled_from(["normal", "ties", "special"]),
)
def test_middle_values_are_those_of_a_sort_within_each_group(seed, n, n_groups, kind):
    # Large groups take a partition each, many small ones one sort: both give the floats
    # a full sort puts in the middle, NaN and infinities included (sorted last and at
    # the ends).
    rng = np.random.default_rng(seed)
    values = rng.normal(size=n)
    if kind == "ties":
        values = np.round(values)
    elif kind == "special":
        values[rng.random(n) < 0.2] = rng.choice([np.nan, np.inf, -np.inf])
    groups = rng.integers(n_groups, size=n)
    low, high = middle_values(values, groups, n_groups)
    for g in range(n_groups):
        own = np.sort(values[groups == g])
        if len(own):
            np.testing.assert_array_equal(low[g], own[(len(own) - 1) // 2])
            np.testing.assert_array_equal(high[g], own[len(own) // 2])
        else:
            assert np.isnan(low[g]) and np.isnan(high[g])
    with np.errstate(invalid="ignore"):  # inf - inf in a group's middle
        np.testing.assert_array_equal(_group_median(values, groups, n_groups), 0.5 * (low + high))


@given(
    values=st.lists(st.integers(-(2**40), 2**40), max_size=300),
    repeat=st.integers(1, 4),
)
def test_unique_sorted_is_numpy_unique_of_the_sorted_values(values, repeat):
    keys = np.repeat(np.array(values, dtype=np.int64), repeat)
    np.random.default_rng(len(values)).shuffle(keys)
    uniques, starts = unique_sorted(keys)
    expected, first = np.unique(np.sort(keys), return_index=True)
    np.testing.assert_array_equal(uniques, expected)
    np.testing.assert_array_equal(starts, first)


@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.sampled_from([0, 1, 9, 600]),
    n_groups=st.sampled_from([1, 4, 70, 40_000]),
    d=st.sampled_from([2, 3]),
)
def test_group_bounds_are_those_of_ufunc_at(seed, n, n_groups, d):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(n, d)) * 10.0 ** rng.integers(-3, 4)
    groups = rng.integers(n_groups, size=n)
    low, high = group_bounds(points, groups, n_groups)
    expected_low = np.full((n_groups, d), np.inf)
    expected_high = np.full((n_groups, d), -np.inf)
    np.minimum.at(expected_low, groups, points)
    np.maximum.at(expected_high, groups, points)
    np.testing.assert_array_equal(low, expected_low)
    np.testing.assert_array_equal(high, expected_high)


@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.sampled_from([1, 9, 300]),
    n_groups=st.sampled_from([1, 4, 50]),
    d=st.sampled_from([2, 3]),
)
def test_group_centroids_are_each_groups_mean(seed, n, n_groups, d):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(n, d)) * 10.0 ** rng.integers(-3, 4)
    labels = rng.integers(-1, n_groups, size=n)  # -1: in no group
    centroids, sizes = group_centroids(points, labels, n_groups)
    assert centroids.shape == (n_groups, d)
    for g in range(n_groups):
        members = points[labels == g]
        assert sizes[g] == len(members)
        if len(members):
            # Summed in another order than numpy's mean: equal up to rounding at the
            # members' own scale (a mean near 0 has no relative precision).
            scale = np.abs(members).max()
            np.testing.assert_allclose(centroids[g], members.mean(axis=0), atol=1e-12 * scale)
        else:
            assert np.isnan(centroids[g]).all()
