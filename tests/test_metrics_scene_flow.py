"""Scene-flow measures: hand-computed values, loop references, edge cases, input checks."""

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from sklearn.metrics import jaccard_score
from sklearn.model_selection import GridSearchCV

from mmreg import MultiModelRegistration
from mmreg.datasets import make_scene
from mmreg.metrics import (
    dynamic_iou,
    dynamic_mask,
    end_point_error,
    make_end_point_error_scorer,
    scene_flow_metrics,
    scene_flow_scorers,
    three_way_epe,
)

THRESHOLDS = (0.05, 0.1, 0.3)


def reference_hplflownet(flow_true, flow_pred):
    """HPLFlowNet's ``evaluate_3d``, one point at a time in plain Python."""
    errors, strict, relaxed, outliers = [], [], [], []
    for f, g in zip(flow_true, flow_pred, strict=True):
        e = math.sqrt(sum((gi - fi) ** 2 for fi, gi in zip(f, g, strict=True)))
        r = e / (math.sqrt(sum(fi**2 for fi in f)) + 1e-4)
        errors.append(e)
        strict.append(e < 0.05 or r < 0.05)
        relaxed.append(e < 0.1 or r < 0.1)
        outliers.append(e > 0.3 or r > 0.1)
    n = len(errors)
    return {
        "EPE3D": sum(errors) / n,
        "Acc3DS": sum(strict) / n,
        "Acc3DR": sum(relaxed) / n,
        "Outliers3D": sum(outliers) / n,
    }


def far_from_thresholds(flow_true, flow_pred, margin=1e-9):
    """No point's absolute or relative error lies within ``margin`` of a cut-off."""
    e = np.linalg.norm(flow_pred - flow_true, axis=1)
    r = e / (np.linalg.norm(flow_true, axis=1) + 1e-4)
    return all(np.all(np.abs(v - t) > margin) for v in (e, r) for t in THRESHOLDS)


flow_pairs = st.integers(1, 30).flatmap(
    lambda n: st.tuples(
        arrays(np.float64, (n, 3), elements=st.floats(-2, 2)),
        arrays(np.float64, (n, 3), elements=st.floats(-0.5, 0.5)),
    )
)


# --- end_point_error ---------------------------------------------------------------


def test_end_point_error_by_hand():
    truth = [[0.0, 0, 0], [1, 0, 0], [0, 2, 0]]
    estimate = [[3.0, 4, 0], [1, 0, 0], [0, 2, 1]]  # errors 5, 0, 1
    assert end_point_error(truth, estimate) == pytest.approx(2.0)
    assert end_point_error(truth, estimate, sample_weight=[1, 1, 2]) == pytest.approx(7 / 4)
    assert end_point_error(truth, truth) == 0.0


@given(flow_pairs)
def test_end_point_error_matches_a_loop(pair):
    truth, error = pair
    estimate = truth + error
    loop = sum(math.dist(f, g) for f, g in zip(truth, estimate, strict=True)) / len(truth)
    assert end_point_error(truth, estimate) == pytest.approx(loop, rel=1e-9, abs=1e-12)
    # Symmetric, and blind to a common offset of both flows.
    assert end_point_error(estimate, truth) == pytest.approx(loop, rel=1e-9, abs=1e-12)
    shifted = end_point_error(truth + 7.0, estimate + 7.0)
    assert shifted == pytest.approx(loop, rel=1e-6, abs=1e-9)


def test_integer_weights_are_repeated_points():
    rng = np.random.default_rng(0)
    truth, estimate = rng.normal(size=(2, 6, 3))
    weight = np.array([1, 3, 0, 2, 1, 1])
    repeated = np.repeat(np.arange(6), weight)
    weighted = scene_flow_metrics(truth, estimate, sample_weight=weight)
    plain = scene_flow_metrics(truth[repeated], estimate[repeated])
    assert weighted == pytest.approx(plain)


def test_any_dimension():
    assert end_point_error([[0.0, 0.0]], [[3.0, 4.0]]) == pytest.approx(5.0)
    assert end_point_error([[1.0]], [[0.5]]) == pytest.approx(0.5)


# --- scene_flow_metrics --------------------------------------------------------------


