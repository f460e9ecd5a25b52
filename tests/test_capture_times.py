"""Capture times from files to SweepRegistration: the dataset runner and the command line.

The scene: an Argoverse 2 log (written here, the real file formats) of a static world and
a car driving 8 m/s, which each sweep's two LiDAR heads see 50 ms apart, so the car is
two copies 0.4 m apart within one sweep. Registered with the points' capture times
(``offset_ns``) the car's flow is recovered to a few centimetres; without them it is
off by a tenth of a metre and more.
"""

import json
import re

import numpy as np
import pandas as pd
import pytest

from mmreg import MultiModelRegistration, SweepRegistration
from mmreg import io as mmio
from mmreg.cli import main
from mmreg.datasets import load_argoverse2, write_argoverse2_log
from mmreg.runner import _takes_times, dataset_jobs, read_job_result, run_dataset

# Static boxes (centre, size) and one car, in the city frame, all above the ground (z = 0,
# removed within 0.3 m).
STATIC = [
    ((0.0, 0.0, 2.5), (6.0, 2.0, 3.0)),
    ((0.0, 12.0, 2.5), (4.0, 4.0, 4.0)),
    ((12.0, 6.0, 2.5), (2.0, 8.0, 3.0)),
]
CAR = ((-9.0, 6.0, 1.5), (4.0, 2.0, 1.5))
INTERVAL = 0.1
STAMPS = (315966265259836000, 315966265259836000 + 100_000_000)
VELOCITY = np.array([8.0, 0.0, 0.0])  # m/s in the city frame
EGO_STEP = np.array([0.3, 0.0, 0.0])  # the ego vehicle's motion between the sweeps
# Points of the static boxes (each) and of the car in the two sweeps.
SIZES = ((2000, 1600), (2500, 2000))
# The two heads' capture times of the car in each sweep (it has moved in azimuth).
HEAD_TIMES = ((0.01, 0.06), (0.04, 0.09))
# The surfaces are sampled about 0.1 m apart: the deskewed car's flow is within a small
# share of that, the skewed one's is off by two of these and more.
SPACING = 0.05


def _pose(translation):
    T = np.eye(4)
    T[:3, 3] = translation
    return T


