"""Run an estimator over a dataset: independent jobs, resumable, one file per job.

:func:`run_dataset` fits a copy of the estimator on every job of a dataset (see
:func:`dataset_jobs`), in this process or on a Dask cluster through joblib's ``"dask"``
backend (the machinery ``paper/`` sweeps with; :mod:`mmreg.runner._workers` chooses),
writes each job's result into ``OUT/jobs/<name>.npz`` whole or not at all, skips the
jobs whose complete result is already there (of the same job, estimator and input files:
a job records the size and modification time of every file it reads, ``job.inputs()``,
and runs again when one changed), and ends with a summary table, one row per job
(``OUT/summary.parquet`` and ``summary.csv``).

Each result ``.npz`` (compressed) holds ``labels`` (the smallest integer type),
``rotations``, ``translations``, ``sigmas``, ``flow`` (float32: the rigid flow,
:attr:`~mmreg.MultiModelRegistration.flow_`), ``moving`` (when the estimator reports
it), ``static_cluster`` (the static world's cluster), ``indices`` and ``meta``: a JSON
string with the job's summary row and the fingerprint of (job, estimator) the result
belongs to. ``indices`` (n,) are the rows of the job's input the fit saw: for a LiDAR
sweep pair, the rows of the first sweep's file (``--ground drop`` leaves the ground rows
out), so ``labels[k]`` and ``flow[k]`` belong to row ``indices[k]`` of the sweep as the
file holds it; ``arange(n)`` for frames and correspondence files. Rows that hold no return (NaN, or
several all-zero rows: a bag with ``is_dense`` false, an organised cloud, a KITTI scan)
are left out of every job, in both sweeps, and counted (``n_no_return``). A fit that
finds the ego vehicle's own body (:attr:`~mmreg.SweepRegistration.ego_body_mask_`)
stores ``ego_body`` (bool, one per label): those rows are labelled -1 but are no
outliers (``n_ego_body`` counts them apart). A sweep
pair also stores ``sweep_flow`` (float32, one row per row of the file; the file keeps
only its rows that are not the fit's own flow, ``sweep_flow_rest`` with the mask
``sweep_flow_own``, and :func:`read_job_result` restores it whole),
``sweep_dynamic`` (bool) and ``sweep_valid`` (bool): the flow of every row, the rows the
fit did not see (or left without a motion: outliers) moving with the fitted static
world, whether it moves 0.05 m or more beyond that motion (the Argoverse 2 challenge's
rule; never the ego vehicle's body), and whether the row is a return from the world (not
a row without a return, not the ego vehicle's body: the annotations' ``is_valid``). For
an Argoverse 2 log the flow and ``is_dynamic`` also go to
``OUT/av2_scene_flow/<log>/<timestamp_ns>.feather``, the scene-flow challenge's format
(:func:`write_scene_flow`: four columns, as its submission check demands; no
``is_valid``), ready for the official evaluation.

A job of two sweeps (:func:`dataset_jobs`: LiDAR logs by default) loads the first sweep
``X`` (n, 3) (or ``[a | a + flow]`` (n, 6) with a network's flow, refinement mode) and
the second ``sweep`` (m, 3); it is fitted as ``fit(X, sweep=sweep)``, by
:func:`default_sweep_estimator` unless another estimator taking ``sweep`` is given.
When the job also loads the points' capture times (``times``, ``sweep_times``) and the
``interval`` between the sweeps (Argoverse 2, bags with per-point times), they are
passed too if the estimator's ``fit`` names all three as parameters
(:class:`~mmreg.SweepRegistration` deskews the moving objects with them); the map's
ground points of both sweeps (``ground``, ``sweep_ground``: boolean masks, Argoverse 2
logs with a map, ``ground="auto"``) likewise go to a ``fit`` that names both. Any other
estimator is fitted without the times, and without the ground rows when it cannot take
the masks (as ``ground="drop"``). The summary's ``capture_times`` column says whether a
job's fit had the times, ``ground`` what became of the known ground (``"masks"``,
``"dropped"``, ``"kept"``); ``pairs`` says what it was given
(``"sweeps"``, ``"flow"``: a network's flow, ``"truth"``: the ground-truth flow, its
scores then measure the clustering alone, also flagged by ``truth_fed``,
``"correspondences"``).

Ctrl-C: the workers of the LocalCluster started here ignore SIGINT (a terminal sends it
to the whole process group); the KeyboardInterrupt is this process's, which closes the
cluster on its way out.

Whole logs: :func:`log_jobs` lists the LiDAR logs of a dataset (one, or a folder of
them) and :func:`run_logs` fits a :class:`~mmreg.SequenceRegistration` on each as one
task, resumable log by log, writing per log ``labels/<frame>.label`` (LiDAR-MOS labels
of every row of every frame), ``tracks.csv``, ``poses.txt`` and ``frames.csv`` (see
:mod:`mmreg.runner._logs`); :func:`fit_log` is one log's fit, without Dask.

Ground: a job of a log with a map (Argoverse 2) carries out ``ground="drop"`` itself and
hands the map's masks with ``"auto"``; without a map (KITTI, bags, folders of sweeps) the
job's explicit ``"keep"`` or ``"drop"`` is set as the estimator's ``ground`` parameter
(:class:`~mmreg.SweepRegistration`: Patchwork++ finds the ground), as ``mmreg register``
does, and the summary's ``ground`` says ``"found"`` (joined to the static world) or
``"dropped"`` with ``n_ground`` points when the fit found one.
"""

import contextlib
import hashlib
import inspect
import json
import logging
import math
import os
import signal
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from mmreg import _interrupt
from mmreg.io._arrays import _load_npz
from mmreg.runner._jobs import (
    Argoverse2PairJob,
    Argoverse2SweepPairJob,
    BrokenLogJob,
    CorrespondenceFileJob,
    FramePairJob,
    SequenceSweepPairJob,
    SweepPairJob,
    check_jobs,
    dataset_jobs,
    warning_columns,
)
from mmreg.runner._logs import LogJob, fit_log, log_jobs, run_logs
from mmreg.runner._workers import run_tasks, task_threads

__all__ = [
    "Argoverse2PairJob",
    "Argoverse2SweepPairJob",
    "BrokenLogJob",
    "CorrespondenceFileJob",
    "FramePairJob",
    "LogJob",
    "SequenceSweepPairJob",
    "SweepPairJob",
    "dataset_jobs",
    "default_estimator",
    "default_sweep_estimator",
    "fit_log",
    "log_jobs",
    "read_job_result",
    "run_dataset",
    "run_logs",
    "sweep_flow",
    "sweep_valid",
    "write_scene_flow",
]

