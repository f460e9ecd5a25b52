"""What 'mmreg register' reports: --tau's default, residuals of sweeps, time, -v counts."""

import json
import re

import numpy as np
import pandas as pd
import pytest
from scipy.spatial import cKDTree

from mmreg import io as mmio
from mmreg.cli import main
from mmreg.datasets import make_flying_things, make_scene


def _box_surface(rng, n, low, high):
    low, high = np.asarray(low, float), np.asarray(high, float)
    points = rng.uniform(low, high, (n, 3))
    face = rng.integers(0, 3, n)
    points[np.arange(n), face] = np.where(rng.integers(0, 2, n), high[face], low[face])
    return points


@pytest.fixture
def sweeps(tmp_path):
    """Two raw sweeps (sampled anew) of a still box and a box moving 1 m along x."""
    rng = np.random.default_rng(3)
    first = np.vstack(
        [
            _box_surface(rng, 300, [0, 0, 0], [4, 4, 3]),
            _box_surface(rng, 150, [8, 0, 0], [10, 1, 1]),
        ]
    )
    second = np.vstack(
        [
            _box_surface(rng, 280, [0, 0, 0], [4, 4, 3]),
            _box_surface(rng, 160, [9, 0, 0], [11, 1, 1]),
        ]
    )
    mmio.write_point_cloud(tmp_path / "s0.ply", first)
    mmio.write_point_cloud(tmp_path / "s1.ply", second)
    return tmp_path, first, second


def _register(capsys, *args):
    capsys.readouterr()
    code = main(["register", *map(str, args)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return captured.out


def test_tau_default_is_five_for_sweeps_and_one_and_a_half_for_correspondences(
    sweeps, tmp_path, capsys
):
    folder, _, _ = sweeps
    _register(
        capsys, folder / "s0.ply", "--sweep", folder / "s1.ply", "--out", tmp_path / "a", "-q"
    )
    run = json.loads((tmp_path / "a" / "run.json").read_text())
    assert run["estimator"]["tau"] == 5.0
    scene = make_scene(n_objects=2, n_points=200, random_state=0)
    np.save(tmp_path / "pairs.npy", scene.X)
    _register(capsys, tmp_path / "pairs.npy", "--out", tmp_path / "b", "-q")
    assert json.loads((tmp_path / "b" / "run.json").read_text())["estimator"]["tau"] == 1.5
    _register(capsys, tmp_path / "pairs.npy", "--out", tmp_path / "c", "-q", "--tau", "2")
    assert json.loads((tmp_path / "c" / "run.json").read_text())["estimator"]["tau"] == 2.0
    # A LiDAR file is a sweep in metres, with or without --sweep (here with a flow).
    _, first, _ = sweeps
    kitti = np.c_[first, np.zeros(len(first))].astype(np.float32)  # x y z reflectance
    kitti.tofile(tmp_path / "000000.bin")
    np.save(tmp_path / "flow.npy", np.tile([0.5, 0.0, 0.0], (len(first), 1)))
    flow = ["--flow", tmp_path / "flow.npy"]
    _register(capsys, tmp_path / "000000.bin", *flow, "--out", tmp_path / "d", "-q")
    assert json.loads((tmp_path / "d" / "run.json").read_text())["estimator"]["tau"] == 5.0
    # A .ply is a sweep when its geometry says so (a z-up disc around the sensor); a camera
    # scene's .ply with its flow stays correspondences.
    _register(capsys, folder / "s0.ply", *flow, "--out", tmp_path / "e", "-q")
    assert json.loads((tmp_path / "e" / "run.json").read_text())["estimator"]["tau"] == 5.0
    camera = make_flying_things(n_objects=2, random_state=0)
    mmio.write_point_cloud(tmp_path / "camera.ply", camera.X[:, :3])
    np.save(tmp_path / "camera_flow.npy", camera.X[:, 3:] - camera.X[:, :3])
    camera_flow = ["--flow", tmp_path / "camera_flow.npy"]
    _register(capsys, tmp_path / "camera.ply", *camera_flow, "--out", tmp_path / "f", "-q")
    assert json.loads((tmp_path / "f" / "run.json").read_text())["estimator"]["tau"] == 1.5
    for command in ("register", "run"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        assert "'auto': 5 for LiDAR sweeps" in text and "else 1.5" in text


def test_sweep_residuals_are_distances_to_the_second_sweep(sweeps, tmp_path, capsys):
    folder, first, second = sweeps
    out = _register(
        capsys, folder / "s0.ply", "--sweep", folder / "s1.ply", "--out", tmp_path / "r"
    )
    summary = pd.read_csv(tmp_path / "r" / "summary.csv")
    labels = np.load(tmp_path / "r" / "labels.npy")
    moved = np.load(tmp_path / "r" / "X.npy")[:, 3:]
    distance = cKDTree(second).query(moved)[0]
    for _, row in summary.iterrows():
        mine = distance[labels == row["label"]]
        assert row["rms_residual"] == pytest.approx(np.sqrt(np.mean(mine**2)), rel=1e-5)
        # A sampled surface: millimetres to centimetres, not the floor (1e-6 of the spread).
        assert row["residual_scale"] > 1e-3
    # The printed time is the whole command's, the fit's beside it.
    line = next(line for line in out.splitlines() if line.startswith(f"{len(first)} points"))
    total, fit = map(float, re.search(r"([\d.]+) s \(the fit ([\d.]+) s\)", line).groups())
    assert total >= fit > 0


def test_verbose_counts_the_results_clusters(tmp_path, capsys):
    scene = make_scene(n_objects=3, n_points=600, random_state=0)
    np.save(tmp_path / "pairs.npy", scene.X)
    out = _register(capsys, tmp_path / "pairs.npy", "--out", tmp_path / "v", "-v")
    n_clusters = len(json.loads((tmp_path / "v" / "motions.json").read_text()))
    assert f"result: clusters {n_clusters}" in out.splitlines()
    iterations = [line for line in out.splitlines() if line.startswith("iteration ")]
    pieces = [int(re.search(r"pieces (\d+)", line).group(1)) for line in iterations]
    clusters = [int(re.search(r"clusters (\d+)", line).group(1)) for line in iterations]
    assert all(c <= p for c, p in zip(clusters, pieces, strict=True))
    assert f": {n_clusters} clusters," in out