def _box_surface(center, size, n, rng):
    size = np.asarray(size)
    areas = np.array([size[1] * size[2], size[0] * size[2], size[0] * size[1]]).repeat(2)
    face = rng.choice(6, n, p=areas / areas.sum())
    points = rng.uniform(-0.5, 0.5, (n, 3))
    points[np.arange(n), face // 2] = np.where(face % 2, 0.5, -0.5)
    return points * size + center


def _sweep(rng, k, n_static, n_car):
    """Sweep ``k``'s points in its ego frame and their capture offsets (ns)."""
    parts, offsets = [], []
    for center, size in STATIC:
        parts.append(_box_surface(center, size, n_static, rng))
        offsets.append(rng.uniform(0.0, INTERVAL, n_static))
    for tau in HEAD_TIMES[k]:
        # Where the car was when this head saw it.
        parts.append(
            _box_surface(CAR[0], CAR[1], n_car // 2, rng) + VELOCITY * (k * INTERVAL + tau)
        )
        offsets.append(np.full(n_car // 2, tau))
    points = np.vstack(parts) - k * EGO_STEP  # city frame -> ego frame k
    return points, np.round(np.concatenate(offsets) * 1e9).astype(np.int64)


def write_skewed_log(folder, *, zero_offsets=False, random_state=0):
    """The two-sweep log; the car's cuboid holds both copies (its pose at each timestamp)."""
    rng = np.random.default_rng(random_state)
    sweeps, offsets, cuboids = {}, {}, []
    for k, (n_static, n_car) in enumerate(SIZES):
        points, offset = _sweep(rng, k, n_static, n_car)
        sweeps[STAMPS[k]] = points
        offsets[STAMPS[k]] = np.zeros_like(offset) if zero_offsets else offset
        # The cuboid at the reference time, grown to hold the copies of the two heads.
        center = np.asarray(CAR[0]) + VELOCITY * (k * INTERVAL + 0.035) - k * EGO_STEP
        cuboids.append(
            dict(
                timestamp_ns=STAMPS[k],
                track_uuid="car",
                category="REGULAR_VEHICLE",
                size=(4.6, 2.2, 1.7),
                pose=_pose(center),
            )
        )
    ego = {t: _pose(k * EGO_STEP) for k, t in enumerate(STAMPS)}
    return write_argoverse2_log(folder, sweeps, ego, cuboids, offsets_ns=offsets)


def _estimator():
    inner = MultiModelRegistration(variant="sweep", tau=2.0, random_state=0)
    return SweepRegistration(
        inner, max_distance=1.5, island_radius=1.0, min_island_size=20, random_state=0
    )


def _car_error(flow, pair):
    return np.abs(flow - pair.flow)[pair.labels == 1].max()


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    return write_skewed_log(tmp_path_factory.mktemp("times") / "log")


@pytest.fixture(scope="module")
def pair(log):
    pair = load_argoverse2(log, drop_ground=True)
    # The scene as meant: every point kept, the car's points labelled and moving.
    (n_static, n_car), (m_static, m_car) = SIZES
    assert len(pair.a) == 3 * n_static + n_car and len(pair.sweep2) == 3 * m_static + m_car
    assert np.unique(pair.labels).tolist() == [0, 1] and (pair.labels == 1).sum() == n_car
    assert np.allclose(pair.times[pair.labels == 1], np.repeat(HEAD_TIMES[0], n_car // 2))
    return pair


# --------------------------------------------------------------------------- the runner
class _NoTimes(SweepRegistration):
    """A sweep estimator whose fit takes the sweep but no capture times."""

    def fit(self, X, y=None, *, sweep=None):
        return super().fit(X, sweep=sweep)


class _Catchall(SweepRegistration):
    def fit(self, X, y=None, **params):
        return super().fit(X, **params)


def _run(jobs, estimator, out, scheduler):
    summary = run_dataset(jobs, estimator, out, scheduler=scheduler, progress=False)
    assert summary.loc[0, "status"] == "done", summary.loc[0, "error"]
    return read_job_result(out / "jobs" / f"{jobs[0].name}.npz")[0]["flow"], summary.iloc[0]


def test_the_runner_hands_the_capture_times_to_fit(log, pair, scheduler, tmp_path):
    jobs = dataset_jobs(log, pairs="sweeps", ground="drop")
    assert len(jobs) == 1
    data = jobs[0].load()
    for key, value in [("times", pair.times), ("sweep_times", pair.sweep2_times)]:
        np.testing.assert_array_equal(data[key], value)
    assert data["interval"] == pytest.approx(INTERVAL)
    timed, timed_row = _run(jobs, _estimator(), tmp_path / "timed", scheduler)
    untimed = dataset_jobs(log, pairs="sweeps", ground="drop", capture_times=False)
    assert "times" not in untimed[0].load()
    skewed, skewed_row = _run(untimed, _estimator(), tmp_path / "skewed", scheduler)
    assert timed_row["capture_times"] and not skewed_row["capture_times"]
    # What the runner fits is a plain fit with the times.
    expected = _estimator().fit(
        pair.a, sweep=pair.sweep2, times=pair.times, sweep_times=pair.sweep2_times, interval=0.1
    )
    np.testing.assert_array_equal(timed, expected.flow_.astype(np.float32))  # as kept
    # The times change the result: the car's flow is right with them, not without.
    assert _car_error(timed, pair) < SPACING < 2 * SPACING < _car_error(skewed, pair)
    # The summary's columns say so too (the car: the one moving object, label 1).
    car = pair.labels == 1
    epe = np.linalg.norm(timed - pair.flow, axis=1)
    assert timed_row["epe_moving"] == pytest.approx(epe[car].mean())
    assert timed_row["epe_static"] == pytest.approx(epe[~car].mean())
    assert timed_row["epe_moving"] < SPACING < skewed_row["epe_moving"]
    assert timed_row["moving_found"] == skewed_row["moving_found"] == 1.0
    # A fit that does not name the times gets none, from the same jobs: as without.
    assert _takes_times(_estimator()) and not _takes_times(MultiModelRegistration())
    assert not _takes_times(_Catchall())  # **params: it may not route them
    params = _estimator().get_params(deep=False)
    plain, plain_row = _run(jobs, _NoTimes(**params), tmp_path / "plain", scheduler)
    assert not plain_row["capture_times"]
    np.testing.assert_array_equal(plain, skewed)


def test_all_zero_offsets_are_no_times(tmp_path):
    # write_argoverse2_log's default, and logs without capture times: nothing to deskew.
    log = write_skewed_log(tmp_path / "log", zero_offsets=True)
    data = dataset_jobs(log, pairs="sweeps", ground="drop")[0].load()
    assert not {"times", "sweep_times", "interval"} & set(data)
    with pytest.raises(TypeError, match="capture_times must be True or False"):
        dataset_jobs(log, pairs="sweeps", ground="drop", capture_times="no")


def test_mmreg_run_passes_the_times_unless_told_not_to(log, scheduler, tmp_path, capsys):
    common = ["run", str(log), "--pairs", "--ground", "drop", "--scheduler", scheduler, "-q"]
    assert main([*common, "--out", str(tmp_path / "with")]) == 0
    assert main([*common, "--out", str(tmp_path / "without"), "--no-capture-times"]) == 0
    with_times = pd.read_csv(tmp_path / "with" / "summary.csv")
    without = pd.read_csv(tmp_path / "without" / "summary.csv")
    assert with_times["capture_times"].tolist() == [True]
    assert without["capture_times"].tolist() == [False]
    # Its defaults (--method sweep --tau 5) find the car either way; only the times put it
    # where it goes.
    assert (with_times["moving_found"] == 1.0).all() and (without["moving_found"] == 1.0).all()
    assert with_times.loc[0, "epe_moving"] < SPACING < 2 * SPACING < without.loc[0, "epe_moving"]
    config = json.loads((tmp_path / "without" / "run.json").read_text())["configuration"]
    assert config["capture_times"] is False
    # An earlier run with the other setting is not resumed as if it were this one.
    assert main([*common, "--out", str(tmp_path / "with"), "--no-capture-times"]) == 2
    assert "other options" in capsys.readouterr().err


# --------------------------------------------------------------------------- mmreg register
@pytest.fixture(scope="module")
def files(pair, tmp_path_factory):
    folder = tmp_path_factory.mktemp("register")
    mmio.write_point_cloud(folder / "a.ply", pair.a)
    mmio.write_point_cloud(folder / "sweep.ply", pair.sweep2)
    np.save(folder / "times.npy", pair.times)
    (folder / "sweep_times.csv").write_text(
        "time\n" + "".join(f"{t!r}\n" for t in pair.sweep2_times.tolist())
    )
    np.save(folder / "flow.npy", pair.flow)
    return folder


def _register(files, out, *extra):
    command = ["register", str(files / "a.ply"), "--sweep", str(files / "sweep.ply")]
    command += ["--tau", "2", "--out", str(out), "-q", *extra]
    return main(command)


def _flow(out):
    X = np.load(out / "X.npy")
    return X[:, 3:] - X[:, :3]


def test_register_deskews_with_the_capture_times(files, pair, tmp_path):
    timing = ["--times", str(files / "times.npy"), "--sweep-times"]
    timing += [str(files / "sweep_times.csv"), "--interval", "0.1"]
    assert _register(files, tmp_path / "timed", *timing) == 0
    assert _register(files, tmp_path / "skewed") == 0
    timed, skewed = _flow(tmp_path / "timed"), _flow(tmp_path / "skewed")
    assert _car_error(timed, pair) < SPACING < 2 * SPACING < _car_error(skewed, pair)
    run = json.loads((tmp_path / "timed" / "run.json").read_text())
    assert run["interval"] == 0.1 and run["times"] == str(files / "times.npy")
    assert run["sweep_times"] == str(files / "sweep_times.csv")


def test_register_takes_the_capture_times_of_two_feather_sweeps(log, files, pair, tmp_path):
    # The log's own files: offset_ns of both, and 0.1 s between their names' timestamps.
    lidar = log / "sensors" / "lidar"
    command = ["register", str(lidar / f"{STAMPS[0]}.feather"), "--sweep"]
    command += [str(lidar / f"{STAMPS[1]}.feather"), "--tau", "2", "-q"]
    assert main([*command, "--out", str(tmp_path / "feather")]) == 0
    run = json.loads((tmp_path / "feather" / "run.json").read_text())
    assert run["file_times"] is True and run["interval"] == 0.1
    # The same fit as with the times given by hand.
    timing = ["--times", str(files / "times.npy"), "--sweep-times"]
    timing += [str(files / "sweep_times.csv"), "--interval", "0.1"]
    assert _register(files, tmp_path / "timed", *timing) == 0
    np.testing.assert_array_equal(_flow(tmp_path / "feather"), _flow(tmp_path / "timed"))
    assert _car_error(_flow(tmp_path / "feather"), pair) < SPACING


def _write(folder, name, values):
    np.save(folder / name, np.asarray(values))
    return str(folder / name)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--times", "T"], "go together .* missing --sweep-times and --interval"),
        (["--times", "T", "--sweep-times", "S"], "missing --interval"),
        (["--times", "SHORT", "--sweep-times", "S", "--interval", "0.1"], "5 capture times"),
        (["--times", "T", "--sweep-times", "T", "--interval", "0.1"], "capture times for the"),
        (["--times", "NAN", "--sweep-times", "S", "--interval", "0.1"], "NaN or infinity"),
        (["--times", "NS", "--sweep-times", "S", "--interval", "0.1"], "not nanoseconds"),
        (["--times", "2D", "--sweep-times", "S", "--interval", "0.1"], "one column"),
        (["--times", "T", "--sweep-times", "MISSING", "--interval", "0.1"], "no such file"),
    ],
)
def test_register_refuses_bad_times(files, pair, tmp_path, capsys, options, message):
    n, m = len(pair.a), len(pair.sweep2)
    assert m != n  # the two sweeps' times cannot be swapped unnoticed
    paths = {
        "T": str(files / "times.npy"),
        "S": str(files / "sweep_times.csv"),
        "SHORT": _write(tmp_path, "short.npy", np.zeros(5)),
        "NAN": _write(tmp_path, "nan.npy", np.r_[np.zeros(n - 1), np.nan]),
        "NS": _write(tmp_path, "ns.npy", pair.times * 1e9),
        "2D": _write(tmp_path, "two.npy", np.zeros((n, 2))),
        "MISSING": str(tmp_path / "missing.npy"),
    }
    assert _register(files, tmp_path / "out", *[paths.get(o, o) for o in options]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert err.startswith("mmreg: error: ") and re.search(message, err), err
    assert not (tmp_path / "out").exists()


def test_register_times_need_the_second_sweep(files, tmp_path, capsys):
    command = ["register", str(files / "a.ply"), "--flow", str(files / "flow.npy")]
    command += ["--times", str(files / "times.npy"), "--out", str(tmp_path / "out")]
    assert main(command) == 2
    err = capsys.readouterr().err
    assert "give it with --sweep" in err and not (tmp_path / "out").exists()


def test_read_times_reads_one_column_strictly(tmp_path):
    (tmp_path / "t.txt").write_text("0.01\n-0.02\n0.1\n")
    assert mmio.read_times(tmp_path / "t.txt").tolist() == [0.01, -0.02, 0.1]
    np.save(tmp_path / "t.npy", np.array([[0.5], [0.25]], dtype=np.float32))
    assert mmio.read_times(tmp_path / "t.npy").tolist() == [0.5, 0.25]
    np.save(tmp_path / "b.npy", np.array([True, False]))
    with pytest.raises(TypeError, match="booleans"):
        mmio.read_times(tmp_path / "b.npy")
    (tmp_path / "w.csv").write_text("time\nsoon\n")
    with pytest.raises(TypeError, match="not a number"):
        mmio.read_times(tmp_path / "w.csv")
    (tmp_path / "t.ply").write_text("ply\n")
    with pytest.raises(ValueError, match="unknown extension"):
        mmio.read_times(tmp_path / "t.ply")
