"""`mmreg run` and `mmreg register` on LiDAR frames as users keep them: folders of frames
of one size (fixed-size downsampling), frames replaced between two runs.

The frames are ray-cast streets (``make_lidar_sweeps``, 512 azimuths): the sensor drives
2 m between the two sweeps, so rows of the two scans stacked row by row (the same ray,
not the same point) read as a static world at rest.
"""

import json
import os

import numpy as np
import pandas as pd
import pytest

from mmreg import MultiModelRegistration, SweepRegistration
from mmreg.cli import main
from mmreg.datasets import make_lidar_sweeps
from mmreg.runner import SweepPairJob, dataset_jobs, read_job_result, run_dataset


def street(n_azimuths=512):
    """Two sweeps of a street; the sensor drives 2 m along x between them."""
    return make_lidar_sweeps(n_azimuths=n_azimuths, ego_speed=20.0, random_state=0)


def same_size(scene, n=12000):
    """Both sweeps cut to ``n`` rows by the same sorted random rows (a fixed-size
    downsampling): row i of each is about the same ray of the scanner."""
    rows = np.sort(np.random.default_rng(0).choice(min(len(scene.a), len(scene.sweep)), n, False))
    return scene.a[rows], scene.sweep[rows]


def sweep_estimator(**params):
    """What 'mmreg run' fits on sweep pairs with its defaults."""
    inner = MultiModelRegistration(variant="sweep", tau=5.0, max_iter=10, random_state=0)
    return SweepRegistration(inner, random_state=0, **params)


def static_translation(arrays):
    """The fitted static world's translation of a job's result (its largest cluster)."""
    labels = arrays["labels"]
    static = np.argmax(np.bincount(labels[labels >= 0]))
    return arrays["translations"][static]


# --------------------------------------------------------------------------- item 1
def test_a_folder_of_equal_size_frames_is_registered_as_sweeps(tmp_path, scheduler):
    scene = street()
    a, b = same_size(scene)
    folder = tmp_path / "frames"
    folder.mkdir()
    np.save(folder / "000000.npy", a)
    np.save(folder / "000001.npy", b)
    jobs = dataset_jobs(folder)
    assert [type(job) for job in jobs] == [SweepPairJob]
    out = tmp_path / "out"
    command = ["run", str(folder), "--pairs", "--out", str(out), "--scheduler", scheduler]
    assert main([*command, "-q"]) == 0
    summary = pd.read_csv(out / "summary.csv")
    assert summary["pairs"].tolist() == ["sweeps"] and summary["n_sweep"].tolist() == [len(b)]
    arrays, _ = read_job_result(out / "jobs" / "000000__000001.npz")
    expected = sweep_estimator().fit(a, sweep=b)
    np.testing.assert_array_equal(arrays["labels"], expected.labels_)
    # The 2 m drive is found (row by row, it read as 0 m, with 42 clusters).
    truth = scene.transforms[0][:3, 3]
    assert np.linalg.norm(static_translation(arrays) - truth) < 0.1 * np.linalg.norm(truth)


def test_stacked_scans_are_refused_and_correspondences_are_not():
    from mmreg.sweeps._stacked_rows import (
        MAX_COHERENCE,
        MAX_STILL_ONLY,
        STILL_SPACINGS,
        stacked_sweeps,
    )

    scene = street()
    found = stacked_sweeps(*same_size(scene))
    assert found["stacked"] and found["still_only"] > 2 * MAX_STILL_ONLY
    # Each scan cut by evenly spaced rows of its own: the rows drift by a few rays and
    # follow nothing, but alike from row to row.
    n = 6000
    a, b = (p[np.linspace(0, len(p) - 1, n).astype(int)] for p in (scene.a, scene.sweep))
    found = stacked_sweeps(a, b)
    assert (
        found["stacked"]
        and found["misfit_spacings"] > 2 * STILL_SPACINGS
        and found["coherence"] < MAX_COHERENCE / 4
    )
    noisy = scene.a + scene.flow + np.random.default_rng(3).normal(0, 0.3, scene.a.shape)
    found = stacked_sweeps(scene.a, noisy)  # noise: misplaced, but not alike
    assert not found["stacked"] and found["coherence"] > 2 * MAX_COHERENCE
    for b in (scene.a + scene.flow, scene.a + scene.flow + 0.05 * np.ones(3)):
        found = stacked_sweeps(scene.a, b)  # where each point went (a bias: still so)
        assert not found["stacked"] and found["still_only"] < MAX_STILL_ONLY / 2
    # Half the rows wrong (their b-points shuffled): correspondences still.
    b = scene.a + scene.flow
    wrong = np.random.default_rng(1).random(len(b)) < 0.5
    b[wrong] = b[np.random.default_rng(2).permutation(np.flatnonzero(wrong))]
    assert not stacked_sweeps(scene.a, b)["stacked"]
    # Scale-free: the same rows in millimetres give the same shares.
    a, b = same_size(scene)
    metres, millimetres = stacked_sweeps(a, b), stacked_sweeps(1000 * a, 1000 * b)
    assert millimetres["still_only"] == pytest.approx(metres["still_only"], abs=0.02)
    assert millimetres["stacked"]


