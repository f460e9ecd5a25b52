"""The paper/ scripts: every output of a quick run, plugins, the cache, Dask, --help."""

import contextlib
import importlib
import io
import json
import re
import sys
import textwrap
from pathlib import Path

import pandas as pd
import pytest
from PIL import Image

PAPER = Path(__file__).resolve().parents[1] / "paper"
sys.path.insert(0, str(PAPER))
import _common  # noqa: E402
import ablation  # noqa: E402
import figure1  # noqa: E402
import figure2  # noqa: E402
import figure_boxplots  # noqa: E402
import run_all  # noqa: E402
import runtime  # noqa: E402
import table1  # noqa: E402

SCRIPTS = [table1, figure_boxplots, figure2, figure1, ablation, runtime, run_all]
TABLE1_METHODS = ["Naive", "SRANSAC", "T-Linkage", "Ours (Vanilla)", "Ours", "mmreg"]
FIGURE2_METHODS = [
    "Naive",
    "SeqR",
    "T-L (SAM)",
    "T-L (Euc.)",
    "Ours (SAM)",
    "Ours (Euc.)",
    "mmreg (SAM)",
    "mmreg (Euc.)",
]
QUIET = ["--no-progress"]

TOY = """
from mmreg import NaiveRegistration

CALLS = []


def make(*, init="euclidean", random_state=None):
    CALLS.append(1)
    return NaiveRegistration(init=init, random_state=random_state)
"""


@pytest.fixture
def toy(tmp_path, monkeypatch):
    """Method "toy" from a real installed distribution's entry point; its fit count."""
    folder = tmp_path / "site"
    folder.mkdir()
    (folder / "toy_paper_plugin.py").write_text(textwrap.dedent(TOY))
    info = folder / "toy_paper_plugin-0.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-paper-plugin\nVersion: 0.0\n")
    (info / "entry_points.txt").write_text("[mmreg.methods]\ntoy = toy_paper_plugin:make\n")
    monkeypatch.syspath_prepend(str(folder))
    importlib.invalidate_caches()
    monkeypatch.delitem(sys.modules, "toy_paper_plugin", raising=False)
    return lambda: len(sys.modules["toy_paper_plugin"].CALLS)


def quiet(main, argv):
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        return main(argv)


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("quick")
    argv = ["--quick", "--out", str(out), "--formats", "png", "--methods", "all", *QUIET]
    assert quiet(run_all.main, argv) == 0
    return out


def test_run_all_quick_writes_every_output(quick_run):
    expected = [
        "table1.csv",
        "table1.md",
        "table1.tex",
        *(f"table1_boxplots_exp{k}.png" for k in (1, 2, 3, 4)),
        "figure2.csv",
        "figure2.md",
        "figure2_flying_things.png",
        "figure2_kitti.png",
        "figure1.png",
        "ablation.csv",
        "ablation.md",
        "ablation.png",
        "runtime.csv",
        "runtime.md",
    ]
    for name in expected:
        assert (quick_run / name).stat().st_size > 0, name
    for png in quick_run.glob("*.png"):
        with Image.open(png) as image:
            assert min(image.size) > 200
    assert not list(quick_run.glob("*.pdf"))  # --formats png
    assert not list(quick_run.rglob("*.tmp"))  # every file written whole


def test_table1_layout(quick_run):
    results = pd.read_csv(quick_run / "table1.csv")
    assert list(dict.fromkeys(results["method"])) == TABLE1_METHODS
    assert sorted(results["experiment"].unique()) == [f"table1-exp{k}" for k in (1, 2, 3, 4)]
    markdown = (quick_run / "table1.md").read_text()
    assert (
        markdown.splitlines()[0] == "| Exp. | Metric (mean) | " + " | ".join(TABLE1_METHODS) + " |"
    )
    for measure in ("Per-point Error [m]", "Rotation error [deg]", "IoU", "Objects found"):
        assert measure in markdown
    assert "*IoU, paper*" in markdown and "**" in markdown
    assert "\\textbf{" in (quick_run / "table1.tex").read_text()
    # Exp. 4: the wrong correspondences are the ground-truth outlier class.
    assert (results.loc[results["experiment"] == "table1-exp4", "n_objects"] == 7).all()


