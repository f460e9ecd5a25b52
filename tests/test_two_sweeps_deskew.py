"""Deskewing: moving objects captured at several times within one sweep."""

import numpy as np
import pytest
from _surfaces import area_weighted_box
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import mmreg.sweeps._cluster_icp as cluster_icp
from mmreg import MultiModelRegistration, SweepRegistration
from mmreg.sweeps._deskew import deskew, relative_motions
from mmreg.sweeps._icp import rotation_vectors_to_matrices

# Static boxes and one car (centre, size), as in test_two_sweeps.
STATIC = [
    ((0.0, 0.0, 0.0), (6.0, 2.0, 3.0)),
    ((0.0, 12.0, 0.0), (4.0, 4.0, 4.0)),
    ((12.0, 6.0, 0.0), (2.0, 8.0, 3.0)),
]
CAR = ((-9.0, 6.0, 0.0), (4.0, 2.0, 1.5))
INTERVAL = 0.1
VELOCITY = np.array([8.0, 0.0, 0.0])  # m/s relative to the static world
# Each sweep sees the car with two LiDAR heads at two capture times; the car has moved
# in azimuth between the sweeps, so the second sweep's times differ from the first's.
HEAD_TIMES = ((0.01, 0.06), (0.04, 0.09))


def _ego():
    return rotation_vectors_to_matrices(np.array([[0.0, 0.0, 0.01]]))[0], np.array([0.3, 0.0, 0.0])


def _sweep(rng, n_static, n_car, head_times, frame):
    """One ego-motion compensated sweep in the frame ``frame`` (the ego motion, or None).

    The car's reference pose is shifted by ``k * VELOCITY * INTERVAL`` (k = 0, 1 for the
    two sweeps); each head's points are where the car was at that head's capture time.
    """
    k = 0 if frame is None else 1
    R, t = (np.eye(3), np.zeros(3)) if frame is None else frame
    parts, times, labels = [], [], []
    for center, size in STATIC:
        parts.append(area_weighted_box(center, size, n_static, rng))
        times.append(rng.uniform(0.0, INTERVAL, n_static))
        labels.append(np.zeros(n_static, dtype=int))
    for tau in head_times:
        car = area_weighted_box(CAR[0], CAR[1], n_car // 2, rng) + VELOCITY * (k * INTERVAL + tau)
        parts.append(car)
        times.append(np.full(n_car // 2, tau))
        labels.append(np.ones(n_car // 2, dtype=int))
    points = np.vstack(parts) @ R.T + t
    return points, np.concatenate(times), np.concatenate(labels)


def make_skewed_pair(random_state=0):
    """Two sweeps of a static world and a car scanned twice per sweep, 50 ms apart."""
    rng = np.random.default_rng(random_state)
    ego = _ego()
    a, times, labels = _sweep(rng, 1500, 1200, HEAD_TIMES[0], None)
    sweep, sweep_times, _ = _sweep(rng, 2200, 1800, HEAD_TIMES[1], ego)
    # The truth: the static world moves with the ego motion, the car's points with the
    # car's motion over the interval (relative VELOCITY * INTERVAL, then the ego motion),
    # whatever their capture time (the Argoverse 2 ground truth's convention).
    rotations = np.stack([ego[0], ego[0]])
    translations = np.stack([ego[1], ego[0] @ (VELOCITY * INTERVAL) + ego[1]])
    b = np.einsum("nij,nj->ni", rotations[labels], a) + translations[labels]
    return a, b, labels, sweep, times, sweep_times


def _estimator(**params):
    inner = MultiModelRegistration(variant="sweep", tau=2.0, random_state=0)
    return SweepRegistration(inner, max_distance=1.5, random_state=0, **params)


def _car_error(est, a, b, labels):
    return np.abs(a + est.flow_ - b)[labels == 1].max()


# The sweeps' surfaces are sampled about 0.1 m apart; the deskewed car is recovered to a
# small share of that, the skewed one is 0.1 m and more off.
SPACING = 0.05


def test_deskewing_recovers_the_motion_that_the_skewed_copies_hide():
    a, b, labels, sweep, times, sweep_times = make_skewed_pair()
    X = np.hstack([a, b])  # exact correspondences: only the ICP can go wrong
    skewed = _estimator(refine="all").fit(X, sweep=sweep)
    timed = _estimator(refine="all").fit(
        X, sweep=sweep, times=times, sweep_times=sweep_times, interval=INTERVAL
    )
    assert skewed.n_clusters_ == timed.n_clusters_ == 2
    np.testing.assert_array_equal(skewed.labels_, timed.labels_)
    assert (
        _car_error(timed, a, b, labels) < SPACING < 2 * SPACING < _car_error(skewed, a, b, labels)
    )
    # The static world is not deskewed: its points moved by the ego motion either way.
    static = labels == 0
    assert np.abs(a + timed.flow_ - b)[static].max() < SPACING


def test_deskewing_two_raw_sweeps():
    a, b, labels, sweep, times, sweep_times = make_skewed_pair(random_state=1)
    est = _estimator(island_radius=1.0, min_island_size=20)
    skewed = est.fit(a, sweep=sweep)
    skewed_error = _car_error(skewed, a, b, labels)
    timed = est.fit(a, sweep=sweep, times=times, sweep_times=sweep_times, interval=INTERVAL)
    assert timed.moving_.sum() == 1
    assert _car_error(timed, a, b, labels) < SPACING < 2 * SPACING < skewed_error


def test_no_times_never_deskews(monkeypatch):
    a, b, labels, sweep, times, sweep_times = make_skewed_pair()
    before = _estimator().fit(np.hstack([a, b]), sweep=sweep)

    def refuse(*args, **kwargs):
        raise AssertionError("deskewed without times")

    monkeypatch.setattr(cluster_icp, "deskew", refuse)
    after = _estimator().fit(np.hstack([a, b]), sweep=sweep)
    np.testing.assert_array_equal(before.flow_, after.flow_)
    with pytest.raises(AssertionError, match="deskewed"):
        _estimator().fit(
            np.hstack([a, b]), sweep=sweep, times=times, sweep_times=sweep_times, interval=0.1
        )


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"times": "n"}, ValueError, "go together"),
        ({"times": "n", "sweep_times": "m"}, ValueError, "only times, sweep_times"),
        ({"times": "n", "sweep_times": "m", "interval": 0.0}, ValueError, "> 0"),
        ({"times": "n", "sweep_times": "m", "interval": "x"}, TypeError, "number of seconds"),
        ({"times": "m", "sweep_times": "m", "interval": 0.1}, ValueError, r"times must have"),
        ({"times": "nan", "sweep_times": "m", "interval": 0.1}, ValueError, "NaN"),
    ],
)
def test_bad_times_are_refused(kwargs, error, message):
    rng = np.random.default_rng(0)
    a, sweep = rng.uniform(size=(40, 3)), rng.uniform(size=(60, 3))
    values = {"n": np.zeros(40), "m": np.zeros(60), "nan": np.full(40, np.nan)}
    kwargs = {k: values.get(v, v) if isinstance(v, str) else v for k, v in kwargs.items()}
    with pytest.raises(error, match=message):
        SweepRegistration().fit(a, sweep=sweep, **kwargs)


def test_times_need_the_second_sweep():
    X = np.random.default_rng(0).uniform(size=(40, 6))
    with pytest.raises(ValueError, match="pass the second sweep"):
        SweepRegistration().fit(X, times=np.zeros(40))


@settings(max_examples=25, deadline=None)
@given(
    turn=st.lists(st.floats(-0.3, 0.3), min_size=3, max_size=3),
    shift=st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3),
    seed=st.integers(0, 2**16),
)
def test_deskew_inverts_the_interpolated_motion(turn, shift, seed):
    rng = np.random.default_rng(seed)
    body = rng.normal(size=(50, 3)) * [2.0, 1.0, 0.7] + [10.0, -4.0, 1.0]
    centre = body.mean(axis=0)
    fractions = rng.uniform(-0.5, 1.5, len(body))
    # Forward, written independently: the centre moves on its line by the fraction of
    # `shift`, the body turns about it by the fraction of `turn`.
    turns = Rotation.from_rotvec(fractions[:, None] * np.asarray(turn)).as_matrix()
    captured = np.einsum("nij,nj->ni", turns, body - centre) + centre + fractions[:, None] * shift
    # The motion whose interpolation that is: M(x) = R (x - c) + c + shift.
    R = Rotation.from_rotvec(turn).as_matrix()
    t = centre + np.asarray(shift) - R @ centre
    back = deskew(captured, np.zeros(len(body), int), fractions, R[None], t[None], centre[None])
    np.testing.assert_allclose(back, body, atol=1e-9)
    straight = deskew(
        captured, np.zeros(len(body), int), fractions, R[None], t[None], centre[None], turn=False
    )
    np.testing.assert_allclose(straight, captured - fractions[:, None] * shift, atol=1e-12)