def test_aligned_stacked_scans_fail_and_the_advice_reuses_the_out(tmp_path, scheduler, capsys):
    a, b = same_size(street())
    folder = tmp_path / "frames"
    folder.mkdir()
    np.save(folder / "000000.npy", a)
    np.save(folder / "000001.npy", b)
    out = tmp_path / "out"
    command = ["run", str(folder), "--out", str(out), "--scheduler", scheduler, "-q"]
    assert main([*command, "--pairs", "aligned"]) == 1
    error = capsys.readouterr().err
    assert "stacked row by row" in error and "drop --pairs aligned" in error
    # Following the advice into the same --out: the failed run is replaced (by the
    # sequence estimator on the two frames, as raw sweeps).
    assert main(command) == 0
    assert json.loads((out / "run.json").read_text())["configuration"]["kind"] == "logs"
    assert sorted(p.name for p in (out / "labels").iterdir()) == ["000000.label", "000001.label"]
    assert not (out / "jobs").exists()
    # A run with results is still guarded.
    assert main([*command, "--pairs", "aligned"]) == 2
    assert "--overwrite" in capsys.readouterr().err


def test_register_target_with_two_lidar_frames_is_refused(tmp_path, capsys):
    scene = street()
    a, b = same_size(scene)
    np.save(tmp_path / "a.npy", a)
    np.save(tmp_path / "b.npy", b)
    out = tmp_path / "r"
    assert main(["register", str(tmp_path / "a.npy"), "--target", str(tmp_path / "b.npy"),
                 "--out", str(out), "-q"]) == 2  # fmt: skip
    error = capsys.readouterr().err
    assert "stacked row by row" in error and f"--sweep {tmp_path / 'b.npy'}" in error
    assert not out.exists()
    # The same rows as one (n, 6) file: refused too.
    np.save(tmp_path / "ab.npy", np.hstack([a, b]))
    assert main(["register", str(tmp_path / "ab.npy"), "--out", str(out), "-q"]) == 2
    assert "stacked row by row" in capsys.readouterr().err
    # Where each point went: accepted, and the drive found.
    np.save(tmp_path / "moved.npy", scene.a + scene.flow)
    np.save(tmp_path / "first.npy", scene.a)
    command = ["register", str(tmp_path / "first.npy"), "--target", str(tmp_path / "moved.npy")]
    assert main([*command, "--out", str(out), "-q"]) == 0


