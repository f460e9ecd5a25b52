"""KITTI pose files: 12 numbers a line, written exactly and read with checks."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from mmreg import SequenceRegistration
from mmreg._validation import check_ego_motion
from mmreg.datasets import open_sequence
from mmreg.io import read_kitti_poses, write_kitti_poses


def _poses(n, seed):
    rng = np.random.default_rng(seed)
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = Rotation.random(n, random_state=seed).as_matrix()
    poses[:, :3, 3] = rng.normal(scale=100.0, size=(n, 3))
    return poses


@given(n=st.integers(1, 30), seed=st.integers(0, 2**16))
def test_round_trip_is_exact(tmp_path_factory, n, seed):
    poses = _poses(n, seed)
    path = tmp_path_factory.mktemp("poses") / "poses.txt"
    write_kitti_poses(path, poses)
    lines = path.read_text().splitlines()
    assert len(lines) == n and all(len(line.split()) == 12 for line in lines)
    np.testing.assert_array_equal(read_kitti_poses(path), poses)
    # (n, 3, 4) gives the same file.
    write_kitti_poses(path, poses[:, :3])
    np.testing.assert_array_equal(read_kitti_poses(path), poses)


def test_reads_kittis_own_seven_digit_file(tmp_path):
    # KITTI's ground truth is written with %e (7 significant digits): still rigid enough.
    path = tmp_path / "00.txt"
    rows = _poses(3, 1)[:, :3].reshape(3, 12)
    path.write_text("".join(" ".join(f"{v:e}" for v in row) + "\n" for row in rows))
    np.testing.assert_allclose(read_kitti_poses(path)[:, :3].reshape(3, 12), rows, rtol=1e-6)


def test_the_kitti_sequence_reader_shares_the_parser(tmp_path):
    (tmp_path / "velodyne").mkdir()
    for k in range(2):
        np.zeros((3, 4), np.float32).tofile(tmp_path / "velodyne" / f"{k:06d}.bin")
    (tmp_path / "calib.txt").write_text("Tr: 1 0 0 0 0 1 0 0 0 0 1 0\n")
    write_kitti_poses(tmp_path / "poses.txt", _poses(2, 3))
    np.testing.assert_allclose(open_sequence(tmp_path).poses, _poses(2, 3), atol=1e-12)
    (tmp_path / "poses.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 nan\n" * 2)
    sequence = open_sequence(tmp_path)  # poses are read when first used
    with pytest.raises(ValueError, match=r"poses\.txt.*NaN or infinity.*line 1"):
        sequence.poses  # noqa: B018


@pytest.mark.parametrize(
    ("text", "error", "message"),
    [
        ("1 0 0 0 0 1 0 0 0 0 1\n", ValueError, "12 number"),
        ("1 0 0 0 0 1 0 0 0 0 1 0 7\n", ValueError, "12 number"),
        ("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 inf\n", ValueError, "line 2"),
        ("1 0 0 0 0 1 0 0 0 0 1 0\n2 0 0 0 0 1 0 0 0 0 1 0\n", ValueError, "rotation.*line 2"),
        ("-1 0 0 0 0 1 0 0 0 0 1 0\n", ValueError, "not a rotation.*line 1"),
        ("1 0 0 0 0 1 0 0 0 0 1 x\n", TypeError, "not a number"),
        ("", ValueError, "no rows"),
    ],
)
def test_reading_errors_name_the_file(tmp_path, text, error, message):
    path = tmp_path / "poses.txt"
    path.write_text(text)
    with pytest.raises(error, match=f"poses.txt.*{message}"):
        read_kitti_poses(path)


def test_missing_file():
    with pytest.raises(FileNotFoundError, match="nowhere.txt"):
        read_kitti_poses("nowhere.txt")


@pytest.mark.parametrize(
    ("poses", "message"),
    [
        (np.eye(4), r"shape \(n_frames, 4, 4\)"),
        (np.zeros((0, 4, 4)), "empty"),
        (np.full((1, 4, 4), np.nan), "NaN"),
        (np.array([[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]]]), "bottom row"),
        (np.diag([1.0, 1.0, 1.1, 1.0])[None], "not a rotation"),
    ],
)
def test_writing_errors_leave_no_file(tmp_path, poses, message):
    with pytest.raises(ValueError, match=message):
        write_kitti_poses(tmp_path / "poses.txt", poses)
    assert not any(tmp_path.iterdir())


@given(
    rotvec=st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),
    stretch=st.sampled_from([1e-5, -1e-5, 1e-3, -1e-3]),
    mirrored=st.booleans(),
)
def test_every_input_takes_the_same_rotations(tmp_path_factory, rotvec, stretch, mirrored):
    # An ego motion, a log's poses and a KITTI pose file accept the same matrices: a
    # rotation scaled by 1 +- 1e-5 (R^T R off by 2e-5), not one scaled by 1 +- 1e-3 (2e-3)
    # nor a mirror.
    rotation = Rotation.from_rotvec(rotvec).as_matrix() * (1.0 + stretch)
    if mirrored:
        rotation = rotation @ np.diag([1.0, 1.0, -1.0])
    pose = np.eye(4)
    pose[:3, :3] = rotation
    expected = abs(stretch) < 1e-4 and not mirrored
    verdicts = []
    for check in (
        lambda: check_ego_motion((rotation, np.zeros(3))),
        lambda: SequenceRegistration()._check_poses(np.stack([np.eye(4), pose]), 2),
        lambda: write_kitti_poses(tmp_path_factory.mktemp("p") / "p.txt", pose[None]),
    ):
        try:
            check()
            verdicts.append(True)
        except ValueError as error:
            assert "rotation" in str(error) or "rigid" in str(error)
            verdicts.append(False)
    assert verdicts == [expected] * 3
