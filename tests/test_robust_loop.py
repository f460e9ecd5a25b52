"""The robust loop's steps alone (:mod:`mmreg.em._robust`): each reads and
writes one state, and turns itself off by its ``skip_steps`` name."""

import inspect

import numpy as np
import pytest

from mmreg.em._robust import (
    _drop_small_clusters,
    _LoopState,
    _m_step,
    _merge_adjacent,
    _setting,
    robust_multi_model_em,
)


def _setting_for(a, b, **options):
    """The loop's setting with :func:`robust_multi_model_em`'s defaults."""
    defaults = {
        name: parameter.default
        for name, parameter in inspect.signature(robust_multi_model_em).parameters.items()
        if parameter.default is not inspect.Parameter.empty and name != "max_iter"
    }
    return _setting(a, b, **{**defaults, **options})


def _turn(angle_deg, axis=2):
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    R = np.eye(3)
    i, j = [k for k in range(3) if k != axis]
    R[[i, i, j, j], [i, j, i, j]] = [c, -s, s, c]
    return R


def _three_boxes(seed):
    """Boxes A and B touching, moving alike; box C 3 m away with another motion.
    Noiseless: b = R a + t exactly. Initial clusters A, B, C."""
    rng = np.random.default_rng(seed)
    boxes = [rng.uniform([x, 0, 0], [x + 1, 1, 1], size=(150, 3)) for x in (0.0, 1.0, 4.0)]
    motions = [(_turn(5), [0.5, 0, 0]), (_turn(5), [0.5, 0, 0]), (_turn(-8, 0), [0, 1.0, 0])]
    a = np.vstack(boxes)
    b = np.vstack([box @ R.T + np.asarray(t) for box, (R, t) in zip(boxes, motions, strict=True)])
    return a, b, np.repeat([0, 1, 2], 150)


@pytest.mark.parametrize("seed", [0, 1])
def test_merging_joins_the_touching_clusters_that_share_a_motion(seed):
    a, b, labels = _three_boxes(seed)
    setting = _setting_for(a, b, tau=0.5, skip_steps=("boundary_layers",))
    state = _LoopState(labels, 3, report=labels, own_scales=False)
    state.start_iteration()
    _m_step(setting, state)
    _merge_adjacent(setting, state)
    assert state.root[0] == state.root[1] != state.root[2]
    assert state.tally["merges"] == 1


def test_merging_turned_off_by_its_name_leaves_every_cluster_its_own():
    a, b, labels = _three_boxes(0)
    setting = _setting_for(a, b, tau=0.5, skip_steps=("merging", "boundary_layers"))
    state = _LoopState(labels, 3, report=labels, own_scales=False)
    state.start_iteration()
    _m_step(setting, state)
    models = state.models
    _merge_adjacent(setting, state)
    np.testing.assert_array_equal(state.root, [0, 1, 2])
    assert state.models is models
    assert state.tally["merges"] == 0


def test_dropping_small_clusters_renumbers_members_roots_and_the_static_world():
    # Clusters 0 (4 members), 1 (2: below m_min = 3), 2 (5); cluster 3 merged into 2.
    a = np.zeros((12, 3))
    setting = _setting_for(a, a + 1.0, min_cluster_size=3, skip_steps=("boundary_layers",))
    members = np.array([0, 0, 0, 0, 1, 1, 2, 2, 2, 2, 2, -1])
    state = _LoopState(members, 4, report=members, own_scales=False)
    state.start_iteration()
    state.members, state.root, state.static = members.copy(), np.array([0, 1, 2, 2]), 2
    _drop_small_clusters(setting, state)
    np.testing.assert_array_equal(state.members, [0, 0, 0, 0, -1, -1, 1, 1, 1, 1, 1, -1])
    np.testing.assert_array_equal(state.kept, [0, 2])
    np.testing.assert_array_equal(state.root, [0, -1, 1, 1])
    assert state.static == 1
    assert state.tally["dropped"] == 1


def test_no_iteration_returns_the_initial_clusters_by_size_without_the_small_ones():
    a, b, _ = _three_boxes(0)
    init = np.r_[np.full(160, 7), np.full(140, 3), np.full(148, 5), [9, 9]]
    result = robust_multi_model_em(a, b, init, tau=0.5, max_iter=0, min_cluster_size=4)
    expected = np.r_[np.zeros(160, int), np.full(140, 2), np.ones(148, int), [-1, -1]]
    np.testing.assert_array_equal(result.labels, expected)
    assert result.n_iter == 0 and result.pieces is None and result.history == []
