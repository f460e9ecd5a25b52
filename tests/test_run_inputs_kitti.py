"""`mmreg run` and `mmreg register` on KITTI-style folders: --ground without a map, a
SemanticKITTI folder whose poses.txt holds the LiDAR's poses (no calib.txt), and a
folder of sequences (KITTI's sequences/)."""

import json

import numpy as np
import pandas as pd
import pytest
from test_run_inputs import street, sweep_estimator

from mmreg.cli import main
from mmreg.datasets import open_sequence
from mmreg.runner import dataset_jobs, read_job_result


def write_sequence(folder, scans, poses=None, *, calib=False, times=True):
    """A SemanticKITTI-style folder: velodyne/NNNNNN.bin (float32 x y z reflectance),
    labels/NNNNNN.label, and optionally poses.txt (12 numbers a line), calib.txt (an
    identity Tr) and times.txt (0.1 s apart)."""
    (folder / "velodyne").mkdir(parents=True)
    (folder / "labels").mkdir()
    for k, points in enumerate(scans):
        scan = np.c_[points, np.zeros(len(points))].astype(np.float32)
        scan.tofile(folder / "velodyne" / f"{k:06d}.bin")
        np.zeros(len(points), np.uint32).tofile(folder / "labels" / f"{k:06d}.label")
    if poses is not None:
        rows = [" ".join(repr(float(v)) for v in pose[:3].ravel()) for pose in poses]
        (folder / "poses.txt").write_text("\n".join(rows) + "\n")
    if calib:
        (folder / "calib.txt").write_text("Tr: 1 0 0 0 0 1 0 0 0 0 1 0\n")
    if times:
        (folder / "times.txt").write_text("".join(f"{0.1 * k!r}\n" for k in range(len(scans))))
    return folder


def street_poses(scene):
    """The LiDAR's poses of the two sweeps of ``scene`` in a world frame: the first at the
    origin, the second where the static world's motion puts it (pose_1 = inv(T))."""
    return [np.eye(4), np.linalg.inv(scene.transforms[0])]


# --------------------------------------------------------------------------- item 3
@pytest.mark.parametrize("ground", ["auto", "keep", "drop"])
def test_ground_in_run_means_what_it_means_in_register(tmp_path, scheduler, ground):
    scene = street()
    sequence = write_sequence(tmp_path / "00", [scene.a, scene.sweep])
    a, sweep = (p.astype(np.float32).astype(float) for p in (scene.a, scene.sweep))  # as read
    out = tmp_path / "out"
    command = ["run", str(sequence), "--pairs", "--out", str(out), "--scheduler", scheduler, "-q"]
    assert main([*command, "--ground", ground]) == 0
    # The frames' times (times.txt, 0.1 s apart) bound the objects' motions.
    expected = sweep_estimator(ground=ground).fit(a, sweep=sweep, interval=0.1)
    arrays, row = read_job_result(out / "jobs" / "000000.npz")
    np.testing.assert_array_equal(arrays["labels"], expected.labels_)
    # The summary says what was done with the ground Patchwork++ found.
    summary = pd.read_csv(out / "summary.csv").iloc[0]
    said = {"auto": "found", "keep": "kept", "drop": "dropped"}[ground]
    assert summary["ground"] == said == row["ground"]
    if ground == "keep":
        assert expected.ground_mask_ is None and pd.isna(summary.get("n_ground"))
        default = sweep_estimator().fit(a, sweep=sweep)
        assert not np.array_equal(default.labels_, expected.labels_)  # keep is not auto
    else:
        assert summary["n_ground"] == expected.ground_mask_.sum() > len(a) // 4
    if ground == "drop":
        assert (arrays["labels"][expected.ground_mask_] == -1).all()
    # register on the same pair agrees.
    register = ["register", str(sequence), "--frame", "0", "--ground", ground, "-q"]
    assert main([*register, "--out", str(tmp_path / "r")]) == 0
    np.testing.assert_array_equal(np.load(tmp_path / "r" / "labels.npy"), expected.labels_)


