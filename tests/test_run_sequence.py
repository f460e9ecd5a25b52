"""``mmreg run`` on LiDAR logs: the sequence estimator by default, its files (labels of
every row of every frame, tracks.csv, poses.txt, pictures, the Argoverse 2 challenge's
files), a folder of logs resumed log by log, --pairs keeping the pair jobs, and
``mmreg evaluate`` and ``mmreg view`` on the result."""

import contextlib
import io
import json
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mmreg import SequenceRegistration
from mmreg.cli import main
from mmreg.datasets import make_lidar_sequence, open_sequence
from mmreg.io import (
    read_kitti_poses,
    read_semantickitti_labels,
    semantickitti_mos_labels,
    write_kitti_poses,
    write_semantickitti_labels,
)
from mmreg.metrics import moving_iou

distributed = pytest.importorskip("distributed")

N_INVALID = 3  # rows of each scan that are no return (all zero), as KITTI scans hold them
TRACK_COLUMNS = [
    "track", "frame", "time_s", "x_m", "y_m", "z_m", "length_m", "width_m", "height_m",
    "yaw_rad", "vx_m_frame", "vy_m_frame", "vz_m_frame", "speed_m_frame",
    "yaw_rate_rad_frame", "points",
]  # fmt: skip


def _log(n_frames=4, seed=0):
    return make_lidar_sequence(n_frames=n_frames, n_azimuths=256, random_state=seed)


def write_semantickitti(folder, log):
    """A SemanticKITTI sequence: velodyne/*.bin (x, y, z, reflectance; the last rows all
    zero), labels/*.label (LiDAR-MOS classes, instance ids), poses.txt (the LiDAR's own,
    first the identity). Returns the scans as the files hold them."""
    folder = Path(folder)
    (folder / "velodyne").mkdir(parents=True)
    (folder / "labels").mkdir()
    scans = []
    for k, frame in enumerate(log.frames):
        points = np.vstack([frame, np.zeros((N_INVALID, 3))])
        scan = np.hstack([points, np.ones((len(points), 1))]).astype(np.float32)
        scan.tofile(folder / "velodyne" / f"{k:06d}.bin")
        scans.append(scan[:, :3].astype(float))
        labels = np.r_[log.labels[k], np.full(N_INVALID, -1)]
        moving = np.r_[log.moving[k], np.zeros(N_INVALID, bool)]
        write_semantickitti_labels(
            folder / "labels" / f"{k:06d}.label", *semantickitti_mos_labels(labels, moving)
        )
    write_kitti_poses(folder / "poses.txt", np.linalg.inv(log.poses[0]) @ log.poses)
    return scans


@pytest.fixture(scope="module")
def written(tmp_path_factory, scheduler):
    """A SemanticKITTI log run once with the defaults: (folder, out, scans, stdout)."""
    root = tmp_path_factory.mktemp("sequence")
    log = _log()
    scans = write_semantickitti(root / "08", log)
    out = root / "out"
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        code = main(["run", str(root / "08"), "--out", str(out), "--scheduler", scheduler, "-q"])
    assert code == 0
    return root / "08", out, scans, buffer.getvalue()


def _expected(folder):
    """The sequence estimator fitted on the log as 'mmreg run' fits it (its poses given)."""
    with pytest.warns(UserWarning, match="no calib.txt"):
        sequence = open_sequence(folder)
        poses = sequence.poses
    return SequenceRegistration(random_state=0).fit(sequence, poses=poses)