def test_scene_flow_metrics_by_hand():
    truth = [[1.0, 0, 0], [1.0, 0, 0], [0.5, 0, 0], [0.5, 0, 0], [2.0, 0, 0]]
    estimate = [
        [1.04, 0, 0],  # e 0.04: strict, relaxed
        [1.08, 0, 0],  # e 0.08, r 0.08: relaxed only
        [0.549, 0, 0],  # e 0.049 (strict by e), r 0.098: relaxed, not an outlier
        [0.56, 0, 0],  # e 0.06, r 0.12: relaxed by e, outlier by r
        [2.5, 0, 0],  # e 0.5: outlier by e, r 0.25
    ]
    got = scene_flow_metrics(truth, estimate)
    assert got["EPE3D"] == pytest.approx((0.04 + 0.08 + 0.049 + 0.06 + 0.5) / 5)
    assert got["Acc3DS"] == pytest.approx(2 / 5)
    assert got["Acc3DR"] == pytest.approx(4 / 5)
    assert got["Outliers3D"] == pytest.approx(2 / 5)
    assert list(got) == ["EPE3D", "Acc3DS", "Acc3DR", "Outliers3D"]
    assert all(type(v) is float for v in got.values())


def test_relative_error_divides_by_the_true_flow():
    # e = 0.052: 0.104 of the true 0.5 m (an outlier), but 0.094 of the estimate's 0.552 m.
    assert scene_flow_metrics([[0.5, 0, 0]], [[0.552, 0, 0]])["Outliers3D"] == 1.0
    assert scene_flow_metrics([[0.552, 0, 0]], [[0.5, 0, 0]])["Outliers3D"] == 0.0


def test_relative_error_adds_1e_4_to_the_norm():
    # e = 1.5e-5 on a 1e-4 flow: 0.075 with HPLFlowNet's 1e-4 (no outlier), 0.15 without.
    got = scene_flow_metrics([[1e-4, 0, 0]], [[1.15e-4, 0, 0]])
    assert got["Outliers3D"] == 0.0
    assert got["Acc3DS"] == 1.0


def test_static_points_with_any_visible_error_are_outliers():
    # HPLFlowNet's known quirk: with no true flow, 1 cm is a relative error of 100.
    got = scene_flow_metrics([[0.0, 0, 0]], [[0.01, 0, 0]])
    assert got == {"EPE3D": pytest.approx(0.01), "Acc3DS": 1.0, "Acc3DR": 1.0, "Outliers3D": 1.0}


def test_accuracies_use_or_not_and():
    # 0.2 m off a 10 m flow: far beyond 5 cm but within 5 % of the motion.
    got = scene_flow_metrics([[10.0, 0, 0]], [[10.2, 0, 0]])
    assert got["Acc3DS"] == 1.0 and got["Acc3DR"] == 1.0 and got["Outliers3D"] == 0.0
    # 0.4 m off a 10 m flow is 4 %: still accurate, yet an outlier by its 0.3 m.
    got = scene_flow_metrics([[10.0, 0, 0]], [[10.4, 0, 0]])
    assert got["Acc3DS"] == 1.0 and got["Outliers3D"] == 1.0


@given(flow_pairs)
def test_scene_flow_metrics_match_the_reference_loop(pair):
    truth, error = pair
    estimate = truth + error
    assume(far_from_thresholds(truth, estimate))
    got = scene_flow_metrics(truth, estimate)
    expected = reference_hplflownet(truth.tolist(), estimate.tolist())
    assert got["EPE3D"] == pytest.approx(expected["EPE3D"], rel=1e-9, abs=1e-12)
    for key in ("Acc3DS", "Acc3DR", "Outliers3D"):
        assert got[key] == pytest.approx(expected[key])
    assert got["Acc3DS"] <= got["Acc3DR"]  # strict implies relaxed


def test_perfect_estimate():
    truth = np.random.default_rng(1).normal(size=(50, 3))
    got = scene_flow_metrics(truth, truth)
    assert got == {"EPE3D": 0.0, "Acc3DS": 1.0, "Acc3DR": 1.0, "Outliers3D": 0.0}


# --- dynamic_mask --------------------------------------------------------------------


def test_dynamic_mask_speed_rule():
    flow = [[0.0, 0, 0], [0.03, 0.0, 0.0], [0.0, 0.04, 0.035], [0.3, 0.4, 0]]
    # Speeds 0, 0.3, 0.53 and 5 m/s between sweeps 0.1 s apart; the cut-off is 0.5 m/s.
    np.testing.assert_array_equal(dynamic_mask(flow), [False, False, True, True])
    np.testing.assert_array_equal(dynamic_mask(flow, threshold=0.02), [False, True, True, True])


def test_dynamic_mask_relative_to_the_static_world():
    ego = np.tile([1.2, 0.0, 0.0], (3, 1))
    flow = [[1.2, 0.0, 0.0], [1.2, 0.06, 0.0], [0.0, 0.0, 0.0]]  # static, slow, parked-ego
    np.testing.assert_array_equal(dynamic_mask(flow, ego), [False, True, True])
    # Without the ego flow every point of a driving car's sweep would look dynamic.
    assert dynamic_mask(flow)[:2].all()


# --- three_way_epe -------------------------------------------------------------------