def test_noiseless_fits_are_exact(quick_run):
    results = pd.read_csv(quick_run / "table1.csv")
    exp1 = results[(results["experiment"] == "table1-exp1")]
    for method in ("Ours", "mmreg", "SRANSAC"):
        rows = exp1[exp1["method"] == method]
        assert (rows["rotation_error"] <= _common.EXACT["rotation_error"]).all()
        assert (rows["translation_error"] <= _common.EXACT["translation_error"]).all()


def test_figure2_has_the_papers_boxes_and_the_extra_measures(quick_run):
    results = pd.read_csv(quick_run / "figure2.csv")
    assert set(results["experiment"]) == {"figure2-flying_things", "figure2-kitti"}
    assert list(dict.fromkeys(results["method"])) == FIGURE2_METHODS
    for column in figure2.PANEL_COLUMNS:
        assert results[column].notna().all(), column
    assert results["objects_found"].between(0, 1).all()
    assert "Fig. 2, KITTI-like" in (quick_run / "figure2.md").read_text()


def test_ablation_and_runtime_tables(quick_run):
    results = pd.read_csv(quick_run / "ablation.csv")
    assert set(results["init"].dropna()) == set(ablation.INITS)
    assert "% wrong" in (quick_run / "ablation.md").read_text()
    text = (quick_run / "runtime.md").read_text()
    assert "about 0.8 s" in text and "Euclidean clustering (the init)" in text


def test_entry_point_method_appears_in_a_quick_table(toy, tmp_path):
    argv = ["--quick", "--runs", "1", "--experiments", "1", "--methods", "naive,toy"]
    assert quiet(table1.main, [*argv, "--out", str(tmp_path), "--no-cache", *QUIET]) == 0
    header = (tmp_path / "table1.md").read_text().splitlines()[0]
    assert header == "| Exp. | Metric (mean) | Naive | toy |"
    results = pd.read_csv(tmp_path / "table1.csv")
    assert list(results["registry_name"]) == ["naive", "toy"]
    assert toy() == 1


def test_every_registered_method_runs_by_default(toy, tmp_path):
    argv = ["--quick", "--runs", "1", "--datasets", "kitti", "--formats", "png"]
    assert quiet(figure2.main, [*argv, "--out", str(tmp_path), "--no-cache", *QUIET]) == 0
    methods = list(dict.fromkeys(pd.read_csv(tmp_path / "figure2.csv")["method"]))
    assert methods == [*FIGURE2_METHODS, "toy (SAM)", "toy (Euc.)"]  # toy takes an init


def test_unknown_method_is_refused():
    with pytest.raises(SystemExit, match="unknown method.*nope.*available: naive"):
        quiet(table1.main, ["--quick", "--methods", "naive,nope"])


def test_an_interrupted_run_resumes_from_the_cache(toy, tmp_path):
    argv = ["--quick", "--runs", "2", "--experiments", "2,3", "--methods", "naive,ours,toy"]
    argv += ["--out", str(tmp_path), *QUIET]
    assert quiet(table1.main, argv) == 0
    first = pd.read_csv(tmp_path / "table1.csv")
    files = sorted((tmp_path / "cache").rglob("*.json"))
    assert len(files) == len(first) == 2 * 2 * 3  # one file per run
    assert toy() == 4

    assert quiet(table1.main, argv) == 0  # all cached: nothing is fitted again
    assert toy() == 4
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "table1.csv"), first)

    toy_files = [f for f in files if "toy" in f.parent.name]
    toy_files[0].unlink()  # as if interrupted before this run
    assert quiet(table1.main, argv) == 0
    assert toy() == 5
    again = pd.read_csv(tmp_path / "table1.csv")
    timings = ["runtime_s", "init_s"]
    pd.testing.assert_frame_equal(again.drop(columns=timings), first.drop(columns=timings))
    row = json.loads(toy_files[0].read_text())
    assert row["method"] == "toy" and row["registry_name"] == "toy"


