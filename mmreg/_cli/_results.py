"""What ``mmreg view`` and ``mmreg evaluate`` open: a result directory, a run, or a job.

Three kinds of result, each read into :class:`Result`:

* a result directory of ``mmreg register`` or ``mmreg demo --out`` (``labels.npy``,
  ``motions.json``, ``run.json``, and ``X.npy`` or the input files named in
  ``run.json``);
* an ``mmreg run`` folder (``run.json`` with its ``configuration``, ``jobs/<job>.npz``):
  one job by name, or every job;
* one job file, ``RUN/jobs/<job>.npz`` (``labels``, ``rotations``, ``translations``,
  ``flow``, ``moving``, ``meta``, and ``indices`` when the job used some rows of its
  first sweep only: ``labels[i]`` is row ``indices[i]``).

Everything a result's own files answer (labels, motions, flow) is read at once; its
points, which may live in an input file or in the run's dataset, only when asked
(:meth:`Result.points`), so that an IoU needs no input file.
"""

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mmreg._cli._common import CLIError, check_labels, read_result_input, reading

# The arrays every job file holds (see mmreg.runner).
_JOB_ARRAYS = ("labels", "rotations", "translations", "flow")


@dataclass
class Result:
    """One result: its labels and motions, and how to get its points and truth.

    ``derived``: the b-points of :meth:`points` are the result's own flow (two raw
    sweeps), so no error may be measured against them. ``external``: the points are
    read from files outside the result (its input files, or a run's dataset), which may
    have moved or changed since; else from the result's own ``X.npy``.
    """

    name: str
    path: Path
    labels: Any
    rotations: Any = None
    translations: Any = None
    moving: Any = None
    flow: Any = None
    ego_body: Any = None
    camera: Any = None
    derived: bool = False
    external: bool = True
    _points: Any = field(default=None, repr=False)
    _job: Any = field(default=None, repr=False)
    _cache: dict = field(default_factory=dict, repr=False)

    def points(self, *, required=True):
        """``[a | b]`` (or the a-points alone, (n, 3)) of the labels' rows, or a CLIError.

        With ``required=False``, None when the result keeps no points of its own.
        """
        if "points" not in self._cache:
            self._cache["points"] = self._points(required)
        return self._cache["points"]

    def job_data(self):
        """The job's data loaded again from its dataset (``X``, ``labels_true``, ...)."""
        if self._job is None:
            return None
        if "data" not in self._cache:
            self._cache["data"] = _load_job(self._job, self)
        return self._cache["data"]

    def rows(self, array):
        """The rows of the job's data (``X``, its truth) that the labels are.

        The job's data holds the rows of its input that its load keeps (``indices``, e.g.
        a sequence's returns), the result the rows its fit saw (its own ``indices``,
        without the rows that hold no return or, with ``--ground drop``, the ground):
        both name rows of the input, so the one is found in the other.
        """
        indices = self._cache.get("indices")
        if indices is None:
            return array
        import numpy as np

        data = self.job_data()
        loaded = data.get("indices") if data is not None else None
        loaded = np.arange(len(array)) if loaded is None else np.asarray(loaded, dtype=np.intp)
        order = np.argsort(loaded, kind="stable")
        missing = indices[~np.isin(indices, loaded)]
        if len(missing):
            raise CLIError(
                f"{self.path}: its rows include row {int(missing[0])} of the job's input, which "
                f"the input no longer holds ({len(loaded):,} rows; changed since?)"
            )
        at = order[np.searchsorted(loaded, indices, sorter=order)]
        return array[at]


def is_run_folder(path):
    """Whether ``path`` is an 'mmreg run' folder of pairs (``jobs/`` and ``run.json``)."""
    return _is_run_folder(Path(path))


def _is_run_folder(path):
    run = path / "run.json"
    if not (path / "jobs").is_dir() or not run.is_file():
        return False
    with reading(run):
        record = json.loads(run.read_text())
    return isinstance(record, dict) and "configuration" in record


