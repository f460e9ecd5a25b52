"""Rows with no return (NaN, or all zeros) are dropped everywhere, counted, and every
output stays viewable.

A bag with ``is_dense`` false, an organised ``.pcd`` and a KITTI scan all carry such
rows. ``mmreg register`` leaves them out of both sweeps and says how many; its X.npy,
labels and picture hold the other rows (``indices.npy`` names them), which its own
``view`` and ``evaluate`` read; ``mmreg run`` does the same per job, and ``view`` finds
a job's rows again in its dataset.
"""

import json

import numpy as np
import pandas as pd
import pytest
from test_run_outputs_body import street_with_body, write_kitti_bin

from mmreg.cli import main
from mmreg.io import read_point_cloud


@pytest.fixture(scope="module")
def sweeps():
    a, sweep, _ = street_with_body(random_state=1)
    return a, sweep


def _holes(points, every, value, offset=0):
    """``points`` with every ``every``-th row (from ``offset``) set to ``value``."""
    points = points.copy()
    points[offset::every] = value
    return points, np.arange(offset, len(points), every)


def _organised_pcd(path, points, width):
    """A binary PCD of HEIGHT rows of WIDTH points (an organised cloud), NaN kept."""
    height = len(points) // width
    points = points[: height * width].astype("<f4")
    header = (
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
        f"WIDTH {width}\nHEIGHT {height}\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {height * width}\n"
        "DATA binary\n"
    )
    path.write_bytes(header.encode("ascii") + points.tobytes())
    return points.astype(float)


def _check_result(out, n_kept, n_dropped, n_sweep_dropped, capsys):
    run = json.loads((out / "run.json").read_text())
    assert run["n_no_return"] == n_dropped and run["n_sweep_no_return"] == n_sweep_dropped
    X = np.load(out / "X.npy")
    labels = np.load(out / "labels.npy")
    assert X.shape == (n_kept, 6) and np.isfinite(X).all() and len(labels) == n_kept
    # Every output of the result opens with its own commands.
    assert main(["view", str(out), "--out", str(out.parent / f"{out.name}.png")]) == 0
    truth = out.parent / f"{out.name}-truth.npy"
    np.save(truth, np.maximum(labels, 0))
    assert main(["evaluate", str(out), str(truth)]) == 0
    return run, labels


@pytest.mark.parametrize("value", [np.nan, 0.0], ids=["nan", "zero"])
def test_register_drops_rows_without_a_return_from_kitti_scans(tmp_path, sweeps, capsys, value):
    a, sweep = sweeps
    holed, rows = _holes(a, 37, value)
    holed_sweep, sweep_rows = _holes(sweep, 41, value, offset=3)
    write_kitti_bin(tmp_path / "0.bin", holed)
    write_kitti_bin(tmp_path / "1.bin", holed_sweep)
    out = tmp_path / "r"
    command = ["register", str(tmp_path / "0.bin"), "--sweep", str(tmp_path / "1.bin")]
    assert main([*command, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"{len(rows)} + {len(sweep_rows)} rows without a return left out" in printed
    _check_result(out, len(a) - len(rows), len(rows), len(sweep_rows), capsys)
    kept = np.load(out / "indices.npy")
    np.testing.assert_array_equal(kept, np.setdiff1d(np.arange(len(a)), rows))
    np.testing.assert_allclose(np.load(out / "X.npy")[:, :3], a[kept].astype("<f4"))


def test_an_organised_pcd_keeps_its_nan_rows_and_registers(tmp_path, sweeps, capsys):
    a, sweep = sweeps
    holed, _ = _holes(a, 29, np.nan)
    first = _organised_pcd(tmp_path / "0.pcd", holed, width=64)
    second = _organised_pcd(tmp_path / "1.pcd", sweep, width=64)
    read = read_point_cloud(tmp_path / "0.pcd")
    assert read.shape == first.shape
    np.testing.assert_array_equal(np.isnan(read), np.isnan(first))
    bad = tmp_path / "inf.pcd"
    _organised_pcd(bad, np.where(np.isnan(holed), np.inf, holed), width=64)
    with pytest.raises(ValueError, match="inf.pcd: .* NaN or infinity"):
        read_point_cloud(bad)  # infinity is no missing return
    out = tmp_path / "r"
    command = ["register", str(tmp_path / "0.pcd"), "--sweep", str(tmp_path / "1.pcd")]
    assert main([*command, "--out", str(out)]) == 0
    n_nan = int(np.isnan(first).any(axis=1).sum())
    _check_result(out, len(first) - n_nan, n_nan, 0, capsys)
    assert len(second) == len(sweep) // 64 * 64


def test_register_on_a_bag_with_nan_rows(tmp_path, sweeps, capsys):
    pytest.importorskip("rosbags")
    from test_sequences import write_bag

    a, sweep = sweeps
    holed, rows = _holes(a, 31, np.nan)
    holed_sweep, sweep_rows = _holes(sweep, 23, np.nan, offset=5)
    bag = write_bag(tmp_path / "drive", [holed, holed_sweep])
    out = tmp_path / "r"
    assert main(["register", str(bag), "--frame", "0", "--out", str(out)]) == 0
    _check_result(out, len(a) - len(rows), len(rows), len(sweep_rows), capsys)


def test_view_finds_a_run_jobs_rows_when_no_returns_were_dropped(tmp_path, sweeps, scheduler):
    a, sweep = sweeps
    holed, rows = _holes(a, 19, np.nan)
    holed_sweep, _ = _holes(sweep, 17, 0.0)
    for k, points in enumerate((holed, holed_sweep)):
        write_kitti_bin(tmp_path / "seq" / "velodyne" / f"{k:06d}.bin", points)
    out = tmp_path / "run"
    command = ["run", str(tmp_path / "seq"), "--pairs", "--out", str(out), "--scheduler"]
    assert main([*command, scheduler, "-q"]) == 0
    job = out / "jobs" / "000000.npz"
    arrays = np.load(job)
    np.testing.assert_array_equal(arrays["indices"], np.setdiff1d(np.arange(len(a)), rows))
    assert not arrays["sweep_valid"][rows].any()
    assert pd.read_csv(out / "summary.csv")["n_no_return"].tolist() == [len(rows)]
    assert main(["view", str(job), "--out", str(tmp_path / "job.png")]) == 0
