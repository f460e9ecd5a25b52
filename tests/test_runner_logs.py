"""``mmreg run`` on LiDAR logs as users have them: Argoverse 2 logs with or without
annotations and map, splits with a broken log, a network's flow in the challenge layout,
KITTI sequences; the challenge-format output, the ground choice, the rows' indices and
Ctrl-C."""

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from _fake_av2 import SIZES, STAMPS, box_surface, write_log
from conftest import terminal_sigint

from mmreg import MultiModelRegistration, SweepRegistration
from mmreg.cli import main
from mmreg.datasets import load_argoverse2
from mmreg.datasets._argoverse2 import _read_points
from mmreg.runner import (
    SCENE_FLOW_FOLDER,
    _process,
    dataset_jobs,
    read_job_result,
    write_scene_flow,
)

distributed = pytest.importorskip("distributed")


def _cli_estimator():
    """What 'mmreg run' fits on sweep pairs with its defaults."""
    inner = MultiModelRegistration(variant="sweep", tau=5.0, max_iter=10, random_state=0)
    return SweepRegistration(inner, random_state=0)


def _file_points(log, timestamp):
    return _read_points(log / "sensors" / "lidar" / f"{timestamp}.feather")[0]


def _expected_sweep_flow(points, indices, model):
    """The challenge file's rows by hand: the fit's flow on its rows, the static world's
    motion on the others (and on rows without a motion), dynamic beyond 0.05 m."""
    R = model.rotations_[model.static_cluster_]
    t = model.translations_[model.static_cluster_]
    ego = np.array([R @ p + t - p for p in points])
    flow = ego.copy()
    for row, fitted in zip(indices, model.flow_, strict=True):
        if np.all(np.isfinite(fitted)):
            flow[row] = fitted
    return flow, np.linalg.norm(flow - ego, axis=1) >= 0.05


def _check_challenge_file(path, points, indices, model):
    table = pd.read_feather(path)
    assert list(table.columns) == ["flow_tx_m", "flow_ty_m", "flow_tz_m", "is_dynamic"]
    assert [str(t) for t in table.dtypes] == ["float32"] * 3 + ["bool"]
    flow, dynamic = _expected_sweep_flow(points, indices, model)
    assert len(table) == len(points)  # one row per point of the sweep's file
    np.testing.assert_allclose(table.iloc[:, :3].to_numpy(), flow, atol=1e-5)
    np.testing.assert_array_equal(table["is_dynamic"].to_numpy(), dynamic)
    return table