def test_the_cache_key_follows_the_configuration(tmp_path):
    small = table1.experiments(runs=1, n_points=700, methods="naive", which=(1,))[0]
    large = table1.experiments(runs=1, n_points=1400, methods="naive", which=(1,))[0]
    column = small.columns[0]
    seed = small.seeds[0]
    assert _common.cache_path(tmp_path, small, column, seed) != _common.cache_path(
        tmp_path, large, column, seed
    )


def test_dask_cluster_gives_the_serial_results():
    distributed = pytest.importorskip("distributed")
    experiments = table1.experiments(
        runs=2, n_points=700, methods="naive,sequential_ransac,ours,mmreg", which=(2,)
    )
    serial = _common.run_experiments(experiments, progress=False)
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        on_dask = _common.run_experiments(
            experiments, scheduler=cluster.scheduler_address, progress=False
        )
    timings = ["runtime_s", "init_s"]
    pd.testing.assert_frame_equal(on_dask.drop(columns=timings), serial.drop(columns=timings))


def test_joblib_processes_give_the_serial_results():
    experiments = table1.experiments(runs=2, n_points=700, methods="naive,ours", which=(3,))
    serial = _common.run_experiments(experiments, progress=False)
    parallel = _common.run_experiments(experiments, n_jobs=2, progress=False)
    timings = ["runtime_s", "init_s"]
    pd.testing.assert_frame_equal(parallel.drop(columns=timings), serial.drop(columns=timings))


def _options(help_text):
    """Each option's help entry: ``{"--runs": "scenes per ... (default: 100)", ...}``."""
    body = help_text.split("options:", 1)[1]
    entries = re.split(r"\n(?=  -)", body)
    found = {}
    for entry in entries:
        if not entry.strip():
            continue
        head = re.split(r"\s{2,}", entry.strip().splitlines()[0])[0]
        names = re.findall(r"--[\w-]+", head)
        if names:
            found[names[-1]] = " ".join(entry.split())
    return found


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda module: module.__name__)
def test_help_lists_every_option_with_its_default(script, capsys):
    with pytest.raises(SystemExit) as info:
        script.main(["--help"])
    assert info.value.code == 0
    text = capsys.readouterr().out
    options = _options(text)
    assert "--out" in options
    for option, entry in options.items():
        if option != "--help":
            assert "(default:" in entry, entry
    if script is not figure_boxplots and script is not figure1:
        assert "--methods" in options and "--quick" in options


def test_missing_loader_is_a_clear_error(monkeypatch, tmp_path):
    import mmreg.datasets

    monkeypatch.delattr(mmreg.datasets, "load_flying_things", raising=False)
    argv = ["--data", str(tmp_path), "--datasets", "flying_things", "--runs", "1", "--no-cache"]
    with pytest.raises(SystemExit, match="mmreg.datasets.load_flying_things"):
        quiet(figure2.main, [*argv, "--out", str(tmp_path), *QUIET])


def test_best_in_bold_treats_exact_answers_as_ties():
    values = pd.Series({"a": 3e-15, "b": 9e-15, "c": 0.5})
    assert list(_common.best_mask(values, "min", exact=1e-9)) == [True, True, False]
    assert list(_common.best_mask(pd.Series([0.91, 0.9100001, 0.5]), "max")) == [
        True,
        True,
        False,
    ]
    assert list(_common.best_mask(pd.Series([100, 8, 6.5]), None, target=7)) == [
        False,
        False,
        True,
    ]