JOBS_FOLDER = "jobs"
RESULT_KEYS = ("labels", "rotations", "translations", "sigmas", "flow", "indices", "meta")
# Where the flow of every sweep goes in the Argoverse 2 scene-flow challenge's layout.
SCENE_FLOW_FOLDER = "av2_scene_flow"
# One picture per job (``pictures=True``), and the key that carries it from the worker.
PICTURES_FOLDER = "pictures"
_PICTURE = "picture_png"
SCENE_FLOW_COLUMNS = ("flow_tx_m", "flow_ty_m", "flow_tz_m")
# The columns every summary starts with; metrics and estimator-specific numbers follow.
SUMMARY_COLUMNS = [
    "job",
    "status",
    "n",
    "n_clusters",
    "n_moving",
    "n_outliers",
    "n_ego_body",
    "n_no_return",
    "n_iter",
    "converged",
    "load_s",
    "fit_s",
    "resumed",
    "error",
]


def default_estimator():
    """The estimator for LiDAR sweeps: ``MultiModelRegistration(variant="sweep", tau=5)``."""
    from mmreg import MultiModelRegistration

    return MultiModelRegistration(variant="sweep", tau=5.0, random_state=0)


def default_sweep_estimator():
    """The estimator for pairs of raw sweeps: ``SweepRegistration(default_estimator())``."""
    from mmreg import SweepRegistration

    return SweepRegistration(default_estimator(), random_state=0)


# Jobs whose load() gives a second sweep to fit on (fit(X, sweep=...)).
_SWEEP_JOBS = (SweepPairJob, Argoverse2SweepPairJob, SequenceSweepPairJob)
# What a job of two sweeps may add for fit: the capture times of both sweeps' points and
# the seconds between the sweeps' reference times (SweepRegistration.fit's names).
_TIMING = ("times", "sweep_times", "interval")
# The known ground points of both sweeps (boolean masks), for a fit that names them.
_GROUND = ("ground", "sweep_ground")
# The Argoverse 2 challenge's dynamic threshold: metres of flow beyond the ego flow.
DYNAMIC_THRESHOLD = 0.05


def _fit_parameters(estimator):
    """The names ``estimator.fit`` takes as named parameters, or None if it has no signature.

    A ``**kwargs`` catch-all does not count: a Pipeline's ``fit(X, **params)`` refuses
    what it does not route.
    """
    try:
        parameters = inspect.signature(estimator.fit).parameters.values()
    except (TypeError, ValueError):
        return None
    named = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    return {p.name for p in parameters if p.kind in named}


def _named(estimator):
    """The names ``estimator.fit`` takes (none when it has no signature)."""
    return _fit_parameters(estimator) or set()


def _takes_sweep(estimator):
    names = _fit_parameters(estimator)
    return names is None or "sweep" in names  # no signature to read: let fit decide


def _takes_ground(estimator):
    # The map's ground masks, as the times: only to a fit that names both.
    names = _fit_parameters(estimator)
    return names is not None and set(_GROUND) <= names


def _takes_times(estimator):
    # Unlike the sweep (without which a job of two sweeps cannot be fitted), the times
    # are an addition: given only to a fit that names them, so other estimators are
    # fitted exactly as without.
    names = _fit_parameters(estimator)
    return names is not None and set(_TIMING) <= names


def _describe(value):
    """A stable text of a parameter value (arrays by their bytes, not their repr)."""
    if isinstance(value, np.ndarray):
        return f"array{value.shape}{value.dtype}:{hashlib.sha256(value.tobytes()).hexdigest()}"
    if hasattr(value, "get_params"):
        params = value.get_params(deep=False)
        inner = ",".join(f"{k}={_describe(params[k])}" for k in sorted(params))
        return f"{type(value).__module__}.{type(value).__qualname__}({inner})"
    return repr(value)


def _fingerprint(job, estimator):
    """What a result depends on: the job and the estimator with its parameters."""
    from mmreg import __version__

    text = "\n".join([repr(job), _describe(estimator), __version__])
    return hashlib.sha256(text.encode("utf-8", "surrogateescape")).hexdigest()[:16]


def _metrics(X, estimator, data):
    """The job's scores against its truth (empty without truth)."""
    from mmreg.metrics import iou_score, objects_found, scene_flow_metrics

    truth = data.get("labels_true")
    scores = {}
    if truth is not None:
        scored = truth >= 0  # negative: unknown (Argoverse 2) or outlier: not scored
        pred = estimator.labels_[scored]
        truth = truth[scored]
        ids, sizes = np.unique(truth, return_counts=True)
        scores["iou"] = float(iou_score(truth, pred)) if len(truth) else math.nan
        scores["objects_found"] = objects_found(truth, pred) if len(ids) else math.nan
        # Every object but the largest (the static world of a street): the moving ones.
        others = np.delete(ids, np.argmax(sizes)) if len(ids) else ids
        scores["moving_objects"] = len(others)
        scores["moving_found"] = (
            objects_found(truth, pred, objects=others) if len(others) else math.nan
        )
    flow_true = data.get("flow_true")
    if flow_true is not None:
        keep = (
            np.ones(len(X), bool) if data.get("labels_true") is None else data["labels_true"] >= 0
        )
        # A point with no fitted motion (NaN: no cluster at all) counts as not moving.
        flow = np.nan_to_num(estimator.flow_[keep], nan=0.0)
        if keep.any():
            found = scene_flow_metrics(flow_true[keep], flow)
            scores.update({name.lower(): value for name, value in found.items()})
        if truth is not None and len(truth):
            # The mean end-point error on the static world (the largest object) and on
            # the points of every other object (the moving ones), apart.
            error = np.linalg.norm(flow - flow_true[keep], axis=1)
            static = truth == ids[np.argmax(sizes)]
            scores["epe_static"] = float(error[static].mean())
            scores["epe_moving"] = float(error[~static].mean()) if (~static).any() else math.nan
    return scores


def _static_cluster(model):
    """The fitted static world's cluster: the estimator's ``static_cluster_``, else the
    largest cluster; -1 when there is no cluster at all."""
    if len(model.rotations_) == 0:
        return -1
    static = getattr(model, "static_cluster_", None)
    if static is None or static < 0:
        labels = np.asarray(model.labels_)
        counts = np.bincount(labels[labels >= 0], minlength=len(model.rotations_))
        static = int(np.argmax(counts)) if counts.size else 0
    return int(static)