# --------------------------------------------------------------------------- AV2 logs
def test_log_without_annotations_nor_map_registers_its_raw_sweeps(
    tmp_path, scheduler, monkeypatch, capsys
):
    log = write_log(tmp_path / "data" / "log", annotations=False, map_=False)
    jobs = dataset_jobs(log)
    assert [job.name for job in jobs] == [str(t) for t in STAMPS[:2]]  # 3 sweeps, 2 pairs
    data = jobs[0].load()
    a, sweep = _file_points(log, STAMPS[0]), _file_points(log, STAMPS[1])
    np.testing.assert_array_equal(data["X"], a)  # every row, in the file's order
    np.testing.assert_array_equal(data["sweep"], sweep)
    np.testing.assert_array_equal(data["indices"], np.arange(len(a)))
    assert not {"labels_true", "flow_true", "ground", "sweep_ground"} & set(data)
    # The challenge's files are named by the log's folder as given, a symbolic link too.
    assert jobs[0].challenge == f"log/{STAMPS[0]}.feather"
    if hasattr(os, "symlink") and sys.platform != "win32":
        (tmp_path / "0c6e62d7").symlink_to(log, target_is_directory=True)
        linked = dataset_jobs(tmp_path / "0c6e62d7")
        assert linked[1].challenge == f"0c6e62d7/{STAMPS[1]}.feather"
    # Its sensors/lidar folder alone is a folder of sweep files: the same sweeps.
    alone = dataset_jobs(log / "sensors" / "lidar")
    assert [job.name for job in alone] == [job.name for job in jobs]
    np.testing.assert_array_equal(alone[0].load()["X"], a)
    monkeypatch.chdir(tmp_path)
    assert main(["run", str(log), "--pairs", "--scheduler", scheduler, "-q"]) == 0
    (out,) = [p for p in tmp_path.iterdir() if p.name not in ("data", "0c6e62d7")]
    assert re.fullmatch(r"log-mmreg-run-[0-9a-f]{8}", out.name)
    summary = pd.read_csv(out / "summary.csv")
    assert summary["status"].tolist() == ["done", "done"]
    assert summary["pairs"].tolist() == ["sweeps", "sweeps"] and not summary["truth_fed"].any()
    assert "iou" not in summary and "epe3d" not in summary  # no truth: no score
    for k, job in enumerate(jobs):
        arrays, row = read_job_result(out / "jobs" / f"{job.name}.npz")
        job_data = job.load()
        model = _cli_estimator().fit(job_data["X"], sweep=job_data["sweep"])
        np.testing.assert_array_equal(arrays["labels"], model.labels_)
        n = sum(SIZES[k])
        np.testing.assert_array_equal(arrays["indices"], np.arange(n))
        # The building and the car, each one cluster; the car moves 0.5 m along x.
        car = slice(n - SIZES[k][2], n)
        assert len(np.unique(arrays["labels"][car])) == 1 and arrays["moving"].sum() == 1
        path = out / SCENE_FLOW_FOLDER / "log" / f"{STAMPS[k]}.feather"
        table = _check_challenge_file(
            path, _file_points(log, STAMPS[k]), job_data["indices"], model
        )
        assert table["is_dynamic"].to_numpy()[car].all()
        building = slice(SIZES[k][0], n - SIZES[k][2])
        assert not table["is_dynamic"].to_numpy()[building].any()
    # A run resumed after an interruption between a job's result and its challenge file
    # writes the file from the result.
    path = out / SCENE_FLOW_FOLDER / "log" / f"{STAMPS[0]}.feather"
    whole = path.read_bytes()
    path.unlink()
    assert main(["run", str(log), "--pairs", "--scheduler", scheduler, "-q"]) == 0
    assert pd.read_csv(out / "summary.csv")["resumed"].all() and path.read_bytes() == whole
    # Without a map, --ground drop is the estimator's, as in 'mmreg register'.
    command = ["run", str(log), "--pairs", "--ground", "drop", "--scheduler", scheduler, "-q"]
    assert main([*command, "--out", str(tmp_path / "drop")]) == 0
    dropped = pd.read_csv(tmp_path / "drop" / "summary.csv")
    for k, job in enumerate(jobs):
        job_data = job.load()
        model = _cli_estimator().set_params(ground="drop")
        model.fit(job_data["X"], sweep=job_data["sweep"])
        arrays, row = read_job_result(tmp_path / "drop" / "jobs" / f"{job.name}.npz")
        np.testing.assert_array_equal(arrays["labels"], model.labels_)
        assert dropped.loc[k, "ground"] == ("kept" if model.ground_mask_ is None else "dropped")