def test_a_log_gets_labels_of_every_row_tracks_and_poses(written):
    folder, out, scans, printed = written
    # -q: only where the results went.
    assert printed.splitlines() == [printed.splitlines()[0]]
    assert printed.startswith(f"written: {out}/ (labels/ (4 frames), tracks.csv, poses.txt")
    expected = _expected(folder)
    for k, scan in enumerate(scans):
        found = read_semantickitti_labels(out / "labels" / f"{k:06d}.label", n_points=len(scan))
        assert found.convention == "semantickitti" and len(found.semantic) == len(scan)
        semantic, instance = semantickitti_mos_labels(expected.labels_[k], expected.moving_[k])
        np.testing.assert_array_equal(found.semantic, semantic)
        np.testing.assert_array_equal(found.instance, instance)
        # The rows that are no return: unlabelled, no track.
        assert not found.semantic[-N_INVALID:].any() and not found.instance[-N_INVALID:].any()
        assert set(np.unique(found.semantic)) <= {0, 9, 251}
        assert np.all(found.instance[found.semantic == 251] >= 1)
    # The last frame has labels too.
    assert sorted(p.name for p in (out / "labels").iterdir()) == [
        f"{k:06d}.label" for k in range(4)
    ]
    tracks = pd.read_csv(out / "tracks.csv")
    assert list(tracks.columns) == TRACK_COLUMNS  # no times.txt: velocities per frame
    assert tracks["time_s"].isna().all()
    assert len(tracks) == len(expected.tracks_)
    np.testing.assert_array_equal(tracks["track"], expected.tracks_["track"])
    np.testing.assert_allclose(tracks["speed_m_frame"], expected.tracks_["speed"], rtol=1e-5)
    poses = read_kitti_poses(out / "poses.txt")
    np.testing.assert_allclose(poses[0], np.eye(4), atol=1e-12)
    relative = np.linalg.inv(expected.ego_poses_[0]) @ expected.ego_poses_
    np.testing.assert_allclose(poses, relative, atol=1e-9)
    # Tracks are in the frame of the poses: the first sensor pose's.
    first = expected.tracks_.iloc[0]
    centre = np.linalg.inv(expected.ego_poses_[0]) @ [first["x"], first["y"], first["z"], 1]
    np.testing.assert_allclose(tracks.loc[0, ["x_m", "y_m", "z_m"]], centre[:3], atol=1e-4)
    run = json.loads((out / "run.json").read_text())
    assert run["configuration"]["kind"] == "logs" and run["configuration"]["poses"] is True
    assert run["timings"]["logs"]["08"]["frames"] == 4 and run["timings"]["total_s"] > 0
    frames = pd.read_csv(out / "frames.csv", dtype={"name": str})
    assert frames["name"].tolist() == [f"{k:06d}" for k in range(4)]
    assert frames["points"].tolist() == [len(s) for s in scans]
    assert frames["returns"].tolist() == [len(s) - N_INVALID for s in scans]


def test_evaluate_gives_the_mos_iou_of_the_written_log(written, capsys):
    folder, out, scans, _ = written
    capsys.readouterr()
    assert main(["evaluate", str(out), "--json"]) == 0
    scores = json.loads(capsys.readouterr().out)
    truth, pred = [], []
    for k, scan in enumerate(scans):
        true = read_semantickitti_labels(folder / "labels" / f"{k:06d}.label", len(scan))
        found = read_semantickitti_labels(out / "labels" / f"{k:06d}.label", len(scan))
        truth.append(true.semantic == 251)
        pred.append(found.semantic == 251)
    assert scores["frames_labelled"] == 4
    assert scores["mos_iou"] == pytest.approx(moving_iou(truth, pred))
    assert 0 < scores["mos_iou"] <= 1
    assert scores["moving_points_true"] == sum(int(t.sum()) for t in truth)
    # The log's poses are known: the relative pose error of every frame pair.
    assert scores["rpe_m_mean"] >= 0 and scores["poses_given"] is True
    assert scores["objects_true"] >= 1
    # Printed for a person, with the IoU on its line.
    assert main(["evaluate", str(out)]) == 0
    text = capsys.readouterr().out
    line = next(line for line in text.splitlines() if line.startswith("moving-object IoU"))
    assert line.split()[-1] == f"{scores['mos_iou']:.3f}"
    assert main(["evaluate", str(out), str(folder / "labels")]) == 2
    assert "TRUTH does not apply" in capsys.readouterr().err


def test_view_draws_a_frame_of_the_log(written, tmp_path, capsys):
    _, out, _, _ = written
    picture = tmp_path / "frame.png"
    assert main(["view", str(out), "--at", "000001", "--out", str(picture)]) == 0
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["view", str(out), "--at", "1", "--out", str(picture)]) == 2
    assert "exists" in capsys.readouterr().err
    assert main(["view", str(out), "--at", "9", "--out", str(tmp_path / "x.png")]) == 2
    assert "no frame '9'" in capsys.readouterr().err


