"""The jobs of a dataset: what :func:`mmreg.runner.run_dataset` fits, one input each.

A job is a small frozen dataclass (picklable: it holds paths, not data) with a unique
``name`` and a ``load()`` that reads its input where it runs (a Dask worker), returning
a dict with ``X`` (n, 6) and, when the data have them, ``labels_true`` (n,) (negative:
unknown or outlier, not scored) and ``flow_true`` (n, 3). A job of two raw sweeps
(``pairs="sweeps"``) gives ``X`` (n, 3), the first sweep, and ``sweep`` (m, 3), the second
(any size, any order), for :class:`mmreg.SweepRegistration`; an Argoverse 2 one also gives
the capture times of both sweeps' points, ``times`` (n,) and ``sweep_times`` (m,) (seconds
after each sweep's timestamp, from ``offset_ns``), and ``interval``, the seconds between
the two timestamps, unless every offset is zero or ``capture_times=False``.

:func:`dataset_jobs` lists the jobs of a folder:

* an Argoverse 2 log (it holds ``sensors/lidar``): one job per consecutive sweep pair,
  the ground-truth flow as the correspondences and the truth to score against;
* a folder of Argoverse 2 logs: the jobs of every log;
* a folder of frames (``*.ply``, ``*.pcd``, ``*.xyz``, or ``*.npy`` of shape (n, 3)), in
  name order: one job per consecutive pair, frame ``k + 1`` giving the b-points of frame
  ``k`` row by row (the clouds must be index-aligned);
* with ``pairs="sweeps"``, the frames or an Argoverse 2 log's sweeps are raw sweeps: one
  job per consecutive pair, sweep ``k`` registered to sweep ``k + 1`` from the points
  alone (any sizes and orders); an Argoverse 2 job is still scored against the true flow
  of sweep ``k``, and gives its points' capture times (``capture_times``);
* a folder of correspondence files (``*.npy`` (n, 6), ``*.npz``, ``*.csv``, ``*.txt``):
  one job per file. An ``.npz`` may also hold the truth: ``labels`` (n,) and ``flow``
  (n, 3).
"""

import dataclasses
import os
from collections import Counter
from pathlib import Path

import numpy as np

__all__ = [
    "Argoverse2PairJob",
    "Argoverse2SweepPairJob",
    "CorrespondenceFileJob",
    "FramePairJob",
    "SweepPairJob",
    "dataset_jobs",
]

FRAME_EXTENSIONS = (".ply", ".pcd", ".xyz")
CORRESPONDENCE_EXTENSIONS = (".npy", ".npz", ".csv", ".txt")
PAIRS = ("aligned", "sweeps")


@dataclasses.dataclass(frozen=True)
class FramePairJob:
    """Frame ``source`` and the next frame ``target``, index-aligned (b_i = target row i)."""

    name: str
    source: str
    target: str

    def load(self):
        from mmreg import io as mmio

        a = mmio._read_points(self.source, "the frame's points")
        b = mmio._read_points(self.target, "the next frame's points")
        if len(a) != len(b):
            raise ValueError(
                f"{self.target}: holds {len(b)} points but {self.source} holds {len(a)}; "
                "consecutive frames must be index-aligned (row i of one is row i of the other); "
                "for raw sweeps of any sizes and orders use pairs='sweeps' "
                "('mmreg run --pairs sweeps')."
            )
        return {"X": np.hstack([a, b])}


@dataclasses.dataclass(frozen=True)
class SweepPairJob:
    """Frame ``source`` and the next frame ``target`` as two raw sweeps (any sizes, orders)."""

    name: str
    source: str
    target: str

    def load(self):
        from mmreg import io as mmio

        a = mmio._read_points(self.source, "the first sweep's points")
        sweep = mmio._read_points(self.target, "the second sweep's points")
        return {"X": a, "sweep": sweep}


@dataclasses.dataclass(frozen=True)
class CorrespondenceFileJob:
    """One file of correspondences; an ``.npz`` may add ``labels`` and ``flow`` (truth)."""

    name: str
    path: str

    def load(self):
        from mmreg import io as mmio

        X = mmio.read_correspondences(self.path)
        data = {"X": X}
        if Path(self.path).suffix.lower() == ".npz":
            arrays = mmio._load_npz(self.path)
            if "labels" in arrays:
                labels = np.asarray(arrays["labels"])
                if labels.shape != (len(X),) or labels.dtype.kind not in "iu":
                    raise ValueError(
                        f"{self.path}: 'labels' must be {len(X)} integers, one per "
                        f"correspondence; got {labels.dtype} of shape {labels.shape}."
                    )
                data["labels_true"] = labels.astype(np.intp)
            if "flow" in arrays:
                flow = mmio._check_points(arrays["flow"], self.path, 3, "key 'flow'")
                if len(flow) != len(X):
                    raise ValueError(f"{self.path}: 'flow' has {len(flow)} rows for {len(X)}.")
                data["flow_true"] = flow
        return data