def test_dropped_ground_rows_move_with_the_static_world_in_the_challenge_file(tmp_path, scheduler):
    log = write_log(tmp_path / "log", annotations=False)  # a map: the ground is known
    out = tmp_path / "out"
    command = ["run", str(log), "--pairs", "--ground", "drop", "--scheduler", scheduler, "-q"]
    assert main([*command, "--out", str(out)]) == 0
    for k, job in enumerate(dataset_jobs(log, ground="drop")):
        data = job.load()
        n_road = SIZES[k][0]
        np.testing.assert_array_equal(data["indices"], np.arange(n_road, sum(SIZES[k])))
        arrays, _ = read_job_result(out / "jobs" / f"{job.name}.npz")
        np.testing.assert_array_equal(arrays["indices"], data["indices"])
        model = _cli_estimator().fit(data["X"], sweep=data["sweep"])
        path = out / SCENE_FLOW_FOLDER / "log" / f"{STAMPS[k]}.feather"
        table = _check_challenge_file(path, _file_points(log, STAMPS[k]), data["indices"], model)
        # The road rows were not fitted: they get the ego flow (checked row by row above),
        # about 1 m backwards. With the road dropped a building alone holds the static
        # world's rotation, which the ego GICP tilts by up to 0.54 degrees: 0.26 m 20 m away.
        road = table.iloc[:n_road, :3].to_numpy()
        np.testing.assert_allclose(road, np.tile([-1.0, 0, 0], (n_road, 1)), atol=0.5)


def test_map_ground_masks_go_to_a_fit_that_names_them(tmp_path):
    log = write_log(tmp_path / "log")
    seen = {}

    class Grounded(SweepRegistration):
        def fit(self, X, y=None, *, sweep=None, ground=None, sweep_ground=None):
            seen.update(ground=ground, sweep_ground=sweep_ground)
            return super().fit(X, sweep=sweep)

    job = dataset_jobs(log)[0]
    _, arrays, row = _process(job, Grounded(_cli_estimator().estimator, random_state=0))
    assert row["status"] == "done" and row["ground"] == "masks"
    scene = load_argoverse2(log, 0)
    np.testing.assert_array_equal(seen["ground"], scene.ground)
    np.testing.assert_array_equal(seen["sweep_ground"], scene.sweep2_ground)
    assert seen["ground"][: SIZES[0][0]].all() and not seen["ground"][SIZES[0][0] :].any()

    # A fit that does not name them gets none: the map's ground rows are dropped, the
    # same fit as --ground drop. "keep" jobs keep them and pass no mask.
    class Unaware(SweepRegistration):
        def fit(self, X, y=None, *, sweep=None):
            return super().fit(X, sweep=sweep)

    unaware = Unaware(_cli_estimator().estimator, random_state=0)
    _, plain_arrays, plain = _process(job, unaware)
    dropped = dataset_jobs(log, ground="drop")[0]
    _, drop_arrays, drop = _process(dropped, unaware)
    assert plain["ground"] == drop["ground"] == "dropped" and plain["n"] == drop["n"]
    np.testing.assert_array_equal(plain_arrays["indices"], np.flatnonzero(~scene.ground))
    for key in ("indices", "labels", "flow", "sweep_flow"):
        np.testing.assert_array_equal(plain_arrays[key], drop_arrays[key])
    # SweepRegistration itself names them: the map's ground joins its static world.
    _, own_arrays, own = _process(job, _cli_estimator())
    assert own["ground"] == "masks"
    assert len(np.unique(own_arrays["labels"][scene.ground[own_arrays["indices"]]])) == 1
    _, kept_arrays, kept = _process(dataset_jobs(log, ground="keep")[0], Grounded(random_state=0))
    assert kept["ground"] == "kept" and seen["ground"] is None
    np.testing.assert_array_equal(kept_arrays["indices"], np.arange(len(scene.a)))