def open_results(path, *, job=None, every_job=False):
    """The results at ``path`` (a result directory, a run folder or a job file).

    ``job``: the name of one job of a run folder. Without it, a run folder of one job
    gives that job, and of several gives all (``every_job``) or a CLIError asking for
    ``--job``.
    """
    path = Path(path)
    if path.is_file() and path.suffix == ".npz":
        if job is not None:
            raise CLIError(f"{path}: is one job's file already; drop --job {job}")
        return [_job_result(path)]
    if not path.is_dir():
        raise CLIError(
            f"{path}: not a result (no such directory); give a result directory of 'mmreg "
            "register', an 'mmreg run' folder or one of its jobs/<job>.npz"
        )
    if _is_run_folder(path):
        files = sorted((path / "jobs").glob("*.npz"))
        if job is not None:
            chosen = path / "jobs" / f"{job}.npz"
            if not chosen.is_file():
                names = ", ".join(f.stem for f in files[:5]) + (", ..." if len(files) > 5 else "")
                raise CLIError(f"{chosen}: no such job in {path} (it holds {names or 'none'})")
            return [_job_result(chosen)]
        if not files:
            raise CLIError(f"{path}: an 'mmreg run' folder with no finished job in jobs/")
        if len(files) > 1 and not every_job:
            names = ", ".join(f.stem for f in files[:3]) + (", ..." if len(files) > 3 else "")
            raise CLIError(
                f"{path}: holds {len(files):,} jobs; choose one with --job NAME ({names})"
            )
        return [_job_result(f) for f in files]
    if job is not None:
        raise CLIError(f"{path}: --job chooses a job of an 'mmreg run' folder; this is not one")
    return [_directory_result(path)]


def _directory_result(folder):
    import numpy as np

    from mmreg import io as mmio

    labels_path = folder / "labels.npy"
    if not labels_path.exists():
        raise CLIError(
            f"{folder}: not a result: no labels.npy (and no jobs/ of an 'mmreg run'); give a "
            "result directory of 'mmreg register', an 'mmreg run' folder or one of its "
            "jobs/<job>.npz"
        )
    with reading(labels_path):
        labels = mmio.read_labels(labels_path)
    labels = check_labels(labels, len(np.asarray(labels)), labels_path)
    result = Result(name=folder.name, path=folder, labels=labels)
    body_path = folder / "ego_body.npy"
    if body_path.exists():  # two sweeps: the ego vehicle's own body, labelled -1
        with reading(body_path):
            result.ego_body = _check_body(np.load(body_path, allow_pickle=False), labels, body_path)
    motions_path = folder / "motions.json"
    if motions_path.exists():
        with reading(motions_path):
            motions = mmio.read_motions(motions_path)
        result.rotations, result.translations = motions["rotations"], motions["translations"]
        result.moving = motions.get("moving")
        if len(result.rotations) < labels.max(initial=-1) + 1:
            raise CLIError(
                f"{motions_path}: {len(result.rotations)} motions for labels up to {labels.max()}"
            )
    run = {}
    if (folder / "run.json").exists():
        with reading(folder / "run.json"):
            run = json.loads((folder / "run.json").read_text())
        run = run if isinstance(run, dict) else {}
    result.camera = run.get("camera")
    # With --sweep, X.npy holds the first sweep and where the result's flow moves it.
    result.derived = run.get("sweep") is not None
    result.external = not (folder / "X.npy").exists()
    result._points = lambda required: read_result_input(folder, len(labels), required=required)
    return result


