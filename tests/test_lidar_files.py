"""LiDAR sweep files (KITTI .bin, nuScenes .pcd.bin, Argoverse 2 .feather, (n, 3) arrays),
PointCloud2 decoding, and ``mmreg register`` on them.

The registration scene: static boxes seen from a vehicle that moves 0.3 m and turns, and
one car that moves 1 m more; the second sweep holds the same surface points, moved and
shuffled, written as float32 like the sensors write them. The car is found as the one
moving cluster with its motion to float32 precision.
"""

import re
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation
from sklearn.metrics import adjusted_rand_score

from mmreg import io as mmio
from mmreg.cli import main
from mmreg.io._lidar import decode_pointcloud2

STATIC = [
    ((0.0, 0.0, 1.5), (6.0, 2.0, 3.0)),
    ((0.0, 12.0, 2.0), (4.0, 4.0, 4.0)),
    ((12.0, 6.0, 1.5), (2.0, 8.0, 3.0)),
]
CAR = ((-9.0, 6.0, 0.75), (4.0, 2.0, 1.5))
EGO = (Rotation.from_rotvec([0.0, 0.0, 0.01]).as_matrix(), np.array([0.3, 0.0, 0.0]))
CAR_MOTION = (Rotation.from_rotvec([0.0, 0.0, 0.03]).as_matrix(), np.array([1.3, 0.2, 0.0]))
# float32 coordinates of about 12 m are exact to about 1e-6 m; the fit's motion to well
# within this (the sweeps' points are 0.1 m apart).
PRECISION = 1e-3


def _surface(center, size, n, rng):
    size = np.asarray(size)
    areas = np.array([size[1] * size[2], size[0] * size[2], size[0] * size[1]]).repeat(2)
    face = rng.choice(6, n, p=areas / areas.sum())
    points = rng.uniform(-0.5, 0.5, (n, 3))
    points[np.arange(n), face // 2] = np.where(face % 2, 0.5, -0.5)
    return points * size + center


def lidar_scene(random_state=0):
    """``(a, sweep, labels, motions)``: a's points, the moved and shuffled second sweep."""
    rng = np.random.default_rng(random_state)
    parts = [_surface(c, s, 900, rng) for c, s in STATIC] + [_surface(*CAR, 700, rng)]
    labels = np.repeat([0, 0, 0, 1], [900, 900, 900, 700])
    # Stored as float32, as every LiDAR format does: the truth is of the stored points.
    a = np.vstack(parts).astype(np.float32).astype(np.float64)
    motions = [EGO, CAR_MOTION]
    moved = np.empty_like(a)
    for k, (R, t) in enumerate(motions):
        moved[labels == k] = a[labels == k] @ R.T + t
    sweep = moved[rng.permutation(len(a))].astype(np.float32).astype(np.float64)
    return a, sweep, labels, motions


def write_kitti(path, points, reflectance=None):
    values = np.column_stack(
        [points, np.zeros(len(points)) if reflectance is None else reflectance]
    )
    values.astype("<f4").tofile(path)


def write_nuscenes(path, points):
    ring = np.arange(len(points)) % 32
    np.column_stack([points, np.full(len(points), 7.0), ring]).astype("<f4").tofile(path)


def write_feather(path, points, offsets_ns=None, **columns):
    frame = {"x": points[:, 0].astype(np.float32), "y": points[:, 1].astype(np.float32)}
    frame["z"] = points[:, 2].astype(np.float32)
    frame["intensity"] = np.zeros(len(points), np.uint8)
    frame["laser_number"] = (np.arange(len(points)) % 64).astype(np.uint8)
    if offsets_ns is not None:
        frame["offset_ns"] = np.asarray(offsets_ns, dtype=np.int32)
    frame |= columns
    pd.DataFrame(frame).to_feather(path)


# --------------------------------------------------------------------------- readers
def test_kitti_bin_reads_x_y_z_and_keeps_invalid_returns(tmp_path):
    points = np.array([[1.5, -2.0, 0.25], [np.nan, np.nan, np.nan], [0, 0, 0], [3, 4, 5]])
    write_kitti(tmp_path / "000000.bin", points, reflectance=[0.1, 0.2, 0.3, 0.4])
    read = mmio.read_point_cloud(tmp_path / "000000.bin")
    # NaN and all-zero rows stay where they were: the estimators drop them.
    np.testing.assert_array_equal(read, points)
    assert read.dtype == np.float64
    assert mmio.read_point_cloud(tmp_path / "000000.bin", times=True)[1] is None


def test_nuscenes_pcd_bin_is_five_floats_a_point(tmp_path):
    points = np.arange(12.0).reshape(4, 3)
    write_nuscenes(tmp_path / "sweep.pcd.bin", points)
    np.testing.assert_array_equal(mmio.read_point_cloud(tmp_path / "sweep.pcd.bin"), points)
    # The same 80 bytes as a KITTI file would be 5 points of 4 floats: the name decides.
    (tmp_path / "sweep.bin").write_bytes((tmp_path / "sweep.pcd.bin").read_bytes())
    assert mmio.read_point_cloud(tmp_path / "sweep.bin").shape == (5, 3)


def test_feather_gives_points_and_capture_times(tmp_path):
    points = np.array([[1.0, 2.0, 3.0], [-4.0, 5.5, 0.0], [np.nan, np.nan, np.nan]])
    write_feather(tmp_path / "315966265259836000.feather", points, [0, 50_000_000, 99_000_000])
    read, times = mmio.read_point_cloud(tmp_path / "315966265259836000.feather", times=True)
    np.testing.assert_array_equal(read, points)
    np.testing.assert_array_equal(times, [0.0, 0.05, 0.099])
    # Points only, and colours and times together.
    np.testing.assert_array_equal(
        mmio.read_point_cloud(tmp_path / "315966265259836000.feather"), points
    )
    _, rgb, _ = mmio.read_point_cloud(
        tmp_path / "315966265259836000.feather", colors=True, times=True
    )
    assert rgb is None


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("cut.bin", b"\0" * 20, r"20 bytes is not a whole number of KITTI velodyne .bin points"),
        ("cut.pcd.bin", b"\0" * 32, r"32 bytes is not a whole number of nuScenes .pcd.bin"),
        ("empty.bin", b"", "holds no points"),
        ("text.feather", b"x,y,z\n1,2,3\n", "cannot be read as a feather file"),
    ],
)
def test_malformed_sweep_files_are_one_error(tmp_path, name, content, message):
    (tmp_path / name).write_bytes(content)
    with pytest.raises(ValueError, match=message):
        mmio.read_point_cloud(tmp_path / name)