def test_split_with_broken_logs_gives_failed_rows_and_the_others_go_on(tmp_path, scheduler, capsys):
    split = tmp_path / "split"
    write_log(split / "a", annotations=False, map_=False)
    torn = write_log(split / "b", map_=False)
    sweep = torn / "sensors" / "lidar" / f"{STAMPS[2]}.feather"
    sweep.write_bytes(sweep.read_bytes()[:100])  # truncated: the pair (1, 2) cannot load
    (split / "c" / "sensors" / "lidar").mkdir(parents=True)  # no sweep at all
    single = split / "d" / "sensors" / "lidar"
    single.mkdir(parents=True)
    shutil.copy(torn / "sensors" / "lidar" / f"{STAMPS[0]}.feather", single)  # no pair
    out = tmp_path / "out"
    assert (
        main(["run", str(split), "--pairs", "--out", str(out), "--scheduler", scheduler, "-q"]) == 1
    )
    assert "failed" in capsys.readouterr().err
    summary = pd.read_csv(out / "summary.csv").set_index("job")
    a0, a1, b0, b1 = (f"{log}_{t}" for log in "ab" for t in STAMPS[:2])
    assert summary.loc[[a0, a1, b0], "status"].tolist() == ["done"] * 3
    assert summary.loc[b1, "status"] == "error" and "truncated" in summary.loc[b1, "error"]
    assert summary.loc["c", "status"] == "error" and "no LiDAR sweeps" in summary.loc["c", "error"]
    assert summary.loc["d", "status"] == "error" and "one sweep only" in summary.loc["d", "error"]
    # Log b has annotations: scored; log a has none.
    assert summary.loc[b0, "moving_found"] == 1.0 and summary.loc[b0, "iou"] > 0.9
    assert np.isnan(summary.loc[a0, "iou"]) and np.isnan(summary.loc[a0, "moving_found"])
    assert sorted(p.name for p in (out / SCENE_FLOW_FOLDER).iterdir()) == ["a", "b"]


def test_a_log_annotated_at_some_sweeps_is_scored_where_both_are(tmp_path):
    log = write_log(tmp_path / "log", annotated=STAMPS[:2])
    first, second = (job.load() for job in dataset_jobs(log))
    assert {"labels_true", "flow_true"} <= set(first)
    assert not {"labels_true", "flow_true"} & set(second)
    truth_jobs = dataset_jobs(log, pairs="truth")
    assert truth_jobs[0].load()["pairs"] == "truth"
    with pytest.raises(ValueError, match=f"no cuboid annotated at {STAMPS[1]} or {STAMPS[2]}"):
        truth_jobs[1].load()


# --------------------------------------------------------------------------- --pairs truth
def test_truth_fed_jobs_are_marked(tmp_path, scheduler, capsys):
    log = write_log(tmp_path / "log")
    out = tmp_path / "out"
    assert (
        main(["run", str(log), "--pairs", "truth", "--out", str(out), "--scheduler", scheduler])
        == 0
    )
    printed = capsys.readouterr().out
    assert "2 jobs fitted on the ground-truth flow (--pairs truth)" in printed
    summary = pd.read_csv(out / "summary.csv")
    assert summary["pairs"].tolist() == ["truth", "truth"] and summary["truth_fed"].all()
    scene = load_argoverse2(log, 0)
    arrays, _ = read_job_result(out / "jobs" / f"{STAMPS[0]}.npz")
    expected = MultiModelRegistration(variant="sweep", tau=5.0, max_iter=10, random_state=0)
    # The map's ground rows dropped: MultiModelRegistration.fit takes no ground masks.
    assert summary["ground"].tolist() == ["dropped", "dropped"]
    np.testing.assert_array_equal(arrays["labels"], expected.fit(scene.X[~scene.ground]).labels_)
    # Without annotations there is no truth to feed: a failed row per pair.
    bare = write_log(tmp_path / "bare", annotations=False)
    command = ["run", str(bare), "--pairs", "truth", "--scheduler", scheduler, "-q"]
    assert main([*command, "--out", str(tmp_path / "bare-out")]) == 1
    assert "--pairs truth needs the annotations" in capsys.readouterr().err


# --------------------------------------------------------------------------- --flow DIR
def _write_flow(folder, log, bias=0.7):
    """The true flow of every sweep, 30 % short: a network's estimate, challenge layout."""
    for k, t in enumerate(STAMPS[:2]):
        flow = load_argoverse2(log, k).flow * bias
        write_scene_flow(folder / f"{t}.feather", flow, np.zeros(len(flow), bool))
    return folder


