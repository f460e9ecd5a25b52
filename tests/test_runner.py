"""The dataset runner (mmreg.runner, ``mmreg run``) on a LocalCluster started here."""

import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mmreg import MultiModelRegistration
from mmreg.cli import main
from mmreg.datasets import load_argoverse2, write_argoverse2_log
from mmreg.runner import dataset_jobs, default_estimator, read_job_result, run_dataset

distributed = pytest.importorskip("distributed")

ARRAYS = ("labels", "rotations", "translations", "sigmas", "flow")


@pytest.fixture(scope="module")
def scheduler():
    # One in-process worker: the jobs run one after the other, as in a plain loop.
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0"
    ) as cluster:
        yield cluster.scheduler_address


def _estimator():
    return MultiModelRegistration(tau=1.0, random_state=0)


def _write_frames(folder, n_frames=4):
    """A static block and a box moving 0.5 m along x per frame, index-aligned frames."""
    rng = np.random.default_rng(0)
    block = rng.uniform([0, 0, 0], [2, 2, 2], (150, 3))
    box = rng.uniform([6, 0, 0], [7, 1, 1], (80, 3))
    folder.mkdir(parents=True, exist_ok=True)
    for k in range(n_frames):
        np.save(folder / f"frame{k}.npy", np.vstack([block, box + [0.5 * k, 0, 0]]))
    return folder


def _plain_loop(jobs, estimator):
    """What run_dataset must give: load and fit each job in turn."""
    from sklearn.base import clone

    out = {}
    for job in jobs:
        est = clone(estimator).fit(job.load()["X"])
        out[job.name] = {
            "labels": est.labels_,
            "rotations": est.rotations_,
            "translations": est.translations_,
            "sigmas": est.sigmas_,
            "flow": est.flow_,
        }
    return out


def _mtimes(out):
    return {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in (out / "jobs").glob("*.npz")}


def test_frames_match_a_plain_loop(tmp_path, scheduler):
    data = _write_frames(tmp_path / "frames")
    jobs = dataset_jobs(data)
    assert [job.name for job in jobs] == ["frame0__frame1", "frame1__frame2", "frame2__frame3"]
    summary = run_dataset(data, _estimator(), tmp_path / "out", scheduler=scheduler, progress=False)
    expected = _plain_loop(jobs, _estimator())
    assert summary["job"].tolist() == [job.name for job in jobs]
    assert (summary["status"] == "done").all() and not summary["resumed"].any()
    for job in jobs:
        arrays, row = read_job_result(tmp_path / "out" / "jobs" / f"{job.name}.npz")
        for key in ARRAYS:
            np.testing.assert_array_equal(arrays[key], expected[job.name][key])
        assert row["n"] == 230 and row["n_clusters"] == 2
    # The table on disk is the one returned, one row per job.
    for read in (pd.read_parquet, pd.read_csv):
        table = read(tmp_path / "out" / f"summary.{read.__name__.split('_')[1]}")
        assert table["job"].tolist() == summary["job"].tolist()


def test_failed_job_is_retried_and_only_missing_jobs_run(tmp_path, scheduler):
    data = _write_frames(tmp_path / "frames")
    good = np.load(data / "frame3.npy")
    bad = good.copy()
    bad[5, 0] = np.nan
    np.save(data / "frame3.npy", bad)  # the last job cannot load
    out = tmp_path / "out"
    first = run_dataset(data, _estimator(), out, scheduler=scheduler, progress=False)
    assert first["status"].tolist() == ["done", "done", "error"]
    assert "NaN" in first["error"].iloc[2] and first["error"].iloc[0] == ""
    assert sorted(p.name for p in (out / "jobs").iterdir()) == [
        "frame0__frame1.npz",
        "frame1__frame2.npz",
    ]
    before = _mtimes(out)
    np.save(data / "frame3.npy", good)
    second = run_dataset(data, _estimator(), out, scheduler=scheduler, progress=False)
    assert (second["status"] == "done").all()
    assert second["resumed"].tolist() == [True, True, False]
    after = _mtimes(out)
    assert {k: after[k] for k in before} == before  # the done jobs were not rewritten
    expected = _plain_loop(dataset_jobs(data)[2:], _estimator())["frame2__frame3"]
    arrays, _ = read_job_result(out / "jobs" / "frame2__frame3.npz")
    np.testing.assert_array_equal(arrays["labels"], expected["labels"])


