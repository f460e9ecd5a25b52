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


def test_a_changed_or_missing_input_is_named_and_iou_needs_none(files, capsys):
    folder, scene = files
    assert _register(folder, folder / "plain") == 0
    assert _register(folder, folder / "saved", "--save-input") == 0
    changed = scene.X.copy()
    changed[3, 4] += 1.0
    np.save(folder / "pairs.npy", changed)
    capsys.readouterr()
    assert main(["view", str(folder / "plain")]) == 2
    err = capsys.readouterr().err
    assert "pairs.npy: changed since" in err and len(err.strip().splitlines()) == 1
    # The labels alone answer the IoU: the changed input is a warning, the errors n/a.
    assert main(["evaluate", str(folder / "plain"), str(folder / "truth.npz"), "--json"]) == 0
    captured = capsys.readouterr()
    scores = json.loads(captured.out)
    assert scores["iou"] == 1.0 and scores["rotation_error_deg"] is None
    assert "pairs.npy: changed since" in captured.err
    (folder / "pairs.npy").unlink()
    assert main(["view", str(folder / "plain")]) == 2
    assert "pairs.npy: no such file" in capsys.readouterr().err
    assert _evaluate(folder / "plain", folder / "truth.npz", capsys)["iou"] == 1.0
    # The copy makes the result independent of the input file.
    assert main(["view", str(folder / "saved")]) == 0
    assert _evaluate(folder / "saved", folder / "truth.npz", capsys)["iou"] == 1.0


@pytest.fixture
def cloud_and_flow(tmp_path):
    from mmreg import io as mmio

    scene = make_scene(n_objects=3, n_points=600, random_state=1)
    mmio.write_point_cloud(tmp_path / "frame0.ply", scene.a)
    np.save(tmp_path / "flow.npy", scene.b - scene.a)
    np.save(tmp_path / "init.npy", scene.labels)
    command = ["register", str(tmp_path / "frame0.ply"), "--flow", str(tmp_path / "flow.npy")]
    command += ["--init", str(tmp_path / "init.npy"), "--out", str(tmp_path / "out"), "-q"]
    assert main(command) == 0
    return tmp_path, scene


def test_a_changed_flow_is_blamed_on_the_flow_not_the_cloud(cloud_and_flow, capsys):
    folder, scene = cloud_and_flow
    flow = np.load(folder / "flow.npy")
    flow[5, 0] += 0.5
    np.save(folder / "flow.npy", flow)
    capsys.readouterr()
    assert main(["view", str(folder / "out")]) == 2
    err = capsys.readouterr().err
    assert f"{(folder / 'flow.npy').resolve()}: changed since" in err
    assert "frame0.ply" not in err


def test_a_moved_cloud_is_named(cloud_and_flow, capsys):
    folder, scene = cloud_and_flow
    (folder / "frame0.ply").rename(folder / "elsewhere.ply")
    capsys.readouterr()
    assert main(["view", str(folder / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"mmreg: error: {(folder / 'frame0.ply').resolve()}: no such file")
    assert len(err.splitlines()) == 1