def reference_three_way(flow_true, flow_pred, foreground, dynamic):
    sums = {"foreground_dynamic": [], "foreground_static": [], "background_static": []}
    for f, g, fg, dyn in zip(flow_true, flow_pred, foreground, dynamic, strict=True):
        e = math.dist(f, g)
        if fg and dyn:
            sums["foreground_dynamic"].append(e)
        elif fg:
            sums["foreground_static"].append(e)
        elif not dyn:
            sums["background_static"].append(e)
    means = {k: sum(v) / len(v) if v else math.nan for k, v in sums.items()}
    means["three_way_mean"] = sum(means.values()) / 3
    return means


@given(
    st.integers(1, 40).flatmap(
        lambda n: st.tuples(
            arrays(np.float64, (n, 3), elements=st.floats(-2, 2)),
            arrays(np.float64, (n, 3), elements=st.floats(-2, 2)),
            arrays(bool, n),
            arrays(bool, n),
        )
    )
)
def test_three_way_epe_matches_a_loop(data):
    truth, estimate, foreground, dynamic = data
    got = three_way_epe(truth, estimate, foreground=foreground, dynamic=dynamic)
    expected = reference_three_way(truth.tolist(), estimate.tolist(), foreground, dynamic)
    assert list(got) == list(expected)
    for key, value in expected.items():
        if math.isnan(value):
            assert math.isnan(got[key])
        else:
            assert got[key] == pytest.approx(value, rel=1e-9, abs=1e-12)


def test_three_way_epe_weighs_classes_not_points():
    # 1 moving point with 1 m error among 98 static points with none.
    truth = np.zeros((100, 3))
    estimate = np.zeros((100, 3))
    estimate[0, 0] = 1.0
    foreground = np.arange(100) < 2
    dynamic = np.arange(100) < 1
    got = three_way_epe(truth, estimate, foreground=foreground, dynamic=dynamic)
    assert got["foreground_dynamic"] == 1.0
    assert got["three_way_mean"] == pytest.approx(1 / 3)
    assert end_point_error(truth, estimate) == pytest.approx(0.01)


def test_three_way_epe_empty_class_is_nan():
    truth = np.zeros((3, 3))
    got = three_way_epe(truth, truth, foreground=[False] * 3, dynamic=[False] * 3)
    assert got["background_static"] == 0.0
    assert math.isnan(got["foreground_dynamic"]) and math.isnan(got["foreground_static"])
    assert math.isnan(got["three_way_mean"])


def test_three_way_epe_leaves_out_dynamic_background():
    truth = np.zeros((2, 3))
    estimate = np.array([[0.0, 0, 0], [5.0, 0, 0]])
    got = three_way_epe(truth, estimate, foreground=[False, False], dynamic=[False, True])
    assert got["background_static"] == 0.0


# --- dynamic_iou ---------------------------------------------------------------------


@given(st.integers(1, 50).flatmap(lambda n: st.tuples(arrays(bool, n), arrays(bool, n))))
def test_dynamic_iou_is_the_jaccard_index_of_each_class(data):
    truth, pred = data
    got = dynamic_iou(truth, pred)
    for name, t, p in (("dynamic", truth, pred), ("static", ~truth, ~pred)):
        if (t | p).any():
            assert got[name] == pytest.approx(jaccard_score(t, p))
        else:
            assert math.isnan(got[name])
    defined = [v for k, v in got.items() if k != "mean" and not math.isnan(v)]
    assert got["mean"] == pytest.approx(np.mean(defined))
    swapped = dynamic_iou(pred, truth)
    assert swapped == pytest.approx(got, nan_ok=True)


def test_dynamic_iou_by_hand():
    got = dynamic_iou([True, True, False, False], [True, True, True, False])
    assert got == pytest.approx({"dynamic": 2 / 3, "static": 1 / 2, "mean": 7 / 12})
    got = dynamic_iou([False, False], [False, False])  # nothing moves, none predicted
    assert math.isnan(got["dynamic"]) and got["static"] == 1.0 and got["mean"] == 1.0


# --- input checks --------------------------------------------------------------------


@pytest.mark.parametrize(
    "call",
    [
        lambda t, p: end_point_error(t, p),
        lambda t, p: scene_flow_metrics(t, p),
        lambda t, p: three_way_epe(t, p, foreground=[True] * len(t), dynamic=[True] * len(t)),
    ],
)
def test_flow_checks(call):
    good = np.zeros((4, 3))
    with pytest.raises(ValueError, match="different shapes"):
        call(good, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="different shapes"):
        call(good, np.zeros((4, 2)))
    bad = good.copy()
    bad[1, 2] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        call(good, bad)
    bad[1, 2] = np.inf
    with pytest.raises(ValueError, match="flow_true.*infinity|infinity.*flow_true"):
        call(bad, good)
    with pytest.raises(ValueError, match="2D"):
        call(np.zeros(4), np.zeros(4))
    with pytest.raises(ValueError):
        call(np.zeros((0, 3)), np.zeros((0, 3)))