def test_the_same_run_again_is_skipped_and_other_options_are_refused(written, scheduler, capsys):
    folder, out, _, _ = written
    label = out / "labels" / "000000.label"
    before = label.stat().st_mtime_ns
    command = ["run", str(folder), "--out", str(out), "--scheduler", scheduler]
    assert main(command) == 0
    printed = capsys.readouterr().out
    assert "(from an earlier run)" in printed and "frames:" in printed
    assert label.stat().st_mtime_ns == before
    assert main([*command, "-q", "--seed", "1"]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert label.stat().st_mtime_ns == before


def test_pairs_keeps_the_pair_jobs(tmp_path, scheduler):
    write_semantickitti(tmp_path / "08", _log(3))
    for pairs in (["--pairs"], ["--pairs", "sweeps"]):
        out = tmp_path / f"out{len(pairs)}"
        command = ["run", str(tmp_path / "08"), *pairs, "--out", str(out)]
        assert main([*command, "--scheduler", scheduler, "-q"]) == 0
        assert sorted(p.name for p in (out / "jobs").iterdir()) == ["000000.npz", "000001.npz"]
        assert len(pd.read_csv(out / "summary.csv")) == 2
        assert not (out / "labels").exists() and not (out / "tracks.csv").exists()


def test_a_folder_of_logs_runs_each_and_resumes_log_by_log(tmp_path, scheduler, capsys):
    root = tmp_path / "kitti"
    for name, seed in (("00", 0), ("01", 1)):
        write_semantickitti(root / "sequences" / name, _log(3, seed))
    out = tmp_path / "out"
    command = ["run", str(root), "--out", str(out), "--scheduler", scheduler]
    assert main(command) == 0
    printed = capsys.readouterr().out
    assert "2 logs: 2 done, 0 failed" in printed
    for name in ("00", "01"):
        assert len(list((out / name / "labels").glob("*.label"))) == 3
        assert read_kitti_poses(out / name / "poses.txt").shape == (3, 4, 4)
    summary = pd.read_csv(out / "summary.csv", dtype={"log": str})
    assert summary["log"].tolist() == ["00", "01"] and (summary["status"] == "done").all()
    # Again: both skipped.
    stamp = (out / "00" / "log.json").stat().st_mtime_ns
    assert main([*command, "-q"]) == 0
    summary = pd.read_csv(out / "summary.csv", dtype={"log": str})
    assert summary["resumed"].tolist() == [True, True]
    assert (out / "00" / "log.json").stat().st_mtime_ns == stamp
    # A scan of 01 changed: 01 alone runs again, and says why.
    scan = root / "sequences" / "01" / "velodyne" / "000002.bin"
    points = np.fromfile(scan, np.float32).reshape(-1, 4)
    points[:10, 2] += 0.01
    points.tofile(scan)
    os.utime(scan, ns=(stamp + 10**9, stamp + 10**9))
    assert main(command) == 0
    assert "1 log run again: a file read changed" in capsys.readouterr().out
    summary = pd.read_csv(out / "summary.csv", dtype={"log": str})
    assert summary["resumed"].tolist() == [True, False]
    assert summary.loc[1, "changed_input"] == str(scan)
    # evaluate scores every log, one row each.
    assert main(["evaluate", str(out), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [row["log"] for row in rows] == ["00", "01"]
    assert all(0 <= row["mos_iou"] <= 1 for row in rows)
    # view needs to be told which log.
    assert main(["view", str(out), "--out", str(tmp_path / "a.png")]) == 2
    assert "--job" in capsys.readouterr().err
    assert main(["view", str(out), "--job", "01", "--out", str(tmp_path / "a.png")]) == 0


def test_a_folder_of_frames_with_a_frame_rate_and_pictures(tmp_path, scheduler):
    log = _log(3)
    frames = tmp_path / "frames"
    frames.mkdir()
    for k, frame in enumerate(log.frames):
        np.save(frames / f"scan{k}.npy", frame)
    out = tmp_path / "out"
    command = ["run", str(frames), "--frame-rate", "10", "--pictures", "--out", str(out)]
    assert main([*command, "--scheduler", scheduler, "-q"]) == 0
    assert sorted(p.name for p in (out / "labels").iterdir()) == [
        f"scan{k}.label" for k in range(3)
    ]
    tracks = pd.read_csv(out / "tracks.csv")
    assert "vx_m_s" in tracks and "yaw_rate_rad_s" in tracks and "vx_m_frame" not in tracks
    if len(tracks):
        np.testing.assert_allclose(tracks["time_s"], tracks["frame"] / 10.0)
    names = sorted(p.name for p in (out / "pictures").iterdir())
    assert names == ["animation.gif", "scan0.png", "scan1.png", "scan2.png"]
    from PIL import Image

    with Image.open(out / "pictures" / "animation.gif") as gif:
        assert gif.n_frames == 3
    # No poses, no labels: nothing to score against.
    assert main(["evaluate", str(out)]) == 2


def test_an_argoverse2_log_keeps_the_challenge_files(tmp_path, scheduler):
    from _fake_av2 import STAMPS, write_log

    from mmreg.datasets._argoverse2 import _read_points

    log = write_log(tmp_path / "log", annotations=False)
    out = tmp_path / "out"
    assert main(["run", str(log), "--out", str(out), "--scheduler", scheduler, "-q"]) == 0
    assert sorted(p.name for p in (out / "labels").iterdir()) == [f"{t}.label" for t in STAMPS]
    flows = sorted(p.name for p in (out / "av2_scene_flow" / log.name).iterdir())
    assert flows == [f"{t}.feather" for t in STAMPS[:-1]]  # the last sweep has no next
    for t in STAMPS[:-1]:
        points = _read_points(log / "sensors" / "lidar" / f"{t}.feather")[0]
        table = pd.read_feather(out / "av2_scene_flow" / log.name / f"{t}.feather")
        assert list(table.columns) == ["flow_tx_m", "flow_ty_m", "flow_tz_m", "is_dynamic"]
        assert len(table) == len(points) and np.isfinite(table.iloc[:, :3].to_numpy()).all()
        labels = read_semantickitti_labels(out / "labels" / f"{t}.label", len(points))
        np.testing.assert_array_equal(table["is_dynamic"], labels.semantic == 251)
    # Argoverse 2 has times: velocities per second.
    assert "speed_m_s" in pd.read_csv(out / "tracks.csv")


def test_nuscenes_labels_leave_the_ego_body_out_and_no_poses_is_independent(
    tmp_path, scheduler, capsys
):
    """One-byte labels (a nuScenes conversion: 31 the ego body, 32 and up moving) are
    scored with the body left out; --no-poses registers from the points alone."""
    log = _log(3)
    folder = tmp_path / "scene"
    scans = write_semantickitti(folder, log)
    rng = np.random.default_rng(0)
    truth, ignore = [], []
    for k, scan in enumerate(scans):
        moving = np.r_[log.moving[k], np.zeros(N_INVALID, bool)]
        body = ~moving & (rng.random(len(scan)) < 0.05)  # some points are the "body"
        values = np.where(moving, 35, np.where(body, 31, 24)).astype(np.uint8)
        values.tofile(folder / "labels" / f"{k:06d}.label")
        truth.append(moving)
        ignore.append(body)
    out = tmp_path / "out"
    command = ["run", str(folder), "--no-poses", "--out", str(out), "--scheduler", scheduler]
    assert main([*command, "-q"]) == 0
    record = json.loads((out / "log.json").read_text())
    assert record["row"]["poses_given"] is False
    pred = [
        read_semantickitti_labels(out / "labels" / f"{k:06d}.label").semantic == 251
        for k in range(3)
    ]

    capsys.readouterr()
    assert main(["evaluate", str(out), "--json"]) == 0
    scores = json.loads(capsys.readouterr().out)
    assert scores["mos_iou"] == pytest.approx(moving_iou(truth, pred, ignore=ignore))
    assert scores["poses_given"] is False and scores["rpe_m_max"] >= 0
    assert "objects_true" not in scores  # one byte a point: no instance ids


def test_a_log_of_a_folder_that_cannot_be_read_fails_alone(tmp_path, scheduler, capsys):
    root = tmp_path / "sequences"
    write_semantickitti(root / "00", _log(2))
    (root / "01" / "velodyne").mkdir(parents=True)  # no scan at all
    out = tmp_path / "out"
    assert main(["run", str(root), "--out", str(out), "--scheduler", scheduler, "-q"]) == 1
    assert "1 log failed, e.g. 01" in capsys.readouterr().err
    summary = pd.read_csv(out / "summary.csv", dtype={"log": str})
    assert summary["status"].tolist() == ["done", "error"]
    assert "no .bin scans" in summary.loc[1, "error"]
    assert (out / "00" / "log.json").is_file() and not (out / "01").exists()


def test_run_voxel_size_thins_the_frames(tmp_path):
    """--voxel-size: the fit registers one point per voxel; every point is labelled."""
    from mmreg.cli import main
    from mmreg.datasets import make_lidar_sequence
    from mmreg.io import read_semantickitti_labels

    log = make_lidar_sequence(3, frame_rate=10.0, n_azimuths=256, random_state=0)
    folder = tmp_path / "frames"
    folder.mkdir()
    for k, points in enumerate(log.frames):
        np.save(folder / f"scan{k}.npy", points)
    out = tmp_path / "out"
    assert main(["run", str(folder), "--out", str(out), "--voxel-size", "0.1", "-q"]) == 0
    for k, points in enumerate(log.frames):
        labels = read_semantickitti_labels(out / "labels" / f"scan{k}.label", len(points))
        keys = np.floor(points / 0.1).astype(np.int64)
        _, group = np.unique(keys, axis=0, return_inverse=True)
        group = group.ravel()
        # one label per voxel
        first = np.zeros(group.max() + 1, dtype=np.int64)
        first[group[::-1]] = labels.semantic[::-1]
        np.testing.assert_array_equal(labels.semantic, first[group])
    with pytest.raises(SystemExit):
        main(["run", str(folder), "--out", str(tmp_path / "bad"), "--voxel-size", "0"])


def test_a_log_in_other_units_than_tau_is_told_so_without_verbose(tmp_path, capsys):
    """A log in centimetres run with the default --tau (metres): the result shows no
    motion, and the run says why on the console, -v or not."""
    from mmreg.cli import main
    from mmreg.datasets import make_lidar_sequence

    log = make_lidar_sequence(3, frame_rate=10.0, n_azimuths=256, random_state=0)
    folder = tmp_path / "centimetres"
    folder.mkdir()
    for k, points in enumerate(log.frames):
        np.save(folder / f"scan{k}.npy", points * 100.0)
    command = ["run", str(folder), "--frame-rate", "10"]
    assert main([*command, "--out", str(tmp_path / "metres")]) == 0
    said = capsys.readouterr().out
    assert "centimetres: warning: tau=5 spans fewer than 4 times the median distance" in said
    assert main([*command, "--out", str(tmp_path / "told"), "--tau", "500"]) == 0
    assert "warning" not in capsys.readouterr().out
    # Each pair alone: the multi-model estimator's own warning, shown as well.
    assert main([*command, "--out", str(tmp_path / "pairs"), "--pairs"]) == 0
    assert ": warning: tau=5 spans fewer than 4 times" in capsys.readouterr().out


def test_a_log_not_in_its_sensor_frame_is_told_so_without_verbose(tmp_path, capsys):
    """Frames in a map's coordinates (UTM): the run says so on the console, -v or not,
    for the log and for each pair alone."""
    from mmreg.cli import main
    from mmreg.datasets import make_lidar_sequence

    log = make_lidar_sequence(3, frame_rate=10.0, n_azimuths=256, random_state=0)
    folder = tmp_path / "utm"
    folder.mkdir()
    for k, points in enumerate(log.frames):
        np.save(folder / f"scan{k}.npy", points + [5e5, 4e6, 30.0])
    command = ["run", str(folder), "--frame-rate", "10"]
    assert main([*command, "--out", str(tmp_path / "log")]) == 0
    said = capsys.readouterr().out
    assert "utm: warning: the origin lies 4.03e+06 from frame 0" in said
    assert main([*command, "--out", str(tmp_path / "pairs"), "--pairs"]) == 0
    assert "warning: the origin lies 4.03e+06 from the first sweep" in capsys.readouterr().out