@dataclasses.dataclass(frozen=True)
class Argoverse2PairJob:
    """Sweep pair ``index`` of an Argoverse 2 log: the true flow and labels."""

    name: str
    log_dir: str
    index: int
    drop_ground: bool = True

    def load(self):
        from mmreg.datasets import load_argoverse2

        scene = load_argoverse2(self.log_dir, self.index, drop_ground=self.drop_ground)
        return {"X": scene.X, "labels_true": scene.labels, "flow_true": scene.flow}


@dataclasses.dataclass(frozen=True)
class Argoverse2SweepPairJob:
    """Sweep pair ``index`` of an Argoverse 2 log as two raw sweeps, scored by the true flow.

    ``X`` is sweep t's points and ``sweep`` sweep t+1's (both without the ground when
    ``drop_ground``); the true flow and labels are those of sweep t. With
    ``capture_times``, ``times`` and ``sweep_times`` are the points' capture times (the
    sweep files' ``offset_ns``, in seconds) and ``interval`` the seconds between the two
    sweeps' timestamps, for ``SweepRegistration.fit``'s deskewing; left out when the
    files have no offsets or all of them are zero (nothing to deskew).
    """

    name: str
    log_dir: str
    index: int
    drop_ground: bool = True
    capture_times: bool = True

    def load(self):
        from mmreg.datasets import load_argoverse2

        scene = load_argoverse2(self.log_dir, self.index, drop_ground=self.drop_ground)
        if scene.sweep2 is None:
            raise ValueError(
                f"{self.log_dir}: no lidar sweep at {scene.timestamps[1]}, the next pose's "
                "time; pairs='sweeps' needs both sweeps."
            )
        data = {
            "X": scene.a,
            "sweep": scene.sweep2,
            "labels_true": scene.labels,
            "flow_true": scene.flow,
        }
        times, sweep_times = scene.times, scene.sweep2_times
        if (
            self.capture_times
            and times is not None
            and sweep_times is not None
            and (np.any(times != 0) or np.any(sweep_times != 0))
        ):
            data.update(times=times, sweep_times=sweep_times, interval=float(scene.dt))
        return data


def _is_argoverse2_log(folder):
    return (Path(folder) / "sensors" / "lidar").is_dir()


def _argoverse2_jobs(log_dir, drop_ground, pairs, capture_times, prefix=""):
    from mmreg.datasets import Argoverse2Log

    log = Argoverse2Log(log_dir)
    stamps = log.timestamps
    if pairs == "sweeps":
        # Only pairs of sweeps: the last sweep of a truncated log may be paired with an
        # annotated time that has no sweep (its flow is known, its points are not).
        return [
            Argoverse2SweepPairJob(
                f"{prefix}{stamps[i]}", str(log.log_dir), i, drop_ground, capture_times
            )
            for i in range(len(stamps) - 1)
        ]
    return [
        Argoverse2PairJob(f"{prefix}{stamps[i]}", str(log.log_dir), i, drop_ground)
        for i in range(len(log))
    ]


def _check_some(jobs, folder):
    if not jobs:
        raise ValueError(f"{folder}: no pair of consecutive LiDAR sweeps in its log(s).")
    return jobs


def _npy_columns(path):
    """The number of columns of a 2-D ``.npy`` file, from its header (None if not 2-D)."""
    # A memory map reads the header only.
    shape = np.load(path, mmap_mode="r", allow_pickle=False).shape
    return shape[1] if len(shape) == 2 else None


