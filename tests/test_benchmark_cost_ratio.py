"""benchmarks/cost_ratio.py: its arithmetic, and a run on a small fake data folder."""

import importlib.util
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from mmreg.datasets import make_scene

ROOT = Path(__file__).resolve().parent.parent

# A stand-in for the data folder's load.py, with one scene named like a real one.
FAKE_LOADER = """
from types import SimpleNamespace

import numpy as np

from mmreg.datasets import make_scene


def list_scenes(root=None, real_only=False):
    return ["ddf_loss_ft3d"]


def load_scene(name, root=None, drop_ground=False, **kwargs):
    s = make_scene(n_objects=3, n_points=300, object_size=2.0, separation=3.0,
                   random_state=0)
    return SimpleNamespace(
        name=name, a=s.a, b=s.b, flow=s.b - s.a, labels=s.labels, transforms=None,
        ground=np.zeros(len(s.a), bool), extras={},
    )
"""


@pytest.fixture(scope="module")
def cost_ratio():
    path = ROOT / "benchmarks/cost_ratio.py"
    spec = importlib.util.spec_from_file_location("benchmark_cost_ratio", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("benchmark_cost_ratio", module)
    spec.loader.exec_module(module)
    return module


def test_ratios_are_of_the_minima_and_the_medians(cost_ratio, monkeypatch):
    # One warm-up fit of the default, then default and paper alternately.
    seconds = iter([9.0, 3.0, 1.0, 1.0, 2.0, 2.0, 4.0])
    monkeypatch.setattr(cost_ratio, "cpu_seconds", lambda *args: next(seconds))
    table = cost_ratio.measure([("x", np.zeros((5, 6)), 1.0, None)], reps=3, log=lambda _: None)
    row = table.iloc[0]
    assert (row["default min s"], row["default median s"]) == (1.0, 2.0)
    assert (row["paper min s"], row["paper median s"]) == (1.0, 2.0)
    assert row["ratio of minima"] == 1.0 and row["ratio of medians"] == 1.0
    assert row["within 2x"] == "yes"
    seconds = iter([9.0, 5.0, 1.0, 5.0, 2.0, 5.0, 4.0])
    table = cost_ratio.measure([("x", np.zeros((5, 6)), 1.0, None)], reps=3, log=lambda _: None)
    assert table.iloc[0]["ratio of minima"] == 5.0 and table.iloc[0]["within 2x"] == "no"


def test_a_run_on_generated_and_fake_real_inputs_writes_its_table(cost_ratio, tmp_path):
    data = tmp_path / "realdata"
    data.mkdir()
    (data / "load.py").write_text(textwrap.dedent(FAKE_LOADER))
    small = make_scene(n_objects=2, n_points=200, object_size=2.0, separation=3.0, random_state=1)
    out = tmp_path / "cost.md"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(
            cost_ratio, "generated_inputs", lambda: [("small", small.X, 1.5, "euclidean")]
        )
        assert cost_ratio.main(["--data", str(data), "--reps", "1", "--out", str(out)]) == 0
    text = out.read_text()
    assert "| small " in text and "| ddf_loss_ft3d/gt " in text
    # The other real inputs are named as absent, not silently left out.
    assert "flyout_ft3d_0001435/gt: not in" in text
    assert "within 2x" in text