def _job_result(path):
    import numpy as np

    from mmreg.io._arrays import _load_npz
    from mmreg.io._checks import _check_readable

    with reading(path):
        # Read as stored (flows float32 by default): the sweep's whole flow, which
        # mmreg.runner.read_job_result restores, is not needed here.
        arrays = _load_npz(_check_readable(path, "a job's result"))
        missing = [name for name in (*_JOB_ARRAYS, "meta") if name not in arrays]
        if missing:
            raise CLIError(
                f"{path}: not a job's result of 'mmreg run' (no {', '.join(missing)}); "
                f"it holds {sorted(arrays)}"
            )
        meta = json.loads(str(arrays["meta"]))
    labels = check_labels(arrays["labels"], len(arrays["labels"]), path)
    name = meta.get("row", {}).get("job", path.stem) if isinstance(meta, dict) else path.stem
    result = Result(
        name=str(name),
        path=path,
        labels=labels,
        rotations=np.asarray(arrays["rotations"], dtype=float),
        translations=np.asarray(arrays["translations"], dtype=float),
        moving=arrays.get("moving"),
        flow=np.asarray(arrays["flow"], dtype=float),
    )
    if "ego_body" in arrays:
        result.ego_body = _check_body(arrays["ego_body"], labels, path)
    if len(result.flow) != len(labels):
        raise CLIError(f"{path}: {len(result.flow)} flow vectors for {len(labels)} labels")
    if "indices" in arrays:
        indices = np.asarray(arrays["indices"])
        if indices.shape != labels.shape or indices.dtype.kind not in "iu":
            raise CLIError(
                f"{path}: 'indices' must be one row number per label; got {indices.shape}"
            )
        result._cache["indices"] = indices.astype(np.intp)
    run_folder = path.parent.parent
    configuration = None
    if path.parent.name == "jobs" and (run_folder / "run.json").is_file():
        with reading(run_folder / "run.json"):
            configuration = json.loads((run_folder / "run.json").read_text())
        configuration = (
            configuration.get("configuration") if isinstance(configuration, dict) else None
        )
    result._job = (configuration, run_folder)
    result.derived = configuration is not None and configuration.get("pairs") == "sweeps"
    result._points = lambda required: _job_points(result, required)
    return result


def _check_body(body, labels, path):
    """The ego vehicle's body: one bool per label, or a CLIError naming ``path``."""
    import numpy as np

    body = np.asarray(body)
    if body.dtype != bool or body.shape != labels.shape:
        raise CLIError(
            f"{path}: the ego vehicle's body must be one bool per label ({len(labels):,}); got "
            f"{body.dtype} {body.shape}"
        )
    return body


def _load_job(job, result):
    """Load the job named ``result.name`` again from the run's dataset."""
    configuration, run_folder = job
    if configuration is None:
        raise CLIError(
            f"{result.path}: its points are in the dataset of an 'mmreg run' folder, but "
            f"{run_folder / 'run.json'} is missing or names no dataset; open the job inside "
            "its run folder (RUN/jobs/<job>.npz)"
        )
    jobs = run_jobs(configuration, run_folder)
    dataset = configuration.get("dataset")
    found = [j for j in jobs if j.name == result.name]
    if not found:
        raise CLIError(f"{dataset}: holds no job {result.name!r} any more (changed since?)")
    with reading(dataset):
        data = found[0].load()
    return data


def run_jobs(configuration, run_folder):
    """The jobs of an 'mmreg run' of pairs, listed again from its dataset and options."""
    from mmreg.runner import dataset_jobs

    dataset = configuration.get("dataset")
    if not dataset or not Path(dataset).exists():
        raise CLIError(
            f"{dataset}: no such dataset; the run {run_folder} was computed from it (moved "
            "or deleted since?)"
        )
    with reading(dataset):
        ground = configuration.get("ground")
        if ground is None:  # a run of an earlier version
            ground = "drop" if configuration.get("drop_ground", True) else "keep"
        jobs = dataset_jobs(
            dataset,
            layout=configuration.get("layout", "auto"),
            ground=ground,
            pairs=configuration.get("pairs", "aligned"),
            capture_times=configuration.get("capture_times", True),
            flow=configuration.get("flow"),
            topic=configuration.get("topic"),
            pattern=configuration.get("pattern"),
            frame_rate=configuration.get("frame_rate"),
            poses=configuration.get("poses", True),
        )
    return jobs


def _job_points(result, required):
    import numpy as np

    data = result.job_data()
    X = result.rows(np.asarray(data["X"], dtype=float))
    if len(X) != len(result.labels):
        raise CLIError(
            f"{result.path}: {len(result.labels):,} labels but the job's input now has "
            f"{len(X):,} rows (the dataset changed since?)"
        )
    return X
