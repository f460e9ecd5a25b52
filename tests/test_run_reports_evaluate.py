"""'mmreg evaluate' of 'mmreg run --pairs' on a LiDAR log: every pair scored at once
against the log's own labels (moving against static, LiDAR-MOS's IoU; the ego vehicle's
body and unlabelled points left out) and, where the log has poses, the ego motions
against them."""

import contextlib
import io
import json

import numpy as np
import pytest

from mmreg.cli import main
from mmreg.datasets import make_lidar_sequence
from mmreg.io import (
    moving_from_labels,
    read_semantickitti_labels,
    semantickitti_mos_labels,
    write_kitti_poses,
    write_semantickitti_labels,
)
from mmreg.metrics import moving_iou, relative_pose_errors
from mmreg.runner import read_job_result

pytest.importorskip("distributed")

BODY = 40  # rows of each scan on the ego vehicle's body (nuScenes class 31)


@pytest.fixture(scope="module")
def street():
    return make_lidar_sequence(3, n_azimuths=256, random_state=0)


def write_log(folder, street, *, labels="semantickitti", poses=True):
    """A KITTI-layout log: velodyne/*.bin, labels/*.label (SemanticKITTI's uint32, or a
    nuScenes conversion's uint8 with the body's rows 31), poses.txt (the LiDAR's)."""
    (folder / "velodyne").mkdir(parents=True)
    if labels:
        (folder / "labels").mkdir()
    for k, frame in enumerate(street.frames):
        scan = np.hstack([frame, np.ones((len(frame), 1))]).astype(np.float32)
        scan.tofile(folder / "velodyne" / f"{k:06d}.bin")
        path = folder / "labels" / f"{k:06d}.label"
        if labels == "semantickitti":
            write_semantickitti_labels(
                path, *semantickitti_mos_labels(street.labels[k], street.moving[k])
            )
        elif labels == "nuscenes":
            classes = np.where(street.moving[k], 33, 24).astype(np.uint8)
            classes[:BODY] = 31
            classes.tofile(path)
    if poses:
        write_kitti_poses(folder / "poses.txt", np.linalg.inv(street.poses[0]) @ street.poses)
    return folder


def _run_pairs(log, out, *extra):
    code = main(["run", str(log), "--pairs", "--out", str(out), "-q", *extra])
    assert code == 0


def _evaluate(capsys, *command):
    capsys.readouterr()
    code = main(["evaluate", *map(str, command), "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return json.loads(captured.out)


def _expected_mos(out, log, n_pairs):
    """LiDAR-MOS's IoU by hand: a row moves when its cluster does."""
    truth, pred, ignore = [], [], []
    for k in range(n_pairs):
        arrays, _ = read_job_result(out / "jobs" / f"{k:06d}.npz")
        n = len(arrays["sweep_valid"])
        found = read_semantickitti_labels(log / "labels" / f"{k:06d}.label", n_points=n)
        moving, left_out = moving_from_labels(found.semantic, found.convention)
        guess = np.zeros(len(moving), bool)
        for index, label in zip(arrays["indices"], arrays["labels"], strict=True):
            if label >= 0:
                guess[index] = arrays["moving"][label]
        truth.append(moving)
        pred.append(guess)
        ignore.append(left_out)
    return moving_iou(truth, pred, ignore=ignore), truth, ignore


def test_a_pairs_run_of_a_labelled_log_is_scored_at_once(tmp_path, street, capsys):
    log = write_log(tmp_path / "08", street)
    out = tmp_path / "out"
    _run_pairs(log, out)
    scores = _evaluate(capsys, out)
    expected, truth, ignore = _expected_mos(out, log, 2)
    assert scores["log"] == "08" and scores["pairs"] == 2 and scores["frames_labelled"] == 2
    assert scores["mos_iou"] == pytest.approx(expected)
    assert scores["moving_points_true"] == sum(
        int((t & ~i).sum()) for t, i in zip(truth, ignore, strict=True)
    )
    # The ego motions against the log's poses, pair by pair.
    poses = np.linalg.inv(street.poses[0]) @ street.poses
    errors = []
    for k in range(2):
        arrays, _ = read_job_result(out / "jobs" / f"{k:06d}.npz")
        static = int(arrays["static_cluster"])
        motion = np.eye(4)
        motion[:3, :3] = arrays["rotations"][static]
        motion[:3, 3] = arrays["translations"][static]
        found = np.stack([np.eye(4), np.linalg.inv(motion)])
        true = np.stack([np.eye(4), np.linalg.inv(np.linalg.inv(poses[k + 1]) @ poses[k])])
        errors.append(relative_pose_errors(found, true)[0][0])
    assert scores["rpe_m_mean"] == pytest.approx(np.mean(errors))
    assert scores["rpe_m_max"] == pytest.approx(np.max(errors))
    assert scores["poses_given"] is True
    # One pair alone.
    alone = _evaluate(capsys, out, "--job", "000001")
    assert alone["pairs"] == 1 and alone["frames_labelled"] == 1


def test_the_ego_body_of_a_nuscenes_conversion_is_left_out(tmp_path, street, capsys):
    log = write_log(tmp_path / "scene", street, labels="nuscenes", poses=False)
    out = tmp_path / "out"
    _run_pairs(log, out)
    scores = _evaluate(capsys, out)
    expected, truth, ignore = _expected_mos(out, log, 2)
    assert all(i[:BODY].all() and not i[BODY:].any() for i in ignore)
    assert scores["mos_iou"] == pytest.approx(expected)
    assert scores["rpe_m_mean"] is None  # no poses: not measured


def test_a_log_with_poses_and_no_labels_gets_its_ego_motions_scored(tmp_path, street, capsys):
    log = write_log(tmp_path / "08", street, labels=None)
    out = tmp_path / "out"
    _run_pairs(log, out, "--no-poses")
    scores = _evaluate(capsys, out)
    assert scores["mos_iou"] is None and scores["frames_labelled"] == 0
    assert scores["poses_given"] is False  # registered from the points alone
    assert 0 <= scores["rpe_m_mean"] <= scores["rpe_m_max"] < 0.5
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["evaluate", str(out)]) == 0
    assert "relative pose error, mean [m]" in printed.getvalue()
    assert "3 frames" not in printed.getvalue() and "(2 pairs)" in printed.getvalue()