def test_a_networks_flow_is_refined_on_the_next_sweep(tmp_path, scheduler, capsys):
    log = write_log(tmp_path / "log")
    flows = _write_flow(tmp_path / "zeroflow" / "log", log)
    out = tmp_path / "out"
    command = ["run", str(log), "--scheduler", scheduler, "-q", "--flow"]
    assert main([*command, str(tmp_path / "zeroflow"), "--out", str(out)]) == 0
    summary = pd.read_csv(out / "summary.csv")
    assert summary["pairs"].tolist() == ["flow", "flow"] and not summary["truth_fed"].any()
    for k, t in enumerate(STAMPS[:2]):
        scene = load_argoverse2(log, k)
        X = np.hstack([scene.a, scene.a + 0.7 * scene.flow])
        # One row per point: the file's float32 flow, as the job reads it.
        flow = pd.read_feather(flows / f"{t}.feather").iloc[:, :3].to_numpy(np.float64)
        np.testing.assert_allclose(X[:, 3:] - X[:, :3], flow, atol=1e-5)
        # The log has a map and SweepRegistration.fit takes no ground mask: the map's
        # ground rows are dropped from both sweeps.
        keep = ~scene.ground
        X = np.hstack([scene.a[keep], scene.a[keep] + flow[keep]])
        expected = _cli_estimator().fit(X, sweep=scene.sweep2[~scene.sweep2_ground])
        arrays, _ = read_job_result(out / "jobs" / f"{t}.npz")
        np.testing.assert_array_equal(arrays["indices"], np.flatnonzero(keep))
        np.testing.assert_array_equal(arrays["labels"], expected.labels_)
        np.testing.assert_array_equal(arrays["flow"], expected.flow_.astype(np.float32))
        # The refinement puts the car where it goes: better than the 30 % short input.
        car = scene.labels[keep] == 1
        refined = np.linalg.norm(arrays["flow"] - scene.flow[keep], axis=1)[car].mean()
        given = np.linalg.norm(flow[keep] - scene.flow[keep], axis=1)[car].mean()
        assert refined < given / 2
    # DIR/<timestamp_ns>.feather for one log: the same jobs.
    flat = dataset_jobs(log, flow=flows)
    assert [job.flow for job in flat] == [job.flow for job in dataset_jobs(log, flow=flows.parent)]
    # A flow file with other rows than the sweep: that job fails, naming the rows.
    write_scene_flow(flows / f"{STAMPS[1]}.feather", np.zeros((5, 3)), np.zeros(5, bool))
    again = [*command, str(flows), "--out", str(tmp_path / "short")]
    assert main(again) == 1
    summary = pd.read_csv(tmp_path / "short" / "summary.csv")
    assert summary["status"].tolist() == ["done", "error"]
    assert "5 rows but the sweep has 590 points" in summary.loc[1, "error"]
    capsys.readouterr()
    assert main(["run", str(log), "--flow", str(tmp_path / "nothing"), "-q"]) == 2
    assert "no such folder" in capsys.readouterr().err


# --------------------------------------------------------------------------- KITTI
def _write_kitti(folder):
    """Three scans (float32 x, y, z, reflectance) of a still box and a box moving 0.5 m
    along x per scan, sampled anew each scan, with KITTI's poses.txt and calib.txt."""
    rng = np.random.default_rng(0)
    (folder / "velodyne").mkdir(parents=True)
    sizes = [(250, 150), (220, 170), (270, 130)]
    for k, (n_still, n_moving) in enumerate(sizes):
        still = box_surface(rng, n_still, [0, 0, 0], [3, 3, 2])
        moving = box_surface(rng, n_moving, [6, 0, 0], [8, 2, 1.5]) + [0.5 * k, 0, 0]
        points = np.vstack([still, moving])
        scan = np.c_[points, np.full(len(points), 0.5)].astype(np.float32)
        scan.tofile(folder / "velodyne" / f"{k:06d}.bin")
    identity = " ".join(["1", "0", "0", "0", "0", "1", "0", "0", "0", "0", "1", "0"])
    (folder / "poses.txt").write_text("\n".join([identity] * 3) + "\n")
    (folder / "calib.txt").write_text(f"Tr: {identity}\n")
    return folder, sizes


