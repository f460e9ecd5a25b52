"""benchmarks/real.py end to end on a small fake data folder (no real data needed)."""

import importlib.util
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parent.parent

# A stand-in for the data folder's load.py: two generated scenes named like real ones, so
# that the benchmark makes the same variants (ZeroFlow + ground truth; ground truth +
# noisy) and finds the same foreground / dynamic information.
FAKE_LOADER = """
from types import SimpleNamespace

import numpy as np

from mmreg.datasets import make_scene

SCENES = ("icpflow_av2_demo", "av2_api_7fab2350")


def list_scenes(root=None, real_only=False):
    return list(SCENES)


def load_scene(name, root=None, drop_ground=False, **kwargs):
    seed = SCENES.index(name)
    s = make_scene(n_objects=3, n_points=600, object_size=2.0, separation=3.0,
                   random_state=seed)
    labels = s.labels.copy()
    a = s.a
    b = np.where((labels == 0)[:, None], a, s.b)  # object 0 is the static world
    flow = b - a
    labels[:5] = -1                               # unknown motion: kept, not scored
    ground = np.zeros(len(a), bool)
    ground[5:25] = True                           # dropped with drop_ground=True
    transforms = np.tile(np.eye(4), (3, 1, 1))
    transforms[1:, :3, :3] = s.rotations[1:]
    transforms[1:, :3, 3] = s.translations[1:]
    moving = labels >= 1
    foreground = moving.copy()
    foreground[25:60] = True                      # a parked car in the static world
    if name == "icpflow_av2_demo":
        rng = np.random.default_rng(0)
        extras = {
            "classes": np.where(foreground, 18, -1),
            "est_flow_zeroflow": flow * np.where(moving, 0.9, 1.0)[:, None]
            + rng.normal(scale=0.01, size=flow.shape),
        }
    else:
        extras = {"category": np.where(foreground, 19, 0).astype(np.uint8), "dynamic": moving}
    keep = ~ground if drop_ground else np.ones(len(a), bool)
    extras = {k: v[keep] for k, v in extras.items()}
    return SimpleNamespace(
        name=name, a=a[keep], b=b[keep], flow=flow[keep], labels=labels[keep],
        transforms=transforms, ground=ground[keep], valid=None, pc2=None, real=True,
        labels_kind="generated", meta={"dt_s": 0.1}, extras=extras,
    )
"""


