"""Sequences of LiDAR frames: ROS 1 / ROS 2 bags, KITTI sequences, Argoverse 2 logs, folders.

Every bag, folder and file is written here: bags with rosbags' own writers and
serialisers (the formats ROS writes), a KITTI sequence with a calibration whose ``Tr`` is
not the identity, so the velodyne poses are only right when ``Tr`` is applied on both
sides.
"""

import json
import pickle
import re

import numpy as np
import pytest
from _surfaces import area_weighted_box
from scipy.spatial.transform import Rotation
from sklearn.metrics import adjusted_rand_score

from mmreg.cli import main
from mmreg.datasets import (
    Argoverse2Sweeps,
    BagSequence,
    FrameFolder,
    KittiSequence,
    open_sequence,
    write_argoverse2_log,
)

rosbags = pytest.importorskip("rosbags")

STAMP = 1_700_000_000  # seconds of the first frame
PERIOD_NS = 100_000_000


# --------------------------------------------------------------------------- scenes
def _transform(rotvec, translation):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = translation
    return T


EGO = _transform([0.0, 0.0, 0.01], [0.3, 0.0, 0.0])  # frame k -> frame k+1, static world
CAR = _transform([0.0, 0.0, 0.03], [1.3, 0.2, 0.0])  # frame k -> frame k+1, the car
PRECISION = 1e-3  # float32 coordinates; the motions' error is far below


def scene_frames(n_frames=3, random_state=0):
    """Frames of static boxes and a car (label 1), each the previous one moved, float32."""
    rng = np.random.default_rng(random_state)
    static = [((0.0, 0.0, 1.5), (6.0, 2.0, 3.0)), ((0.0, 12.0, 2.0), (4.0, 4.0, 4.0))]
    static.append(((12.0, 6.0, 1.5), (2.0, 8.0, 3.0)))
    parts = [area_weighted_box(c, s, 900, rng) for c, s in static]
    parts.append(area_weighted_box((-9.0, 6.0, 0.75), (4.0, 2.0, 1.5), 700, rng))
    labels = np.repeat([0, 0, 0, 1], [900, 900, 900, 700])
    frames = [np.vstack(parts).astype(np.float32)]
    for _ in range(n_frames - 1):
        moved = np.empty(frames[-1].shape)
        for k, T in enumerate((EGO, CAR)):
            moved[labels == k] = frames[-1][labels == k] @ T[:3, :3].T + T[:3, 3]
        frames.append(moved.astype(np.float32))
    return [f.astype(np.float64) for f in frames], labels


def _pointcloud2(types, points, stamp_ns, times_ns=None, ros1=False):
    PointField = types["sensor_msgs/msg/PointField"]
    fields = [PointField(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")]
    layout = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if times_ns is not None:
        fields.append(PointField(name="t", offset=12, datatype=6, count=1))  # Ouster style
        layout.append(("t", "<u4"))
    record = np.zeros(len(points), layout)
    for k, name in enumerate("xyz"):
        record[name] = points[:, k]
    if times_ns is not None:
        record["t"] = times_ns
    Time = types["builtin_interfaces/msg/Time"]
    Header = types["std_msgs/msg/Header"]
    extra = {"seq": 0} if ros1 else {}
    header = Header(
        stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id="lidar", **extra
    )
    return types["sensor_msgs/msg/PointCloud2"](
        header=header,
        height=1,
        width=len(points),
        fields=fields,
        is_bigendian=False,
        point_step=record.itemsize,
        row_step=record.itemsize * len(points),
        data=np.frombuffer(record.tobytes(), np.uint8),
        is_dense=True,
    )


def write_bag(path, frames, *, ros=2, topics=("/points",), times_ns=None, extra_topic=True):
    """A ROS 1 ``.bag`` or a ROS 2 bag folder with ``frames`` on every topic of ``topics``."""
    from rosbags.typesys import Stores, get_typestore

    msgtype = "sensor_msgs/msg/PointCloud2"
    if ros == 1:
        from rosbags.rosbag1 import Writer

        typestore = get_typestore(Stores.ROS1_NOETIC)
        writer, serialize = Writer(path), typestore.serialize_ros1
    else:
        from rosbags.rosbag2 import Writer

        typestore = get_typestore(Stores.ROS2_HUMBLE)
        writer, serialize = Writer(path, version=8), typestore.serialize_cdr
    with writer:
        connections = [writer.add_connection(t, msgtype, typestore=typestore) for t in topics]
        if extra_topic:  # not a point cloud: never a frame
            text = writer.add_connection("/log", "std_msgs/msg/String", typestore=typestore)
            message = typestore.types["std_msgs/msg/String"](data="hello")
            writer.write(text, STAMP * 10**9, serialize(message, "std_msgs/msg/String"))
        for k, points in enumerate(frames):
            stamp = STAMP * 10**9 + k * PERIOD_NS
            msg = _pointcloud2(typestore.types, points, stamp, times_ns, ros1=ros == 1)
            for connection in connections:
                # Received 20 ms after the stamp: the frame's time is the header's.
                writer.write(connection, stamp + 20_000_000, serialize(msg, msgtype))
    return path


def _bag_path(tmp_path, ros):
    return tmp_path / ("run.bag" if ros == 1 else "run")


# --------------------------------------------------------------------------- bags
@pytest.mark.parametrize("ros", [1, 2])
def test_a_bag_is_a_sequence_of_its_point_clouds(tmp_path, ros):
    frames, _ = scene_frames(3)
    times = np.linspace(0, 99_000_000, len(frames[0])).astype(np.uint32)
    path = write_bag(_bag_path(tmp_path, ros), frames, ros=ros, times_ns=times)
    seq = open_sequence(path)
    assert isinstance(seq, BagSequence) and seq.kind == "bag" and seq.topic == "/points"
    assert len(seq) == 3 and seq.names == ["/points#0", "/points#1", "/points#2"]
    for k, frame in enumerate(seq):
        np.testing.assert_array_equal(frame.points, frames[k])
        assert frame.timestamp == pytest.approx(STAMP + 0.1 * k, abs=1e-6)
        np.testing.assert_array_equal(frame.times, times * 1e-9)
        assert frame.index == k and frame.pose is None
    np.testing.assert_array_equal(seq[-1].points, frames[2])
    with pytest.raises(IndexError, match="frame 3 out of range; it has 3"):
        seq[3]
    # It keeps paths only: a process pool can take it.
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(seq))[1].points, frames[1])


