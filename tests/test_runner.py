"""The dataset runner (mmreg.runner, ``mmreg run``) on a LocalCluster started here."""

import json
import os
import pickle
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mmreg import MultiModelRegistration, SweepRegistration
from mmreg.cli import main
from mmreg.datasets import load_argoverse2, write_argoverse2_log
from mmreg.runner import (
    dataset_jobs,
    default_estimator,
    default_sweep_estimator,
    read_job_result,
    run_dataset,
)

distributed = pytest.importorskip("distributed")

ARRAYS = ("labels", "rotations", "translations", "sigmas", "flow")


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


def _aligned(folder):
    """The jobs of a folder of index-aligned frames (frames are sweeps unless told)."""
    return dataset_jobs(folder, pairs="aligned")


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
            "flow": est.flow_.astype(np.float32),  # as a job's file keeps it by default
        }
    return out


def _mtimes(out):
    return {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in (out / "jobs").glob("*.npz")}


def test_frames_match_a_plain_loop(tmp_path, scheduler):
    data = _write_frames(tmp_path / "frames")
    jobs = dataset_jobs(data, pairs="aligned")
    assert [job.name for job in jobs] == ["frame0__frame1", "frame1__frame2", "frame2__frame3"]
    summary = run_dataset(jobs, _estimator(), tmp_path / "out", scheduler=scheduler, progress=False)
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
    first = run_dataset(_aligned(data), _estimator(), out, scheduler=scheduler, progress=False)
    assert first["status"].tolist() == ["done", "done", "error"]
    assert "NaN" in first["error"].iloc[2] and first["error"].iloc[0] == ""
    assert sorted(p.name for p in (out / "jobs").iterdir()) == [
        "frame0__frame1.npz",
        "frame1__frame2.npz",
    ]
    before = _mtimes(out)
    np.save(data / "frame3.npy", good)
    second = run_dataset(_aligned(data), _estimator(), out, scheduler=scheduler, progress=False)
    assert (second["status"] == "done").all()
    assert second["resumed"].tolist() == [True, True, False]
    after = _mtimes(out)
    assert {k: after[k] for k in before} == before  # the done jobs were not rewritten
    expected = _plain_loop(_aligned(data)[2:], _estimator())["frame2__frame3"]
    arrays, _ = read_job_result(out / "jobs" / "frame2__frame3.npz")
    np.testing.assert_array_equal(arrays["labels"], expected["labels"])


