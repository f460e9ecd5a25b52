"""What the paper's scripts share: methods as table columns, scenes, the runner, outputs.

* :class:`Column`: one column of a table or box of a figure, a method of the registry
  (:mod:`mmreg.methods`) with the paper's parameters and an initial clustering;
  :func:`select_columns` honours ``--methods`` and adds third-party methods.
* :class:`Experiment`: a family of scenes (a pure function of a seed) and its columns;
  :func:`flow_scene` builds the flow scenes the scripts share.
* :func:`run_experiments`: every (experiment, column, seed) once, in parallel with joblib
  (``--n-jobs``) or on a Dask cluster (``--scheduler``), with a progress bar per
  experiment and a cache of one small JSON file per run, so an interrupted run resumes.
* :func:`write_frame`, :func:`write_text`, :func:`save_figure`: outputs written whole.

Only the public API of mmreg is used.
"""

import argparse
import contextlib
import hashlib
import json
import math
import os
import re
import tempfile
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import joblib
import numpy as np
import pandas as pd
from sklearn.utils import Bunch
from tqdm.auto import tqdm

import mmreg.datasets
from mmreg.init import EuclideanClustering, PrecomputedMasks
from mmreg.methods import BUILTIN_METHODS, available_methods, make_method, method_parameters
from mmreg.metrics import (
    ground_truth_poses,
    iou_score,
    objects_found,
    per_point_error,
    rotation_error,
    translation_error,
)

HERE = Path(__file__).resolve().parent
DEFAULT_OUT = HERE / "out"

# Errors at or below these are rounding noise of an exact answer (double precision; the
# rotation angle comes from an arccos, exact only to about sqrt(eps) rad = 1e-6 degrees).
EXACT = {"per_point_error": 1e-9, "rotation_error": 1e-5, "translation_error": 1e-9}

# Measures of every run: column -> (title with unit, "max" or "min" is better).
MEASURES = {
    "iou": ("IoU", "max"),
    "iou_outliers": ("IoU, gross errors as outlier class", "max"),
    "objects_found": ("Objects found", "max"),
    "per_point_error": ("Per-point error [m]", "min"),
    "rotation_error": ("Rotation error [deg]", "min"),
    "translation_error": ("Translation error [m]", "min"),
    "n_clusters": ("Clusters reported", None),
    "runtime_s": ("Runtime [s]", "min"),
}
ROW_KEYS = ["experiment", "method", "registry_name", "run", "seed"]


# --------------------------------------------------------------------------- columns
@dataclass(frozen=True)
class Column:
    """A method of the registry with its parameters, as one column of a table.

    ``init`` names one of the scene's initial clusterings (``"euclidean"``, ``"sam"``,
    ...), passed as precomputed labels; ``strict=False`` drops the parameters the method
    does not take (third-party methods get the family's parameters that way).
    """

    label: str
    method: str
    params: dict = field(default_factory=dict, hash=False)
    init: str | None = None
    strict: bool = True

    def key(self):
        """Short hash of everything that defines the column's results."""
        text = json.dumps(
            [self.label, self.method, self.params, self.init, self.strict],
            sort_keys=True,
            default=repr,
        )
        return hashlib.sha1(text.encode()).hexdigest()[:10]


def parse_methods(text):
    """``"a,b"`` -> ``["a", "b"]``; ``"all"`` or None -> every available method."""
    if text is None or text.strip() == "all":
        return available_methods()
    names = [name.strip() for name in text.split(",") if name.strip()]
    known = available_methods()
    unknown = [name for name in names if name not in known]
    if unknown:
        raise SystemExit(
            f"error: unknown method(s) {', '.join(unknown)}; available: {', '.join(known)}"
        )
    return names


