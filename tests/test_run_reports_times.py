"""The seconds between frames: KITTI's times.txt, a .pcd's absolute time field, and
--frame-rate where the frames have none, for 'mmreg run' on logs and on pairs and for
'mmreg register'; with them, speeds in m/s."""

import contextlib
import io
import json

import numpy as np
import pandas as pd
import pytest

from mmreg.cli import main
from mmreg.datasets import make_lidar_sequence, open_sequence
from mmreg.runner import dataset_jobs

pytest.importorskip("distributed")

START = 1_700_000_000.0  # seconds since 1970: an absolute stamp


@pytest.fixture(scope="module")
def street():
    return make_lidar_sequence(3, n_azimuths=256, random_state=0)


def write_pcd(path, points, field=None, values=None, type_="F", size=8):
    """A binary PCD of float32 x, y, z and, with ``field``, one time column."""
    names, sizes, types = ["x", "y", "z"], ["4"] * 3, ["F"] * 3
    columns = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if field is not None:
        names.append(field)
        sizes.append(str(size))
        types.append(type_)
        columns.append((field, f"<{type_.lower()}{size}"))
    record = np.empty(len(points), dtype=columns)
    for k, name in enumerate("xyz"):
        record[name] = points[:, k]
    if field is not None:
        record[field] = values
    header = [
        "VERSION 0.7",
        f"FIELDS {' '.join(names)}",
        f"SIZE {' '.join(sizes)}",
        f"TYPE {' '.join(types)}",
        f"COUNT {' '.join(['1'] * len(names))}",
        f"WIDTH {len(points)}",
        "HEIGHT 1",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {len(points)}",
        "DATA binary",
    ]
    path.write_bytes(("\n".join(header) + "\n").encode("ascii") + record.tobytes())


def _stamped_pcds(folder, street, rate=10.0):
    """The frames as .pcd files whose points carry absolute times (float64 seconds): the
    sweep's first point at START + k / rate, the others up to a period later."""
    folder.mkdir()
    for k, frame in enumerate(street.frames):
        offsets = np.linspace(0.0, 0.09, len(frame))
        write_pcd(folder / f"scan{k}.pcd", frame, "timestamp", START + k / rate + offsets)
    return folder


def _run(*command):
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main([*map(str, command)])
    return code, out.getvalue()


def test_pairs_take_the_frame_rate_where_the_frames_have_no_times(tmp_path, street):
    folder = tmp_path / "frames"
    folder.mkdir()
    for k, frame in enumerate(street.frames):
        np.save(folder / f"scan{k}.npy", frame)
    assert all("interval" not in job.load() for job in dataset_jobs(folder))
    assert all(job.load()["interval"] == 0.5 for job in dataset_jobs(folder, frame_rate=2))
    out = tmp_path / "out"
    code, printed = _run("run", folder, "--pairs", "--frame-rate", 2, "--out", out)
    assert code == 0
    summary = pd.read_csv(out / "summary.csv")
    assert summary["interval"].tolist() == [0.5, 0.5]
    assert summary["speed_unit"].tolist() == ["m/s", "m/s"]
    assert "fastest [m/s]" in printed
    # Without a rate: metres per frame, said so.
    code, printed = _run("run", folder, "--pairs", "--out", tmp_path / "per-frame")
    assert code == 0 and "fastest [m/frame]" in printed


def test_kitti_times_win_over_the_frame_rate(tmp_path, street):
    folder = tmp_path / "08"
    (folder / "velodyne").mkdir(parents=True)
    for k, frame in enumerate(street.frames):
        scan = np.hstack([frame, np.ones((len(frame), 1))]).astype(np.float32)
        scan.tofile(folder / "velodyne" / f"{k:06d}.bin")
    (folder / "times.txt").write_text("0.0\n0.1\n0.2\n")
    jobs = dataset_jobs(folder, frame_rate=2)
    assert [job.load()["interval"] for job in jobs] == pytest.approx([0.1, 0.1])
    assert all(job.frame_rate == 2 for job in jobs)


def test_a_pcd_time_field_stamps_its_frames(tmp_path, street):
    folder = _stamped_pcds(tmp_path / "pcd", street)
    sequence = open_sequence(folder)
    stamps = [sequence[k].timestamp for k in range(3)]
    assert stamps == pytest.approx([START, START + 0.1, START + 0.2], abs=1e-6)
    # Pairs: the interval from the stamps.
    jobs = dataset_jobs(folder)
    assert [job.load()["interval"] for job in jobs] == pytest.approx([0.1, 0.1], abs=1e-6)
    # The log: speeds in m/s and the frames' times.
    out = tmp_path / "log"
    assert _run("run", folder, "--out", out, "-q")[0] == 0
    tracks = pd.read_csv(out / "tracks.csv")
    assert "speed_m_s" in tracks.columns and "speed_m_frame" not in tracks.columns
    frames = pd.read_csv(out / "frames.csv")
    assert frames["time_s"].diff().iloc[1:].to_numpy() == pytest.approx([0.1, 0.1], abs=1e-6)


def test_relative_or_coarse_pcd_times_are_no_stamps(tmp_path, street):
    frame = street.frames[0]
    cases = {
        "relative.pcd": ("time", np.linspace(0, 0.1, len(frame)), "F", 4),  # after a stamp
        "coarse.pcd": ("timestamp", np.full(len(frame), START), "F", 4),  # float32 absolute
        "nanoseconds.pcd": ("t", np.arange(len(frame)) * 1000, "U", 4),  # relative ns
    }
    for name, (field, values, type_, size) in cases.items():
        write_pcd(tmp_path / name, frame, field, values, type_, size)
        from mmreg.io._correspondences import _read_point_file

        points, _, _, stamp = _read_point_file(tmp_path / name, "points", stamp=True)
        assert stamp is None and len(points) == len(frame)
    write_pcd(
        tmp_path / "absolute_ns.pcd",
        frame,
        "t",
        np.full(len(frame), 1_700_000_000_5 * 10**8, dtype=np.uint64),
        "U",
        8,
    )
    from mmreg.io._correspondences import _read_point_file

    assert _read_point_file(tmp_path / "absolute_ns.pcd", "p", stamp=True)[3] == pytest.approx(
        1_700_000_000.5
    )


def test_register_takes_the_frame_rate_and_a_pcd_pairs_stamps(tmp_path, street):
    folder = tmp_path / "frames"
    folder.mkdir()
    for k, frame in enumerate(street.frames):
        np.save(folder / f"scan{k}.npy", frame)
    out = tmp_path / "r"
    code, printed = _run("register", folder, "--frame", 0, "--frame-rate", 10, "--out", out)
    assert code == 0
    assert json.loads((out / "run.json").read_text())["interval"] == pytest.approx(0.1)
    assert "speed [m/s]" in printed
    summary = pd.read_csv(out / "summary.csv")
    moving = summary[summary["moving"].astype(bool) & ~summary["background"].astype(bool)]
    assert len(moving) and np.isfinite(moving["speed"]).all()
    code, _ = _run(
        "register", folder, "--frame-rate", 10, "--interval", 0.1, "--out", tmp_path / "x"
    )
    assert code == 2
    # Two .pcd sweeps with absolute times: the interval between their stamps.
    pcds = _stamped_pcds(tmp_path / "pcd", street)
    out = tmp_path / "pcd-result"
    command = ["register", pcds / "scan0.pcd", "--sweep", pcds / "scan1.pcd", "--out", out]
    assert _run(*command)[0] == 0
    assert json.loads((out / "run.json").read_text())["interval"] == pytest.approx(0.1, abs=1e-6)
