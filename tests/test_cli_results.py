"""``mmreg view`` and ``mmreg evaluate`` on what ``mmreg run`` writes, and on sweep results."""

import json
import shutil

import numpy as np
import pytest
from _fake_av2 import box_surface, write_log

from mmreg import io as mmio
from mmreg.cli import main
from mmreg.metrics import ground_truth_poses, rotation_error, translation_error
from mmreg.runner import dataset_jobs

distributed = pytest.importorskip("distributed")


def _write_frames(folder):
    """A static block and a box moving 0.5 m along x per frame, index-aligned frames."""
    rng = np.random.default_rng(0)
    block = rng.uniform([0, 0, 0], [2, 2, 2], (150, 3))
    box = rng.uniform([6, 0, 0], [7, 1, 1], (80, 3))
    folder.mkdir(parents=True)
    for k in range(3):
        np.save(folder / f"frame{k}.npy", np.vstack([block, box + [0.5 * k, 0, 0]]))
    return folder, np.r_[np.zeros(150, int), np.ones(80, int)]


def _json(capsys, *command):
    capsys.readouterr()
    assert main([*command, "--json"]) == 0
    captured = capsys.readouterr()
    return json.loads(captured.out), captured.err


def test_view_and_evaluate_a_run_of_frames(tmp_path, scheduler, capsys):
    frames, truth = _write_frames(tmp_path / "frames")
    np.save(tmp_path / "truth.npy", truth)
    out = tmp_path / "run"
    command = ["run", str(frames), "--pairs", "aligned", "--out", str(out), "-q"]
    assert main([*command, "--scheduler", scheduler]) == 0
    # Frames of index-aligned clouds are correspondences: --tau's default is 1.5.
    assert json.loads((out / "run.json").read_text())["configuration"]["tau"] == 1.5
    capsys.readouterr()
    # Two jobs: view needs to be told which.
    assert main(["view", str(out)]) == 2
    err = capsys.readouterr().err
    assert "holds 2 jobs; choose one with --job NAME" in err and len(err.splitlines()) == 1
    picture = tmp_path / "job.png"
    assert main(["view", str(out), "--job", "frame0__frame1", "--out", str(picture)]) == 0
    assert picture.read_bytes()[:4] == b"\x89PNG"
    job = out / "jobs" / "frame1__frame2.npz"
    assert main(["view", str(job), "--out", str(tmp_path / "file.png")]) == 0
    assert (tmp_path / "file.png").read_bytes()[:4] == b"\x89PNG"
    assert main(["view", str(out), "--job", "nope"]) == 2
    assert "no such job" in capsys.readouterr().err
    # The frames' correspondences are data: errors against the true clusters' motions.
    scores, _ = _json(capsys, "evaluate", str(job), str(tmp_path / "truth.npy"))
    assert scores["iou"] == 1.0 and scores["objects_found"] == 1.0
    assert scores["translation_error"] < 1e-9 and scores["rotation_error_deg"] < 1e-6
    # Frames hold no truth of their own.
    assert main(["evaluate", str(out)]) == 2
    assert "holds no truth; give TRUTH" in capsys.readouterr().err