def select_columns(builtin, names, family_params, inits):
    """The columns of the methods ``names``: built-ins as given, then one column per init.

    Parameters
    ----------
    builtin : list of Column
        The paper's columns of the experiment.
    names : list of str
        Registry names to run (``--methods``).
    family_params : dict
        Parameters of the experiment family handed to a third-party method (each takes
        those it knows): ``tau``, ``tau_t``, ``residual_threshold``, ...
    inits : dict of str -> str
        Initial clusterings to give a third-party method that takes ``init``:
        label suffix -> scene init name, e.g. ``{"": "euclidean"}`` or
        ``{" (SAM)": "sam", " (Euc.)": "euclidean"}``.
    """
    columns = [column for column in builtin if column.method in names]
    for name in names:
        if name in BUILTIN_METHODS:
            continue
        if "init" in method_parameters(name):
            for suffix, init in inits.items():
                columns.append(Column(f"{name}{suffix}", name, dict(family_params), init, False))
        else:
            columns.append(Column(name, name, dict(family_params), None, False))
    return columns


# --------------------------------------------------------------------------- scenes
@dataclass
class Scene:
    """One scene with everything needed to score a method on it.

    ``truth``: the paper's ground truth (its IoU, per-point and pose errors), with
    ``transforms`` indexed by it; ``with_outliers``: the motion of each correspondence
    with ``-1`` for gross errors (second IoU, objects found); ``objects``: the labels of
    ``with_outliers`` counted by objects found; ``inits``: initial labels by name, and the
    seconds each took in ``init_seconds``.
    """

    X: np.ndarray
    truth: np.ndarray
    transforms: tuple
    with_outliers: np.ndarray
    objects: np.ndarray
    inits: dict
    init_seconds: dict
    extra: dict = field(default_factory=dict)


