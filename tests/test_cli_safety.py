"""``mmreg`` as a new user tries it: never corrupt data, never destroy files, never crash.

One test (or a few) per row of issue 19: a truncated point cloud, result folders that
must not be replaced or merged into, an --out that cannot be written, DBSCAN's radius,
huge coordinates, bad option values, picture formats, the moving flag, warnings, the
--n-jobs option and a quick start. (Ctrl-C: tests/test_cli_interrupt.py.)
"""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from mmreg import io as mmio
from mmreg._cli import _common
from mmreg._cli import register as register_command
from mmreg.cli import main
from mmreg.datasets import make_scene


def mmreg(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "mmreg.cli", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.fixture(scope="module")
def scene():
    return make_scene(n_objects=3, n_points=900, random_state=0)


@pytest.fixture
def pairs(tmp_path, scene):
    path = tmp_path / "pairs.npy"
    np.save(path, scene.X)
    np.save(tmp_path / "init.npy", scene.labels)
    return path


def _run(*args, capsys):
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _listing(folder):
    return sorted(p.name for p in folder.iterdir())


def _snapshot(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


# --------------------------------------------------------------------------- truncated .ply
@pytest.mark.parametrize("which", ["input", "target"])
def test_truncated_ply_is_an_error_naming_the_counts(tmp_path, scene, which, capsys, monkeypatch):
    """Open3D zero-filled the missing vertices and printed a warning on stdout even with -q."""
    mmio.write_point_cloud(tmp_path / "a.ply", scene.a)
    mmio.write_point_cloud(tmp_path / "b.ply", scene.b)
    cut = tmp_path / f"{which}.ply"
    data = (tmp_path / ("a.ply" if which == "input" else "b.ply")).read_bytes()
    header = data.index(b"end_header\n") + len(b"end_header\n")
    cut.write_bytes(data[: header + 500 * 24 + 7])  # 500 whole vertices and a piece
    args = ["a.ply", "--target", cut.name] if which == "target" else [cut.name, "--target", "b.ply"]
    if which == "input":  # a process of its own: nothing may reach stdout, even from C
        result = mmreg("register", *args, "--out", "out", "-q", cwd=tmp_path)
        code, out, err = result.returncode, result.stdout, result.stderr
    else:
        monkeypatch.chdir(tmp_path)
        code, out, err = _run("register", *args, "--out", "out", "-q", capsys=capsys)
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1
    assert f"mmreg: error: {cut.name}: truncated PLY file" in err
    assert "promised 900 vertices but 500 were read" in err
    assert not (tmp_path / "out").exists()
    assert [p for p in _listing(tmp_path) if p.startswith(".")] == []


# --------------------------------------------------------------------------- result folders
def test_the_default_out_differs_per_input_and_is_never_replaced(
    tmp_path, scene, capsys, monkeypatch
):
    for folder in ("seq1", "seq2"):
        (tmp_path / folder).mkdir()
        np.save(tmp_path / folder / "000000.npy", scene.X)
    monkeypatch.chdir(tmp_path)
    for folder in ("seq1", "seq2"):
        code, _, err = _run("register", f"{folder}/000000.npy", "-q", capsys=capsys)
        assert code == 0, err
    results = [p for p in _listing(tmp_path) if p.startswith("000000-mmreg-")]
    assert len(results) == 2  # one per input, neither replaced
    first = tmp_path / register_command.default_out(
        type("A", (), {"input": "seq1/000000.npy", "target": None, "flow": None})
    )
    before = _snapshot(first)
    code, _, err = _run("register", "seq1/000000.npy", "-q", capsys=capsys)
    assert code == 2
    assert f"{first.name}: a result already exists there; pass --overwrite" in err
    assert _snapshot(first) == before
    code, _, err = _run("register", "seq1/000000.npy", "-q", "--overwrite", capsys=capsys)
    assert code == 0, err


@pytest.mark.parametrize("exchange", [True, False], ids=["renameat2", "rename-aside"])
def test_overwrite_replaces_a_result_as_a_whole(tmp_path, pairs, capsys, monkeypatch, exchange):
    out = tmp_path / "out"
    assert _run("register", pairs, "--out", out, "-q", capsys=capsys)[0] == 0
    (out / "truth.npz").write_bytes(b"from an earlier demo")  # a file results may hold
    inode = out.stat().st_ino
    if not exchange:
        monkeypatch.setattr(_common, "_exchange", lambda first, second: False)
    code, _, err = _run("register", pairs, "--out", out, "-q", "--overwrite", capsys=capsys)
    assert code == 0, err
    assert set(_listing(out)) == set(_common.RESULT_FILES) - {"X.npy"}  # truth.npz is gone
    assert out.stat().st_ino != inode  # a new folder put in place, not files moved in
    assert _listing(tmp_path) == ["init.npy", "out", "pairs.npy"]


def test_a_failed_write_keeps_the_earlier_result(tmp_path, pairs, capsys, monkeypatch):
    out = tmp_path / "out"
    pairs = [pairs, "--init", tmp_path / "init.npy"]
    assert _run("register", *pairs, "--out", out, "-q", capsys=capsys)[0] == 0
    before = _snapshot(out)

    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(mmio, "write_point_cloud", broken)
    code, _, err = _run("register", *pairs, "--out", out, "-q", "--overwrite", capsys=capsys)
    assert code == 2
    assert err == f"mmreg: error: {out}: cannot write the result: no space left on device\n"
    assert _snapshot(out) == before
    assert _listing(tmp_path) == ["init.npy", "out", "pairs.npy"]


def test_an_empty_folder_is_used(tmp_path, pairs, capsys):
    (tmp_path / "empty").mkdir()
    assert _run("register", pairs, "--out", tmp_path / "empty", "-q", capsys=capsys)[0] == 0
    assert set(_listing(tmp_path / "empty")) == set(_common.RESULT_FILES) - {"X.npy"}


# --------------------------------------------------------------------------- unwritable --out
def _no_work(monkeypatch):
    def fail(*args, **kwargs):
        raise AssertionError("the input was read before --out was checked")

    monkeypatch.setattr(register_command, "read_input", fail)


def test_out_naming_a_file_fails_before_any_work(tmp_path, pairs, capsys, monkeypatch):
    _no_work(monkeypatch)
    (tmp_path / "notes.txt").write_text("mine")
    code, _, err = _run("register", pairs, "--out", tmp_path / "notes.txt", capsys=capsys)
    assert code == 2
    expected = f"{tmp_path / 'notes.txt'}: exists and is not a folder; choose another --out"
    assert err == f"mmreg: error: {expected}\n"
    assert (tmp_path / "notes.txt").read_text() == "mine"
    code, _, err = _run("register", pairs, "--out", tmp_path / "notes.txt" / "r", capsys=capsys)
    assert code == 2 and f"{tmp_path / 'notes.txt' / 'r'}: cannot be written" in err


@pytest.mark.skipif(not os.path.isdir("/sys/fs"), reason="needs a read-only /sys")
def test_out_in_a_read_only_folder_fails_before_any_work(pairs, capsys, monkeypatch):
    _no_work(monkeypatch)
    code, _, err = _run("register", pairs, "--out", "/sys/fs/mmreg-result", capsys=capsys)
    assert code == 2
    assert err.startswith("mmreg: error: /sys/fs/mmreg-result: cannot be written: folder /sys/fs")
    assert ".partial" not in err


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root writes anyway")
def test_out_in_a_folder_without_write_permission(tmp_path, pairs, capsys, monkeypatch):
    _no_work(monkeypatch)
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        code, _, err = _run("register", pairs, "--out", locked / "result", capsys=capsys)
    finally:
        locked.chmod(0o755)
    assert code == 2 and f"{locked / 'result'}: cannot be written" in err


# --------------------------------------------------------------------------- --init dbscan
def test_dbscan_init_adapts_to_the_units(tmp_path, scene, capsys):
    """eps=0.05 fixed found no cluster in millimetres: all outliers, exit 0, no word."""
    np.save(tmp_path / "mm.npy", scene.X * 1000)
    out = tmp_path / "out"
    code, _, err = _run(
        "register",
        tmp_path / "mm.npy",
        "--init",
        "dbscan",
        "--tau",
        "1500",
        "--out",
        out,
        "-q",
        capsys=capsys,
    )
    assert code == 0, err
    assert "DBSCAN found no cluster" not in err
    run = json.loads((out / "run.json").read_text())
    assert run["initial_clusters"] >= 3 and run["n_clusters"] == 3
    assert run["n_outliers"] == 0


def test_dbscan_with_too_small_an_eps_warns(tmp_path, pairs, capsys):
    code, _, err = _run(
        "register",
        pairs,
        "--init",
        "dbscan",
        "--eps",
        "1e-6",
        "--out",
        tmp_path / "o",
        "-q",
        capsys=capsys,
    )
    assert code == 0
    assert "mmreg: warning: DBSCAN found no cluster: all 900 a-points are noise" in err


# --------------------------------------------------------------------------- huge values
@pytest.mark.parametrize("scale", [1e150, 1e200])
def test_huge_coordinates_are_a_clear_error(tmp_path, scene, capsys, scale):
    np.save(tmp_path / "huge.npy", scene.X * scale)
    code, _, err = _run("register", tmp_path / "huge.npy", "--out", tmp_path / "o", capsys=capsys)
    assert code == 2
    assert f"{tmp_path / 'huge.npy'}: values of the correspondences reach" in err
    assert "within +-1e+100" in err and "Traceback" not in err
    assert _listing(tmp_path) == ["huge.npy"]


def test_the_estimators_refuse_huge_coordinates(scene):
    from mmreg import MultiModelRegistration
    from mmreg.init import EuclideanClustering

    for estimator in (MultiModelRegistration(), EuclideanClustering()):
        with pytest.raises(ValueError, match=r"values of X reach [\d.]+e\+150 in magnitude"):
            estimator.fit(scene.X * 1e150)


# --------------------------------------------------------------------------- option values
@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["register", "pairs.npy", "--tau", "inf"], "--tau"),
        (["register", "pairs.npy", "--tau", "nan"], "--tau"),
        (["register", "pairs.npy", "--seed", "-1"], "--seed"),
        (["register", "pairs.npy", "--n-jobs", "0"], "--n-jobs"),
        (["register", "pairs.npy", "--eps", "0"], "--eps"),
        (["view", "result", "--dpi", "0"], "--dpi"),
        (["demo", "--seed", "-5"], "--seed"),
    ],
)
def test_bad_option_values_are_usage_errors_naming_the_option(args, option, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(args)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {option}" in err and "Traceback" not in err


# --------------------------------------------------------------------------- view --out
@pytest.fixture
def result(tmp_path, pairs, capsys):
    out = tmp_path / "result"
    assert (
        _run("register", pairs, "--init", tmp_path / "init.npy", "--out", out, "-q", capsys=capsys)[
            0
        ]
        == 0
    )
    return out


@pytest.mark.parametrize(
    ("name", "magic"), [("x.pdf", b"%PDF"), ("x.svg", b"<?xml"), ("x.PNG", b"\x89PNG")]
)
def test_view_writes_the_format_of_the_extension(tmp_path, result, capsys, name, magic):
    code, out, err = _run("view", result, "--out", tmp_path / name, "--view", "top", capsys=capsys)
    assert code == 0, err
    assert (tmp_path / name).read_bytes().startswith(magic)


def test_view_refuses_an_unknown_format_and_an_existing_file(tmp_path, result, capsys):
    code, _, err = _run("view", result, "--out", tmp_path / "x.xyz", capsys=capsys)
    assert code == 2 and "x.xyz: unknown picture format '.xyz'" in err
    (tmp_path / "mine.png").write_bytes(b"my picture")
    code, _, err = _run("view", result, "--out", tmp_path / "mine.png", capsys=capsys)
    assert code == 2 and "mine.png: exists; pass --overwrite" in err
    assert (tmp_path / "mine.png").read_bytes() == b"my picture"
    assert (
        _run("view", result, "--out", tmp_path / "mine.png", "--overwrite", capsys=capsys)[0] == 0
    )
    assert _run("view", result, capsys=capsys)[0] == 0  # its own result.png: replaced


# --------------------------------------------------------------------------- moving flag
def test_a_turning_car_with_wrong_correspondences_is_moving(tmp_path, capsys):
    """15 degrees and 1 m; 10 % wrong correspondences inflated its RMS residual."""
    rng = np.random.default_rng(0)
    ground = rng.uniform([-15, -15, 0], [15, 15, 0.2], (4000, 3))
    car = rng.uniform([-2, -1, 0.3], [2, 1, 1.8], (600, 3)) + [5, 3, 0]
    c, s = np.cos(np.radians(15)), np.sin(np.radians(15))
    turn = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    center = car.mean(axis=0)
    b = np.vstack([ground, (car - center) @ turn.T + center + [1.0, 0, 0]])
    b += rng.normal(0, 0.02, b.shape)
    b[4000:4060] += rng.uniform(-15, 15, (60, 3))  # wrong correspondences of the car
    np.save(tmp_path / "pairs.npy", np.hstack([np.vstack([ground, car]), b]))
    np.save(tmp_path / "init.npy", np.repeat([0, 1], [4000, 600]))
    out = tmp_path / "out"
    code, _, err = _run(
        "register",
        tmp_path / "pairs.npy",
        "--paper",
        "--init",
        tmp_path / "init.npy",
        "--max-iter",
        "3",
        "--out",
        out,
        "-q",
        capsys=capsys,
    )
    assert code == 0, err
    motions = json.loads((out / "motions.json").read_text())
    assert [m["moving"] for m in motions] == [False, True]
    summary = np.genfromtxt(out / "summary.csv", delimiter=",", names=True)
    car_row = summary[1]
    # Far from the cut-off: the displacement is well beyond 3 residual scales, while
    # the plain RMS residual (which the old rule used) is larger than the displacement.
    assert car_row["displacement_vs_background"] > 1.5 * 3 * car_row["residual_scale"]
    assert car_row["rms_residual"] > 3 * car_row["displacement_vs_background"]


# --------------------------------------------------------------------------- the rest
def test_n_jobs_reaches_the_initialiser_and_the_estimator(tmp_path, pairs, capsys):
    from mmreg import MultiModelRegistration

    out = tmp_path / "out"
    code, _, err = _run(
        "register", pairs, "--n-jobs", "2", "--clusters", "20", "--out", out, "-q", capsys=capsys
    )
    assert code == 0, err
    run = json.loads((out / "run.json").read_text())
    assert run["n_jobs"] == 2
    assert run["estimator"]["n_jobs"] == 2
    assert MultiModelRegistration().get_params()["n_jobs"] is None  # one thread unless asked


def test_register_help_names_n_jobs(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["register", "--help"])
    assert exit_info.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "--n-jobs N_JOBS" in text and "n_jobs; -1: every core" in text


def test_verbose_prints_the_iterations_of_the_paper_variant(tmp_path, pairs, capsys):
    args = ["register", pairs, "--init", tmp_path / "init.npy", "--out", tmp_path / "out"]
    code, out, err = _run(*args, "--paper", "-v", capsys=capsys)
    assert code == 0, err
    lines = [line for line in out.splitlines() if line.startswith("iteration ")]
    assert lines and lines[0].startswith("iteration 1, clusters ")
    code, out, err = _run(*args, "--paper", "--overwrite", capsys=capsys)
    assert code == 0, err
    assert "iteration " not in out


def test_no_stray_warnings_in_normal_use(tmp_path, pairs):
    """A plain run prints nothing on stderr: no numpy or matplotlib warnings."""
    runs = [
        ["register", str(pairs), "--init", str(tmp_path / "init.npy"), "--out", "r", "-q"],
        ["view", "r", "--view", "3d", "--out", "r3d.png"],
        ["evaluate", "r", str(tmp_path / "init.npy")],
    ]
    code = f"from mmreg.cli import main\nraise SystemExit(max(main(a) for a in {runs!r}))\n"
    result = subprocess.run(
        [sys.executable, "-W", "default", "-c", code],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert result.stderr == "", result.stderr
    assert (tmp_path / "r3d.png").exists()


def test_every_file_the_commands_read_is_checked(tmp_path, result, scene, capsys):
    """Masks, ground truth and a result's X.npy go through the same strict readers."""
    masks = tmp_path / "masks.npz"
    np.savez(masks, masks=np.ones((1, 4, 4), bool), pixels=np.zeros((900, 2), int))
    masks.write_bytes(masks.read_bytes()[:-30])
    code, _, err = _run("register", tmp_path / "pairs.npy", "--init", masks, capsys=capsys)
    assert code == 2 and f"{masks}: cannot be read as a .npz file" in err
    truth = tmp_path / "truth.npz"
    np.savez(truth, labels=scene.labels)
    truth.write_bytes(truth.read_bytes() + b"\x00")
    code, _, err = _run("evaluate", result, truth, capsys=capsys)
    assert code == 2 and f"{truth}: corrupt .npz file" in err
    saved = [tmp_path / "pairs.npy", "--init", tmp_path / "init.npy", "--save-input"]
    assert _run("register", *saved, "--out", result, "--overwrite", "-q", capsys=capsys)[0] == 0
    x = result / "X.npy"
    x.write_bytes(x.read_bytes()[:-8])
    for command in (["view", result], ["evaluate", result, tmp_path / "init.npy"]):
        code, _, err = _run(*command, capsys=capsys)
        assert code == 2 and f"{x}: corrupt .npy file" in err and "(truncated)" in err