# --------------------------------------------------------------------------- item 6
def test_a_semantickitti_folder_with_lidar_poses_and_no_calib(tmp_path, scheduler, capsys):
    scene = street(256)
    poses = street_poses(scene)
    sequence = write_sequence(tmp_path / "scene-0004", [scene.a, scene.sweep], poses)
    seq = open_sequence(sequence)  # nothing read but the listing: no warning yet
    with pytest.warns(UserWarning, match="no calib.txt beside it") as caught:
        np.testing.assert_allclose(seq.poses, poses, atol=1e-12)
    assert caught[0].filename == __file__  # the user's line
    np.testing.assert_allclose(seq.ego_motion(0, 1), scene.transforms[0], atol=1e-12)
    assert [frame.timestamp for frame in seq] == [0.0, 0.1]  # times.txt
    # register and run both read it, the poses starting the ego motion.
    out = tmp_path / "r"
    capsys.readouterr()
    assert main(["register", str(sequence), "--frame", "0", "--out", str(out), "-q"]) == 0
    error = capsys.readouterr().err  # the note, one line
    assert "mmreg: warning: " in error and "poses.txt: no calib.txt beside it" in error
    record = json.loads((out / "run.json").read_text())
    assert record["ego_motion_from"] == "poses"
    motion = json.loads((out / "motions.json").read_text())
    static = max(motion, key=lambda m: m["size"])
    np.testing.assert_allclose(static["translation"], scene.transforms[0][:3, 3], atol=0.05)
    command = [
        "run",
        str(sequence),
        "--pairs",
        "--out",
        str(tmp_path / "run"),
        "--scheduler",
        scheduler,
    ]
    assert main([*command, "-q"]) == 0
    summary = pd.read_csv(tmp_path / "run" / "summary.csv")
    assert summary["status"].tolist() == ["done"]
    assert "no calib.txt beside it" in summary.loc[0, "warnings"]


def test_broken_poses_fail_only_what_reads_them(tmp_path):
    scene = street(256)
    sequence = write_sequence(tmp_path / "seq", [scene.a, scene.sweep], [np.eye(4)])
    seq = open_sequence(sequence)  # one pose for two scans: read when used
    np.testing.assert_array_equal(seq[1].points, scene.sweep.astype(np.float32))
    assert seq[1].timestamp == 0.1
    with pytest.raises(ValueError, match="poses.txt: 1 poses for the 2 scans"):
        _ = seq[1].pose
    # KITTI odometry's camera poses (the root's poses/NN.txt) need calib.txt.
    root = tmp_path / "dataset"
    odometry = write_sequence(root / "sequences" / "08", [scene.a, scene.sweep])
    (root / "poses").mkdir()
    (root / "poses" / "08.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n" * 2)
    with pytest.raises(FileNotFoundError, match="calib.txt: no such file"):
        _ = open_sequence(odometry).poses


# --------------------------------------------------------------------------- item 13
def _box_scans(n_frames, seed=0):
    """Small scans of a still box and a box moving 0.5 m along x per scan."""
    from _fake_av2 import box_surface

    rng = np.random.default_rng(seed)
    return [
        np.vstack(
            [
                box_surface(rng, 250, [0, 0, 0], [3, 3, 2]),
                box_surface(rng, 150, [6, 0, 0], [8, 2, 1.5]) + [0.5 * k, 0, 0],
            ]
        )
        for k in range(n_frames)
    ]


@pytest.mark.parametrize("root", ["sequences", "dataset"])
def test_a_folder_of_kitti_sequences_runs_every_sequence(tmp_path, scheduler, capsys, root):
    sequences = tmp_path / "dataset" / "sequences"
    write_sequence(sequences / "00", _box_scans(3))
    write_sequence(sequences / "01", _box_scans(2, seed=1))
    (sequences / "02" / "velodyne").mkdir(parents=True)  # no scan: one failed row
    path = sequences if root == "sequences" else tmp_path / "dataset"
    jobs = dataset_jobs(path)
    names = ["00_000000", "00_000001", "01_000000", "02"]
    assert [job.name for job in jobs] == names
    out = tmp_path / "out"
    assert (
        main(["run", str(path), "--pairs", "--out", str(out), "--scheduler", scheduler, "-q"]) == 1
    )
    summary = pd.read_csv(out / "summary.csv", dtype={"job": str})
    assert summary["job"].tolist() == names
    assert summary["status"].tolist() == ["done", "done", "done", "error"]
    assert "no .bin scans" in summary.loc[3, "error"]
    assert "1 job failed, e.g. 02" in capsys.readouterr().err
    # Each job is its sequence's own pair.
    alone = dataset_jobs(sequences / "01")[0].load()
    arrays, _ = read_job_result(out / "jobs" / "01_000000.npz")
    expected = sweep_estimator().fit(alone["X"], sweep=alone["sweep"])
    np.testing.assert_array_equal(arrays["labels"], expected.labels_)