def test_half_written_result_is_not_taken_as_done(tmp_path, scheduler):
    data = _write_frames(tmp_path / "frames")
    out = tmp_path / "out"
    run_dataset(_aligned(data), _estimator(), out, scheduler=scheduler, progress=False)
    path = out / "jobs" / "frame1__frame2.npz"
    whole = path.read_bytes()
    arrays, _ = read_job_result(path)
    path.write_bytes(whole[: len(whole) // 2])
    assert read_job_result(path) is None
    # A temporary file left by an interrupted write is not a result either.
    (out / "jobs" / ".frame2__frame3.npz.x1y2.tmp").write_bytes(whole[:100])
    again = run_dataset(_aligned(data), _estimator(), out, scheduler=scheduler, progress=False)
    assert again["resumed"].tolist() == [True, False, True]
    redone, _ = read_job_result(path)
    for key in ARRAYS:  # the same job gives the same result
        np.testing.assert_array_equal(redone[key], arrays[key])


def test_other_estimator_runs_every_job_again(tmp_path, scheduler):
    data = _write_frames(tmp_path / "frames", n_frames=3)
    out = tmp_path / "out"
    run_dataset(_aligned(data), _estimator(), out, scheduler=scheduler, progress=False)
    other = MultiModelRegistration(tau=1.0, variant="paper", random_state=0)
    again = run_dataset(_aligned(data), other, out, scheduler=scheduler, progress=False)
    assert not again["resumed"].any()
    expected = _plain_loop(_aligned(data), other)
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
    jobs = dataset_jobs(log, pairs="truth", ground="drop")
    assert len(jobs) == 2 and all(job.ground == "drop" for job in jobs)
    summary = run_dataset(jobs, None, tmp_path / "out", scheduler=scheduler, progress=False)
    assert summary["pairs"].tolist() == ["truth", "truth"] and summary["truth_fed"].all()
    assert (summary["status"] == "done").all() and len(summary) == 2
    for job, (_, row) in zip(jobs, summary.iterrows(), strict=True):
        scene = load_argoverse2(log, job.index, drop_ground=True)
        est = default_estimator().fit(scene.X)
        arrays, _ = read_job_result(tmp_path / "out" / "jobs" / f"{job.name}.npz")
        np.testing.assert_array_equal(arrays["labels"], est.labels_)
        np.testing.assert_array_equal(arrays["flow"], est.flow_.astype(np.float32))
        # The wall and the car, each found whole, their rigid flows the true flow.
        assert row["n"] == 320 and row["n_clusters"] == 2 and row["n_moving"] == 1
        assert row["iou"] == 1.0 and row["moving_found"] == 1.0
        assert row["epe3d"] < 1e-6


def test_command_line_resumes_and_guards_out(tmp_path, scheduler, capsys):
    data = _write_frames(tmp_path / "frames", n_frames=3)
    out = tmp_path / "out"
    command = ["run", str(data), "--out", str(out), "--scheduler", scheduler, "--pairs"]
    command += ["aligned", "--method", "robust", "--tau", "1", "--quiet"]
    assert main(command) == 0
    assert len(pd.read_csv(out / "summary.csv")) == 2
    assert sorted(os.listdir(out)) == ["jobs", "run.json", "summary.csv", "summary.parquet"]
    arrays, _ = read_job_result(out / "jobs" / "frame0__frame1.npz")
    expected = _plain_loop(_aligned(data)[:1], _estimator())["frame0__frame1"]
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


def _box_surface(rng, n, low, high):
    """``n`` points on the faces of the box [low, high]: a surface ICP can lock onto."""
    low, high = np.asarray(low, float), np.asarray(high, float)
    points = rng.uniform(low, high, (n, 3))
    face = rng.integers(0, 3, n)
    points[np.arange(n), face] = np.where(rng.integers(0, 2, n), high[face], low[face])
    return points


def _write_sweeps(folder):
    """Three raw sweeps of a still box and a box moving 0.5 m along x per sweep: every
    sweep samples the surfaces anew, so the frames differ in size and order.

    Returns the folder and, per frame, how many of its first rows are the still box.
    """
    rng = np.random.default_rng(0)
    folder.mkdir(parents=True, exist_ok=True)
    still = []
    for k, (n_still, n_moving) in enumerate([(250, 150), (220, 170), (270, 130)]):
        moving = _box_surface(rng, n_moving, [6, 0, 0], [8, 2, 1.5]) + [0.5 * k, 0, 0]
        frame = np.vstack([_box_surface(rng, n_still, [0, 0, 0], [3, 3, 2]), moving])
        np.save(folder / f"frame{k}.npy", frame)
        still.append(n_still)
    return folder, still


def _fit_job(job, estimator):
    from sklearn.base import clone

    data = job.load()
    return clone(estimator).fit(data["X"], sweep=data["sweep"])


def test_raw_sweeps_of_different_sizes_one_job_per_pair(tmp_path, scheduler):
    data, still = _write_sweeps(tmp_path / "frames")
    jobs = dataset_jobs(data, pairs="sweeps")
    assert [job.name for job in jobs] == ["frame0__frame1", "frame1__frame2"]
    assert all(pickle.loads(pickle.dumps(job)) == job for job in jobs)  # sent to workers
    out = tmp_path / "out"
    summary = run_dataset(jobs, None, out, scheduler=scheduler, progress=False)
    assert summary["job"].tolist() == ["frame0__frame1", "frame1__frame2"]
    assert (summary["status"] == "done").all()
    assert summary["n"].tolist() == [400, 390] and summary["n_sweep"].tolist() == [390, 400]
    for k, job in enumerate(jobs):
        arrays, row = read_job_result(out / "jobs" / f"{job.name}.npz")
        expected = _fit_job(job, default_sweep_estimator())
        np.testing.assert_array_equal(arrays["labels"], expected.labels_)
        np.testing.assert_array_equal(arrays["flow"], expected.flow_.astype(np.float32))
        n = len(np.load(data / f"frame{k}.npy"))
        assert arrays["labels"].shape == (n,) and arrays["flow"].shape == (n, 3)
        # Each box is one cluster of the first sweep, the second box the moving one.
        labels = arrays["labels"]
        box1, box2 = np.unique(labels[: still[k]]), np.unique(labels[still[k] :])
        assert len(box1) == len(box2) == 1 and box1[0] != box2[0]
        assert arrays["moving"].tolist() == [j == box2[0] for j in range(row["n_clusters"])]
        truth = np.zeros((n, 3))
        truth[still[k] :, 0] = 0.5
        assert np.abs(arrays["flow"] - truth).max() < 0.1  # sampling spacing: about 0.2
    # Resumable: a second run reads every result back.
    again = run_dataset(jobs, None, out, scheduler=scheduler, progress=False)
    assert again["resumed"].all()


def test_aligned_frames_of_different_sizes_point_to_the_sweeps(tmp_path, scheduler, capsys):
    data, _ = _write_sweeps(tmp_path / "frames")
    jobs = dataset_jobs(data, pairs="aligned")
    summary = run_dataset(jobs, _estimator(), tmp_path / "out", scheduler=scheduler, progress=False)
    assert (summary["status"] == "error").all()
    assert all("pairs at 'auto'" in error for error in summary["error"])
    command = ["run", str(data), "--out", str(tmp_path / "cli"), "--scheduler", scheduler, "-q"]
    assert main([*command, "--pairs", "aligned"]) == 1
    assert "drop --pairs aligned" in capsys.readouterr().err
    # A plain estimator cannot take the second sweep: said before any job runs.
    with pytest.raises(TypeError, match="SweepRegistration"):
        run_dataset(dataset_jobs(data, pairs="sweeps"), _estimator(), tmp_path / "other")
    with pytest.raises(ValueError, match="pairs='sweeps' needs frames"):
        dataset_jobs(_write_correspondences(tmp_path / "pairs"), pairs="sweeps")


def _write_correspondences(folder):
    folder.mkdir()
    np.save(folder / "pair0.npy", np.zeros((5, 6)))
    return folder


def _write_sweep_log(folder):
    """Three sweeps seen from a car driving 1 m per sweep: a road (ground), a building
    and a car driving 1.5 m per sweep, each sweep sampled anew (sizes differ)."""
    rng = np.random.default_rng(2)
    stamps = [315966265259836000 + k * 100_000_000 for k in range(3)]
    sweeps, cuboids = {}, []
    for k, (n_road, n_building, n_car) in enumerate(
        [(200, 250, 150), (180, 280, 130), (220, 230, 160)]
    ):
        road = np.c_[rng.uniform(-20, 20, (n_road, 2)), np.zeros(n_road)]
        building = _box_surface(rng, n_building, [-6, -8, 0.5], [-2, -4, 4]) - [k, 0, 0]
        car = _box_surface(rng, n_car, [-2, -0.8, -0.5], [2, 0.8, 0.5]) + [8 + 0.5 * k, 3, 1]
        sweeps[stamps[k]] = np.vstack([road, building, car])
        cuboids.append(
            dict(
                timestamp_ns=stamps[k],
                track_uuid="car-1",
                category="REGULAR_VEHICLE",
                size=(4.4, 1.8, 1.5),
                pose=_pose(8.0 + 0.5 * k, 3, 1.0),
            )
        )
    # Annotated one step past the last sweep, as the AV2 API's truncated logs: a third
    # pair of flow, but not of sweeps.
    stamps.append(stamps[-1] + 100_000_000)
    cuboids.append(cuboids[-1] | dict(timestamp_ns=stamps[-1], pose=_pose(9.5, 3, 1.0)))
    ego = {t: _pose(1.0 * k) for k, t in enumerate(stamps)}
    return write_argoverse2_log(folder, sweeps, ego, cuboids)


def test_argoverse2_log_from_the_two_sweeps(tmp_path, scheduler, capsys):
    log = _write_sweep_log(tmp_path / "log")
    out = tmp_path / "out"
    command = [
        "run",
        str(log),
        "--pairs",
        "--ground",
        "drop",
        "--out",
        str(out),
        "--scheduler",
        scheduler,
    ]
    assert main([*command, "-q"]) == 0
    summary = pd.read_csv(out / "summary.csv")
    jobs = dataset_jobs(log, ground="drop")
    # Three sweeps, two pairs (the annotation past the last sweep pairs no sweep).
    assert len(jobs) == 2 and len(dataset_jobs(log, pairs="truth")) == 2
    assert summary["job"].astype(str).tolist() == [job.name for job in jobs]
    assert summary["n"].tolist() == [400, 410] and summary["n_sweep"].tolist() == [410, 390]
    for job, (_, row) in zip(jobs, summary.iterrows(), strict=True):
        # What the command line fits: its defaults (--method sweep --tau 5 --max-iter 10).
        inner = MultiModelRegistration(variant="sweep", tau=5.0, max_iter=10, random_state=0)
        expected = _fit_job(job, SweepRegistration(inner, random_state=0))
        arrays, _ = read_job_result(out / "jobs" / f"{job.name}.npz")
        np.testing.assert_array_equal(arrays["labels"], expected.labels_)
        assert arrays["flow"].shape == (row["n"], 3)
        # The rows of the sweep's file it fitted: those off the road (the first 200 or
        # 180 rows of the file are the road, z = 0).
        scene = load_argoverse2(log, job.index)
        np.testing.assert_array_equal(arrays["indices"], np.flatnonzero(~scene.ground))
        assert arrays["indices"][0] == len(scene.a) - row["n"]
        assert row["pairs"] == "sweeps" and not row["truth_fed"]
        # Scored against the true flow of the first sweep: the building and the car found.
        assert row["n_clusters"] == 2 and row["n_moving"] == 1
        assert row["iou"] == 1.0 and row["moving_found"] == 1.0 and row["epe3d"] < 0.1
    configuration = json.loads((out / "run.json").read_text())["configuration"]
    assert configuration["pairs"] == "auto" and configuration["ground"] == "drop"


def test_pictures_are_drawn_for_every_job(tmp_path, scheduler):
    data, _ = _write_sweeps(tmp_path / "frames")
    out = tmp_path / "out"
    command = ["run", str(data), "--pairs", "sweeps", "--pictures", "-q"]
    assert main([*command, "--out", str(out), "--scheduler", scheduler]) == 0
    pictures = sorted((out / "pictures").iterdir())
    assert [p.name for p in pictures] == ["frame0__frame1.png", "frame1__frame2.png"]
    for picture in pictures:
        assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # Pictures change no result: the same command without them resumes every job.
    summary = run_dataset(dataset_jobs(data, pairs="sweeps"), None, out, scheduler=scheduler)
    assert summary["resumed"].all()