def test_a_ros2_bag_opens_from_its_folder_or_its_database(tmp_path):
    frames, _ = scene_frames(2)
    folder = write_bag(tmp_path / "run", frames)
    database = next(folder.glob("*.db3"))
    np.testing.assert_array_equal(open_sequence(database)[1].points, frames[1])


@pytest.mark.parametrize("ros", [1, 2])
def test_a_bag_of_several_topics_needs_one(tmp_path, ros):
    frames, _ = scene_frames(2)
    path = write_bag(_bag_path(tmp_path, ros), frames, ros=ros, topics=("/front", "/rear"))
    with pytest.raises(ValueError, match="2 PointCloud2 topics \\(/front, /rear\\); choose"):
        open_sequence(path)
    assert open_sequence(path, topic="/rear").topic == "/rear"
    with pytest.raises(ValueError, match="no PointCloud2 topic '/log'; .* /front, /rear"):
        open_sequence(path, topic="/log")


# --------------------------------------------------------------------------- KITTI
def _kitti_folder(tmp_path, frames, poses, *, layout="semantic"):
    """A sequence folder 08 with velodyne/, calib.txt and the camera's poses."""
    root = tmp_path / "dataset"
    folder = root / "sequences" / "08"
    (folder / "velodyne").mkdir(parents=True)
    for k, points in enumerate(frames):
        np.column_stack([points, np.ones(len(points))]).astype("<f4").tofile(
            folder / "velodyne" / f"{k:06d}.bin"
        )
    tr = _transform([1.2, -1.2, 1.2], [0.27, -0.08, -0.05])  # velodyne -> camera
    (folder / "calib.txt").write_text(
        "P0: "
        + " ".join(["1"] * 12)
        + "\nTr: "
        + " ".join(repr(float(v)) for v in tr[:3].ravel())
        + "\n"
    )
    camera = [tr @ V @ np.linalg.inv(tr) for V in poses]
    text = "".join(" ".join(repr(float(v)) for v in P[:3].ravel()) + "\n" for P in camera)
    if layout == "semantic":
        (folder / "poses.txt").write_text(text)
    else:  # KITTI odometry: dataset/poses/08.txt
        (root / "poses").mkdir()
        (root / "poses" / "08.txt").write_text(text)
    (folder / "times.txt").write_text("".join(f"{0.1 * k!r}\n" for k in range(len(frames))))
    return folder


def _velodyne_poses(n):
    """Pose k = pose k-1 @ inv(EGO): the static world moves by EGO from frame to frame."""
    poses = [np.eye(4)]
    for _ in range(n - 1):
        poses.append(poses[-1] @ np.linalg.inv(EGO))
    return poses


