"""SweepRegistration's reach: objects farther than the "auto" guess are still found.

The reach (``max_displacement="auto"``) is a guess at the traffic's speed times the
sweeps' interval: ``0.6 tau`` or 1.5 ego steps. 2 Hz keyframes with the ego car slow
(3 m/s: 1.5 m a step) leave an oncoming car 4.8 m on, beyond the 3 m guess; the islands
that nothing within it explains search again twice as far. Flat patches that the wider
search slides along their own plane stay static.
"""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from mmreg import SweepRegistration
from mmreg.datasets import make_lidar_sweeps
from mmreg.sweeps._ambiguous_shapes import is_line, slides_in_plane


def _relative_step(scene, k):
    """Mean motion of object k relative to the static world, between the sweeps."""
    truth = scene.transforms[0]
    points = scene.a[scene.labels == k]
    at_rest = points @ truth[:3, :3].T + truth[:3, 3]
    return np.linalg.norm((points + scene.flow[scene.labels == k] - at_rest).mean(axis=0))


def test_a_car_beyond_the_guessed_reach_is_found():
    scene = make_lidar_sweeps(
        n_beams=32, interval=0.5, ego_speed=3.0, n_azimuths=1024, random_state=0
    )
    far = 2  # the oncoming car
    assert 4.5 < _relative_step(scene, far) < 5.0
    est = SweepRegistration(random_state=0).fit(scene.a, sweep=scene.sweep)
    assert est.max_displacement_ == 3.0  # the guess stays below the car's step
    for k in (1, far):
        mask = scene.labels == k
        cluster = np.bincount(est.labels_[mask][est.labels_[mask] >= 0]).argmax()
        iou = (mask & (est.labels_ == cluster)).sum() / (mask | (est.labels_ == cluster)).sum()
        assert iou > 0.9 and est.moving_[cluster]
    truth = scene.transforms[0]
    static = scene.labels == 0
    assert not any(np.mean(static[est.labels_ == c]) > 0.5 for c in np.flatnonzero(est.moving_))
    error = np.linalg.norm(est.flow_ - scene.flow, axis=1)
    assert np.median(error[scene.labels == far]) < 0.1
    assert np.linalg.norm(est.ego_motion_[1] - truth[:3, 3]) < 0.02


def test_a_given_reach_is_kept():
    """A user's max_displacement is a bound: nothing beyond it is searched."""
    scene = make_lidar_sweeps(
        n_beams=32, interval=0.5, ego_speed=3.0, n_azimuths=1024, random_state=0
    )
    est = SweepRegistration(max_displacement=3.0, random_state=0)
    est.fit(scene.a, sweep=scene.sweep)
    far = scene.labels == 2
    assert not est.moving_[np.unique(est.labels_[far][est.labels_[far] >= 0])].any()


@given(
    angles=st.tuples(*[st.floats(-np.pi, np.pi)] * 3),
    in_plane=st.floats(0.0, 2 * np.pi),
    length=st.floats(0.5, 10.0),
    seed=st.integers(0, 2**16),
)
def test_a_flat_patch_slides_along_its_plane_not_across_it(angles, in_plane, length, seed):
    rng = np.random.default_rng(seed)
    turn = Rotation.from_euler("xyz", angles).as_matrix()
    patch = np.c_[rng.uniform(-1, 1, (80, 2)), rng.normal(0, 0.005, 80)] @ turn.T + [5, 2, 0]
    along = turn @ [np.cos(in_plane), np.sin(in_plane), 0.0]
    across = turn @ [0.6 * np.cos(in_plane), 0.6 * np.sin(in_plane), 0.8]  # 0.8 across
    ego = (Rotation.from_euler("z", 0.1).as_matrix(), np.array([1.0, 0.0, 0.0]))
    translations = np.array([ego[1] + length * ego[0] @ along, ego[1] + length * ego[0] @ across])
    rotations = np.stack([ego[0], ego[0]])
    groups = np.repeat([0, 1], 80)
    points = np.vstack([patch, patch])
    slides = slides_in_plane(points, groups, 2, (rotations, translations), ego)
    assert slides.tolist() == [True, False]
    # A box of the same size is not flat: it never slides.
    box = rng.uniform(-1, 1, (80, 3)) @ turn.T
    assert not slides_in_plane(box, np.zeros(80, int), 1, (rotations[:1], translations[:1]), ego)[0]
    assert not is_line(np.vstack([patch, box]), groups, 2).any()
    pole = np.c_[rng.normal(0, 0.02, (80, 2)), rng.uniform(0, length, 80)] @ turn.T
    assert is_line(pole, np.zeros(80, int), 1)[0]