def _static_motion(model):
    """Rotation and translation of the fitted static world (the largest cluster if unnamed).

    No cluster at all: the identity (every point stays where it is).
    """
    static = _static_cluster(model)
    if static < 0:
        return np.eye(3), np.zeros(3)
    return np.asarray(model.rotations_)[static], np.asarray(model.translations_)[static]


def _moving_speeds(X, model, static, interval):
    """The speed of every moving cluster's centroid relative to the static world: metres
    per second over ``interval``, else metres per frame (an empty array without any)."""
    moving = getattr(model, "moving_", None)
    labels = np.asarray(model.labels_)
    if moving is None or static < 0:
        return np.zeros(0)
    rotations, translations = np.asarray(model.rotations_), np.asarray(model.translations_)
    R0, t0 = rotations[static], translations[static]
    speeds = []
    for k in np.flatnonzero(np.asarray(moving, bool)):
        rows = labels == k
        if k == static or not rows.any():
            continue
        centre = np.asarray(X, float)[rows, :3].mean(axis=0)
        # Where the object went against where the static world's motion would take it.
        speeds.append(np.linalg.norm(rotations[k] @ centre + translations[k] - (R0 @ centre + t0)))
    speeds = np.asarray(speeds, float)
    return speeds / interval if interval else speeds


def sweep_flow(points, indices, flow, rotation, translation, ego_body=None):
    """The flow of every row of a sweep from a fit on the rows ``indices``.

    Rows the fit did not see (dropped ground) and rows it left without a motion (NaN
    flow: outliers) move with the static world, ``R p + t - p``. ``is_dynamic``: the
    flow differs from that by at least 0.05 m, the Argoverse 2 challenge's rule; never on
    the rows ``ego_body`` flags (one bool per row of ``flow``: returns from the ego
    vehicle's own body, which keep their zero flow, where they were in the sensor's
    frame, but are no moving object).

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.runner import sweep_flow
    >>> points = np.array([[10.0, 0, 0], [1.0, 0, 0]])  # a wall, the car's bonnet
    >>> flow = np.array([[-1.0, 0, 0], [0.0, 0, 0]])  # the car drove 1 m on
    >>> out, dynamic = sweep_flow(points, [0, 1], flow, np.eye(3), [-1.0, 0, 0],
    ...                           ego_body=[False, True])
    >>> out.tolist(), dynamic.tolist()
    ([[-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]], [False, False])
    """
    points = np.asarray(points, dtype=float)
    indices = np.asarray(indices, dtype=np.intp)
    ego = points @ np.asarray(rotation).T + translation - points
    out = ego.copy()
    fitted = np.asarray(flow)[:, :3]
    out[indices] = np.where(np.isfinite(fitted), fitted, ego[indices])
    dynamic = np.linalg.norm(out - ego, axis=1) >= DYNAMIC_THRESHOLD
    if ego_body is not None:
        dynamic[indices[np.asarray(ego_body, dtype=bool)]] = False
    return out, dynamic


def sweep_valid(points, indices, ego_body=None):
    """Whether each row of a sweep is a return from the world: not NaN, not one of the
    driver's rows at the origin, not the ego vehicle's own body (``ego_body``: one bool
    per row of ``indices``). The Argoverse 2 annotations' ``is_valid``.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.runner import sweep_valid
    >>> points = np.array([[10.0, 0, 0], [1.0, 0, 0], [np.nan] * 3, [5.0, 5, 0]])
    >>> sweep_valid(points, [0, 1, 3], ego_body=[False, True, False]).tolist()
    [True, False, False, True]
    """
    from mmreg._validation import invalid_points

    points = np.asarray(points, dtype=float)
    valid = ~invalid_points(points)
    if ego_body is not None:
        valid[np.asarray(indices, dtype=np.intp)[np.asarray(ego_body, dtype=bool)]] = False
    return valid


def _known_ground(data, model):
    """The job's data for ``model`` and what became of the ground points it knows.

    ``"masks"``: the map's ground masks go to a ``fit`` that names them; ``"dropped"``:
    the ground rows were removed, by the job (``ground="drop"``) or here, for a ``fit``
    that takes no masks (on the real Argoverse 2 pair ``av2_api_7fab2350`` the default
    SweepRegistration found 1 of 21 moving objects with the ground kept, 5 without);
    ``"kept"``: fitted as ordinary points (``ground="keep"``, or no map); None: a job
    without ground (frames, correspondences).
    """
    rule = data.get("ground_rule")
    if any(data.get(key) is None for key in _GROUND):
        return data, rule
    if _takes_ground(model) and np.shape(data["X"])[1] == 3:  # masks go with raw sweeps
        return data, "masks"
    keep, keep_sweep = ~np.asarray(data["ground"]), ~np.asarray(data["sweep_ground"])
    out = {key: value for key, value in data.items() if key not in _GROUND}
    for key in ("X", "indices", "times", "labels_true", "flow_true"):
        if out.get(key) is not None:
            out[key] = np.asarray(out[key])[keep]
    for key in ("sweep", "sweep_times"):
        if out.get(key) is not None:
            out[key] = np.asarray(out[key])[keep_sweep]
    return out, "dropped"


def _with_ground_choice(model, data):
    """``model`` told the job's explicit ground choice, where the job has no map for it.

    Without a map, ``ground="keep"`` or ``"drop"`` is the estimator's to carry out
    (:class:`~mmreg.SweepRegistration` finds the ground with Patchwork++), as in ``mmreg
    register``; ``"auto"`` leaves the estimator's own setting.
    """
    choice = data.get("ground_choice")
    if choice not in ("keep", "drop") or data.get("ground_rule") == "dropped":  # by the map
        return model
    if "ground" in model.get_params(deep=False):
        return model.set_params(ground=choice)
    if choice == "drop":
        raise ValueError(
            "ground='drop' (--ground drop): this log has no ground map, and "
            f"{type(model).__name__} has no 'ground' parameter to find the ground with; "
            "use SweepRegistration, or ground='auto' or 'keep'."
        )
    return model