def test_a_folder_mixing_sweep_files_and_clouds_names_pattern(tmp_path, scheduler, capsys):
    scene = street(256)
    folder = tmp_path / "mixed"
    folder.mkdir()
    for k, points in enumerate((scene.a, scene.sweep)):
        scan = np.c_[points, np.zeros(len(points))].astype(np.float32)
        scan.tofile(folder / f"{k:06d}.bin")
    from mmreg import io as mmio

    mmio.write_point_cloud(folder / "extra.pcd", scene.a[:100])
    with pytest.raises(ValueError, match=r"2 \.bin, 1 \.pcd.*pattern='\*\.bin'"):
        dataset_jobs(folder)  # the .bin files were left out without a word
    out = tmp_path / "out"
    command = ["run", str(folder), "--pairs", "--out", str(out), "--scheduler", scheduler, "-q"]
    assert main(command) == 2
    error = capsys.readouterr().err
    assert "--pattern '*.bin'" in error and "pattern=" not in error
    assert main([*command, "--pattern", "*.bin"]) == 0
    summary = pd.read_csv(out / "summary.csv", dtype={"job": str})
    assert summary["job"].tolist() == ["000000"] and summary["n"].tolist() == [len(scene.a)]
    assert json.loads((out / "run.json").read_text())["configuration"]["pattern"] == "*.bin"
    # register reads the same folder with the same option.
    register = ["register", str(folder), "--frame", "0", "-q", "--out", str(tmp_path / "r")]
    assert main(register) == 2
    error = capsys.readouterr().err
    assert "--pattern '*.bin'" in error and "pattern=" not in error
    assert main([*register, "--pattern", "*.bin"]) == 0


def test_an_empty_folder_names_every_kind_of_frame(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match=r"\.bin") as error:
        dataset_jobs(tmp_path / "empty")
    assert ".pcd.bin" in str(error.value) and ".ply" in str(error.value)


# --------------------------------------------------------------------------- item 2
def _write_aligned(folder, k, shift):
    """Index-aligned frame ``k``: a block at rest and a box moved by ``shift`` along x."""
    rng = np.random.default_rng(0)
    block = rng.uniform([0, 0, 0], [2, 2, 2], (150, 3))
    box = rng.uniform([6, 0, 0], [7, 1, 1], (80, 3))
    np.save(folder / f"frame{k}.npy", np.vstack([block, box + [shift, 0, 0]]))


def test_a_replaced_frame_runs_its_jobs_again(tmp_path, scheduler, capsys):
    folder = tmp_path / "frames"
    folder.mkdir()
    for k in range(4):
        _write_aligned(folder, k, 0.5 * k)
    out = tmp_path / "out"
    command = ["run", str(folder), "--pairs", "aligned", "--tau", "1"]
    command += ["--out", str(out), "--scheduler", scheduler]
    assert main([*command, "-q"]) == 0
    # frame2 replaced by another frame of the same size: the box 40 m away.
    path = folder / "frame2.npy"
    before = path.stat().st_mtime_ns
    _write_aligned(folder, 2, 40.0)
    os.utime(path, ns=(before + 10**9, before + 10**9))  # a coarse clock still tells
    capsys.readouterr()
    assert main(command) == 0
    printed = capsys.readouterr().out
    assert "2 jobs run again: a file read changed" in printed and "frame2.npy" in printed
    assert "1 from an earlier run" in printed
    summary = pd.read_csv(out / "summary.csv", keep_default_na=False)
    assert summary["resumed"].tolist() == [True, False, False]
    assert summary["changed_input"].tolist() == ["", str(path), str(path)]
    # The results are those of the new frame: the box moves 39.5 m to it, 38.5 m back.
    for name, moved in (("frame1__frame2", 39.5), ("frame2__frame3", -38.5)):
        arrays, _ = read_job_result(out / "jobs" / f"{name}.npz")
        assert np.nanmedian(arrays["flow"][150:, 0]) == pytest.approx(moved, abs=0.1)
    # A third run reads every result back.
    assert main([*command, "-q"]) == 0
    assert pd.read_csv(out / "summary.csv")["resumed"].all()


def test_results_record_the_files_read(tmp_path, scheduler):
    folder = tmp_path / "frames"
    folder.mkdir()
    for k in range(3):
        _write_aligned(folder, k, 0.5 * k)
    jobs = dataset_jobs(folder, pairs="aligned")
    estimator = MultiModelRegistration(tau=1.0, random_state=0)
    run_dataset(jobs, estimator, tmp_path / "out", scheduler=scheduler, progress=False)
    from mmreg.runner import _read_result

    _, meta = _read_result(tmp_path / "out" / "jobs" / f"{jobs[0].name}.npz")
    stat = (folder / "frame1.npy").stat()
    assert meta["inputs"][str(folder / "frame1.npy")] == [stat.st_size, stat.st_mtime_ns]
    assert sorted(meta["inputs"]) == [str(folder / "frame0.npy"), str(folder / "frame1.npy")]
