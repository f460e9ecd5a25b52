"""What ``mmreg run`` tells and keeps: the console table of the pairs, ``-q`` and ``-v``,
every folder named, ``run.json``'s timings, compact job files (restored exactly), the
pictures of a finished run drawn without fitting again, and where the work runs (in
this process unless worker processes pay off)."""

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mmreg.cli import main
from mmreg.datasets import make_lidar_sequence
from mmreg.runner import read_job_result

pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def frames(tmp_path_factory):
    """Three frames of a street as (n, 3) .npy files."""
    folder = tmp_path_factory.mktemp("reports") / "frames"
    folder.mkdir()
    log = make_lidar_sequence(3, n_azimuths=256, random_state=0)
    for k, frame in enumerate(log.frames):
        np.save(folder / f"scan{k}.npy", frame)
    return folder


def _run(*command):
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["run", *map(str, command)])
    return code, out.getvalue()


@pytest.fixture(scope="module")
def kitti(tmp_path_factory):
    """The same street as a KITTI sequence (velodyne/*.bin), no poses."""
    folder = tmp_path_factory.mktemp("kitti") / "08"
    (folder / "velodyne").mkdir(parents=True)
    log = make_lidar_sequence(3, n_azimuths=256, random_state=0)
    for k, frame in enumerate(log.frames):
        scan = np.hstack([frame, np.ones((len(frame), 1))]).astype(np.float32)
        scan.tofile(folder / "velodyne" / f"{k:06d}.bin")
    return folder


@pytest.fixture(scope="module")
def pairs_run(frames, tmp_path_factory):
    """The pairs of the frames, run once (no cluster: the default for two jobs)."""
    out = tmp_path_factory.mktemp("pairs") / "out"
    code, printed = _run(frames, "--pairs", "--out", out, "--frame-rate", 10)
    assert code == 0, printed
    return out, printed


# --------------------------------------------------------------------------- the console
def test_pairs_print_a_table_of_moving_objects_static_share_and_seconds(pairs_run):
    out, printed = pairs_run
    lines = printed.splitlines()
    header = next(line for line in lines if line.lstrip().startswith("job "))
    for column in ("points", "moving objects", "static world", "fastest [m/s]", "fit [s]"):
        assert column in header
    summary = pd.read_csv(out / "summary.csv")
    for name, share in zip(summary["job"], summary["static_share"], strict=True):
        row = next(line for line in lines if line.lstrip().startswith(name))
        assert f"{share:.0%}" in row.split()
    assert "2 jobs: 2 done, 0 failed" in printed and "(in this process)" in printed
    assert printed.splitlines()[-1] == (
        f"written: {out}/ (jobs/ (2 jobs), summary.parquet, summary.csv, run.json)"
    )


def test_quiet_still_says_where_the_results_went_and_verbose_tells_where_it_ran(frames, tmp_path):
    out = tmp_path / "quiet"
    code, printed = _run(frames, "--pairs", "--out", out, "-q")
    assert code == 0 and printed == f"written: {out}/ (jobs/ (2 jobs), summary.parquet, " + (
        "summary.csv, run.json)\n"
    )
    code, printed = _run(frames, "--pairs", "--out", out, "-v")  # resumed: nothing fitted
    assert code == 0
    assert "ran in this process" in printed
    assert "scan0__scan1" in printed and "scan1__scan2" in printed  # every job's row


def test_run_json_keeps_the_timings_of_a_pairs_run(pairs_run):
    out, _ = pairs_run
    timings = json.loads((out / "run.json").read_text())["timings"]
    summary = pd.read_csv(out / "summary.csv")
    assert timings["where"] == "this process" and timings["workers"] == 0
    assert timings["jobs_run"] == 2 and timings["jobs_resumed"] == 0
    # summary.csv keeps the seconds to the microsecond (and fewer digits of a few ms).
    assert timings["fit_s"] == pytest.approx(summary["fit_s"].sum(), abs=1e-5)
    assert timings["load_s"] == pytest.approx(summary["load_s"].sum(), abs=1e-5)
    assert timings["total_s"] >= timings["fit_s"]


