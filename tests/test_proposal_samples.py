"""The proposals' hypotheses, all groups fitted at once, are each group's own (groups of
at least 4 rows, as propose_clusters gives)."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree
from sklearn.utils import check_random_state

from mmreg.em._hypotheses import fit_minimal_samples
from mmreg.em._steps import (
    _local_samples,
    _local_translations,
    _sample_every_group,
)


def one_group_at_a_time(a, b, members_of, n_hypotheses, rng, reference, turned):
    out = []
    for members in members_of:
        pa, pb = a[members], b[members]
        samples = _local_samples(pa, n_hypotheses, 3, rng, tree=cKDTree(pa))
        rotations, translations, _ = fit_minimal_samples(pa, pb, samples)
        if turned:
            turn, shift = _local_translations(
                pa, pb, n_hypotheses, reference, rng, tree=cKDTree(pa)
            )
            rotations = np.concatenate([rotations, turn])
            translations = np.concatenate([translations, shift])
        out.append((rotations, translations))
    return out


@settings(max_examples=60, deadline=None)
@given(
    sizes=st.lists(st.integers(4, 40), min_size=0, max_size=6),
    n_hypotheses=st.integers(1, 12),
    turned=st.booleans(),
    flat=st.booleans(),
    seed=st.integers(0, 2**16),
)
def test_batched_hypotheses_are_each_groups_own(sizes, n_hypotheses, turned, flat, seed):
    data = np.random.default_rng(seed)
    n = sum(sizes)
    a = data.normal(scale=5.0, size=(n, 3))
    if flat:  # collinear points: degenerate samples, dropped group by group
        a[:, 1:] = 0.0
    b = a @ np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]).T + data.normal(size=3)
    members_of = np.split(data.permutation(n), np.cumsum(sizes)[:-1]) if sizes else []
    reference = (np.eye(3), np.zeros(3))
    got = _sample_every_group(
        a, b, members_of, n_hypotheses, 3, check_random_state(seed), reference, turned
    )
    expected = one_group_at_a_time(
        a, b, members_of, n_hypotheses, check_random_state(seed), reference, turned
    )
    assert len(got) == len(expected)
    for (rotations, translations), (want_r, want_t) in zip(got, expected, strict=True):
        np.testing.assert_array_equal(rotations, want_r)
        np.testing.assert_array_equal(translations, want_t)
