"""MultiModelRegistration on inputs that are not what they claim: other units, invalid and
duplicated rows, two point clouds stacked row by row, a flow in other units."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_array_equal
from scipy.spatial.transform import Rotation
from sklearn.metrics import adjusted_rand_score

from mmreg import MultiModelRegistration
from mmreg._validation import invalid_points, invalid_rows, no_return
from mmreg.cli import main
from mmreg.datasets import make_scene
from mmreg.estimators._multi_model_registration import ScaleWarning, _first_copies
from mmreg.init import EuclideanClustering


def _street_like(random_state=0):
    """Four objects; the first two (half the rows) keep still, the third creeps 2 cm (below
    min_motion = tau / 100 = 5 cm at tau = 5: it is static world), the fourth moves."""
    scene = make_scene(n_objects=4, n_points=800, random_state=random_state)
    a, labels = scene.X[:, :3], scene.labels
    rng = np.random.default_rng(random_state)
    b = a + rng.normal(scale=0.002, size=a.shape)
    b[labels == 2] += [0.02, 0.0, 0.0]
    b[labels == 3] = scene.X[labels == 3, 3:]
    return np.hstack([a, b]), labels


STREET, STREET_LABELS = _street_like()


def _estimator(tau=5.0):
    # 20 initial clusters: 800 rows of four objects hold fewer than the default 100.
    return MultiModelRegistration(tau=tau, init=EuclideanClustering(n_clusters=20), random_state=0)


FIT = _estimator().fit(STREET)


def test_creeping_object_is_static_world_and_moving_one_is_found():
    assert FIT.min_motion_ == 0.05
    assert adjusted_rand_score(np.minimum(STREET_LABELS, 3) // 3, FIT.labels_) == 1.0


@settings(max_examples=8, deadline=None)
@given(scale=st.floats(1e-3, 1e3))
def test_labels_do_not_depend_on_units(scale):
    est = _estimator(5.0 * scale).fit(STREET * scale)
    assert est.min_motion_ == pytest.approx(0.05 * scale)
    assert adjusted_rand_score(FIT.labels_, est.labels_) == 1.0


def test_invalid_rows_are_left_out_and_counted():
    nan_rows = np.full((7, 6), np.nan)
    zero_a = np.hstack([np.zeros((40, 3)), STREET[:40, 3:]])  # failed returns at the origin
    X = np.vstack([STREET, nan_rows, zero_a])
    est = _estimator().fit(X)
    assert est.n_invalid_ == 47
    assert_array_equal(est.labels_[: len(STREET)], FIT.labels_)
    assert_array_equal(est.labels_[len(STREET) :], -1)
    assert np.isnan(est.flow_[len(STREET) :]).all()
    assert_array_equal(est.predict(X)[len(STREET) :], -1)
    assert FIT.n_invalid_ == 0


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 2**16))
def test_duplicated_rows_do_not_change_the_labels(seed):
    rows = np.random.default_rng(seed).choice(len(STREET), 100, replace=False)
    est = _estimator().fit(np.vstack([STREET, STREET[rows]]))
    assert adjusted_rand_score(FIT.labels_, est.labels_[: len(STREET)]) == 1.0
    assert_array_equal(est.labels_[len(STREET) :], est.labels_[rows])


def test_two_point_clouds_stacked_row_by_row_are_refused():
    # Two samples of the same scene, drawn independently: rows pair points across it
    # (flows of nearest a-points differ by about the scene's radius; real flows: 0.02).
    other = np.random.default_rng(1).permutation(len(STREET))
    X = np.hstack([STREET[:, :3], STREET[other, 3:]])
    with pytest.raises(ValueError, match="SweepRegistration"):
        MultiModelRegistration(tau=1.5).fit(X)


def test_a_static_world_that_turns_83_degrees_warns_about_units():
    # Points in metres and a flow in millimetres turn an Argoverse 2 sweep's static world
    # by 83 degrees; a sensor turns a few degrees between two sweeps.
    turn = Rotation.from_euler("z", 83, degrees=True).as_matrix()
    X = STREET.copy()
    world = STREET_LABELS < 3
    X[world, 3:] = X[world, :3] @ turn.T
    with pytest.warns(ScaleWarning, match="units") as caught:
        est = _estimator().fit(X)
    assert est.static_cluster_ >= 0
    assert any(w.filename == __file__ for w in caught)


def test_the_command_line_refuses_two_point_clouds_in_one_line(tmp_path, capsys):
    other = np.random.default_rng(1).permutation(len(STREET))
    path = tmp_path / "stacked.npy"
    np.save(path, np.hstack([STREET[:, :3], STREET[other, 3:]]))
    assert main(["register", str(path), "--out", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("mmreg: error: ") and err.count("\n") == 1
    assert "stacked.npy" in err and "--sweep" in err


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**16), values=st.integers(1, 4))
def test_first_copies_are_those_of_an_exact_row_comparison(seed, values):
    # Few distinct values: many equal rows, and rows whose weighted sums tie by chance.
    X = np.random.default_rng(seed).integers(0, values, (300, 6)).astype(float)
    _, first, inverse = np.unique(X, axis=0, return_index=True, return_inverse=True)
    assert_array_equal(_first_copies(X), first[inverse.ravel()])


@given(
    kinds=st.lists(st.sampled_from(["point", "origin", "nan"]), min_size=0, max_size=30),
    d=st.sampled_from([2, 3]),
)
def test_invalid_points_are_the_invalid_rows_of_the_points_stacked_twice(kinds, d):
    rng = np.random.default_rng(len(kinds))
    points = rng.normal(size=(len(kinds), d))
    for row, kind in enumerate(kinds):
        if kind == "origin":
            points[row] = 0.0
        elif kind == "nan":
            points[row, rng.integers(d)] = np.nan
    stacked = invalid_rows(np.hstack([points, points]))
    assert_array_equal(invalid_points(points), stacked)
    # What the command line and the runner drop: points of odd columns as a set, rows of
    # even columns as correspondences [a | b].
    assert_array_equal(no_return(points), stacked if d % 2 else invalid_rows(points))