def test_flat_files_of_another_layout_are_one_error(tmp_path):
    rng = np.random.default_rng(0)
    points = rng.uniform(-40, 40, (400, 3))  # 400: a whole number of 16-byte points either way
    points.astype("<f8").tofile(tmp_path / "doubles.bin")  # float64 x y z
    with pytest.raises(ValueError, match=r"lie 1e\+09 or more .* \(float64 values\?\)"):
        mmio.read_point_cloud(tmp_path / "doubles.bin")
    points.astype("<f4").tofile(tmp_path / "three.bin")  # float32 x y z, no reflectance
    with pytest.raises(ValueError, match=r"reflectance\) is negative: .*\(x y z alone"):
        mmio.read_point_cloud(tmp_path / "three.bin")
    # A few stray rows (a bad return, a negative reflectance) are the sensor's, kept.
    reflectance = rng.uniform(0, 1, 400)
    reflectance[:8] = -1.0
    write_kitti(tmp_path / "strays.bin", points, reflectance=reflectance)
    np.testing.assert_allclose(mmio.read_point_cloud(tmp_path / "strays.bin"), points, rtol=1e-6)


def test_feather_without_z_names_the_columns(tmp_path):
    pd.DataFrame({"x": [1.0], "y": [2.0], "intensity": [3]}).to_feather(tmp_path / "a.feather")
    with pytest.raises(ValueError, match=r"missing column\(s\) z .* it has x, y, intensity"):
        mmio.read_point_cloud(tmp_path / "a.feather")


def test_a_bag_is_not_one_point_cloud(tmp_path):
    (tmp_path / "run.bag").write_bytes(b"#ROSBAG V2.0\n")
    with pytest.raises(ValueError, match="open_sequence"):
        mmio.read_point_cloud(tmp_path / "run.bag")


def test_an_n_by_3_array_takes_flow_or_target(tmp_path):
    a = np.arange(12.0).reshape(4, 3)
    np.save(tmp_path / "a.npy", a)
    np.save(tmp_path / "flow.npy", np.ones((4, 3)))
    X = mmio.read_correspondences(tmp_path / "a.npy", flow=tmp_path / "flow.npy")
    np.testing.assert_array_equal(X, np.hstack([a, a + 1]))
    write_kitti(tmp_path / "b.bin", a * 2)
    X = mmio.read_correspondences(tmp_path / "a.npy", target=tmp_path / "b.bin")
    np.testing.assert_array_equal(X, np.hstack([a, a * 2]))
    np.save(tmp_path / "pairs.npy", np.zeros((4, 6)))
    with pytest.raises(ValueError, match=r"holds both a and b \(6 columns\)"):
        mmio.read_correspondences(tmp_path / "pairs.npy", flow=tmp_path / "flow.npy")
    np.save(tmp_path / "four.npy", np.zeros((4, 4)))
    with pytest.raises(ValueError, match="has 4 columns"):
        mmio.read_correspondences(tmp_path / "four.npy", flow=tmp_path / "flow.npy")