def _drop_no_returns(data):
    """The job's data without the rows that hold no return, and how many the first sweep had.

    A row with NaN, or one of several at the origin (a driver's failed returns: a bag
    with ``is_dense`` false, an organised cloud, a KITTI scan), is no measurement
    (:func:`mmreg._validation.invalid_rows`): it is left out of the fit and of the
    result's rows (``indices`` no longer name it), in both sweeps, with its capture time,
    ground flag and truth. The count is of the first sweep's file
    (``sweep_points``) when the job gives it: rows a sequence job dropped itself count too.
    """
    from mmreg._validation import no_return  # points (odd columns) or [a | b]

    X = np.asarray(data["X"], dtype=float)
    keep = ~no_return(X)
    points = data.get("sweep_points")
    counted = int(np.count_nonzero(~keep if points is None else no_return(points)))
    keep_sweep = None if data.get("sweep") is None else ~no_return(data["sweep"])
    if keep.all() and (keep_sweep is None or keep_sweep.all()):
        return data, counted
    if not keep.any():
        raise ValueError(f"every one of its {len(X):,} rows holds no return (NaN or zero).")
    out = dict(data)
    out["indices"] = np.asarray(data.get("indices", np.arange(len(X))))[keep]
    for key in ("X", "times", "labels_true", "flow_true", "ground"):
        if out.get(key) is not None:
            out[key] = np.asarray(out[key])[keep]
    if keep_sweep is not None:
        for key in ("sweep", "sweep_times", "sweep_ground"):
            if out.get(key) is not None:
                out[key] = np.asarray(out[key])[keep_sweep]
    return out, counted


def _picture(X, model, data, name, ego_body=None):
    """The PNG bytes of one job's result, drawn as ``mmreg view`` draws it."""
    import io

    from mmreg.plotting import plot_result

    figure = plot_result(
        X[:, :3],
        model.labels_,
        (model.rotations_, model.translations_),
        moving=getattr(model, "moving_", None),
        interval=data.get("interval"),
        ego_body=ego_body,
        title=f"{name}: {len(X):,} points -> {model.n_clusters_} clusters",
    )
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=110)
    return buffer.getvalue()


def _process(job, estimator, pictures=False):
    """Load and fit one job (runs on a worker); ``(name, arrays or None, row)``.

    An error of the job becomes its row (status ``"error"``), so one bad input does not
    stop a dataset; KeyboardInterrupt and the like still propagate.
    """
    from sklearn.base import clone

    row = {"job": job.name, "status": "error"}
    try:
        start = time.perf_counter()
        with warnings.catch_warnings(record=True) as loading:  # a poses file's note
            warnings.simplefilter("always")
            data = job.load()
        model = _with_ground_choice(clone(estimator), data)
        data, row["ground"] = _known_ground(data, model)
        data, row["n_no_return"] = _drop_no_returns(data)
        X = np.asarray(data["X"], dtype=float)
        row["n"] = len(X)
        sweep = data.get("sweep")
        if sweep is not None:
            row["n_sweep"] = len(sweep)
        row["pairs"] = data.get("pairs", "sweeps" if sweep is not None else "correspondences")
        row["truth_fed"] = row["pairs"] == "truth"
        row["load_s"] = time.perf_counter() - start
        params = {} if sweep is None else {"sweep": sweep}
        timed = (
            sweep is not None
            and all(data.get(key) is not None for key in _TIMING)
            and _takes_times(model)
        )
        if timed:
            params.update({key: data[key] for key in _TIMING})
        elif sweep is not None and data.get("interval") and "interval" in _named(model):
            params["interval"] = data["interval"]  # alone: it bounds the objects' motions
        row["capture_times"] = timed
        row["interval"] = float(params.get("interval", math.nan))
        if row["ground"] == "masks":
            params.update({key: data[key] for key in _GROUND})
            row["n_ground"] = int(np.count_nonzero(data["ground"]))
        poses = sweep is not None and data.get("ego_motion") is not None
        if poses and "ego_motion" in (_fit_parameters(model) or ()):  # the poses' start
            params["ego_motion"] = data["ego_motion"]
        start = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            model.fit(X, **params)
        row["fit_s"] = time.perf_counter() - start
        moving = getattr(model, "moving_", None)
        # The ego vehicle's own body is labelled -1 but is no outlier: counted apart.
        body = getattr(model, "ego_body_mask_", None)
        body = np.zeros(len(X), bool) if body is None else np.asarray(body, dtype=bool)
        row.update(
            status="done",
            n_clusters=int(model.n_clusters_),
            n_moving=int(np.sum(moving)) if moving is not None else -1,
            n_outliers=int(np.sum((model.labels_ < 0) & ~body)),
            n_ego_body=int(body.sum()),
            n_iter=int(getattr(model, "n_iter_", -1)),
            converged=bool(getattr(model, "converged_", True)),
            **warning_columns([*loading, *caught]),
        )
        found = getattr(model, "ground_mask_", None)
        if found is not None and row["ground"] in (None, "kept"):
            # Found by the estimator (Patchwork++): joined to the static world or left out.
            dropped = model.get_params(deep=False).get("ground") == "drop"
            row["ground"] = "dropped" if dropped else "found"
            row["n_ground"] = int(np.count_nonzero(found))
        row.update(_metrics(X, model, data))
        static = _static_cluster(model)
        labels = np.asarray(model.labels_)
        # The static world's share of the returns the fit saw (the ego body left out).
        seen = max(1, len(X) - int(body.sum()))
        row["static_share"] = np.count_nonzero(labels == static) / seen if static >= 0 else 0.0
        speeds = _moving_speeds(X, model, static, params.get("interval"))
        row["max_speed"] = float(speeds.max()) if len(speeds) else math.nan
        row["speed_unit"] = "m/s" if params.get("interval") else "m/frame"
        indices = data.get("indices")
        indices = np.arange(len(X)) if indices is None else np.asarray(indices, dtype=np.int64)
        arrays = {
            "labels": labels.astype(np.int64),
            "rotations": np.asarray(model.rotations_, dtype=float),
            "translations": np.asarray(model.translations_, dtype=float),
            "sigmas": np.asarray(model.sigmas_, dtype=float),
            "flow": np.asarray(model.flow_, dtype=float),
            "indices": indices,
            "static_cluster": np.array(static, dtype=np.int64),
        }
        if moving is not None:
            arrays["moving"] = np.asarray(moving, dtype=bool)
        if hasattr(model, "ego_body_mask_"):
            arrays["ego_body"] = body
        points = data.get("sweep_points")
        if points is not None:
            row["n_file"] = len(points)
            points = np.asarray(points, float)
            flow, dynamic = sweep_flow(
                points, indices, model.flow_, *_static_motion(model), ego_body=body
            )
            arrays["sweep_flow"], arrays["sweep_dynamic"] = flow.astype(np.float32), dynamic
            arrays["sweep_valid"] = sweep_valid(points, indices, body)
        if pictures:  # drawn here, on the worker; written by the caller with the result
            png = _picture(X, model, data, job.name, body)
            arrays[_PICTURE] = np.frombuffer(png, dtype=np.uint8)
    except Exception as error:  # one job's failure is its row, not the run's end
        row["error"] = f"{type(error).__name__}: {' '.join(str(error).split())}"[:1000]
        return job.name, None, row
    return job.name, arrays, row