def test_pictures_added_to_a_finished_pairs_run_are_drawn_without_fitting(frames, tmp_path):
    out = tmp_path / "out"
    assert _run(frames, "--pairs", "--out", out, "-q")[0] == 0
    jobs = sorted((out / "jobs").glob("*.npz"))
    before = {p.name: p.stat().st_mtime_ns for p in jobs}
    code, printed = _run(frames, "--pairs", "--out", out, "--pictures")
    assert code == 0
    assert sorted(p.name for p in (out / "pictures").iterdir()) == [
        "scan0__scan1.png",
        "scan1__scan2.png",
    ]
    assert {p.name: p.stat().st_mtime_ns for p in jobs} == before  # not fitted again
    assert "2 pictures of finished jobs drawn" in printed
    assert "pictures/ (2 pictures)" in printed.splitlines()[-1]


def test_pictures_added_to_a_finished_log_are_drawn_from_its_files(frames, tmp_path):
    out = tmp_path / "log"
    assert _run(frames, "--out", out, "-q")[0] == 0
    record = (out / "log.json").read_bytes()
    stamp = (out / "log.json").stat().st_mtime_ns
    code, printed = _run(frames, "--out", out, "--pictures")
    assert code == 0
    drawn = sorted(p.name for p in (out / "pictures").iterdir())
    assert drawn == ["animation.gif", "scan0.png", "scan1.png", "scan2.png"]
    assert (out / "log.json").read_bytes() == record  # the log was not fitted again
    assert (out / "log.json").stat().st_mtime_ns == stamp
    assert "pictures/" in printed.splitlines()[-1]


# --------------------------------------------------------------------------- the files
def test_job_files_keep_integers_and_float32_and_give_back_every_array(kitti, tmp_path):
    out = tmp_path / "out"
    assert _run(kitti, "--pairs", "--out", out, "-q")[0] == 0
    path = out / "jobs" / "000000.npz"
    stored = np.load(path)
    assert stored["labels"].dtype.itemsize <= 2 and stored["flow"].dtype == np.float32
    assert "sweep_flow" not in stored.files  # kept where it is not the fit's own flow
    arrays, row = read_job_result(path)
    assert arrays["labels"].dtype == np.int64 and arrays["sweep_flow"].dtype == np.float32
    assert len(arrays["sweep_flow"]) == row["n_file"]
    # The sweep's flow is the fit's own on the rows it saw (where it has one).
    rows = arrays["indices"]
    finite = np.isfinite(arrays["flow"]).all(axis=1)
    np.testing.assert_array_equal(arrays["sweep_flow"][rows[finite]], arrays["flow"][finite])


def test_full_arrays_keep_every_array_whole(kitti, tmp_path):
    out = tmp_path / "full"
    assert _run(kitti, "--pairs", "--out", out, "--full-arrays", "-q")[0] == 0
    stored = np.load(out / "jobs" / "000000.npz")
    assert stored["flow"].dtype == np.float64 and stored["labels"].dtype == np.int64
    assert "sweep_flow" in stored.files


@settings(max_examples=30, deadline=None)
@given(
    n_file=st.integers(1, 40),
    data=st.data(),
)
def test_compact_job_arrays_round_trip_exactly(n_file, data):
    from mmreg.runner import _compact, _expand

    rows = np.array(
        sorted(data.draw(st.sets(st.integers(0, n_file - 1), min_size=1))), dtype=np.int64
    )
    values = st.floats(-50, 50, allow_nan=False, width=32)
    flow = np.array(
        data.draw(
            st.lists(st.tuples(values, values, values), min_size=len(rows), max_size=len(rows))
        ),
        dtype=float,
    )
    missing = np.array(data.draw(st.lists(st.booleans(), min_size=len(rows), max_size=len(rows))))
    flow[missing] = np.nan  # rows without a motion: the static world's flow in the sweep's
    sweep = np.array(
        data.draw(st.lists(st.tuples(values, values, values), min_size=n_file, max_size=n_file)),
        dtype=np.float32,
    )
    sweep[rows[~missing]] = flow[~missing].astype(np.float32)
    labels = np.array(
        data.draw(st.lists(st.integers(-1, 300), min_size=len(rows), max_size=len(rows)))
    )
    arrays = {"labels": labels, "indices": rows, "flow": flow, "sweep_flow": sweep}
    back = _expand(_compact(arrays))
    np.testing.assert_array_equal(back["labels"], labels)
    np.testing.assert_array_equal(back["indices"], rows)
    np.testing.assert_array_equal(back["flow"], flow.astype(np.float32))
    np.testing.assert_array_equal(back["sweep_flow"], sweep)