# --------------------------------------------------------------------------- PointCloud2
_CODES = {"f4": 7, "f8": 8, "u4": 6, "i2": 3}


def _cloud(points, *, height=1, big=False, kind="f4", pad=0, row_pad=0, time=None, stamp=(0, 0)):
    """A PointCloud2-like message: x y z of ``kind`` after ``pad`` bytes, a time field."""
    order = ">" if big else "<"
    n = len(points)
    width = n // height
    names, formats, offsets = ["x", "y", "z"], [order + kind] * 3, []
    size = np.dtype(kind).itemsize
    offsets = [pad, pad + size, pad + 2 * size]
    if time is not None:
        names.append(time[0])
        formats.append(order + time[1].dtype.str[1:])
        offsets.append(pad + 3 * size)
    end = offsets[-1] + np.dtype(formats[-1]).itemsize
    point_step = end + 3  # trailing bytes of other fields
    dtype = np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": point_step}
    )
    record = np.zeros(n, dtype)
    for k, name in enumerate("xyz"):
        record[name] = points[:, k]
    if time is not None:
        record[time[0]] = time[1]
    rows = record.tobytes()
    row_bytes = width * point_step
    data = b"".join(
        rows[r * row_bytes : (r + 1) * row_bytes] + b"\xab" * row_pad for r in range(height)
    )
    fields = [
        SimpleNamespace(name=name, offset=o, datatype=_CODES[f[1:]], count=1)
        for name, f, o in zip(names, formats, offsets, strict=True)
    ]
    return SimpleNamespace(
        header=SimpleNamespace(stamp=SimpleNamespace(sec=stamp[0], nanosec=stamp[1])),
        height=height,
        width=width,
        fields=fields,
        is_bigendian=big,
        point_step=point_step,
        row_step=row_bytes + row_pad,
        data=np.frombuffer(data, np.uint8),
        is_dense=False,
    )


@given(
    st.integers(1, 4),
    st.booleans(),
    st.sampled_from(["f4", "f8"]),
    st.integers(0, 5),
    st.integers(0, 7),
    st.integers(0, 2**32 - 1),
)
def test_pointcloud2_layouts_decode_to_the_points(height, big, kind, pad, row_pad, seed):
    rng = np.random.default_rng(seed)
    points = rng.uniform(-100, 100, (height * 5, 3)).astype(kind)
    points[rng.random(len(points)) < 0.2] = np.nan  # is_dense false: NaN rows kept
    msg = _cloud(points, height=height, big=big, kind=kind, pad=pad, row_pad=row_pad)
    decoded, stamp, times = decode_pointcloud2(msg)
    np.testing.assert_array_equal(decoded, points.astype(np.float64))
    assert stamp is None and times is None


def test_pointcloud2_times_are_seconds_after_the_stamp():
    points = np.zeros((3, 3))
    # Ouster: uint32 nanoseconds after the stamp.
    msg = _cloud(points, time=("t", np.array([0, 5_000_000, 99_000_000], np.uint32)), stamp=(7, 5))
    _, stamp, times = decode_pointcloud2(msg)
    assert stamp == 7 + 5e-9
    np.testing.assert_allclose(times, [0.0, 0.005, 0.099], rtol=0, atol=1e-15)
    # Hesai: absolute float64 seconds (whose spacing near 1.7e9 s is 0.24 microseconds).
    absolute = 1_700_000_000 + np.array([0.25, 0.26, 0.3])
    msg = _cloud(points, time=("timestamp", absolute), stamp=(1_700_000_000, 250_000_000))
    np.testing.assert_allclose(decode_pointcloud2(msg)[2], [0.0, 0.01, 0.05], atol=1e-6)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"fields": "drop z"}, r"without field\(s\) z; it has x, y"),
        ({"kind": "i2"}, "x, y, z must be float32 or float64"),
        ({"point_step": 8}, "fields end at byte 12 but point_step is 8"),
        ({"data": "short"}, "holds 27 bytes of data; height 1 x row_step 30"),
    ],
)
def test_malformed_pointcloud2_is_one_error(change, message):
    msg = _cloud(np.zeros((2, 3)), kind=change.get("kind", "f4"))
    if change.get("fields"):
        msg.fields = msg.fields[:2]
    if "point_step" in change:
        msg.point_step = change["point_step"]
    if change.get("data"):
        msg.data = msg.data[:-3]
    with pytest.raises(ValueError, match=message):
        decode_pointcloud2(msg, "bag [/points message 3]")


# --------------------------------------------------------------------------- the command line
def _found_motion(out):
    import json

    labels = np.load(out / "labels.npy")
    motions = json.loads((out / "motions.json").read_text())
    return labels, motions