def test_half_written_result_is_not_taken_as_done(tmp_path, scheduler):
    data = _write_frames(tmp_path / "frames")
    out = tmp_path / "out"
    run_dataset(data, _estimator(), out, scheduler=scheduler, progress=False)
    path = out / "jobs" / "frame1__frame2.npz"
    whole = path.read_bytes()
    arrays, _ = read_job_result(path)
    path.write_bytes(whole[: len(whole) // 2])
    assert read_job_result(path) is None
    # A temporary file left by an interrupted write is not a result either.
    (out / "jobs" / ".frame2__frame3.npz.x1y2.tmp").write_bytes(whole[:100])
    again = run_dataset(data, _estimator(), out, scheduler=scheduler, progress=False)
    assert again["resumed"].tolist() == [True, False, True]
    redone, _ = read_job_result(path)
    for key in ARRAYS:  # the same job gives the same result
        np.testing.assert_array_equal(redone[key], arrays[key])


def test_other_estimator_runs_every_job_again(tmp_path, scheduler):
    data = _write_frames(tmp_path / "frames", n_frames=3)
    out = tmp_path / "out"
    run_dataset(data, _estimator(), out, scheduler=scheduler, progress=False)
    other = MultiModelRegistration(tau=1.0, variant="paper", random_state=0)
    again = run_dataset(data, other, out, scheduler=scheduler, progress=False)
    assert not again["resumed"].any()
    expected = _plain_loop(dataset_jobs(data), other)
    arrays, _ = read_job_result(out / "jobs" / "frame0__frame1.npz")
    np.testing.assert_array_equal(arrays["labels"], expected["frame0__frame1"]["labels"])


def _pose(x, y=0.0, z=0.0):
    T = np.eye(4)
    T[:3, 3] = x, y, z
    return T


def _write_log(folder):
    """Three sweeps: a wall, a road (ground) and a car driving 1.5 m per sweep."""
    rng = np.random.default_rng(1)
    road = np.c_[rng.uniform(-20, 20, (300, 2)), np.zeros(300)]
    wall = np.c_[rng.uniform(-10, 10, 200), np.full(200, -6.0), rng.uniform(1, 4, 200)]
    car = rng.uniform([-2, -0.8, 0.5], [2, 0.8, 1.5], (120, 3)) + [8, 3, 0]
    stamps = [315966265259836000 + k * 100_000_000 for k in range(3)]
    points = np.vstack([road, wall, car])
    cuboids = [
        dict(
            timestamp_ns=t,
            track_uuid="car-1",
            category="REGULAR_VEHICLE",
            size=(4.4, 1.8, 1.5),
            pose=_pose(8.0 + 0.5 * k, 3, 1.0),
        )
        for k, t in enumerate(stamps)
    ]
    ego = {t: _pose(1.0 * k) for k, t in enumerate(stamps)}
    return write_argoverse2_log(folder, {t: points for t in stamps}, ego, cuboids)


def test_argoverse2_log_scored_against_the_truth(tmp_path, scheduler):
    log = _write_log(tmp_path / "log")
    jobs = dataset_jobs(log)
    assert len(jobs) == 2 and all(job.drop_ground for job in jobs)
    summary = run_dataset(log, None, tmp_path / "out", scheduler=scheduler, progress=False)
    assert (summary["status"] == "done").all() and len(summary) == 2
    for job, (_, row) in zip(jobs, summary.iterrows(), strict=True):
        scene = load_argoverse2(log, job.index, drop_ground=True)
        est = default_estimator().fit(scene.X)
        arrays, _ = read_job_result(tmp_path / "out" / "jobs" / f"{job.name}.npz")
        np.testing.assert_array_equal(arrays["labels"], est.labels_)
        np.testing.assert_array_equal(arrays["flow"], est.flow_)
        # The wall and the car, each found whole, their rigid flows the true flow.
        assert row["n"] == 320 and row["n_clusters"] == 2 and row["n_moving"] == 1
        assert row["iou"] == 1.0 and row["moving_found"] == 1.0
        assert row["epe3d"] < 1e-6


def test_command_line_resumes_and_guards_out(tmp_path, scheduler, capsys):
    data = _write_frames(tmp_path / "frames", n_frames=3)
    out = tmp_path / "out"
    command = ["run", str(data), "--out", str(out), "--scheduler", scheduler]
    command += ["--method", "robust", "--tau", "1", "--quiet"]
    assert main(command) == 0
    assert len(pd.read_csv(out / "summary.csv")) == 2
    assert sorted(os.listdir(out)) == ["jobs", "run.json", "summary.csv", "summary.parquet"]
    arrays, _ = read_job_result(out / "jobs" / "frame0__frame1.npz")
    expected = _plain_loop(dataset_jobs(data)[:1], _estimator())["frame0__frame1"]
    np.testing.assert_array_equal(arrays["labels"], expected["labels"])
    before = _mtimes(out)
    assert main(command) == 0 and _mtimes(out) == before
    capsys.readouterr()
    assert main([*command[:-1], "--tau", "2", "--quiet"]) == 2
    assert "--overwrite" in capsys.readouterr().err
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    assert main([*command[:3], str(mine), *command[4:]]) == 2
    assert "did not write (notes.txt)" in capsys.readouterr().err
    assert os.listdir(mine) == ["notes.txt"]
    assert main([*command[:-1], "--tau", "2", "--quiet", "--overwrite"]) == 0
    assert Path(out / "run.json").read_text().count('"tau": 2.0') == 1