def test_kitti_sequence(tmp_path, scheduler, capsys):
    sequence, sizes = _write_kitti(tmp_path / "08")
    jobs = dataset_jobs(sequence)
    assert [job.name for job in jobs] == ["000000", "000001"]
    out = tmp_path / "out"
    assert (
        main(["run", str(sequence), "--pairs", "--out", str(out), "--scheduler", scheduler, "-q"])
        == 0
    )
    summary = pd.read_csv(out / "summary.csv")
    assert summary["n"].tolist() == [400, 390] and summary["n_sweep"].tolist() == [390, 400]
    for k, job in enumerate(jobs):
        scan = np.fromfile(sequence / "velodyne" / f"{k:06d}.bin", np.float32).reshape(-1, 4)
        nxt = np.fromfile(sequence / "velodyne" / f"{k + 1:06d}.bin", np.float32).reshape(-1, 4)
        expected = _cli_estimator().fit(scan[:, :3].astype(float), sweep=nxt[:, :3].astype(float))
        arrays, _ = read_job_result(out / "jobs" / f"{job.name}.npz")
        np.testing.assert_array_equal(arrays["labels"], expected.labels_)
        np.testing.assert_array_equal(arrays["indices"], np.arange(len(scan)))
        still = arrays["labels"][: sizes[k][0]]
        moving = arrays["labels"][sizes[k][0] :]
        assert len(np.unique(still)) == len(np.unique(moving)) == 1 and still[0] != moving[0]
    assert not (out / SCENE_FLOW_FOLDER).exists()  # the challenge's files: Argoverse 2 only
    # The velodyne folder alone is a folder of sweep files: the same pairs.
    alone = dataset_jobs(sequence / "velodyne")
    assert [job.name for job in alone] == ["000000", "000001"]
    for job, again in zip(jobs, alone, strict=True):
        one, two = job.load(), again.load()
        np.testing.assert_array_equal(one["X"], two["X"])
        np.testing.assert_array_equal(one["sweep"], two["sweep"])
    # A torn scan fails its jobs; KITTI has no ground map to drop by.
    whole = (sequence / "velodyne" / "000002.bin").read_bytes()
    (sequence / "velodyne" / "000002.bin").write_bytes(b"\0" * 20)
    assert (
        main(
            [
                "run",
                str(sequence),
                "--pairs",
                "--out",
                str(tmp_path / "torn"),
                "--scheduler",
                scheduler,
                "-q",
            ]
        )
        == 1
    )
    assert "1 job failed" in capsys.readouterr().err
    torn = pd.read_csv(tmp_path / "torn" / "summary.csv")
    assert torn["status"].tolist() == ["done", "error"]
    assert "000002.bin: 20 bytes is not a whole number of KITTI" in torn.loc[1, "error"]
    # KITTI has no ground map: --ground drop is the estimator's (Patchwork++).
    (sequence / "velodyne" / "000002.bin").write_bytes(whole)
    command = ["run", str(sequence), "--pairs", "--ground", "drop", "--scheduler", scheduler, "-q"]
    assert main([*command, "--out", str(tmp_path / "drop")]) == 0