def timed_labels(initializer, X):
    """Labels of a fitted initialiser and the seconds the fit took."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # e.g. fewer than 100 clusters on a tiny scene
        start = time.perf_counter()
        labels = np.asarray(initializer.fit(X).labels_)
        return labels, time.perf_counter() - start


DATASETS = {
    "flying_things": ("FlyingThings3D-like", "make_flying_things", "load_flying_things"),
    "kitti": ("KITTI-like", "make_street", "load_kitti_scene_flow"),
}


def load_real_scene(dataset, data, index, n_points=32768):
    """Frame ``index`` of a real data set through mmreg's loader (clear error if none).

    The loaders give the ground-truth flow; the paper used a network's flow instead
    (CamliRAFT), so its errors are simulated with
    :func:`mmreg.datasets.corrupt_scene_flow` (defaults: depth-dependent noise, bleeding,
    10 % gross errors) and the SAM masks with :func:`mmreg.datasets.simulate_sam_masks`
    from the object map. Ground truth: the object map (``instance_labels``).
    """
    name = DATASETS[dataset][2]
    loader = getattr(mmreg.datasets, name, None)
    if loader is None:
        raise SystemExit(
            f"error: --data needs mmreg.datasets.{name}, which this version of mmreg does "
            "not have; leave --data out to run on generated scenes."
        )
    try:
        bunch = loader(data, index, n_points=n_points, random_state=index)
    except (FileNotFoundError, ValueError) as exc:
        raise SystemExit(f"error: cannot read frame {index} of {data} ({name}): {exc}") from exc
    if bunch.get("instance_labels") is None:
        raise SystemExit(
            f"error: frame {index} of {data} has no object map; the measures need "
            "ground-truth objects"
        )
    truth = np.asarray(bunch.instance_labels)
    pixels = np.asarray(bunch.pixels)
    noisy = mmreg.datasets.corrupt_scene_flow(
        bunch.a,
        bunch.flow,
        pixels[:, ::-1],
        np.maximum(truth, 0),
        image_shape=tuple(bunch.image_shape),
        random_state=index,
    )
    masks = None
    if bunch.get("instance_image") is not None:
        masks = mmreg.datasets.simulate_sam_masks(bunch.instance_image, random_state=index)
    return Bunch(
        X=np.hstack([bunch.a, bunch.a + noisy.flow]),
        labels=truth,
        instance_labels=truth,
        outlier_mask=noisy.outlier_mask,
        flow_clean=bunch.flow,
        pixels=pixels,
        masks=masks,
    )


def flow_scene(seed, *, dataset, n_points=None, image_size=None, corruption=None, data=None):
    """A FlyingThings3D- or KITTI-like scene with SAM-like and Euclidean initial clusters.

    Generated by :func:`mmreg.datasets.make_flying_things` / ``make_street`` with
    ``random_state=seed`` unless ``data`` is given (then frame ``seed`` of the real data
    set, see :func:`load_real_scene`). The paper's truth: ``instance_labels`` (KITTI: each
    car and the background), poses by Horn's method on the clean flow; gross flow errors
    are the outlier class of ``with_outliers`` (motion groups: parked cars belong to the
    background).
    """
    if data is not None:
        bunch = load_real_scene(dataset, data, seed, **({"n_points": n_points} if n_points else {}))
    else:
        make = getattr(mmreg.datasets, DATASETS[dataset][1])
        kwargs = {"random_state": seed}
        if n_points is not None:
            kwargs["n_points"] = n_points
        if image_size is not None:
            kwargs["image_size"] = tuple(image_size)
        if corruption is not None:
            kwargs["corruption"] = corruption
        bunch = make(**kwargs)
    X = np.asarray(bunch.X, dtype=float)
    motions = np.asarray(bunch.labels)
    truth = np.asarray(bunch.get("instance_labels", motions))
    outlier = np.asarray(bunch.get("outlier_mask", np.zeros(len(X), dtype=bool)))
    flow_clean = bunch.get("flow_clean")
    clean = X if flow_clean is None else np.hstack([X[:, :3], X[:, :3] + flow_clean])
    inits, seconds = {}, {}
    inits["euclidean"], seconds["euclidean"] = timed_labels(EuclideanClustering(100), X)
    if bunch.get("masks") is not None and bunch.get("pixels") is not None:
        inits["sam"], seconds["sam"] = timed_labels(PrecomputedMasks(bunch.masks, bunch.pixels), X)
    return Scene(
        X=X,
        truth=truth,
        transforms=ground_truth_poses(clean, truth),
        with_outliers=np.where(outlier, -1, motions),
        objects=np.unique(motions[motions > 0]),
        inits=inits,
        init_seconds=seconds,
        extra={"bunch": bunch},
    )


@dataclass
class Experiment:
    """Scenes ``scene(seed, **config)`` for ``seeds``, each scored with every column."""

    name: str
    title: str
    scene: object
    config: dict
    columns: list
    seeds: list

    def key(self):
        """Short hash of the scene family (function and configuration)."""
        text = json.dumps(
            [getattr(self.scene, "__qualname__", repr(self.scene)), self.config],
            sort_keys=True,
            default=repr,
        )
        return hashlib.sha1(text.encode()).hexdigest()[:10]


# --------------------------------------------------------------------------- measuring
def estimator_for(column, scene, seed):
    """The column's unfitted estimator on ``scene``, seeded by ``seed`` if it takes one."""
    params = dict(column.params)
    if column.init is not None:
        params["init"] = scene.inits[column.init]
    if "random_state" in method_parameters(column.method):
        params.setdefault("random_state", seed)
    return make_method(column.method, strict=column.strict, **params)


def measure(column, scene, seed):
    """Fit the column's method on the scene; its measures as one row (a dict)."""
    estimator = estimator_for(column, scene, seed)
    X = scene.X
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        start = time.perf_counter()
        estimator.fit(X)
        runtime = time.perf_counter() - start
        labels = np.asarray(estimator.labels_)
        if hasattr(estimator, "rotations_") and hasattr(estimator, "translations_"):
            transforms = (estimator.rotations_, estimator.translations_)
        else:
            transforms = ground_truth_poses(X, labels)
        n_clusters = getattr(estimator, "n_clusters_", None)
        if n_clusters is None:
            n_clusters = len(np.unique(labels[labels >= 0]))
        truth = scene.truth
        row = {
            "iou": iou_score(truth, labels),
            "iou_outliers": iou_score(scene.with_outliers, labels),
            "objects_found": objects_found(scene.with_outliers, labels, objects=scene.objects),
            "per_point_error": per_point_error(X, truth, labels, scene.transforms, transforms),
            "rotation_error": rotation_error(truth, labels, scene.transforms, transforms),
            "translation_error": translation_error(truth, labels, scene.transforms, transforms),
            "n_clusters": int(n_clusters),
            "n_objects": len(np.unique(truth[truth >= 0])),
            "n_motions": len(np.unique(scene.with_outliers[scene.with_outliers >= 0])),
            "n_points": len(X),
            "runtime_s": runtime,
            "init_s": scene.init_seconds.get(column.init, 0.0),
        }
    return {key: (float(v) if isinstance(v, np.floating) else v) for key, v in row.items()}