def test_deskew_leaves_points_without_a_group():
    points = np.arange(12.0).reshape(4, 3)
    out = deskew(
        points,
        np.array([-1, 0, -1, 0]),
        np.ones(4),
        np.eye(3)[None],
        np.ones((1, 3)),
        np.zeros((1, 3)),
    )
    np.testing.assert_array_equal(out[[0, 2]], points[[0, 2]])
    np.testing.assert_array_equal(out[[1, 3]], points[[1, 3]] - 1.0)


def test_relative_motions_compose_with_the_world():
    rng = np.random.default_rng(3)
    world = (Rotation.from_rotvec(rng.normal(size=3) * 0.1).as_matrix(), rng.normal(size=3))
    R = Rotation.from_rotvec(rng.normal(size=(4, 3)) * 0.1).as_matrix()
    t = rng.normal(size=(4, 3))
    (R1, t1), (R2, t2) = relative_motions(R, t, world)

    def matrix(rotation, translation):
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = rotation, translation
        return T

    E = matrix(*world)
    for k in range(4):
        M = matrix(R[k], t[k])
        np.testing.assert_allclose(matrix(R1[k], t1[k]), np.linalg.inv(E) @ M, atol=1e-12)
        np.testing.assert_allclose(matrix(R2[k], t2[k]), M @ np.linalg.inv(E), atol=1e-12)


def test_a_cluster_the_second_sweep_does_not_see_keeps_its_motion():
    a, b, labels, sweep, times, sweep_times = make_skewed_pair()
    # The second sweep without the car (its points are the last ones).
    seen = np.arange(len(sweep)) < 3 * 2200
    X = np.hstack([a, b])
    est = _estimator().fit(
        X, sweep=sweep[seen], times=times, sweep_times=sweep_times[seen], interval=INTERVAL
    )
    plain = MultiModelRegistration(variant="sweep", tau=2.0, random_state=0).fit(X)
    car = est.labels_[labels == 1][0]
    np.testing.assert_array_equal(est.flow_[labels == 1], plain.flow_[labels == 1])
    assert np.isnan(est.icp_scales_[car])
