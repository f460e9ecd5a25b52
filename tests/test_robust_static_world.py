"""``variant="sweep"`` on sweep-like scenes: a static world in islands, noisy movers, flow out.

Each scene is a small stand-in for a LiDAR sweep with a network's scene flow (ground
removed): islands of static structure farther apart than ``tau``, all moving with the ego
motion with millimetre flow errors, and moving cars whose flow errs by centimetres. The
default is ``variant="sweep"``; ``variant="robust"`` fails them (one shared noise scale
makes the cars' flows outliers, and the islands stay one cluster each), which is checked
too.
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mmreg import MultiModelRegistration
from mmreg.metrics import objects_found

EGO = (Rotation.from_euler("z", 0.4, degrees=True).as_matrix(), np.array([0.07, 0.01, 0.0]))


def _box(rng, center, size, n):
    return center + rng.uniform(-0.5, 0.5, (n, 3)) * size


def sweep_like_scene(seed=0, *, car_noise=0.03, static_noise=0.003, n_islands=12):
    """Static islands 15 m apart (tau = 5) and two cars moving ~1 m, as (X, labels, flow)."""
    rng = np.random.default_rng(seed)
    angles = np.linspace(0, 2 * np.pi, n_islands, endpoint=False)
    radius = 15.0 * n_islands / (2 * np.pi)
    islands = [
        _box(rng, [radius * np.cos(t), radius * np.sin(t), 1.0], [4.0, 4.0, 2.0], 300)
        for t in angles
    ]
    static = np.vstack(islands)
    cars = [_box(rng, c, [4.0, 1.8, 1.5], 250) for c in ([0.0, 3.0, 0.8], [6.0, -4.0, 0.8])]
    car_motions = [
        (Rotation.from_euler("z", 2.0, degrees=True).as_matrix(), np.array([1.1, 0.1, 0.0])),
        (Rotation.from_euler("z", -1.0, degrees=True).as_matrix(), np.array([-0.2, 0.9, 0.0])),
    ]
    a = np.vstack([static, *cars])
    labels = np.repeat([0, 1, 2], [len(static), len(cars[0]), len(cars[1])])
    true_b = np.empty_like(a)
    true_b[labels == 0] = static @ EGO[0].T + EGO[1]
    for k, (rotation, translation) in enumerate(car_motions, start=1):
        true_b[labels == k] = a[labels == k] @ rotation.T + translation
    noise = np.where(labels[:, None] == 0, static_noise, car_noise)
    b = true_b + rng.normal(size=a.shape) * noise
    return np.hstack([a, b]), labels, true_b - a


@pytest.fixture(scope="module")
def fitted():
    X, labels, flow = sweep_like_scene()
    est = MultiModelRegistration(tau=5.0, variant="sweep", random_state=0).fit(X)
    return est, X, labels, flow


def test_static_islands_are_one_cluster_flagged_static(fitted):
    est, _, labels, _ = fitted
    static = labels == 0
    assert est.static_cluster_ >= 0
    assert np.mean(est.labels_[static] == est.static_cluster_) > 0.99
    assert not est.moving_[est.static_cluster_]


def test_cars_ten_times_noisier_than_the_static_world_are_found(fitted):
    est, _, labels, _ = fitted
    assert objects_found(labels, est.labels_, objects=[1, 2]) == 1.0
    for car in (1, 2):
        members = est.labels_[labels == car]
        assert np.mean(members < 0) < 0.05
        cluster = np.bincount(members[members >= 0]).argmax()
        assert est.moving_[cluster]


def test_one_cluster_per_motion(fitted):
    est, *_ = fitted
    assert est.n_clusters_ == 3


def test_rigid_flow_out_is_closer_to_the_truth_than_the_input(fitted):
    est, X, labels, flow = fitted
    given = np.linalg.norm(X[:, 3:] - X[:, :3] - flow, axis=1)
    rigid = np.linalg.norm(est.flow_ - flow, axis=1)
    for k in (0, 1, 2):
        assert rigid[labels == k].mean() < 0.5 * given[labels == k].mean()


def test_without_the_static_world_step_the_islands_stay_apart():
    X, labels, _ = sweep_like_scene(seed=1)
    est = MultiModelRegistration(
        tau=5.0, variant="sweep", random_state=0, skip_steps=("static_world",)
    )
    est.fit(X)
    assert est.static_cluster_ == -1
    assert est.n_clusters_ >= 12
    # Without a static world the clusters share one noise scale, and the proposals take
    # none wider: the loop settles instead of proposing the noisy cars again and again.
    assert est.n_iter_ < est.max_iter


def test_two_far_apart_objects_with_one_motion_stay_apart_without_a_majority():
    # Exp. 3's meaning of the gate: no motion holds half of the scene, so none is the
    # static world, and two objects 20 m apart that move alike stay two clusters.
    rng = np.random.default_rng(2)
    centers = [[0, 0, 0], [20, 0, 0], [0, 20, 0], [20, 20, 0], [40, 10, 0]]
    a = np.vstack([_box(rng, c, [2.0, 2.0, 2.0], 200) for c in centers])
    labels = np.repeat(np.arange(5), 200)  # the two alike hold 40 %: no majority
    motions = [
        (np.eye(3), np.array([1.0, 0.0, 0.0])),
        (np.eye(3), np.array([1.0, 0.0, 0.0])),
        (Rotation.from_euler("x", 10, degrees=True).as_matrix(), np.array([0.0, 1.0, 0.0])),
        (Rotation.from_euler("y", -10, degrees=True).as_matrix(), np.array([0.0, 0.0, 1.0])),
        (Rotation.from_euler("z", 15, degrees=True).as_matrix(), np.array([-1.0, 0.0, 0.0])),
    ]
    b = np.empty_like(a)
    for k, (rotation, translation) in enumerate(motions):
        b[labels == k] = a[labels == k] @ rotation.T + translation
    b += rng.normal(scale=0.01, size=b.shape)
    est = MultiModelRegistration(tau=5.0, variant="sweep", random_state=0).fit(np.hstack([a, b]))
    assert est.static_cluster_ == -1
    assert est.n_clusters_ == 5
    assert est.moving_.all()


def test_the_shared_noise_variant_fails_these_scenes():
    X, labels, _ = sweep_like_scene()
    est = MultiModelRegistration(tau=5.0, variant="robust", random_state=0).fit(X)
    assert est.static_cluster_ == -1
    assert est.n_clusters_ > 3 or objects_found(labels, est.labels_, objects=[1, 2]) < 1.0


def test_unknown_skip_step_is_a_clear_error():
    X, _, _ = sweep_like_scene(n_islands=3)
    with pytest.raises(ValueError, match="Unknown steps"):
        MultiModelRegistration(variant="sweep", skip_steps=("nonsense",)).fit(X)


def test_an_initial_cluster_holding_a_moving_and_a_parked_car_splits():
    # The initialiser joined car 1 (250 points, moving 1.1 m) with a parked car (150
    # points whose flow is 2 cm off the ego motion, as an annotation's jitter makes it):
    # the car must come out alone and the parked one with the static world.
    X, labels, _ = sweep_like_scene(seed=3)
    init = 3 + np.arange(len(labels)) // 300  # one initial cluster per island
    init[labels > 0] = labels[labels > 0]
    parked = np.flatnonzero(labels == 0)[:300]
    # The parked car is the island's far half; the near half is not in the scene.
    keep = np.ones(len(labels), dtype=bool)
    keep[parked[X[parked, 0] <= np.median(X[parked, 0])]] = False
    X[parked, 3] += 0.02
    init[parked] = 1
    X, labels, init = X[keep], labels[keep], init[keep]
    est = MultiModelRegistration(tau=5.0, variant="sweep", init=init, random_state=0).fit(X)
    assert objects_found(labels, est.labels_, objects=[1, 2]) == 1.0
    car = est.labels_[labels == 1]
    assert np.mean(car == np.bincount(car[car >= 0]).argmax()) > 0.95
    assert np.mean(est.labels_[labels == 0] == est.static_cluster_) > 0.99


def test_the_loop_converges_before_max_iter(fitted):
    est, *_ = fitted
    assert est.converged_
    assert est.n_iter_ < est.max_iter