def test_mask_checks():
    flow = np.zeros((3, 3))
    with pytest.raises(ValueError, match="foreground has length 2"):
        three_way_epe(flow, flow, foreground=[True, False], dynamic=[True] * 3)
    with pytest.raises(ValueError, match="dynamic must be 1-D"):
        three_way_epe(flow, flow, foreground=[True] * 3, dynamic=[[True] * 3])
    with pytest.raises(ValueError, match="NaN"):
        three_way_epe(flow, flow, foreground=[1.0, np.nan, 0.0], dynamic=[True] * 3)
    with pytest.raises(ValueError, match="boolean"):
        three_way_epe(flow, flow, foreground=[0, 2, 1], dynamic=[True] * 3)
    with pytest.raises(TypeError, match="boolean"):
        three_way_epe(flow, flow, foreground=["a", "b", "c"], dynamic=[True] * 3)
    # 0/1 integers are masks too.
    got = three_way_epe(flow, flow, foreground=[1, 1, 0], dynamic=[1, 0, 0])
    assert list(got.values()) == [0.0, 0.0, 0.0, 0.0]
    with pytest.raises(ValueError, match="dynamic_pred has length 2"):
        dynamic_iou([True, False, True], [True, False])
    with pytest.raises(ValueError, match="empty"):
        dynamic_iou([], [])


def test_sample_weight_checks():
    flow = np.zeros((3, 3))
    with pytest.raises(ValueError, match=r"shape \(3,\)"):
        end_point_error(flow, flow, sample_weight=[1, 1])
    with pytest.raises(ValueError, match="NaN"):
        end_point_error(flow, flow, sample_weight=[1, np.nan, 1])
    with pytest.raises(ValueError, match="non-negative"):
        scene_flow_metrics(flow, flow, sample_weight=[1, -1, 1])
    with pytest.raises(ValueError, match="positive sum"):
        scene_flow_metrics(flow, flow, sample_weight=[0, 0, 0])


def test_dynamic_mask_checks():
    with pytest.raises(ValueError, match="flow_true and flow_static have different shapes"):
        dynamic_mask(np.zeros((3, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="threshold"):
        dynamic_mask(np.zeros((3, 3)), threshold=0.0)
    with pytest.raises(ValueError, match="NaN"):
        dynamic_mask([[np.nan, 0, 0]])


# --- scorers -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_scene():
    scene = make_scene(n_objects=2, n_points=200, noise=0.01, random_state=0)
    return scene.X, scene.b - scene.a


def test_end_point_error_scorer_scores_the_fitted_flow(small_scene):
    X, flow = small_scene
    est = MultiModelRegistration(init=np.arange(200) % 8, variant="paper").fit(X)
    scorer = make_end_point_error_scorer()
    assert scorer(est, X, flow) == pytest.approx(-end_point_error(flow, est.flow_))
    scores = {name: s(est, X, flow) for name, s in scene_flow_scorers().items()}
    expected = scene_flow_metrics(flow, est.flow_)
    assert scores == pytest.approx(
        {
            "neg_EPE3D": -expected["EPE3D"],
            "Acc3DS": expected["Acc3DS"],
            "Acc3DR": expected["Acc3DR"],
            "neg_Outliers3D": -expected["Outliers3D"],
        }
    )


def test_flow_scorers_in_a_grid_search(small_scene):
    X, flow = small_scene
    rows = np.arange(len(X))
    search = GridSearchCV(
        MultiModelRegistration(init=np.arange(200) % 8, variant="paper"),
        {"max_iter": [0, 10]},
        scoring=scene_flow_scorers(),
        refit="neg_EPE3D",
        cv=[(rows, rows)],
    ).fit(X, flow)
    assert search.best_params_ == {"max_iter": 10}
    epe = -search.cv_results_["mean_test_neg_EPE3D"]
    assert epe[1] < epe[0]


def test_flow_scorer_errors(small_scene):
    X, flow = small_scene
    est = MultiModelRegistration(init=np.arange(200) % 8, variant="paper").fit(X)
    scorer = make_end_point_error_scorer()
    with pytest.raises(ValueError, match="ground-truth flow as y"):
        scorer(est, X, None)
    with pytest.raises(ValueError, match=r"cv=\[\(rows, rows\)\]"):
        scorer(est, X[:100], flow[:100])

    class NoFlow:
        pass

    with pytest.raises(ValueError, match="flow_"):
        scorer(NoFlow(), X, flow)