def dataset_jobs(path, *, layout="auto", drop_ground=True, pairs="aligned", capture_times=True):
    """The jobs of the dataset at ``path`` (a folder), in a stable order.

    Parameters
    ----------
    path : str or path-like
        An Argoverse 2 log, a folder of logs, of frames or of correspondence files.
    layout : {"auto", "argoverse2", "frames", "correspondences"}, default="auto"
        What the folder holds; ``"auto"``: an Argoverse 2 log or folder of logs if it
        looks like one, else frames when the files are point clouds or (n, 3) ``.npy``
        arrays, else correspondence files.
    drop_ground : bool, default=True
        Argoverse 2: remove the ground points (by the log's ground height map).
    pairs : {"aligned", "sweeps"}, default="aligned"
        What a pair of consecutive frames or sweeps is. ``"aligned"``: correspondences,
        row ``i`` of frame ``k + 1`` matching row ``i`` of frame ``k`` (Argoverse 2: the
        true flow gives every point's match). ``"sweeps"``: two raw sweeps of any sizes
        and orders, to register from the points alone with
        :class:`mmreg.SweepRegistration` (Argoverse 2: still scored against the true
        flow). Not for a folder of correspondence files.
    capture_times : bool, default=True
        Argoverse 2 with ``pairs="sweeps"``: hand the points' capture times (the sweep
        files' ``offset_ns``) and the interval between the sweeps to the estimator, whose
        ``fit`` deskews the moving objects with them (:class:`mmreg.SweepRegistration`).
        False: register the sweeps as if every point were taken at its sweep's
        timestamp. Ignored for the other layouts (their files carry no times).

    Returns
    -------
    jobs : list
        Of FramePairJob, SweepPairJob, CorrespondenceFileJob, Argoverse2PairJob or
        Argoverse2SweepPairJob.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist (also a ValueError).
    ValueError
        If ``path`` is not a folder, holds no job, or mixes kinds of files.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg._dataset_jobs import dataset_jobs
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     for k in range(3):
    ...         np.save(Path(folder) / f"frame{k}.npy", np.zeros((5, 3)))
    ...     [job.name for job in dataset_jobs(folder)]
    ['frame0__frame1', 'frame1__frame2']
    """
    allowed = ("auto", "argoverse2", "frames", "correspondences")
    if layout not in allowed:
        raise ValueError(f"layout must be one of {allowed}; got {layout!r}.")
    if pairs not in PAIRS:
        raise ValueError(f"pairs must be one of {PAIRS}; got {pairs!r}.")
    if not isinstance(capture_times, (bool, np.bool_)):
        raise TypeError(f"capture_times must be True or False; got {capture_times!r}.")
    capture_times = bool(capture_times)
    folder = Path(path)
    if not folder.exists():
        raise FileNotFoundError(f"{folder}: no such folder (the dataset).")
    if not folder.is_dir():
        raise ValueError(f"{folder}: not a folder; a dataset is a folder of files or logs.")
    if layout in ("auto", "argoverse2"):
        if _is_argoverse2_log(folder):
            return _check_some(_argoverse2_jobs(folder, drop_ground, pairs, capture_times), folder)
        logs = sorted(p for p in folder.iterdir() if p.is_dir() and _is_argoverse2_log(p))
        if logs:
            jobs = [
                job
                for log in logs
                for job in _argoverse2_jobs(log, drop_ground, pairs, capture_times, f"{log.name}_")
            ]
            return _check_some(jobs, folder)
        if layout == "argoverse2":
            raise ValueError(
                f"{folder}: not an Argoverse 2 log (no sensors/lidar) nor a folder of logs."
            )
    files = sorted(
        p
        for p in folder.iterdir()
        if p.is_file()
        and not p.name.startswith(".")
        and p.suffix.lower() in (*FRAME_EXTENSIONS, *CORRESPONDENCE_EXTENSIONS)
    )
    if not files:
        raise ValueError(
            f"{folder}: no frames ({', '.join(FRAME_EXTENSIONS)}, .npy) nor correspondence "
            f"files ({', '.join(CORRESPONDENCE_EXTENSIONS)}) in it."
        )
    if layout == "auto":
        suffixes = {p.suffix.lower() for p in files}
        if suffixes <= set(FRAME_EXTENSIONS):
            layout = "frames"
        elif suffixes == {".npy"}:
            columns = {_npy_columns(p) for p in files}
            if columns == {3}:
                layout = "frames"
            elif columns == {6}:
                layout = "correspondences"
            else:
                raise ValueError(
                    f"{folder}: its .npy files are neither all frames (n, 3) nor all "
                    f"correspondences (n, 6); found {sorted(map(str, columns))} columns."
                )
        elif suffixes & set(FRAME_EXTENSIONS):
            raise ValueError(
                f"{folder}: mixes point clouds and other files ({', '.join(sorted(suffixes))}); "
                "a dataset folder holds frames or correspondence files, not both."
            )
        else:
            layout = "correspondences"
    if layout == "frames":
        if len(files) < 2:
            raise ValueError(f"{folder}: one frame only; a job is a pair of consecutive frames.")
        kind = SweepPairJob if pairs == "sweeps" else FramePairJob
        return [
            kind(f"{first.stem}__{second.stem}", str(first), str(second))
            for first, second in zip(files[:-1], files[1:], strict=True)
        ]
    if pairs == "sweeps":
        raise ValueError(
            f"{folder}: holds correspondence files; pairs='sweeps' needs frames (point "
            "clouds or (n, 3) .npy files) or Argoverse 2 logs."
        )
    names = [p.stem for p in files]
    if len(set(names)) != len(names):
        raise ValueError(f"{folder}: two files share a name but for the extension.")
    return [CorrespondenceFileJob(p.stem, str(p)) for p in files]


def check_jobs(jobs):
    """``jobs`` as a list, each with a ``name`` usable as a file name and a ``load()``."""
    jobs = list(jobs)
    names = []
    for job in jobs:
        name = getattr(job, "name", None)
        if not callable(getattr(job, "load", None)) or not isinstance(name, str):
            raise TypeError(f"a job needs a str 'name' and a 'load()' method; got {job!r}.")
        if not name or name in (".", "..") or os.sep in name or "/" in name or name[0] == ".":
            raise ValueError(f"job name {name!r} cannot be a file name.")
        names.append(name)
    repeated = sorted(name for name, count in Counter(names).items() if count > 1)
    if repeated:
        raise ValueError(f"job names must be unique; repeated: {repeated[:3]}.")
    return jobs
