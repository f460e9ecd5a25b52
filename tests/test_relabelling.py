"""Rows that two labellings put in different clusters, and the loop's convergence on it."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from scipy.optimize import linear_sum_assignment
from scipy.spatial.transform import Rotation

from mmreg._array.relabelling import rows_moved
from mmreg.em._robust import robust_multi_model_em

labellings = st.builds(
    lambda seed, n, k: np.random.default_rng(seed).integers(-1, k, size=n),
    st.integers(0, 2**32 - 1),
    st.integers(0, 300),
    st.integers(1, 12),
)


def _renumbered(labels, seed):
    """The same clusters under other numbers (-1 stays -1)."""
    numbers = np.random.default_rng(seed).permutation(int(labels.max(initial=-1)) + 2) + 7
    return np.where(labels >= 0, numbers[np.maximum(labels, 0)], -1)


def _fewest_moved(before, after):
    """The fewest rows moved under any one-to-one matching of the clusters."""
    both = (before >= 0) & (after >= 0)
    table = np.zeros((before.max(initial=-1) + 1, after.max(initial=-1) + 1))
    np.add.at(table, (before[both], after[both]), 1)
    rows, cols = linear_sum_assignment(table, maximize=True)
    return len(before) - np.sum((before < 0) & (after < 0)) - int(table[rows, cols].sum())


@given(labels=labellings, seed=st.integers(0, 1000))
def test_a_renumbering_moves_nothing(labels, seed):
    assert rows_moved(labels, _renumbered(labels, seed)) == 0


@given(before=labellings, seed=st.integers(0, 2**32 - 1))
def test_between_the_optimal_matching_and_every_row(before, seed):
    rng = np.random.default_rng(seed)
    after = np.where(rng.random(len(before)) < 0.3, rng.integers(-1, 5, len(before)), before)
    after = _renumbered(after, seed)
    moved = rows_moved(before, after)
    # Greedy by overlap keeps at least half of what the best matching keeps.
    best = _fewest_moved(before, after)
    kept_at_best = len(before) - np.sum((before < 0) & (after < 0)) - best
    assert best <= moved <= best + kept_at_best / 2
    assert moved >= np.count_nonzero((before < 0) != (after < 0))


def test_a_merge_moves_the_smaller_part_and_a_split_the_smaller_piece():
    before = np.repeat([0, 1, 2, -1], [50, 20, 30, 5])
    merged = np.repeat([4, 4, 9, -1], [50, 20, 30, 5])
    assert rows_moved(before, merged) == 20
    split = np.repeat([3, 8, 1, 6, -1], [35, 15, 20, 30, 5])
    assert rows_moved(before, split) == 15
    to_outliers = before.copy()
    to_outliers[:3] = -1
    assert rows_moved(before, to_outliers) == 3


def _two_objects_one_split_in_the_init():
    rng = np.random.default_rng(0)
    near = rng.uniform(0, 1, size=(80, 3))
    far = rng.uniform(0, 1, size=(60, 3)) + [5.0, 0, 0]
    turn = Rotation.from_rotvec([0, 0, 0.3]).as_matrix()
    a = np.vstack([near, far])
    b = np.vstack([near @ turn.T + [0, 1.0, 0], far + [0.5, 0, 0]])
    # The first object in two pieces of 25 and 55 correspondences.
    init = np.r_[np.where(near[:, 0] < 0.4, 0, 1), np.full(60, 2)]
    assert np.bincount(init).tolist() == [25, 55, 60]
    return a, b, init


def test_a_merge_counts_as_the_smaller_pieces_moves():
    a, b, init = _two_objects_one_split_in_the_init()
    for sweep in (False, True):
        # 25 moved of 140: beyond a tolerance of 14, within one of 70.
        strict = robust_multi_model_em(a, b, init, tau=1.0, tol=0.1, sweep=sweep, random_state=0)
        assert [step["changed"] for step in strict.history] == [25, 0]
        assert strict.history[0]["merges"] == 1
        loose = robust_multi_model_em(a, b, init, tau=1.0, tol=0.5, sweep=sweep, random_state=0)
        assert loose.n_iter == 1 and loose.converged
        np.testing.assert_array_equal(loose.labels, strict.labels)
        assert np.bincount(strict.labels).tolist() == [80, 60]
