"""SweepRegistration's raw rounds start the estimator from one static cluster.

Every island that keeps the ego motion (and every small one) starts in the ego motion's
cluster: the estimator's first clusters are that one and the moving islands, not one
per static island with the same motion (which it only merged again).
"""

import numpy as np

from mmreg import SweepRegistration
from mmreg.datasets import make_lidar_sweeps


def _rigid_fit(a, b):
    """Least-squares rigid motion carrying ``a`` onto ``b`` (Kabsch)."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rotation, cb - rotation @ ca


def test_the_estimator_starts_from_one_static_cluster():
    scene = make_lidar_sweeps(
        n_beams=32, interval=0.1, ego_speed=5.0, n_azimuths=512, random_state=0
    )
    est = SweepRegistration(random_state=0)
    seen = []
    make_cluster = est._cluster

    def recording(rng):
        cluster = make_cluster(rng)

        def fit(X, init):
            seen.append((X.copy(), np.asarray(init).copy()))
            return cluster(X, init)

        return fit

    est._cluster = recording
    est.fit(scene.a, sweep=scene.sweep)
    X, init = seen[0]
    a, b = X[:, :3], X[:, 3:]
    static = init == 0
    rotation, translation = _rigid_fit(a[static], b[static])
    residual = np.linalg.norm(a @ rotation.T + translation - b, axis=1)
    # The ego motion's cluster: one rigid motion, exactly.
    assert residual[static].max() < 1e-6
    # Every other starting cluster is a moving island: the ego motion leaves it.
    others = np.unique(init[init > 0])
    assert len(others) and all(residual[init == k].max() > 1e-3 for k in others)


def test_a_sweep_without_islands_starts_from_the_ego_motion_alone():
    # No island reaches min_island_size: every point starts in the ego motion's cluster.
    scene = make_lidar_sweeps(
        n_beams=32, interval=0.1, ego_speed=5.0, n_azimuths=512, random_state=0
    )
    est = SweepRegistration(min_island_size=10**6, random_state=0)
    est.fit(scene.a, sweep=scene.sweep)
    init = est.estimator_.init_labels_
    assert len(init) and (init == init[0]).all()
    assert not est.moving_.any()