def _check_n_workers(n_workers):
    if n_workers is not None and (
        isinstance(n_workers, bool) or not isinstance(n_workers, int) or n_workers < 0
    ):
        raise ValueError(
            f"n_workers must be a non-negative integer (0: in this process) or None; got "
            f"{n_workers!r}."
        )


def _task(job, estimator, pictures, earlier=None):
    """One task of a run: fit ``job`` (:func:`_process`), or with ``earlier`` (the arrays
    and row of its finished result) draw its picture alone (:func:`_redraw`)."""
    if earlier is None:
        return _process(job, estimator, pictures)
    return _redraw(job, *earlier)


class _Stored:
    """A finished job's result as :func:`_picture` reads a fitted estimator."""

    def __init__(self, arrays):
        self.labels_ = np.asarray(arrays["labels"], dtype=np.intp)
        self.rotations_ = np.asarray(arrays["rotations"], dtype=float)
        self.translations_ = np.asarray(arrays["translations"], dtype=float)
        moving = arrays.get("moving")
        self.moving_ = None if moving is None else np.asarray(moving, dtype=bool)
        self.n_clusters_ = len(self.rotations_)


def _fitted_points(data, indices):
    """The points a job's fit saw, from its data loaded again: the rows ``indices`` of
    the first sweep's file (``sweep_points``), else of the loaded ``X``."""
    indices = np.asarray(indices, dtype=np.intp)
    points = data.get("sweep_points")
    if points is not None:
        return np.asarray(points, dtype=float)[indices]
    X = np.asarray(data["X"], dtype=float)
    loaded = data.get("indices")
    if loaded is None:
        return X[indices]
    loaded = np.asarray(loaded, dtype=np.intp)
    order = np.argsort(loaded, kind="stable")
    at = order[np.searchsorted(loaded, indices, sorter=order)]
    if np.any(loaded[at] != indices):
        raise ValueError("its input no longer holds the rows of its result (changed since?)")
    return X[at]


def _redraw(job, arrays, row):
    """The picture of a finished job (``pictures`` asked of a run that had none): its
    points loaded again, its result as stored; ``(name, {picture} or {error}, None)``."""
    try:
        data = job.load()
        X = _fitted_points(data, arrays["indices"])
        interval = row.get("interval")
        interval = interval if interval and math.isfinite(interval) else None
        body = arrays.get("ego_body")
        png = _picture(X, _Stored(arrays), {"interval": interval}, job.name, body)
    except Exception as error:  # the picture's failure is a note, not the job's
        return job.name, {"picture_error": f"{type(error).__name__}: {error}"[:500]}, None
    return job.name, {_PICTURE: np.frombuffer(png, dtype=np.uint8)}, None


def _write_picture(out, name, png):
    """``out/pictures/<name>.png``, whole or not at all."""
    from mmreg.io import atomic_write

    folder = Path(out) / PICTURES_FOLDER
    folder.mkdir(exist_ok=True)
    with atomic_write(folder / f"{name}.png") as handle:
        handle.write(png.tobytes())


def _result_path(out, name):
    return Path(out) / JOBS_FOLDER / f"{name}.npz"


def read_job_result(path, fingerprint=None):
    """The arrays and summary row of a job's result file, or None if it is not complete.

    A file that is truncated, corrupt (every member's CRC-32 is checked), lacks an array,
    or belongs to another job or estimator (``fingerprint``) is not a result.

    Parameters
    ----------
    path : str or path-like
        ``OUT/jobs/<name>.npz``.
    fingerprint : str, default=None
        The fingerprint the result must carry; None accepts any.

    Returns
    -------
    result : tuple (arrays, row) or None
        ``arrays``: ``{name: ndarray}``; ``row``: the job's summary row (a dict).
    """
    found = _read_result(path)
    if found is None:
        return None
    arrays, meta = found
    if fingerprint is not None and meta.get("fingerprint") != fingerprint:
        return None
    return arrays, meta["row"]


def _read_result(path):
    """``(arrays, meta)`` of a complete result file, or None."""
    try:
        arrays = _expand(_load_npz(path))
        meta = json.loads(str(arrays.pop("meta")))
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if any(key not in arrays for key in RESULT_KEYS if key != "meta") or "row" not in meta:
        return None
    return arrays, meta


def _input_stamps(job):
    """``{path: [size, mtime_ns]}`` of the files ``job`` reads (``job.inputs()``; None for a
    file that is missing), or None for a job that does not say what it reads."""
    inputs = getattr(job, "inputs", None)
    if not callable(inputs):
        return None
    stamps = {}
    for path in inputs() or ():
        try:
            stat = os.stat(path)
        except OSError:
            stamps[str(path)] = None
        else:
            stamps[str(path)] = [stat.st_size, stat.st_mtime_ns]
    return stamps


def _changed_input(stamps, earlier):
    """The first input whose size or modification time differs from ``earlier`` (the
    stamps recorded with a result), "" when none; a result without stamps, of a job
    that has some, counts as changed (its first input)."""
    if stamps is None:
        return ""
    if not isinstance(earlier, dict):
        return next(iter(stamps), "?")
    for path in sorted(set(stamps) | set(earlier)):
        if stamps.get(path) != earlier.get(path):
            return path
    return ""


def _small_int(values):
    """Integers in the smallest signed type that holds them (labels, row numbers)."""
    values = np.asarray(values)
    if values.size == 0:
        return values.astype(np.int32)
    low, high = int(values.min()), int(values.max())
    for kind in (np.int8, np.int16, np.int32):
        if np.iinfo(kind).min <= low and high <= np.iinfo(kind).max:
            return values.astype(kind)
    return values.astype(np.int64)


def _compact(arrays):
    """A job's arrays as its file keeps them by default: labels and row numbers in the
    smallest integer type, flows float32, and of ``sweep_flow`` (every row of the sweep's
    file) only the rows that are not the fit's own flow (``sweep_flow_rest``, with the
    mask ``sweep_flow_own`` of the others): :func:`_expand` restores it exactly. A
    35k-point pair takes 0.33 MB (compressed) instead of 1.9 MB."""
    out = dict(arrays)
    for key in ("labels", "indices"):
        out[key] = _small_int(arrays[key])
    out["flow"] = np.asarray(arrays["flow"], dtype=np.float32)
    if "sweep_flow" in arrays:
        sweep = np.asarray(out.pop("sweep_flow"), dtype=np.float32)
        indices = np.asarray(arrays["indices"], dtype=np.intp)
        flow = out["flow"]
        finite = np.all(np.isfinite(flow), axis=1)
        own = np.zeros(len(sweep), bool)
        rows = indices[finite]
        own[rows] = np.all(sweep[rows] == flow[finite], axis=1)
        out["sweep_flow_own"] = own
        out["sweep_flow_rest"] = sweep[~own]
    return out


