"""Islands the ego motion explains too well skip their hypotheses: the choice is the same."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from mmreg.sweeps._icp import SurfaceNormals
from mmreg.sweeps._island_motions import (
    choose_island_motions,
    ego_fit,
    start_draws,
    translation_starts,
)


def _box(rng, centre, n=120):
    """Points on the faces of a 1 m box."""
    p = rng.uniform(-0.5, 0.5, (n, 3))
    axis = rng.integers(0, 3, n)
    p[np.arange(n), axis] = np.where(rng.random(n) < 0.5, -0.5, 0.5)
    return p + centre


@given(seed=st.integers(0, 2**16), shift=st.floats(0.3, 2.0), unseen=st.floats(0.0, 0.3))
def test_no_island_the_ego_motion_explains_can_be_chosen(seed, shift, unseen):
    rng = np.random.default_rng(seed)
    n_islands, n_starts = 6, 3
    boxes = [_box(rng, [4.0 * k, 0.0, 0.0]) for k in range(n_islands)]
    a = np.vstack(boxes)
    groups = np.repeat(np.arange(n_islands), [len(b) for b in boxes])
    # Islands 0-2 stay (a share `unseen` of island 2's points has no second view);
    # islands 3-5 move by `shift` along y.
    second = [b if k < 3 else b + [0.0, shift, 0.0] for k, b in enumerate(boxes)]
    second[2] = second[2][: int(len(second[2]) * (1 - unseen)) or 1]
    sweep = np.vstack(second)
    tree = cKDTree(sweep)
    target = (sweep, tree, SurfaceNormals(sweep, tree, 10))
    ego = (np.eye(3), np.zeros(3))
    # Every island gets its true motion, a wrong one and the ego motion as hypotheses.
    translations = np.zeros((n_islands, n_starts, 3))
    translations[3:, 0, 1] = shift
    translations[:, 1] = rng.normal(0.0, 0.5, (n_islands, 3))
    translations = translations.reshape(-1, 3)
    rotations = np.broadcast_to(np.eye(3), (len(translations), 3, 3)).copy()
    valid = np.ones((n_islands, n_starts), dtype=bool)
    resting = cKDTree(a)
    hopeless = ego_fit(a, groups, n_islands, ego, 0.005, target, max_distance=1.0).hopeless()
    choice = [
        choose_island_motions(
            a,
            groups,
            n_islands,
            ego,
            (rotations, translations),
            starts,
            0.005,
            target,
            (resting, groups, 0.05),
            max_distance=1.0,
        )
        for starts in (valid, valid & ~hopeless[:, None])
    ]
    moving, pick, explained = choice[0]
    assert hopeless[:2].all() and not hopeless[3:].any()
    assert moving[3:].all()
    assert not (moving & hopeless).any()
    # So the hopeless islands need not be weighed at all (SweepRegistration leaves
    # them out): the same islands move, with the same motions.
    np.testing.assert_array_equal(choice[1][0], moving)
    np.testing.assert_array_equal(choice[1][1][moving], pick[moving])
    np.testing.assert_array_equal(choice[1][2][moving], explained[moving])


@given(
    seed=st.integers(0, 2**16),
    wanted=st.lists(st.booleans(), min_size=5, max_size=5),
)
def test_the_starts_of_the_wanted_islands_are_the_starts_of_all(seed, wanted):
    # Each island's histogram peaks are its own voters' alone: asked only of some
    # islands (with the draws made beforehand), those islands get the same starts.
    rng = np.random.default_rng(seed)
    n_islands = 5
    boxes = [_box(rng, [3.0 * k, 0.0, 0.0], n=80) for k in range(n_islands)]
    a = np.vstack(boxes)
    groups = np.repeat(np.arange(n_islands), [len(b) for b in boxes])
    sweep = np.vstack([b + rng.normal(0.0, 0.4, 3) for b in boxes])
    ego = (np.eye(3), np.zeros(3))
    wanted = np.array(wanted)
    common = dict(max_displacement=1.5, bin_size=0.25)
    args = (a, groups, n_islands, sweep, groups, n_islands, ego)
    every = translation_starts(*args, random_state=seed, **common)
    draws = start_draws(groups, n_islands, len(sweep), seed)
    some = translation_starts(*args, draws=draws, wanted=wanted, **common)
    np.testing.assert_array_equal(some[wanted], every[wanted])
    # The others keep their centroid starts only.
    np.testing.assert_array_equal(some[~wanted, :3], every[~wanted, :3])
    assert np.isnan(some[~wanted, 3:]).all()