def test_evaluate_every_job_of_a_sweep_run_against_its_datasets_truth(tmp_path, scheduler, capsys):
    log = write_log(tmp_path / "log")
    out = tmp_path / "run"
    command = ["run", str(log), "--pairs", "sweeps", "--out", str(out), "--scheduler", scheduler]
    assert main([*command, "-q"]) == 0
    # Two LiDAR sweeps: --tau's default is 5, as for 'mmreg register --sweep'.
    assert json.loads((out / "run.json").read_text())["configuration"]["tau"] == 5.0
    rows, _ = _json(capsys, "evaluate", str(out))
    jobs = dataset_jobs(log, pairs="sweeps")
    assert [row["job"] for row in rows] == [job.name for job in jobs]
    for row, job in zip(rows, jobs, strict=True):
        # The building and the car found, the flow close to the truth.
        assert row["iou"] == 1.0 and row["objects_found_besides_background"] == 1.0
        assert row["epe3d"] < 0.1 and row["bucketed_dynamic_normalized_epe"] < 0.1
        # The errors against the true objects' motions, fitted on the true flow.
        data = job.load()
        arrays = np.load(out / "jobs" / f"{job.name}.npz")
        a, truth, keep = data["X"], data["labels_true"], data["labels_true"] >= 0
        true = ground_truth_poses(np.hstack([a, a + data["flow_true"]]), truth)
        pred = (arrays["rotations"], arrays["translations"])
        args = (truth[keep], arrays["labels"][keep], true, pred)
        assert row["rotation_error_deg"] == pytest.approx(rotation_error(*args))
        assert row["translation_error"] == pytest.approx(translation_error(*args))
    # A job that used some rows of its sweep only names them (indices): read by them.
    subset = tmp_path / "subset"
    shutil.copytree(out, subset)
    path = subset / "jobs" / f"{jobs[0].name}.npz"
    arrays = dict(np.load(path))
    rows_used = np.arange(0, len(arrays["labels"]), 2)
    for key in ("labels", "flow", "ego_body", "indices"):  # one row per label each
        arrays[key] = arrays[key][rows_used]
    np.savez(path, **arrays)
    scores, _ = _json(capsys, "evaluate", str(path))
    assert scores["iou"] == 1.0 and scores["epe3d"] < 0.1
    assert main(["view", str(path), "--out", str(tmp_path / "subset.png")]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(out)]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].split()[:2] == ["job", "IoU"] and len(table) == 4
    # Labels alone: no errors measured against the result's own flow.
    job = sorted((out / "jobs").glob("*.npz"))[0]
    labels = np.load(job)["labels"]
    np.save(tmp_path / "labels.npy", labels)
    scores, err = _json(capsys, "evaluate", str(job), str(tmp_path / "labels.npy"))
    assert scores["iou"] == 1.0
    assert scores["rotation_error_deg"] is None and scores["per_point_error"] is None
    assert "its own flow" in err


def test_sweep_result_with_labels_only_truth_measures_no_error(tmp_path, capsys):
    rng = np.random.default_rng(3)
    still = box_surface(rng, 300, [0, 0, 0], [4, 4, 3])
    moving = box_surface(rng, 150, [8, 0, 0], [10, 1, 1])
    first = np.vstack([still, moving])
    second = np.vstack(
        [
            box_surface(rng, 280, [0, 0, 0], [4, 4, 3]),
            box_surface(rng, 160, [9, 0, 0], [11, 1, 1]),
        ]
    )
    mmio.write_point_cloud(tmp_path / "s0.ply", first)
    mmio.write_point_cloud(tmp_path / "s1.ply", second)
    out = tmp_path / "out"
    command = ["register", str(tmp_path / "s0.ply"), "--sweep", str(tmp_path / "s1.ply")]
    assert main([*command, "--out", str(out), "-q"]) == 0
    truth = np.r_[np.zeros(300, int), np.ones(150, int)]
    np.save(tmp_path / "truth.npy", truth)
    scores, err = _json(capsys, "evaluate", str(out), str(tmp_path / "truth.npy"))
    assert scores["iou"] == 1.0
    assert scores["rotation_error_deg"] is None and scores["translation_error"] is None
    assert "labels only" in err
    # With the true motions the errors are measured (the box moved 1 m along x).
    rotations = np.stack([np.eye(3)] * 2)
    translations = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    np.savez(tmp_path / "truth.npz", labels=truth, rotations=rotations, translations=translations)
    scores, _ = _json(capsys, "evaluate", str(out), str(tmp_path / "truth.npz"))
    assert scores["translation_error"] < 0.1 and scores["per_point_error"] < 0.1
    # clusters.ply carries the labels: one per a-point, as in labels.npy.
    o3d = pytest.importorskip("open3d")
    cloud = o3d.t.io.read_point_cloud(str(out / "clusters.ply"))
    np.testing.assert_array_equal(cloud.point["label"].numpy().ravel(), np.load(out / "labels.npy"))
