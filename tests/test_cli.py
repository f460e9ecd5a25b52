"""The ``mmreg`` command line, run as a user runs it: subprocesses on files written here.

Good inputs (``.npy``, ``.csv``, ``.ply`` with ``--target`` or ``--flow``, a labels or a
masks file as ``--init``) give a whole result directory whose files read back and agree
with the scene; bad ones give one line ``mmreg: error: FILE: problem``, a non-zero exit
code, no traceback and no output directory.
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mmreg import io as mmio
from mmreg.cli import build_parser, main
from mmreg.datasets import make_flying_things, make_scene

RESULT_FILES = {
    "labels.npy",
    "motions.json",
    "summary.csv",
    "clusters.ply",
    "result.png",
    "run.json",
}


def mmreg(*args, cwd):
    """Run ``python -m mmreg.cli ARGS`` in ``cwd``; the finished process."""
    return subprocess.run(
        [sys.executable, "-m", "mmreg.cli", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.fixture(scope="module")
def scene():
    """A noiseless scene of 3 objects: every motion is exact."""
    return make_scene(n_objects=3, n_points=900, random_state=0)


@pytest.fixture(scope="module")
def files(tmp_path_factory, scene):
    """The scene in every input format, and broken files."""
    folder = tmp_path_factory.mktemp("inputs")
    np.save(folder / "pairs.npy", scene.X)
    mmio.write_correspondences(folder / "pairs.csv", scene.X)
    mmio.write_point_cloud(folder / "a.ply", scene.a)
    mmio.write_point_cloud(folder / "b.ply", scene.b)
    np.save(folder / "flow.npy", scene.b - scene.a)
    np.save(folder / "truth.npy", scene.labels)
    np.save(folder / "init.npy", scene.labels)  # the true objects as initial clusters
    np.save(folder / "five_columns.npy", scene.X[:, :5])
    with_nan = scene.X.copy()
    with_nan[7, 4] = np.nan
    np.save(folder / "nan.npy", with_nan)
    np.save(folder / "short_flow.npy", (scene.b - scene.a)[:-5])
    np.save(folder / "short_init.npy", scene.labels[:-1])
    np.savez(folder / "no_pixels.npz", masks=np.ones((1, 4, 4), dtype=bool))
    (folder / "pairs.xlsx").write_bytes(b"not a spreadsheet")
    return folder


def _check_result(out, scene, n_clusters):
    """Every file of a result directory reads back and agrees with the noiseless scene."""
    from PIL import Image

    assert {p.name for p in out.iterdir()} == RESULT_FILES
    labels = mmio.read_labels(out / "labels.npy")
    assert labels.shape == (len(scene.X),)
    assert len(np.unique(labels[labels >= 0])) == n_clusters

    # motions.json reproduces each cluster's b-points from its a-points.
    motions = mmio.read_motions(out / "motions.json")
    assert len(motions["rotations"]) == n_clusters
    for j in range(n_clusters):
        members = labels == j
        moved = scene.a[members] @ motions["rotations"][j].T + motions["translations"][j]
        residual = np.linalg.norm(moved - scene.b[members], axis=1)
        assert np.all(residual <= 5 * motions["sigmas"][j] + 1e-9)
        assert motions["sizes"][j] == members.sum()

    summary = pd.read_csv(out / "summary.csv")
    assert len(summary) == n_clusters
    assert summary["size"].sum() == np.sum(labels >= 0)
    assert summary["background"].sum() == 1

    points, colors = mmio.read_point_cloud(out / "clusters.ply", colors=True)
    assert points.shape == (len(scene.X), 3) and colors.shape == (len(scene.X), 3)
    np.testing.assert_allclose(points, scene.a, atol=1e-9)
    # One colour per cluster.
    assert len(np.unique(np.round(colors, 3), axis=0)) == n_clusters + np.any(labels < 0)

    with Image.open(out / "result.png") as image:
        pixels = np.asarray(image.convert("RGB"), dtype=float)
    assert pixels.shape[0] > 300 and pixels.shape[1] > 300
    assert pixels.std() > 0

    run = json.loads((out / "run.json").read_text())
    # No copy of the input, but where it is and what it holds.
    assert Path(run["input_path"]).is_absolute()
    X = mmio.read_correspondences(
        run["input_path"], target=run.get("target_path"), flow=run.get("flow_path")
    )
    np.testing.assert_allclose(X, scene.X, rtol=0, atol=1e-9)
    assert run["n_correspondences"] == len(scene.X)


def test_register_npy_writes_a_whole_result(files, scene, tmp_path):
    result = mmreg("register", files / "pairs.npy", "--out", tmp_path / "out", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    _check_result(tmp_path / "out", scene, 3)
    assert "3 clusters" in result.stdout
    # No staging folder left behind.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


@pytest.mark.parametrize(
    "args",
    [
        ["a.ply", "--target", "b.ply"],
        ["a.ply", "--flow", "flow.npy", "--paper", "--quiet"],
    ],
    ids=["ply+target", "ply+flow"],
)
def test_register_point_clouds(files, scene, tmp_path, args):
    result = mmreg("register", *args, "--out", tmp_path / "out", cwd=files)
    assert result.returncode == 0, result.stderr
    _check_result(tmp_path / "out", scene, 3)


def test_register_csv_with_labels_init_in_process(files, scene, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(
        ["register", str(files / "pairs.csv"), "--init", str(files / "init.npy")]
        + ["--out", str(out), "-q"]
    )
    assert code == 0
    assert capsys.readouterr().out == ""  # --quiet
    _check_result(out, scene, 3)
    np.testing.assert_array_equal(mmio.read_labels(out / "labels.npy"), scene.labels)


def test_register_on_a_voxel_sample(files, scene, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["register", str(files / "pairs.npy"), "--voxel-size", "0.2", "--out", str(out)])
    assert code == 0
    _check_result(out, scene, 3)
    run = json.loads((out / "run.json").read_text())
    assert run["estimator"]["voxel_size"] == 0.2
    assert main(["register", str(files / "pairs.npy"), "--voxel-size", "0.2", "--paper"]) == 2
    assert "drop --paper" in capsys.readouterr().err


def test_register_default_out_is_named_after_the_input(files, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["register", str(files / "pairs.npy"), "-q"]) == 0
    (out,) = tmp_path.iterdir()
    assert out.name.startswith("pairs-mmreg-") and (out / "labels.npy").exists()


def test_register_with_masks_init(tmp_path, capsys):
    scene = make_flying_things(
        n_objects=3, n_points=1500, image_size=(135, 240), corruption=False, random_state=0
    )
    np.save(tmp_path / "pairs.npy", scene.X)
    masks = np.stack([m["segmentation"] for m in scene.masks])
    np.savez(tmp_path / "masks.npz", masks=masks, pixels=scene.pixels)
    out = tmp_path / "out"
    code = main(
        ["register", str(tmp_path / "pairs.npy"), "--init", str(tmp_path / "masks.npz")]
        + ["--out", str(out)]
    )
    assert code == 0
    run = json.loads((out / "run.json").read_text())
    covered = np.unique(masks.argmax(axis=0)[scene.pixels[:, 1], scene.pixels[:, 0]])
    assert 1 < run["initial_clusters"] <= len(masks) and len(covered) > 1
    assert "clusters" in capsys.readouterr().out


def test_a_folder_of_the_users_files_is_never_touched(files, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    (out / "labels.npy").write_text("stale")
    for extra in ([], ["--overwrite"]):
        code = main(["register", str(files / "pairs.npy"), "--out", str(out), "-q", *extra])
        assert code == 2
        assert "notes.txt" in capsys.readouterr().err
        assert sorted(p.name for p in out.iterdir()) == ["labels.npy", "notes.txt"]
        assert (out / "labels.npy").read_text() == "stale"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_nothing_is_written_when_writing_fails(files, tmp_path, monkeypatch, capsys):
    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(mmio, "write_point_cloud", broken)
    out = tmp_path / "out"
    assert main(["register", str(files / "pairs.npy"), "--out", str(out), "-q"]) == 2
    assert "disk full" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # neither the result nor a staging folder


BAD_INPUTS = {
    "missing file": (["missing.npy"], "missing.npy"),
    "wrong shape": (["five_columns.npy"], "five_columns.npy"),
    "NaN": (["nan.npy"], "nan.npy"),
    "mismatched lengths": (["a.ply", "--flow", "short_flow.npy"], "short_flow.npy"),
    "unknown extension": (["pairs.xlsx"], "pairs.xlsx"),
    "cloud without target": (["a.ply"], "a.ply"),
    "missing target": (["a.ply", "--target", "gone.ply"], "gone.ply"),
    "labels of the wrong length": (["pairs.npy", "--init", "short_init.npy"], "short_init.npy"),
    "masks without pixels": (["pairs.npy", "--init", "no_pixels.npz"], "no_pixels.npz"),
}
# Run as a subprocess (the others in-process through main(), which is what the console
# script calls, to keep the test time down).
IN_A_SUBPROCESS = {"missing file", "NaN", "mismatched lengths", "unknown extension"}


@pytest.mark.parametrize("case", BAD_INPUTS, ids=list(BAD_INPUTS))
def test_bad_input_is_one_line_naming_the_file(files, tmp_path, case, capsys, monkeypatch):
    args, name = BAD_INPUTS[case]
    out = tmp_path / "out"
    if case in IN_A_SUBPROCESS:
        result = mmreg("register", *args, "--out", out, cwd=files)
        code, stderr = result.returncode, result.stderr
    else:
        monkeypatch.chdir(files)
        code = main(["register", *args, "--out", str(out)])
        stderr = capsys.readouterr().err
    assert code == 2
    assert "Traceback" not in stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("mmreg: error: ") and name in lines[0]
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_bad_option_is_a_usage_error(files, tmp_path):
    result = mmreg("register", "pairs.npy", "--tau", "-1", cwd=files)
    assert result.returncode == 2
    assert "--tau" in result.stderr and "Traceback" not in result.stderr


def test_help_lists_the_commands():
    result = subprocess.run(
        [sys.executable, "-m", "mmreg.cli", "--help"], capture_output=True, text=True
    )
    assert result.returncode == 0
    for command in ("demo", "register", "evaluate", "view"):
        assert command in result.stdout


@pytest.mark.parametrize("command", ["demo", "register", "evaluate", "view"])
def test_every_option_shows_its_default(command, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([command, "--help"])
    assert exit_info.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    parser = build_parser()
    sub = parser._subparsers._group_actions[0].choices[command]
    for action in sub._actions:
        if action.option_strings and action.default not in (None, "==SUPPRESS=="):
            assert f"(default: {action.default})" in text, action.dest


def test_evaluate_and_view(files, scene, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["register", str(files / "pairs.npy"), "--out", str(out), "-q"]) == 0
    np.savez(
        tmp_path / "truth.npz",
        labels=scene.labels,
        rotations=scene.rotations,
        translations=scene.translations,
    )
    result = mmreg("evaluate", out, tmp_path / "truth.npz", "--json", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    scores = json.loads(result.stdout)
    assert scores["iou"] == 1.0 and scores["objects_found"] == 1.0
    assert scores["clusters_predicted"] == scores["objects_true"] == 3
    assert scores["rotation_error_deg"] < 1e-6 and scores["per_point_error"] < 1e-6

    capsys.readouterr()
    assert main(["evaluate", str(out), str(files / "truth.npy")]) == 0
    assert "IoU" in capsys.readouterr().out
    assert main(["evaluate", str(out), str(files / "short_init.npy")]) == 2
    assert "short_init.npy" in capsys.readouterr().err

    picture = tmp_path / "again.png"
    result = mmreg("view", out, "--out", picture, "--view", "top", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    from PIL import Image

    with Image.open(picture) as image:
        assert np.asarray(image.convert("L"), dtype=float).std() > 0


def test_view_of_a_missing_directory(tmp_path, capsys):
    assert main(["view", str(tmp_path / "nowhere")]) == 2
    assert "nowhere" in capsys.readouterr().err


def test_demo_writes_a_picture(tmp_path):
    result = mmreg("demo", "--out", "demo-out", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    out = tmp_path / "demo-out"
    assert RESULT_FILES | {"truth.npz", "X.npy"} == {p.name for p in out.iterdir()}
    for line in ("IoU", "moving cars found", "gross errors flagged", "best match (IoU)"):
        assert line in result.stdout
    from PIL import Image

    with Image.open(out / "result.png") as image:
        assert np.asarray(image.convert("L"), dtype=float).std() > 0
    # The result directory works with the other commands.
    assert main(["evaluate", str(out), str(out / "truth.npz"), "--json"]) == 0


def test_mmreg_demo_is_an_alias(capsys):
    from mmreg._demo import main as demo_main

    with pytest.raises(SystemExit):
        demo_main(["--help"])
    assert "usage: mmreg demo" in capsys.readouterr().out


def test_plugins_add_subcommands_and_broken_ones_are_skipped(monkeypatch, capsys):
    import types

    import mmreg._cli as cli

    hello = types.SimpleNamespace(
        HELP="say hello",
        add_arguments=lambda parser: parser.add_argument("--name", default="world"),
        run=lambda args: print(f"hello {args.name}") or 0,
    )

    class Entry:
        def __init__(self, name, value, loaded):
            self.name, self.value, self._loaded = name, value, loaded

        def load(self):
            if isinstance(self._loaded, Exception):
                raise self._loaded
            return self._loaded

    entries = [Entry("hello", "pkg:hello", hello), Entry("broken", "pkg:x", ImportError("no pkg"))]
    monkeypatch.setattr(cli, "entry_points", lambda group: entries)
    assert main(["hello", "--name", "mmreg"]) == 0
    captured = capsys.readouterr()
    assert captured.out == "hello mmreg\n"
    assert "plugin 'broken'" in captured.err and "no pkg" in captured.err