def test_ros2_bag_with_a_topic(tmp_path, scheduler, capsys):
    pytest.importorskip("rosbags")
    from test_sequences import write_bag

    sequence, sizes = _write_kitti(tmp_path / "scans")
    scans = [
        np.fromfile(path, np.float32).reshape(-1, 4)[:, :3].copy()
        for path in sorted((sequence / "velodyne").glob("*.bin"))
    ]
    scans[0][3] = np.nan  # no return: left out of the fit, its row kept in the indices
    bag = write_bag(tmp_path / "drive", scans, topics=("/a", "/b"))
    out = tmp_path / "out"
    command = ["run", str(bag), "--pairs", "--scheduler", scheduler, "-q", "--out", str(out)]
    assert main(command) == 2  # two PointCloud2 topics: which one?
    assert "/a" in capsys.readouterr().err
    assert main([*command, "--topic", "/b"]) == 0
    summary = pd.read_csv(out / "summary.csv")
    assert summary["job"].tolist() == [0, 1] and summary["n"].tolist() == [399, 390]
    arrays, _ = read_job_result(out / "jobs" / "000000.npz")
    np.testing.assert_array_equal(arrays["indices"], np.delete(np.arange(400), 3))
    kept = scans[0][arrays["indices"]].astype(float)
    expected = _cli_estimator().fit(kept, sweep=scans[1].astype(float))
    np.testing.assert_array_equal(arrays["labels"], expected.labels_)
    still = arrays["labels"][: sizes[0][0] - 1]
    assert len(np.unique(still)) == 1 and len(np.unique(arrays["labels"])) == 2
    assert np.isnan(arrays["sweep_flow"][3]).all() and len(arrays["sweep_flow"]) == 400


# --------------------------------------------------------------------------- options
def test_default_out_names_differ_by_path_and_keep_ground_is_an_alias(tmp_path, capsys):
    from mmreg._cli import build_parser
    from mmreg._cli.dataset import default_out

    parser = build_parser()
    one = parser.parse_args(["run", str(tmp_path / "x" / "log")])
    two = parser.parse_args(["run", str(tmp_path / "y" / "log")])
    assert default_out(one) != default_out(two)
    assert default_out(one).startswith("log-mmreg-run-")
    # No --pairs: the sequence estimator on a log; a bare --pairs is today's auto.
    assert one.ground == "auto" and one.pairs is None
    assert parser.parse_args(["run", "log", "--pairs"]).pairs == "auto"
    assert parser.parse_args(["run", "log", "--keep-ground"]).ground == "keep"
    with pytest.raises(SystemExit):
        parser.parse_args(["run", "log", "--help"])
    assert "deprecated: the same as --ground keep" in " ".join(capsys.readouterr().out.split())


# --------------------------------------------------------------------------- Ctrl-C
@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals and process groups")
def test_ctrl_c_to_the_process_group_is_one_line_and_exit_130(tmp_path):
    data = tmp_path / "frames"
    data.mkdir()
    rng = np.random.default_rng(0)
    for k in range(12):
        still = box_surface(rng, 3000, [0, 0, 0], [10, 10, 4])
        moving = box_surface(rng, 1500, [12, 0, 0], [16, 2, 1.5]) + [0.5 * k, 0, 0]
        np.save(data / f"f{k:02d}.npy", np.vstack([still, moving]))
    out = tmp_path / "out"
    command = [sys.executable, "-m", "mmreg.cli", "run", str(data), "--pairs", "sweeps"]
    environment = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    process = subprocess.Popen(
        [*command, "--out", str(out), "--n-workers", "1", "-q"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group, as a terminal's foreground job
        env=environment,
        preexec_fn=terminal_sigint,
    )
    try:
        deadline = time.monotonic() + 240
        # The workers are up and running jobs once the first result is written.
        while not list((out / "jobs").glob("*.npz")) and process.poll() is None:
            assert time.monotonic() < deadline, "no job finished"
            time.sleep(0.05)
        assert process.poll() is None, process.communicate()
        os.killpg(process.pid, signal.SIGINT)  # what Ctrl-C in a terminal does
        stdout, stderr = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
    assert process.returncode == 130, stderr
    assert stderr == "mmreg: interrupted\n" and stdout == ""
    done = sorted(p.name for p in (out / "jobs").iterdir())
    assert 1 <= len(done) < 11 and all(name.endswith(".npz") for name in done)