def _run_scene(experiment, run, seed, columns):
    """Every column on scene ``seed`` of the experiment: ``(run, seed, rows)``."""
    scene = experiment.scene(seed, **experiment.config)
    rows = []
    for column in columns:
        row = {
            "experiment": experiment.name,
            "method": column.label,
            "registry_name": column.method,
            "init": column.init,
            "run": run,
            "seed": seed,
        }
        row.update(measure(column, scene, seed))
        rows.append(row)
    return run, seed, rows


# --------------------------------------------------------------------------- cache
def _slug(text):
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "method"


def cache_path(cache_dir, experiment, column, seed):
    """One small JSON file per (experiment, method, seed)."""
    folder = Path(cache_dir) / f"{_slug(experiment.name)}-{experiment.key()}"
    return folder / f"{_slug(column.label)}-{column.key()}" / f"seed{seed}.json"


def _read_cache(path):
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


def _write_atomic(path, text):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as handle:
            handle.write(text)
        os.chmod(tmp, 0o644)  # mkstemp makes it private
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


# --------------------------------------------------------------------------- runner
@contextlib.contextmanager
def parallel_backend(n_jobs=1, scheduler=None):
    """joblib's backend for the runs: local processes, or a Dask cluster at ``scheduler``."""
    if scheduler is None:
        with joblib.parallel_config(n_jobs=n_jobs):
            yield
        return
    try:
        from distributed import Client
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise SystemExit(
            "error: --scheduler needs dask.distributed: pip install 'mmreg[dask]'"
        ) from exc
    with Client(scheduler), joblib.parallel_config(backend="dask", n_jobs=-1):
        yield


def run_experiments(experiments, *, cache_dir=None, n_jobs=1, scheduler=None, progress=True):
    """Every (experiment, column, seed), cached; one row per run, in a stable order.

    Parameters
    ----------
    experiments : list of Experiment
    cache_dir : path or None
        Folder of the per-run cache (one JSON file per run); runs found there are not
        recomputed. None: no cache.
    n_jobs : int
        joblib processes (``-1``: all cores); ignored with ``scheduler``.
    scheduler : str or None
        Address of a Dask scheduler (``tcp://host:8786``); the scenes are computed on its
        workers, which must be able to import mmreg and this folder (``PYTHONPATH``).
    progress : bool
        A tqdm progress bar per experiment (on stderr).
    """
    frames = []
    with parallel_backend(n_jobs, scheduler):
        for experiment in experiments:
            frames.append(_run_experiment(experiment, cache_dir=cache_dir, progress=progress))
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def _run_experiment(experiment, *, cache_dir, progress):
    rows, todo = {}, []
    for run, seed in enumerate(experiment.seeds):
        missing = []
        for column in experiment.columns:
            cached = None
            if cache_dir is not None:
                cached = _read_cache(cache_path(cache_dir, experiment, column, seed))
            if cached is None:
                missing.append(column)
            else:
                rows[(run, column.label)] = cached
        if missing:
            todo.append((run, seed, missing))
    total = len(experiment.seeds) * len(experiment.columns)
    bar = tqdm(
        total=total,
        initial=len(rows),
        desc=experiment.title[:60],
        unit="run",
        disable=not progress,
        leave=True,
    )
    by_label = {column.label: column for column in experiment.columns}
    with bar:
        if todo:
            jobs = (
                joblib.delayed(_run_scene)(experiment, run, seed, missing)
                for run, seed, missing in todo
            )
            for run, seed, new_rows in joblib.Parallel(return_as="generator_unordered")(jobs):
                for row in new_rows:
                    rows[(run, row["method"])] = row
                    if cache_dir is not None:
                        path = cache_path(cache_dir, experiment, by_label[row["method"]], seed)
                        _write_atomic(path, json.dumps(row))
                bar.update(len(new_rows))
    ordered = [
        rows[(run, column.label)]
        for run in range(len(experiment.seeds))
        for column in experiment.columns
    ]
    frame = pd.DataFrame(ordered)
    frame.insert(1, "title", experiment.title)
    return frame


