"""``mmreg register --ego-motion``: a known motion of the static world, read from a file."""

import json

import numpy as np
import pytest

from mmreg import io as mmio
from mmreg.cli import main
from mmreg.datasets import make_lidar_sweeps


@pytest.fixture(scope="module")
def keyframes(tmp_path_factory):
    """Two sweeps 0.5 s apart (the sensor drove 5 m) and odometry 37 cm off."""
    folder = tmp_path_factory.mktemp("keyframes")
    scene = make_lidar_sweeps(n_moving=1, interval=0.5, n_azimuths=512, random_state=1)
    mmio.write_point_cloud(folder / "s0.ply", scene.a)
    mmio.write_point_cloud(folder / "s1.ply", scene.sweep)
    odometry = scene.transforms[0].copy()
    odometry[:3, 3] += [0.3, -0.2, 0.05]
    np.savetxt(folder / "odometry.txt", odometry)
    return folder, scene


def _static_motion(out):
    motions = json.loads((out / "motions.json").read_text())
    static = [m for m in motions if not m["moving"]]
    assert len(static) == 1
    return np.asarray(static[0]["transform"])


def test_raw_sweeps_start_from_the_odometry(keyframes, tmp_path, capsys):
    folder, scene = keyframes
    out = tmp_path / "out"
    args = [folder / "s0.ply", "--sweep", folder / "s1.ply", "--out", out, "-q"]
    code = main(["register", *map(str, args), "--ego-motion", str(folder / "odometry.txt")])
    assert code == 0, capsys.readouterr().err
    truth = scene.transforms[0]
    found = _static_motion(out)
    assert np.linalg.norm(found[:3, 3] - truth[:3, 3]) < 0.02  # the 37 cm are corrected


@pytest.mark.parametrize(
    "matrix, message",
    [
        (np.eye(3), "4x4 homogeneous matrix"),
        (np.diag([2.0, 2.0, 2.0, 1.0]), "not a rotation"),
        (np.vstack([np.eye(4)[:3], [0.0, 0.0, 1.0, 1.0]]), "last row"),
    ],
)
def test_a_file_that_is_not_a_motion_is_one_line(keyframes, tmp_path, capsys, matrix, message):
    folder, _ = keyframes
    np.save(tmp_path / "T.npy", matrix)
    args = [folder / "s0.ply", "--sweep", folder / "s1.ply", "--ego-motion", tmp_path / "T.npy"]
    assert main(["register", *map(str, args), "--out", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert message in err and "T.npy" in err and len(err.strip().splitlines()) == 1


def test_a_flow_refined_on_a_sweep_takes_no_ego_motion(keyframes, tmp_path, capsys):
    folder, scene = keyframes
    np.save(tmp_path / "flow.npy", scene.flow)
    args = [folder / "s0.ply", "--flow", tmp_path / "flow.npy", "--sweep", folder / "s1.ply"]
    args += ["--ego-motion", folder / "odometry.txt", "--out", tmp_path / "out", "-q"]
    assert main(["register", *map(str, args)]) == 2
    assert "--ego-motion goes with two raw sweeps" in capsys.readouterr().err