def _check_car(out, a, labels, motions_true):
    found, motions = _found_motion(out)
    assert adjusted_rand_score(labels, found) == 1.0
    moving = [m for m in motions if m["moving"]]
    assert len(moving) == 1
    R, t = CAR_MOTION
    assert np.abs(np.array(moving[0]["rotation"]) - R).max() < PRECISION
    assert np.abs(np.array(moving[0]["translation"]) - t).max() < PRECISION
    flow = np.load(out / "X.npy")
    true = np.vstack([a[labels == k] @ Rk.T + tk for k, (Rk, tk) in enumerate(motions_true)])
    order = np.argsort(labels, kind="stable")
    assert np.abs(flow[order, 3:] - true).max() < PRECISION


@pytest.mark.parametrize("kind", ["kitti", "nuscenes", "feather", "npy"])
def test_register_finds_the_car_in_two_sweep_files(tmp_path, kind):
    a, sweep, labels, motions = lidar_scene()
    suffix = {"kitti": ".bin", "nuscenes": ".pcd.bin", "feather": ".feather", "npy": ".npy"}
    writer = {"kitti": write_kitti, "nuscenes": write_nuscenes, "feather": write_feather}
    writer = writer.get(kind, np.save)
    first, second = tmp_path / f"000000{suffix[kind]}", tmp_path / f"000001{suffix[kind]}"
    writer(first, a)
    writer(second, sweep)
    command = ["register", str(first), "--sweep", str(second), "--tau", "2", "-q"]
    assert main([*command, "--out", str(tmp_path / "out")]) == 0
    _check_car(tmp_path / "out", a, labels, motions)


def test_register_takes_an_n_by_3_npy_with_flow(tmp_path):
    a, _, labels, motions = lidar_scene()
    b = a.copy()
    for k, (R, t) in enumerate(motions):
        b[labels == k] = a[labels == k] @ R.T + t
    np.save(tmp_path / "a.npy", a)
    np.save(tmp_path / "flow.npy", b - a)
    out = tmp_path / "out"
    command = ["register", str(tmp_path / "a.npy"), "--flow", str(tmp_path / "flow.npy")]
    assert main([*command, "--out", str(out), "-q", "--save-input"]) == 0
    found, motions_found = _found_motion(out)
    assert adjusted_rand_score(labels, found) == 1.0
    moving = [m for m in motions_found if m["moving"]]
    assert len(moving) == 1
    assert np.abs(np.array(moving[0]["translation"]) - CAR_MOTION[1]).max() < 1e-9
    # view and evaluate read the (n, 3) INPUT and its flow again.
    np.save(tmp_path / "truth.npy", labels)
    assert main(["evaluate", str(out), str(tmp_path / "truth.npy")]) == 0


@pytest.mark.parametrize(
    ("files", "extra", "message"),
    [
        ({"a.bin": b"\0" * 36}, ["--sweep", "a.bin"], "36 bytes is not a whole number"),
        ({"a.bin": b"\0" * 64, "s.bin": b"\0" * 60}, ["--sweep", "s.bin"], "s.bin: 60 bytes"),
        ({"a.feather": "no z"}, ["--sweep", "a.feather"], r"missing column\(s\) z"),
        ({"a.npy": (5, 6), "f.npy": (5, 3)}, ["--flow", "f.npy"], r"holds both a and b"),
        ({"a.npy": (5, 4), "f.npy": (5, 3)}, ["--flow", "f.npy"], "has 4 columns"),
        ({"a.npy": (5, 3), "f.npy": (4, 3)}, ["--flow", "f.npy"], "holds 4 points but"),
        ({"a.npy": (5, 3)}, [], "holds only the a-points; .* --sweep S"),
        ({"a.bin": b"\0" * 64}, ["--frame", "2"], "--frame applies only to a ROS bag"),
        ({"a.bin": b"\0" * 64}, ["--topic", "/x"], "--topic applies only to a ROS bag"),
        (
            {"a.bin": b"\0" * 64, "s.bin": b"\0" * 64},
            ["--sweep", "s.bin", "--interval", "0.1"],  # --interval alone bounds the motions
            "a.bin: 0 of its 4 rows hold a return",
        ),
    ],
)
def test_register_refuses_malformed_point_files(tmp_path, capsys, files, extra, message):
    for name, content in files.items():
        if isinstance(content, bytes):
            (tmp_path / name).write_bytes(content)
        elif isinstance(content, tuple):
            np.save(tmp_path / name, np.zeros(content))
        else:
            pd.DataFrame({"x": [1.0], "y": [2.0]}).to_feather(tmp_path / name)
    first = next(iter(files))
    extra = [str(tmp_path / e) if (tmp_path / e).exists() else e for e in extra]
    argv = ["register", str(tmp_path / first), *extra, "--out", str(tmp_path / "out"), "-q"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and err.startswith("mmreg: error: "), err
    assert re.search(message, err), err
    assert not (tmp_path / "out").exists()