# --------------------------------------------------------------------------- the workers
def test_default_workers_count_cores_threads_and_tasks():
    from mmreg.runner._workers import default_workers, free_cores

    assert default_workers(1, cores=64) == 0  # a single log: this process
    assert default_workers(5, cores=1) == 0
    assert default_workers(5, threads=2, cores=2) == 0  # the job's own threads fill them
    assert default_workers(5, threads=2, cores=8) == 4
    assert default_workers(3, cores=8) == 3  # at most one per task
    assert free_cores(4, load=0.0) == 4 and free_cores(4, load=10.0) == 1


def test_a_cluster_only_for_enough_work_left():
    from mmreg.runner._workers import worth_a_cluster

    assert not worth_a_cluster(3, 1.0, 2)  # the rest of a 4-frame log
    assert worth_a_cluster(38, 1.0, 2)  # the rest of a 40-frame log
    assert not worth_a_cluster(38, 1.0, 1)  # one worker is never faster than here
    assert not worth_a_cluster(1, 1e6, 8)  # one task left: here


def test_the_jobs_own_threads_come_from_n_jobs():
    from mmreg import MultiModelRegistration, SequenceRegistration, SweepRegistration
    from mmreg.runner._workers import task_threads

    assert task_threads(SequenceRegistration(), cores=4) == 1
    inner = SweepRegistration(MultiModelRegistration(n_jobs=-1))
    assert task_threads(SequenceRegistration(inner), cores=4) == 4
    assert task_threads(SweepRegistration(MultiModelRegistration(n_jobs=3)), cores=2) == 2


def test_few_jobs_and_a_single_log_start_no_cluster(frames, tmp_path, monkeypatch):
    import distributed

    def refuse(*args, **kwargs):
        raise AssertionError("no cluster should start")

    monkeypatch.setattr(distributed, "LocalCluster", refuse)
    assert _run(frames, "--pairs", "--out", tmp_path / "pairs", "-q")[0] == 0
    assert _run(frames, "--out", tmp_path / "log", "-q")[0] == 0
    for name in ("pairs", "log"):
        timings = json.loads((tmp_path / name / "run.json").read_text())["timings"]
        assert timings["where"] == "this process" and timings["cluster_start_s"] == 0.0
    assert _run(frames, "--pairs", "--out", tmp_path / "zero", "--n-workers", 0, "-q")[0] == 0


def test_n_workers_refuses_a_negative_count(frames, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["run", str(frames), "--n-workers", "-1"])
    assert "must be 0 (in this process) or more" in capsys.readouterr().err


def test_frames_csv_counts_the_static_world(frames, tmp_path):
    out = tmp_path / "log"
    code, printed = _run(frames, "--out", out)
    assert code == 0
    table = pd.read_csv(out / "frames.csv")
    assert {"static_points", "ego_body_points"} <= set(table.columns)
    labels = np.fromfile(out / "labels" / "scan1.label", dtype="<u4") & 0xFFFF
    assert table.loc[1, "static_points"] == int(np.count_nonzero(labels == 9))
    assert "static world" in printed
    assert Path(out / "run.json").is_file()


@pytest.mark.parametrize("pays", [True, False])
def test_run_tasks_times_the_first_task_here_then_chooses(monkeypatch, pays):
    from mmreg.runner import _workers

    monkeypatch.setattr(_workers, "free_cores", lambda: 4)
    monkeypatch.setattr(_workers, "worth_a_cluster", lambda n_left, seconds, workers: pays)
    here, there = [], []

    def on_cluster(tasks, address, workers):
        there.append((list(tasks), address, workers))
        return 1.5

    plan = _workers.run_tasks(list("abcdef"), here.extend, on_cluster)
    if pays:
        assert here == ["a"] and there == [(list("bcdef"), None, 4)]
        assert plan["where"] == "local cluster" and plan["workers"] == 4
        assert plan["start_s"] == 1.5
    else:
        assert here == list("abcdef") and there == [] and plan["where"] == "this process"
    # Told: a scheduler, or a number of workers (0: here), is not second-guessed.
    here.clear(), there.clear()
    _workers.run_tasks(list("ab"), here.extend, on_cluster, scheduler="tcp://x:1")
    _workers.run_tasks(list("ab"), here.extend, on_cluster, n_workers=3)
    _workers.run_tasks(list("ab"), here.extend, on_cluster, n_workers=0)
    assert there == [(["a", "b"], "tcp://x:1", None), (["a", "b"], None, 3)]
    assert here == ["a", "b"]
