"""A result directory keeps no copy of the input unless asked (``--save-input``)."""

import json

import numpy as np
import pytest

from mmreg.cli import main
from mmreg.datasets import make_scene


@pytest.fixture
def files(tmp_path):
    scene = make_scene(n_objects=3, n_points=600, random_state=0)
    np.save(tmp_path / "pairs.npy", scene.X)
    np.save(tmp_path / "init.npy", scene.labels)
    np.savez(tmp_path / "truth.npz", labels=scene.labels)
    return tmp_path, scene


def _register(folder, out, *extra):
    command = ["register", str(folder / "pairs.npy"), "--init", str(folder / "init.npy")]
    return main([*command, "--out", str(out), "-q", *extra])


def _evaluate(result, truth, capsys):
    capsys.readouterr()
    assert main(["evaluate", str(result), str(truth), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_view_and_evaluate_read_the_input_again(files, capsys):
    folder, scene = files
    assert _register(folder, folder / "plain") == 0
    assert _register(folder, folder / "saved", "--save-input") == 0
    assert not (folder / "plain" / "X.npy").exists()
    np.testing.assert_array_equal(np.load(folder / "saved" / "X.npy"), scene.X)
    run = json.loads((folder / "plain" / "run.json").read_text())
    assert run["input_path"] == str((folder / "pairs.npy").resolve())
    plain = _evaluate(folder / "plain", folder / "truth.npz", capsys)
    saved = _evaluate(folder / "saved", folder / "truth.npz", capsys)
    assert plain == saved and plain["rotation_error_deg"] is not None
    assert main(["view", str(folder / "plain"), "--out", str(folder / "plain.png")]) == 0
    assert (folder / "plain.png").read_bytes()[:4] == b"\x89PNG"


def test_a_changed_or_missing_input_is_an_error(files, capsys):
    folder, scene = files
    assert _register(folder, folder / "plain") == 0
    assert _register(folder, folder / "saved", "--save-input") == 0
    changed = scene.X.copy()
    changed[3, 4] += 1.0
    np.save(folder / "pairs.npy", changed)
    capsys.readouterr()
    assert main(["view", str(folder / "plain")]) == 2
    assert "changed since" in capsys.readouterr().err
    assert main(["evaluate", str(folder / "plain"), str(folder / "truth.npz")]) == 2
    assert "changed since" in capsys.readouterr().err
    (folder / "pairs.npy").unlink()
    assert main(["view", str(folder / "plain")]) == 2
    assert "pairs.npy: no such file" in capsys.readouterr().err
    # The copy makes the result independent of the input file.
    assert main(["view", str(folder / "saved")]) == 0
    assert _evaluate(folder / "saved", folder / "truth.npz", capsys)["iou"] == 1.0
