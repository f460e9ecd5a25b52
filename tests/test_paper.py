"""The paper/ scripts run end to end on small scenes and give the paper's ordering."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "paper"))
import figure_boxplots  # noqa: E402
import table1  # noqa: E402


@pytest.fixture(scope="module")
def results():
    return table1.run(n_runs=1, n_points=1400, seed=0)


def test_table1_layout(results):
    summary = table1.summarise(results)
    assert list(summary.columns) == ["Experiment", "Metric (mean)", *table1.METHODS]
    assert len(summary) == len(table1.EXPERIMENTS) * len(table1.METRICS)
    assert set(results["method"]) == set(table1.METHODS)


def test_table1_ours_exact_on_noiseless_and_gate_helps_on_shared_motion(results):
    ours = results[results["method"] == "Ours"].set_index("experiment")
    vanilla = results[results["method"] == "Ours (Vanilla)"].set_index("experiment")
    assert ours.loc[1, "iou"] == 1.0
    assert ours.loc[1, "rotation_error"] < 1e-6
    # Experiment 3: two objects share a motion; only the gate keeps them apart.
    assert ours.loc[3, "iou"] > vanilla.loc[3, "iou"]


def test_boxplots_are_written(results, tmp_path):
    results.to_csv(tmp_path / "table1.csv", index=False)
    figure_boxplots.main(["--out", str(tmp_path)])
    assert sorted(p.name for p in tmp_path.glob("*.png")) == [
        f"boxplots_experiment_{k}.png" for k in table1.EXPERIMENTS
    ]