def _expand(arrays):
    """The arrays of a job's file as :func:`_process` made them: labels and row numbers
    int64 (arithmetic on int8 overflows), ``sweep_flow`` whole; flows stay float32."""
    out = dict(arrays)
    for key in ("labels", "indices"):
        if key in out and np.asarray(out[key]).dtype.kind in "iu":
            out[key] = np.asarray(out[key]).astype(np.int64)
    if "sweep_flow_rest" not in arrays or "sweep_flow_own" not in arrays:
        return out
    own = np.asarray(out.pop("sweep_flow_own"), dtype=bool)
    rest = np.asarray(out.pop("sweep_flow_rest"), dtype=np.float32)
    flow = np.asarray(arrays["flow"], dtype=np.float32)
    indices = np.asarray(arrays["indices"], dtype=np.intp)
    if len(rest) != np.count_nonzero(~own) or len(flow) != len(indices):
        raise ValueError("sweep_flow_rest does not fit sweep_flow_own")
    sweep = np.empty((len(own), 3), dtype=np.float32)
    sweep[~own] = rest
    at = np.full(len(own), -1, dtype=np.intp)
    at[indices] = np.arange(len(indices))
    if np.any(at[own] < 0):
        raise ValueError("sweep_flow_own marks a row the fit did not see")
    sweep[own] = flow[at[own]]
    out["sweep_flow"] = sweep
    return out


def _write_result(path, arrays, row, fingerprint, inputs=None, *, full=False):
    """A job's file, compressed; compact (:func:`_compact`) unless ``full``."""
    from mmreg import io as mmio

    meta = {"fingerprint": fingerprint, "row": row, "inputs": inputs}
    meta = json.dumps(meta, default=json_value)
    arrays = arrays if full else _compact(arrays)
    with mmio.atomic_write(path) as handle:
        np.savez_compressed(handle, **arrays, meta=np.array(meta))


def write_scene_flow(path, flow, is_dynamic):
    """Write one sweep's flow as the Argoverse 2 scene-flow challenge's feather file.

    Columns ``flow_tx_m``, ``flow_ty_m``, ``flow_tz_m`` (float32, metres, in the first
    sweep's ego frame) and ``is_dynamic`` (bool), one row per point of the sweep in the
    order of its file: the format of ``av2/evaluation/scene_flow/SUBMISSION_FORMAT.md``
    and ``write_output_file`` in ``av2/evaluation/scene_flow/utils.py`` of
    https://github.com/argoverse/av2-api (which store float16 and, for a submission,
    only the rows of the evaluation mask: ``make_submission_archive.py`` selects and
    casts them); the file is written whole or not at all.

    Parameters
    ----------
    path : str or path-like
        ``<folder>/<log_id>/<timestamp_ns>.feather`` (its folder is created).
    flow : array-like of shape (n, 3)
        The flow of every point.
    is_dynamic : array-like of shape (n,) of bool
        Whether each point moves beyond the static world's motion.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> import pandas as pd
    >>> from mmreg.runner import write_scene_flow
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = Path(folder) / "log" / "100.feather"
    ...     write_scene_flow(path, np.ones((2, 3)), np.array([True, False]))
    ...     pd.read_feather(path).to_dict("list")  # doctest: +NORMALIZE_WHITESPACE
    {'flow_tx_m': [1.0, 1.0], 'flow_ty_m': [1.0, 1.0], 'flow_tz_m': [1.0, 1.0],
     'is_dynamic': [True, False]}
    """
    import pyarrow as pa
    import pyarrow.feather as feather

    from mmreg import io as mmio

    flow = np.asarray(flow, dtype=np.float32).reshape(-1, 3)
    columns = {name: flow[:, k] for k, name in enumerate(SCENE_FLOW_COLUMNS)}
    columns["is_dynamic"] = np.asarray(is_dynamic, dtype=bool).reshape(len(flow))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with mmio.atomic_write(path) as handle:
        feather.write_feather(pa.table(columns), handle, compression="uncompressed")


def _write_sweep_flow(out, job, arrays):
    """The challenge's file of a job of a log (``job.challenge``), from its result."""
    relative = getattr(job, "challenge", "")
    if relative and "sweep_flow" in arrays:
        path = Path(out) / SCENE_FLOW_FOLDER / relative
        write_scene_flow(path, arrays["sweep_flow"], arrays["sweep_dynamic"])


def json_value(value):
    """``json.dumps``'s ``default``: numpy scalars as Python numbers."""
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


@contextlib.contextmanager
def dask_client(scheduler, n_workers, needed_by="run_dataset"):
    """A Dask client on the cluster at ``scheduler``, or on a new LocalCluster of
    ``n_workers`` processes (``needed_by`` names the caller in the missing-package error)."""
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ImportError(f"{needed_by} needs dask.distributed: pip install 'mmreg[dask]'") from exc
    with contextlib.ExitStack() as stack:
        if scheduler is None:
            # One thread per worker: the fits use numpy/scipy, which hold the GIL between
            # the vectorised calls, so processes (not threads) run jobs side by side.
            # Not daemonic: a log's fit may start a process of its own for its pairs.
            with _children_ignore_ctrl_c(), dask.config.set({"distributed.worker.daemon": False}):
                cluster = stack.enter_context(
                    LocalCluster(
                        n_workers=n_workers,
                        threads_per_worker=1,
                        processes=True,
                        dashboard_address=":0",  # a free port: other clusters may run here
                        silence_logs=logging.CRITICAL,  # a lost worker is a row, not a log
                    )
                )
            scheduler = cluster
        yield stack.enter_context(Client(scheduler))


@contextlib.contextmanager
def _dask_backend(scheduler, n_workers):
    """joblib's dask backend on the cluster at ``scheduler``, or on a new LocalCluster."""
    import joblib

    with dask_client(scheduler, n_workers), joblib.parallel_config(backend="dask"):
        yield