@pytest.mark.parametrize("layout", ["semantic", "odometry"])
def test_kitti_poses_are_the_velodyne_poses(tmp_path, layout):
    frames, _ = scene_frames(3)
    poses = _velodyne_poses(3)
    seq = open_sequence(_kitti_folder(tmp_path, frames, poses, layout=layout))
    assert isinstance(seq, KittiSequence) and len(seq) == 3
    np.testing.assert_allclose(seq.poses, poses, atol=1e-12)
    np.testing.assert_allclose(seq.ego_motion(0, 1), EGO, atol=1e-12)
    np.testing.assert_allclose(seq.ego_motion(0, 2), EGO @ EGO, atol=1e-12)
    frame = seq[2]
    np.testing.assert_array_equal(frame.points, frames[2])
    assert frame.timestamp == pytest.approx(0.2) and frame.times is None
    np.testing.assert_allclose(frame.pose, poses[2], atol=1e-12)


def test_kitti_files_that_do_not_match_are_one_error(tmp_path):
    frames, _ = scene_frames(2)
    folder = _kitti_folder(tmp_path, frames, _velodyne_poses(2))
    (folder / "poses.txt").write_text((folder / "poses.txt").read_text().splitlines()[0] + "\n")
    seq = open_sequence(folder)  # read when used: the points do not need them
    np.testing.assert_array_equal(seq[1].points, frames[1])
    with pytest.raises(ValueError, match=r"poses.txt: 1 poses for the 2 scans"):
        _ = seq.poses
    with pytest.raises(ValueError, match=r"poses.txt: 1 poses for the 2 scans"):
        _ = seq[1].pose
    (folder / "poses.txt").unlink()
    (folder / "times.txt").write_text("0.0\n0.1\n0.2\n")
    with pytest.raises(ValueError, match=r"times.txt: 3 times for the 2 scans"):
        _ = open_sequence(folder).timestamps
    (folder / "times.txt").unlink()
    (folder / "calib.txt").write_text("P0: 1 2 3\n")
    assert open_sequence(folder).poses is None  # no poses: calib.txt is not needed


# --------------------------------------------------------------------------- AV2, folders
def test_argoverse2_sweeps_by_timestamp_with_times_and_poses(tmp_path):
    frames, _ = scene_frames(2)
    stamps = (315966265259836000, 315966265359836000)
    poses = dict(zip(stamps, _velodyne_poses(2), strict=True))  # city_SE3_egovehicle
    offsets = {stamps[1]: np.arange(len(frames[1])) * 1000}
    log = write_argoverse2_log(
        tmp_path / "log", dict(zip(stamps, frames, strict=True)), poses, [], offsets_ns=offsets
    )
    for path in (log, log / "sensors" / "lidar"):
        seq = open_sequence(path)
        assert isinstance(seq, Argoverse2Sweeps) and len(seq) == 2
        np.testing.assert_array_equal(seq.timestamps, np.array(stamps) * 1e-9)
        np.testing.assert_allclose(seq.ego_motion(0, 1), EGO, atol=1e-6)
        frame = seq[1]
        np.testing.assert_allclose(frame.points, frames[1], atol=1e-2)  # float16 in AV2 files
        np.testing.assert_allclose(frame.times, np.arange(len(frames[1])) * 1e-6, atol=1e-15)


def test_a_folder_of_frames_in_natural_name_order(tmp_path):
    for k in (10, 2, 1):
        np.save(tmp_path / f"frame{k}.npy", np.full((4, 3), float(k)))
    seq = open_sequence(tmp_path)
    assert isinstance(seq, FrameFolder) and seq.kind == "folder"
    assert [float(f.points[0, 0]) for f in seq] == [1.0, 2.0, 10.0]
    assert seq[0].timestamp is None and seq[0].times is None
    np.full((4, 4), 5.0, dtype="<f4").tofile(tmp_path / "scan.bin")
    with pytest.raises(ValueError, match=r"several kinds \(1 \.bin, 3 \.npy\)"):
        open_sequence(tmp_path)
    assert open_sequence(tmp_path, pattern="*.bin").names == ["scan.bin"]
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no frames"):
        open_sequence(tmp_path / "empty")
    with pytest.raises(ValueError, match="topic= .* applies to a ROS bag only"):
        open_sequence(tmp_path, topic="/points")
    with pytest.raises(ValueError, match="is one file, not a sequence"):
        open_sequence(tmp_path / "scan.bin")