# --------------------------------------------------------------------------- outputs
def add_runner_arguments(parser, *, runs_default, runs_help, parallel=True):
    """The options every experiment script shares (``parallel=False``: no runner options)."""
    parser.add_argument("--runs", type=int, default=runs_default, help=runs_help)
    parser.add_argument(
        "--seed", type=int, default=0, help="base seed: every scene is a function of it"
    )
    parser.add_argument(
        "--methods",
        default="all",
        help="comma-separated registry names (mmreg.methods.available_methods(), entry "
        "points of the group 'mmreg.methods' included), or 'all'",
    )
    if parallel:
        parser.add_argument(
            "--n-jobs", type=int, default=1, help="parallel joblib processes (-1: all cores)"
        )
        parser.add_argument(
            "--scheduler",
            default=None,
            help="address of a Dask scheduler (tcp://host:8786) to run the scenes on its "
            "workers instead (their PYTHONPATH must hold this folder)",
        )
    parser.add_argument(
        "--out", type=Path, default=DEFAULT_OUT, help="folder for the CSV, tables and figures"
    )
    if parallel:
        parser.add_argument(
            "--cache",
            type=Path,
            default=None,
            help="folder of the per-run cache (one JSON file per run; an interrupted run "
            "resumes from it); default: OUT/cache",
        )
        parser.add_argument("--no-cache", action="store_true", help="recompute every run")
    parser.add_argument("--quick", action="store_true", help="tiny scenes, for tests (seconds)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def make_parser(doc):
    """An argument parser whose description is the script's docstring."""
    return argparse.ArgumentParser(description=doc, formatter_class=_Formatter, allow_abbrev=False)


class _Formatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Defaults shown, the docstring kept as written."""


def run_with_options(experiments, args):
    """:func:`run_experiments` with the cache, parallelism and progress the options ask for."""
    cache_dir = None
    if not getattr(args, "no_cache", True):
        cache_dir = args.cache if args.cache is not None else args.out / "cache"
    return run_experiments(
        experiments,
        cache_dir=cache_dir,
        n_jobs=args.n_jobs,
        scheduler=args.scheduler,
        progress=not args.no_progress,
    )


def write_frame(frame, path):
    """A CSV written whole (temporary file, then renamed)."""
    _write_atomic(path, frame.to_csv(index=False))
    return Path(path)


def write_text(text, path):
    """A text file written whole."""
    _write_atomic(path, text)
    return Path(path)


def add_formats_argument(parser):
    """``--formats``: the file types of the figures."""
    parser.add_argument(
        "--formats",
        default="png,pdf",
        help="comma-separated file types of the figures (any matplotlib can write)",
    )


def save_figure(fig, path_stem, dpi=110, formats="png,pdf"):
    """``<stem>.png``, ``<stem>.pdf``, ... (``formats``), each written whole."""
    import matplotlib.pyplot as plt

    paths = []
    for kind in formats.split(","):
        suffix = "." + kind.strip().lstrip(".")
        path = Path(f"{path_stem}{suffix}")
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.stem}.tmp{suffix}")
        fig.savefig(tmp, dpi=dpi)
        os.replace(tmp, path)
        paths.append(path)
    plt.close(fig)
    return paths


def fmt(value):
    """Three significant digits, like the paper."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if value == 0:
        return "0"
    return f"{value:.3g}"


def best_mask(values, better, exact=None, target=None):
    """Which of ``values`` are best: ties at display precision and exact answers count."""
    values = pd.Series(values, dtype=float)
    shown = values.map(lambda v: float(fmt(v)) if np.isfinite(v) else np.nan)
    if exact is not None:
        shown = shown.where(~(values <= exact), 0.0)
    if target is not None:
        distance = (shown - target).abs()
        return distance == distance.min()
    if better == "max":
        return shown == shown.max()
    if better == "min":
        return shown == shown.min()
    return pd.Series(False, index=values.index)
