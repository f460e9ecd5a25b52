"""The ego vehicle's own body in the outputs: never dynamic, never valid, no outlier.

A generated street (z up, the sensor 1.8 m above the road, driving 1 m between the
sweeps) with a ring of points fixed in the sensor's frame within 2.5 m of it, in both
sweeps: the car's own body, as a roof-mounted LiDAR sees it. It is counted apart from
the outliers in ``mmreg run``'s summary and ``mmreg register``'s run.json, table and
picture, it is never ``is_dynamic`` in the challenge's format and ``sweep_valid`` (the
annotations' ``is_valid``) is False on it.
"""

import json

import numpy as np
import pandas as pd
import pytest

from mmreg.cli import main
from mmreg.datasets import make_lidar_sweeps
from mmreg.plotting import plot_sweep
from mmreg.runner import _process, dataset_jobs, default_sweep_estimator, write_scene_flow

pytest.importorskip("small_gicp")  # the body is told apart by GICP's ego motion

N_BODY = 240


def body_ring(n=N_BODY):
    """The car's roof and bonnet edge seen from a roof-mounted sensor: a wavy ring
    1.0-2.3 m from the sensor, 0.1-0.5 m below it, fixed in the sensor's frame."""
    angle = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    radius = 1.3 + 0.3 * np.cos(2.0 * angle)
    return np.c_[
        1.4 * radius * np.cos(angle),
        0.8 * radius * np.sin(angle),
        -0.3 + 0.2 * np.sin(3.0 * angle),
    ]


def street_with_body(random_state=0):
    """``(a, sweep, body_rows)``: the sweeps of a street with the body ring last in both."""
    scene = make_lidar_sweeps(n_moving=1, n_parked=1, n_azimuths=256, random_state=random_state)
    ring = body_ring()
    assert np.linalg.norm(ring, axis=1).max() < 2.5
    rng = np.random.default_rng(random_state)
    a = np.vstack([scene.a, ring])
    sweep = np.vstack([scene.sweep, ring + rng.normal(0.0, 0.003, ring.shape)])
    return a, sweep, np.arange(len(scene.a), len(a))


def write_kitti_bin(path, points):
    path.parent.mkdir(parents=True, exist_ok=True)
    np.c_[points, np.ones(len(points))].astype("<f4").tofile(path)


@pytest.fixture(scope="module")
def sweeps():
    return street_with_body()


def test_run_counts_the_body_apart_and_never_calls_it_dynamic(tmp_path, sweeps):
    a, sweep, body = sweeps
    for k, points in enumerate((a, sweep)):
        write_kitti_bin(tmp_path / "seq" / "velodyne" / f"{k:06d}.bin", points)
    (job,) = dataset_jobs(tmp_path / "seq")
    name, arrays, row = _process(job, default_sweep_estimator())
    assert row["status"] == "done", row.get("error")
    flagged = np.flatnonzero(arrays["ego_body"])
    rows = arrays["indices"][flagged]
    assert set(rows) <= set(body) and len(rows) > 0.9 * len(body)
    assert row["n_ego_body"] == len(rows)
    assert row["n_outliers"] == int(np.sum(arrays["labels"] < 0)) - len(rows)
    # The body keeps its zero flow (it stays where it was in the sensor's frame) but is
    # neither dynamic nor valid.
    np.testing.assert_array_equal(arrays["sweep_flow"][rows], 0.0)
    assert not arrays["sweep_dynamic"][rows].any()
    assert not arrays["sweep_valid"][rows].any()
    assert arrays["sweep_valid"].sum() == len(a) - len(rows)
    # And so in the challenge's file: four columns, is_dynamic False on the body.
    path = tmp_path / "av2" / "log" / "1.feather"
    write_scene_flow(path, arrays["sweep_flow"], arrays["sweep_dynamic"])
    table = pd.read_feather(path)
    assert list(table.columns) == ["flow_tx_m", "flow_ty_m", "flow_tz_m", "is_dynamic"]
    assert not table["is_dynamic"].to_numpy()[rows].any()


def test_register_counts_draws_and_keeps_the_body_apart(tmp_path, sweeps, capsys):
    a, sweep, body = sweeps
    write_kitti_bin(tmp_path / "0.bin", a)
    write_kitti_bin(tmp_path / "1.bin", sweep)
    out = tmp_path / "r"
    assert main(["register", str(tmp_path / "0.bin"), "--sweep", str(tmp_path / "1.bin"),
                 "--out", str(out)]) == 0  # fmt: skip
    printed = capsys.readouterr().out
    run = json.loads((out / "run.json").read_text())
    labels = np.load(out / "labels.npy")
    flagged = np.load(out / "ego_body.npy")
    assert flagged.dtype == bool and flagged.shape == labels.shape
    assert set(np.flatnonzero(flagged)) <= set(body) and flagged.sum() > 0.9 * len(body)
    assert (labels[flagged] == -1).all()
    assert run["n_ego_body"] == flagged.sum()
    assert run["n_outliers"] == int(np.sum((labels < 0) & ~flagged))
    assert f"{run['n_outliers']:,} outlier" in printed
    assert f"{int(flagged.sum()):,} on the ego vehicle's body" in printed
    # 'mmreg view' draws it apart again; 'mmreg evaluate' counts it apart.
    assert main(["view", str(out), "--out", str(tmp_path / "again.png")]) == 0
    np.save(tmp_path / "truth.npy", np.maximum(labels, 0))
    capsys.readouterr()
    assert main(["evaluate", str(out), str(tmp_path / "truth.npy"), "--json"]) == 0
    scores = json.loads(capsys.readouterr().out)
    assert scores["ego_body"] == flagged.sum()
    assert scores["outliers_predicted"] == run["n_outliers"]


def test_the_picture_draws_the_body_apart_from_the_outliers(sweeps):
    a, _, body = sweeps
    labels = np.zeros(len(a), dtype=int)
    labels[body] = -1
    labels[:7] = -1  # seven outliers far from the sensor
    mask = np.zeros(len(a), dtype=bool)
    mask[body] = True
    fig = plot_sweep(a, labels, ego_body=mask)
    texts = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert f"the ego vehicle's body ({len(body):,} pts)" in texts
    assert "outliers (7 pts)" in texts
    with pytest.raises(ValueError, match="one bool per point"):
        plot_sweep(a, labels, ego_body=mask[:-1])