@contextlib.contextmanager
def _children_ignore_ctrl_c():
    """Start processes that ignore SIGINT: Ctrl-C is this process's to handle.

    A terminal sends Ctrl-C's SIGINT to the whole foreground process group, the Dask
    worker processes included: each printed a traceback, and the workers killed in their
    start left semaphores the resource tracker warned of. A process started while
    SIGINT is ignored keeps ignoring it (the disposition survives fork and exec, and
    Python leaves an inherited SIG_IGN alone), so the workers leave the interruption to
    this process, which closes the cluster (and with it the workers). A Ctrl-C during
    the cluster's start (a second or two) is lost.
    """
    try:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread: signals are not ours to handle
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _write_table(frame, out):
    from mmreg import io as mmio

    with mmio.atomic_write(Path(out) / "summary.parquet") as handle:
        frame.to_parquet(handle, index=False)
    with mmio.atomic_write(Path(out) / "summary.csv", "w") as handle:
        frame.to_csv(handle, index=False, float_format="%.6g")


def run_dataset(
    jobs,
    estimator=None,
    out="mmreg-run",
    *,
    scheduler=None,
    n_workers=None,
    overwrite=False,
    progress=True,
    pictures=False,
    full_arrays=False,
):
    """Fit ``estimator`` on every job of a dataset on Dask; resumable, one file per job.

    Every job runs as one task of joblib's ``"dask"`` backend (``paper/`` runs its
    sweeps the same way): it loads its input on the worker, fits a clone of
    ``estimator`` and sends back the arrays, which are written to ``out/jobs/<name>.npz``
    (to a temporary file in that folder, then :func:`os.replace`: whole or not at all).
    A job whose complete result for this estimator is already there is not run again,
    so an interrupted run resumes where it stopped, unless a file it reads changed since
    (a job's ``inputs()`` names its files; their sizes and modification times are kept
    with the result). A job that raises becomes a row
    with ``status="error"`` and its message; the others go on, and the next run retries
    it.

    Parameters
    ----------
    jobs : str, path-like or list of jobs
        A dataset folder (its jobs: :func:`dataset_jobs`), or jobs: objects with a
        unique ``name`` (a file name) and a ``load()`` returning ``{"X": (n, 6)}``, plus
        ``"labels_true"`` (n,) and ``"flow_true"`` (n, 3) when the truth is known, and
        ``"sweep"`` (m, 3) for a job of two raw sweeps (then ``X`` may be (n, 3): the
        first sweep; see ``pairs`` of :func:`dataset_jobs`), with ``"times"`` (n,),
        ``"sweep_times"`` (m,) and ``"interval"`` (seconds) when the points' capture
        times are known: these go to ``fit`` when it names all three as parameters;
        ``"ground"`` (n,) and ``"sweep_ground"`` (m,) (known ground points, to a ``fit``
        naming both); ``"indices"`` (n,) (the rows of the input ``X`` holds; default
        ``arange(n)``), ``"sweep_points"`` (every row of the first sweep's file: then
        ``sweep_flow`` is stored) and ``"pairs"`` (what ``X`` is). A job with a
        ``challenge`` attribute (``"<log>/<timestamp_ns>.feather"``) also writes its
        sweep's flow in the Argoverse 2 challenge's format. The jobs are pickled to the
        workers, which must be able to read the files they name.
    estimator : estimator, default=None
        A scikit-learn style estimator (``fit(X)``, ``labels_``, ``rotations_``,
        ``translations_``, ``sigmas_``, ``flow_``); None: :func:`default_estimator`, or
        :func:`default_sweep_estimator` when the jobs are pairs of raw sweeps. Jobs with
        a second sweep need an estimator whose ``fit`` takes ``sweep``
        (:class:`~mmreg.SweepRegistration`).
    out : str or path-like, default="mmreg-run"
        Folder of the results (created): ``jobs/<name>.npz``, ``summary.parquet``,
        ``summary.csv``.
    scheduler : str, default=None
        Address of a running Dask scheduler (``"tcp://host:8786"``); None starts a
        :class:`distributed.LocalCluster` for the run.
    n_workers : int, default=None
        Worker processes of a LocalCluster; 0 runs the jobs in this process, without a
        cluster; None chooses (:func:`mmreg.runner._workers.run_tasks`): this process
        unless at least two workers fit on the free cores given each job's own threads
        (the estimator's ``n_jobs``) and the jobs left after the first, timed here,
        would take twice a cluster's start longer here than on them. Ignored with
        ``scheduler``.
    overwrite : bool, default=False
        Run every job again, replacing the results found in ``out``.
    progress : bool, default=True
        A tqdm progress bar over the jobs on stderr.
    pictures : bool, default=False
        Also draw every job's result as ``mmreg view`` does (a LiDAR sweep from above)
        into ``out/pictures/<name>.png``, where the jobs run. A finished job without its
        picture is drawn from its stored result and its points loaded again, not fitted
        again.
    full_arrays : bool, default=False
        Keep every array of a job's file whole (float64 flow, int64 labels, the
        sweep's flow of every row); by default the file keeps labels and rows in the
        smallest integer type, flows as float32, and the sweep's flow only where it is
        not the fit's own, which :func:`read_job_result` restores exactly.

    Returns
    -------
    summary : pandas.DataFrame
        One row per job, in the jobs' order: ``job``, ``status`` (``"done"`` or
        ``"error"``), ``n`` (correspondences, or points of the first sweep; ``n_sweep``:
        of the second), ``n_clusters``, ``n_moving``,
        ``n_outliers`` (label -1, the ego vehicle's body left out), ``n_ego_body`` (returns
        from the ego vehicle's own body), ``n_no_return`` (rows of the first sweep that
        hold no return, left out), ``n_iter``, ``converged``, ``load_s``, ``fit_s`` (seconds, on the
        worker), ``resumed`` (read from an earlier run), ``error``, ``warnings``
        (``input_warnings``: those that say the input is not in the points' units or
        their sensor's frame), and with
        the truth ``iou``, ``objects_found``, ``moving_objects``, ``moving_found``
        (objects besides the largest found with IoU >= 0.5), ``epe3d``, ``acc3ds``,
        ``acc3dr``, ``outliers3d`` (of the rigid flow, :func:`mmreg.metrics.
        scene_flow_metrics`), ``epe_static`` and ``epe_moving`` (the mean EPE on the
        largest object's points and on the others'). Points with a negative true label
        are not scored. ``capture_times``: whether ``fit`` was given the points' capture
        times; ``interval``: the seconds between the sweeps given to ``fit`` (with the
        times, or alone: a sequence's stamps, which bound the objects' motions), else
        NaN; ``ground``: whether the map's ground masks were handed to ``fit``
        (``"masks"``), the ground rows dropped (``"dropped"``: ``ground="drop"``, or
        ``"auto"`` with a ``fit`` that takes no masks, or found by the estimator and left
        out) or kept (``"kept"``), or found by the estimator and joined to the static
        world (``"found"``), with ``n_ground`` its points; ``changed_input``: for a job
        run again because a file it reads changed since the earlier result, that file;
        ``pairs``: what it was fitted on (``"sweeps"``, ``"flow"``, ``"truth"``,
        ``"correspondences"``) and ``truth_fed``: whether that was the ground-truth flow;
        ``n_file``: rows of the first sweep's file; ``static_share``: the share of the
        fitted rows (the ego vehicle's body left out) in the static world's cluster;
        ``max_speed``: the fastest moving cluster's centroid relative to the static
        world, in ``speed_unit`` (``"m/s"`` when the interval is known, else
        ``"m/frame"``); ``picture_error``: why a finished job's picture could not be
        drawn. ``summary.attrs["plan"]`` says where the jobs ran (``where``,
        ``workers``, ``start_s``: the cluster's start, ``why``, ``redrawn``: the
        pictures of finished jobs drawn).

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from distributed import LocalCluster
    >>> from mmreg import MultiModelRegistration
    >>> from mmreg.runner import dataset_jobs, run_dataset
    >>> rng = np.random.default_rng(0)
    >>> frame = rng.uniform(-1, 1, (200, 3))
    >>> with tempfile.TemporaryDirectory() as folder, LocalCluster(
    ...         n_workers=1, processes=False, dashboard_address=":0") as cluster:
    ...     for k in range(3):  # index-aligned frames: row i moves with row i
    ...         np.save(Path(folder) / f"frame{k}.npy", frame + [0.1 * k, 0, 0])
    ...     est = MultiModelRegistration(init=np.zeros(200, int), variant="paper")
    ...     jobs = dataset_jobs(folder, pairs="aligned")
    ...     summary = run_dataset(jobs, est, Path(folder) / "out",
    ...                           scheduler=cluster.scheduler_address, progress=False)
    >>> summary[["job", "status", "n", "n_clusters"]].values.tolist()
    [['frame0__frame1', 'done', 200, 1], ['frame1__frame2', 'done', 200, 1]]
    """
    import joblib
    import pandas as pd
    from tqdm import tqdm

    if isinstance(jobs, (str, Path)):
        jobs = dataset_jobs(jobs)
    jobs = check_jobs(jobs)
    sweeps = any(isinstance(job, _SWEEP_JOBS) for job in jobs)
    if estimator is None:
        estimator = default_sweep_estimator() if sweeps else default_estimator()
    if not hasattr(estimator, "fit"):
        raise TypeError(f"estimator must have a fit method; got {type(estimator).__name__}.")
    if sweeps and not _takes_sweep(estimator):
        raise TypeError(
            f"the jobs are pairs of raw sweeps, fitted as fit(X, sweep=...), but "
            f"{type(estimator).__name__}.fit takes no sweep; wrap it: "
            "SweepRegistration(estimator)."
        )
    _check_n_workers(n_workers)
    out = Path(out)
    (out / JOBS_FOLDER).mkdir(parents=True, exist_ok=True)
    fingerprints = {job.name: _fingerprint(job, estimator) for job in jobs}
    # What each job reads, as it is now: a result of other inputs is run again.
    stamps = {job.name: _input_stamps(job) for job in jobs}
    rows, todo, changed, redraw = {}, [], {}, []
    for job in jobs:
        found = None
        if not overwrite:
            found = _read_result(_result_path(out, job.name))
        if found is not None and found[1].get("fingerprint") != fingerprints[job.name]:
            found = None
        if found is not None:
            changed[job.name] = _changed_input(stamps[job.name], found[1].get("inputs"))
            if changed[job.name]:
                found = None
        if found is None:
            todo.append(job)
        else:
            found = (found[0], found[1]["row"])
            rows[job.name] = found[1] | {"resumed": True}
            relative = getattr(job, "challenge", "")
            if relative and not (out / SCENE_FLOW_FOLDER / relative).is_file():
                _write_sweep_flow(out, job, found[0])
            if pictures and not (out / PICTURES_FOLDER / f"{job.name}.png").is_file():
                redraw.append((job, found))  # --pictures added to a finished run
    bar = tqdm(
        total=len(jobs) + len(redraw),
        initial=len(rows),
        disable=not progress,
        file=sys.stderr,
        unit="job",
        desc="mmreg run",
    )
    by_name = {job.name: job for job in jobs}
    tasks = [(job, None) for job in todo] + redraw

    def handle(result):
        name, arrays, row = result
        if arrays is not None and _PICTURE in arrays:
            _write_picture(out, name, arrays.pop(_PICTURE))
        if row is None:  # a finished job's picture, drawn again
            if arrays is None or "picture_error" in arrays:
                rows[name]["picture_error"] = (arrays or {}).get("picture_error", "")
        else:
            if arrays is not None:
                path = _result_path(out, name)
                _write_result(path, arrays, row, fingerprints[name], stamps[name], full=full_arrays)
                _write_sweep_flow(out, by_name[name], arrays)
            rows[name] = row | {"resumed": False}
            if changed.get(name):
                rows[name]["changed_input"] = changed[name]
        bar.update(1)
        _interrupt.check()  # a Ctrl-C that a callback swallowed stops here

    def here(chosen):
        for job, earlier in chosen:
            handle(_task(job, estimator, pictures, earlier))

    def cluster(chosen, address, workers):
        begin = time.perf_counter()
        with _dask_backend(address, workers):
            start_s = time.perf_counter() - begin
            delayed = (joblib.delayed(_task)(job, estimator, pictures, e) for job, e in chosen)
            parallel = joblib.Parallel(n_jobs=-1, return_as="generator_unordered")
            for result in parallel(delayed):
                handle(result)
        return start_s

    with bar:
        plan = run_tasks(
            tasks,
            here,
            cluster,
            scheduler=scheduler,
            n_workers=n_workers,
            threads=task_threads(estimator),
        )
    frame = pd.DataFrame([rows[job.name] for job in jobs])
    columns = SUMMARY_COLUMNS + [c for c in frame.columns if c not in SUMMARY_COLUMNS]
    frame = frame.reindex(columns=columns)
    for column in ("error", "changed_input", "picture_error"):
        if column in frame:
            frame[column] = frame[column].astype(object).where(frame[column].notna(), "")
    _write_table(frame, out)
    frame.attrs["plan"] = plan | {"redrawn": len(redraw)}
    return frame