# --------------------------------------------------------------------------- command line
def _check_car(out, labels, frames):
    found = np.load(out / "labels.npy")
    assert adjusted_rand_score(labels, found) == 1.0
    motions = json.loads((out / "motions.json").read_text())
    background = next(m for m in motions if not m["moving"])
    (car,) = [m for m in motions if m["moving"]]
    assert np.abs(np.array(background["transform"]) - EGO).max() < PRECISION
    assert np.abs(np.array(car["transform"]) - CAR).max() < PRECISION
    X = np.load(out / "X.npy")
    np.testing.assert_array_equal(X[:, :3], frames[1])  # --frame 1: frame 1 against 2
    assert np.abs(X[:, 3:] - frames[2]).max() < PRECISION


@pytest.mark.parametrize("ros", [1, 2])
def test_register_a_bag_frame_against_the_next(tmp_path, ros):
    frames, labels = scene_frames(3)
    path = write_bag(_bag_path(tmp_path, ros), frames, ros=ros, topics=("/a", "/points"))
    out = tmp_path / "out"
    command = ["register", str(path), "--topic", "/points", "--frame", "1", "--tau", "2"]
    assert main([*command, "--out", str(out), "-q"]) == 0
    _check_car(out, labels, frames)
    run = json.loads((out / "run.json").read_text())
    assert run["frame"] == 1 and run["topic"] == "/points"


def test_register_a_bag_with_capture_times_deskews_with_its_stamps(tmp_path):
    frames, labels = scene_frames(3)
    # Every point taken at the stamp: deskewing changes nothing, and the interval is the
    # stamps' 0.1 s.
    path = write_bag(tmp_path / "run", frames, times_ns=np.zeros(len(labels), np.uint32) + 1)
    out = tmp_path / "out"
    assert main(["register", str(path), "--frame", "1", "--tau", "2", "--out", str(out), "-q"]) == 0
    run = json.loads((out / "run.json").read_text())
    # Seconds since 1970 as floats are 0.24 microseconds apart.
    assert run["file_times"] is True and run["interval"] == pytest.approx(0.1, abs=1e-6)
    _check_car(out, labels, frames)


def test_register_a_kitti_sequence_frame(tmp_path):
    frames, labels = scene_frames(3)
    poses = _velodyne_poses(3)
    folder = _kitti_folder(tmp_path, frames, poses)
    out = tmp_path / "out"
    assert (
        main(["register", str(folder), "--frame", "1", "--tau", "2", "--out", str(out), "-q"]) == 0
    )
    _check_car(out, labels, frames)
    # The static world's motion found is the poses' ego motion.
    background = next(m for m in json.loads((out / "motions.json").read_text()) if not m["moving"])
    ego = open_sequence(folder).ego_motion(1, 2)
    assert np.abs(np.array(background["transform"]) - ego).max() < PRECISION


@pytest.mark.parametrize(
    ("setup", "extra", "message"),
    [
        ("two topics", [], r"2 PointCloud2 topics \(/front, /rear\); choose one with --topic"),
        ("two topics", ["--topic", "/side"], r"no PointCloud2 topic '/side'; .*/front, /rear"),
        ("one topic", ["--frame", "2"], r"--frame 2 registers frames 2 and 3, but it has 3"),
        ("one topic", ["--sweep", "x.bin"], "drop --sweep"),
        ("one topic", ["--paper"], "drop --paper"),
        ("not a bag", [], "cannot be read as a ROS bag"),
    ],
)
def test_register_refuses_bad_bags_in_one_line(tmp_path, capsys, setup, extra, message):
    frames, _ = scene_frames(3)
    path = tmp_path / "run.bag"
    if setup == "not a bag":
        path.write_bytes(b"not a bag at all")
    else:
        topics = ("/front", "/rear") if setup == "two topics" else ("/points",)
        write_bag(path, frames, ros=1, topics=topics)
    argv = ["register", str(path), *extra, "--out", str(tmp_path / "out"), "-q"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and err.startswith("mmreg: error: "), err
    assert re.search(message, err), err
    assert not (tmp_path / "out").exists()


def test_a_bag_without_rosbags_names_the_extra(tmp_path, monkeypatch, capsys):
    import sys

    frames, _ = scene_frames(2)
    path = write_bag(tmp_path / "run.bag", frames, ros=1)
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)  # as if not installed
    with pytest.raises(ImportError, match=re.escape('pip install "mmreg[ros]"')):
        open_sequence(path)
    assert main(["register", str(path), "--out", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and 'pip install "mmreg[ros]"' in err