@pytest.fixture(scope="module")
def real_benchmark():
    spec = importlib.util.spec_from_file_location("benchmark_real", ROOT / "benchmarks/real.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("benchmark_real", module)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(autouse=True)
def quick_yardstick(real_benchmark, monkeypatch):
    """The machine's speed as a constant: the real yardstick costs a second a call."""
    monkeypatch.setattr(real_benchmark, "machine_speed", lambda: 0.25)


@pytest.fixture
def fake_data(tmp_path):
    data = tmp_path / "realdata"
    data.mkdir()
    (data / "load.py").write_text(textwrap.dedent(FAKE_LOADER))
    return data


def test_benchmark_on_fake_data(real_benchmark, fake_data, tmp_path, capsys):
    out = tmp_path / "results"
    assert real_benchmark.main(["--data", str(fake_data), "--out", str(out)]) == 0
    table = pd.read_csv(out / "real.csv")
    scenes = [
        "icpflow_av2_demo/zeroflow",
        "icpflow_av2_demo/gt",
        "av2_api_7fab2350/gt",
        "av2_api_7fab2350/noisy",
    ]
    methods = real_benchmark.default_methods()
    assert {"mmreg", "paper", "naive", "sequential_ransac", "t_linkage"} <= set(methods)
    assert list(table["scene"].unique()) == scenes
    assert list(table["method"].unique()) == methods
    assert len(table) == len(scenes) * len(methods)
    for column in (
        "n", "time_s", "clusters", "moving_found", "moving_total", "static_in_largest",
        "static_moving", "moving_from", "iou", "epe_in", "epe", "acc3ds", "acc3dr",
        "outliers3d", "3way_in", "3way", "fd", "fs", "bs", "dyn_iou", "epe_obj_in",
        "epe_obj", "epe_objects", "labelled_-1",
    ):  # fmt: skip
        assert column in table, column
    assert (table["n"] == 600 - 20).all()  # ground dropped, unknown points kept
    assert (table["moving_total"] == 2).all()
    # Scores are defined everywhere on these scenes; the ground-truth input has no error.
    assert table[["iou", "epe", "3way", "fd", "fs", "bs", "static_in_largest"]].notna().all().all()
    gt = table["scene"].str.endswith("/gt")
    assert (table.loc[gt, "epe_in"] < 1e-9).all()
    assert (table.loc[~gt, "epe_in"] > 0.005).all()
    assert (table["time_s"] >= table["init_s"]).all()
    assert (table.loc[table["method"] == "sequential_ransac", "init_s"] == 0).all()
    markdown = (out / "real.md").read_text()
    assert "| scene" in markdown and "av2_api_7fab2350/noisy" in markdown
    assert "0.250 s before the run, 0.250 s after" in markdown
    assert "3-way" in capsys.readouterr().out


def test_benchmark_options(real_benchmark, fake_data, tmp_path, capsys):
    out = tmp_path / "results"
    argv = ["--data", str(fake_data), "--out", str(out), "--methods", "paper,naive"]
    argv += ["--scenes", "av2_api_7fab2350/noisy,flyout_ft3d_0000710", "--seeds", "2"]
    assert real_benchmark.main(argv) == 0
    table = pd.read_csv(out / "real.csv")
    assert set(table["scene"]) == {"av2_api_7fab2350/noisy"}
    assert sorted(table["method"]) == ["naive", "naive", "paper", "paper"]
    assert sorted(table["seed"]) == [0, 0, 1, 1]
    # Each seed draws its own noise.
    assert table.groupby("seed")["epe_in"].first().nunique() == 2
    assert "flyout_ft3d_0000710: not in the data folder" in capsys.readouterr().out


def test_benchmark_without_data(real_benchmark, tmp_path, capsys):
    out = tmp_path / "results"
    assert real_benchmark.main(["--data", str(tmp_path / "absent"), "--out", str(out)]) == 0
    assert "no load.py" in capsys.readouterr().out
    assert not out.exists()


def test_unknown_method(real_benchmark, fake_data):
    with pytest.raises(SystemExit, match="unknown method"):
        real_benchmark.main(["--data", str(fake_data), "--methods", "nonsense"])


def test_ablation_runs_or_says_why(real_benchmark, fake_data, tmp_path, capsys):
    out = tmp_path / "results"
    argv = ["--data", str(fake_data), "--out", str(out), "--ablation"]
    argv += ["--scenes", "av2_api_7fab2350/gt"]
    assert real_benchmark.main(argv) == 0
    steps, why = real_benchmark.robust_steps()
    if steps is None:
        assert "Ablation skipped" in capsys.readouterr().out
        assert not out.exists()
    else:
        table = pd.read_csv(out / "real_ablation.csv")
        assert list(table["method"]) == ["mmreg", *(f"mmreg-no-{s}" for s in steps)]
        est = real_benchmark.build_method(f"mmreg-no-{steps[0]}", 0)
        assert est.get_params()["skip_steps"] == (steps[0],)


@pytest.mark.filterwarnings("ignore::UserWarning")  # 580 points cannot make 100 clusters
def test_shared_init_changes_no_result(real_benchmark, fake_data):
    loader, _ = real_benchmark.import_loader(fake_data)
    case = real_benchmark.make_cases(loader, fake_data, "av2_api_7fab2350", ("noisy",), 0)[0][0]
    X = np.hstack([case.a, case.b])
    shared = real_benchmark.SharedInit(X, 0)
    for method in ("mmreg", "paper", "naive", "t_linkage"):
        alone = real_benchmark.build_method(method, 0).fit(X)
        est = real_benchmark.build_method(method, 0)
        shared.give(est)
        np.testing.assert_array_equal(est.fit(X).labels_, alone.labels_)


def test_repeats_time_the_median_of_fresh_fits(real_benchmark, fake_data, tmp_path, monkeypatch):
    fitted = []
    build = real_benchmark.build_method

    def counting(method, seed):
        est = build(method, seed)
        fitted.append(est)
        return est

    # Fits of 5, 1 and 3 "seconds": the table gives the median, 3.
    ticks = iter([0.0, 5.0, 10.0, 11.0, 20.0, 23.0])
    monkeypatch.setattr(real_benchmark, "build_method", counting)
    monkeypatch.setattr(real_benchmark.time, "perf_counter", lambda: next(ticks))
    out = tmp_path / "results"
    argv = ["--data", str(fake_data), "--out", str(out), "--methods", "sequential_ransac"]
    argv += ["--scenes", "av2_api_7fab2350/gt", "--repeats", "3"]
    assert real_benchmark.main(argv) == 0
    table = pd.read_csv(out / "real.csv")
    assert table["time_s"].tolist() == [3.0]
    assert len(fitted) == 3 and len({id(est) for est in fitted}) == 3
    assert "median of 3 fits" in (out / "real.md").read_text()


def test_repeats_must_be_positive(real_benchmark, fake_data, tmp_path, capsys):
    with pytest.raises(SystemExit):
        real_benchmark.main(["--data", str(fake_data), "--out", str(tmp_path), "--repeats", "0"])
    assert "--repeats must be at least 1" in capsys.readouterr().err


def test_machine_speed_times_the_yardstick():
    # A module of its own: the fixture stubs the shared one's yardstick.
    spec = importlib.util.spec_from_file_location("real_unstubbed", ROOT / "benchmarks/real.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert 0 < module.machine_speed(repeats=1) < 60
