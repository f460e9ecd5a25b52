"""What the subcommands share: errors, progress, the result directory and its summary.

A result directory (written by ``mmreg register`` and ``mmreg demo --out``) holds:

* ``labels.npy``: the cluster of every correspondence, ``-1`` for outliers;
* ``motions.json``: per cluster its label, 4 x 4 ``transform``, ``rotation``,
  ``translation``, ``rotation_angle_deg``, ``sigma``, ``size`` and ``moving``;
* ``summary.csv``: one row per cluster (see :func:`summarize`);
* ``clusters.ply``: the a-points coloured by cluster, outliers grey, and each point's
  cluster as an int property ``label`` (-1 for outliers);
* ``result.png``: the picture;
* ``X.npy``: the input correspondences ``[a | b]``, only on request (``mmreg register
  --save-input``) or when there is no input file (``mmreg demo``);
* ``run.json``: the input, the options and the run's numbers; for an input file, its
  absolute path and the SHA-256 of its correspondences, from which ``mmreg view`` and
  ``mmreg evaluate`` read it again when there is no ``X.npy`` (see
  :func:`read_result_input`).

It is written whole or not at all, and never over anything but an earlier result: every
file goes to a hidden staging folder beside it first, which then takes the result's
place in one rename (see :func:`write_result_dir`). Where the result goes is checked
before any work (:func:`check_out`). An interrupted run removes its staging folder
(:func:`remove_partial`).
"""

import contextlib
import errno
import json
import os
import shutil
import signal
import sys
import tempfile
import warnings
from pathlib import Path

RESULT_FILES = (
    "labels.npy",
    "motions.json",
    "summary.csv",
    "clusters.ply",
    "result.png",
    "X.npy",
    "run.json",
)
# Files a result directory may also hold (``mmreg demo --out`` adds the ground truth; two
# sweeps, the ego vehicle's body and the rows of INPUT kept when some held no return).
EXTRA_RESULT_FILES = ("truth.npz", "ego_body.npy", "indices.npy")
# Staging folders (and replaced results) of this process, removed if it is interrupted.
_PARTIAL = set()


# The columns of summary.csv.
SUMMARY_COLUMNS = [
    "label",
    "size",
    "fraction",
    "rotation_angle_deg",
    "tx",
    "ty",
    "tz",
    "translation_norm",
    "displacement",
    "speed",
    "sigma",
    "rms_residual",
    "centroid_x",
    "centroid_y",
    "centroid_z",
    "extent_x",
    "extent_y",
    "extent_z",
    "background",
    "relative_rotation_deg",
    "displacement_vs_background",
    "residual_scale",
    "moving",
]


class CLIError(Exception):
    """A problem to report as one line, ``mmreg: error: <message>``, and exit code 2."""


def one_line(message):
    """``message`` on one line (a reader sees one line on stderr, whatever raised it)."""
    return " ".join(str(message).split())


def error_about(path, error, *others):
    """A :class:`CLIError` ``"PATH: problem"`` from an exception raised on ``path``.

    A message that already names ``path`` or one of ``others`` (the other files read in
    the same step) is kept as it is.
    """
    if isinstance(error, OSError) and error.filename is not None and error.strerror:
        return CLIError(f"{error.filename}: {error.strerror.lower()}")
    message = one_line(error.args[0] if isinstance(error, KeyError) and error.args else error)
    if isinstance(error, FileNotFoundError) and not message:
        message = "no such file"
    names = [str(p) for p in (path, *others) if p is not None]
    if not any(name in message for name in names):
        message = f"{path}: {message}"
    return CLIError(message)


@contextlib.contextmanager
def reading(path, *others):
    """Turn the errors raised while reading ``path`` (and ``others``) into CLIError."""
    try:
        yield
    except CLIError:
        raise
    except (ValueError, TypeError, KeyError, OSError, EOFError) as error:
        raise error_about(path, error, *others) from error


def plural(count, word):
    """``"1 cluster"``, ``"2 clusters"``."""
    return f"{count:,} {word}{'' if count == 1 else 's'}"


def warn(message):
    """One line ``mmreg: warning: ...`` on stderr."""
    print(f"mmreg: warning: {one_line(message)}", file=sys.stderr)


# Warnings that say nothing a user of the command line can act on (numpy's floating
# point notes, deprecations inside libraries): not shown.
STRAY_WARNINGS = (
    RuntimeWarning,
    DeprecationWarning,
    PendingDeprecationWarning,
    FutureWarning,
    ResourceWarning,
)


@contextlib.contextmanager
def reported_warnings():
    """Show Python warnings raised inside as one ``mmreg: warning:`` line each (once).

    :data:`STRAY_WARNINGS` are dropped.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    seen = set()
    for item in caught:
        if issubclass(item.category, STRAY_WARNINGS):
            continue
        text = one_line(item.message)
        if text not in seen:
            seen.add(text)
            warn(text)


def show_warning(message, category, filename, lineno, file=None, line=None):
    """``warnings.showwarning`` for the command line: one ``mmreg: warning:`` line."""
    warn(message)


def _shows_a_bar(stream):
    """Whether tqdm would draw on ``stream`` (its ``disable=None``): unless it says it is
    not a terminal."""
    isatty = getattr(stream, "isatty", None)
    return isatty is None or isatty()


class Steps:
    """A tqdm progress bar over named steps, on stderr; hidden when quiet or not a terminal.

    With ``verbose`` and no bar (stderr is not a terminal), every step is announced as a
    line ``mmreg: <step>`` on stderr instead.
    """

    def __init__(self, total, *, quiet=False, verbose=False):
        self._bar = None
        if not quiet and _shows_a_bar(sys.stderr):  # tqdm (and its lock) only for a bar
            from tqdm import tqdm

            self._bar = tqdm(
                total=total,
                file=sys.stderr,
                leave=False,
                unit="step",
                bar_format="{desc:<34} {bar:20} {n_fmt}/{total_fmt} [{elapsed}]",
            )
        self._announce = bool(verbose) and self._bar is None

    @contextlib.contextmanager
    def step(self, description):
        if self._announce:
            print(f"mmreg: {description}", file=sys.stderr, flush=True)
        if self._bar is not None:
            self._bar.set_description_str(description)
        yield
        if self._bar is not None:
            self._bar.update(1)

    def close(self):
        if self._bar is not None:
            self._bar.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def load_npz(path, what=None):
    """``{name: array}`` of an ``.npz`` file, read strictly (CRC-checked, nothing after its end)."""
    from mmreg.io._arrays import _load_npz
    from mmreg.io._checks import _check_readable

    return _load_npz(_check_readable(path, what))


def load_npy(path, what=None):
    """The array of a ``.npy`` file, read strictly (its size must match its header)."""
    from mmreg.io._arrays import _load_npy
    from mmreg.io._checks import _check_readable

    return _load_npy(_check_readable(path, what))


def check_correspondences(X, path):
    """``X`` as a finite float array of shape (n, 6) with n >= 1, or a CLIError on ``path``."""
    import numpy as np

    X = np.asarray(X)
    if X.ndim != 2 or X.shape[1] != 6:
        raise CLIError(
            f"{path}: expected correspondences of shape (n, 6), the columns a_x a_y a_z b_x "
            f"b_y b_z; got shape {X.shape}"
        )
    if X.dtype.kind not in "iuf":
        raise CLIError(f"{path}: expected numbers; got dtype {X.dtype}")
    X = X.astype(float)
    if len(X) == 0:
        raise CLIError(f"{path}: no correspondences")
    bad = ~np.isfinite(X).all(axis=1)
    if bad.any():
        raise CLIError(
            f"{path}: {bad.sum()} row(s) hold NaN or infinite values, e.g. row {np.argmax(bad)}"
        )
    from mmreg._validation import check_coordinate_range

    try:
        check_coordinate_range(X, name="the correspondences")
    except ValueError as error:
        raise CLIError(f"{path}: {one_line(error)}") from None
    return X


class NoReturns:
    """The rows of two sweeps that hold a return, and how many did not.

    A row with NaN, or one of several at the origin (a LiDAR driver's failed returns: a
    bag with ``is_dense`` false, an organised cloud, a KITTI scan;
    :func:`mmreg._validation.invalid_rows`), is no measurement. ``keep`` and
    ``keep_sweep`` flag the rows kept of INPUT (points or correspondences) and of the
    second sweep; ``n`` and ``n_sweep`` count those dropped.
    """

    def __init__(self, X, sweep):
        import numpy as np

        from mmreg._validation import no_return

        self.keep = ~no_return(X)
        self.keep_sweep = ~no_return(sweep)
        self.n = int(np.count_nonzero(~self.keep))
        self.n_sweep = int(np.count_nonzero(~self.keep_sweep))

    def apply(self, X, sweep, timing, input_name, sweep_name):
        """``X``, ``sweep`` and the capture times (``fit``'s keywords) on the kept rows.

        A CLIError when a sweep keeps too few rows to register.
        """
        pairs = ((self.keep, X, input_name), (self.keep_sweep, sweep, sweep_name))
        for kept, values, name in pairs:
            if int(kept.sum()) < 3:
                raise CLIError(
                    f"{name}: {int(kept.sum())} of its {len(values):,} rows hold a return (the "
                    "others are NaN or at the origin); too few to register"
                )
        timing = dict(timing or {})
        if timing.get("times") is not None:
            timing["times"] = timing["times"][self.keep]
        if timing.get("sweep_times") is not None:
            timing["sweep_times"] = timing["sweep_times"][self.keep_sweep]
        return X[self.keep], sweep[self.keep_sweep], timing

    def record(self):
        """What ``run.json`` keeps: the counts."""
        return {"n_no_return": self.n, "n_sweep_no_return": self.n_sweep}


def ego_body(estimator, n):
    """Which of the ``n`` rows a fit took for the ego vehicle's own body (none if it has no
    such attribute): labelled -1, but no outliers."""
    import numpy as np

    body = getattr(estimator, "ego_body_mask_", None)
    return np.zeros(n, dtype=bool) if body is None else np.asarray(body, dtype=bool)


def count_line(estimator, n, no_returns=None):
    """``"12 outliers, 300 on the ego vehicle's body, 5 rows without a return left out"``:
    the points of a fit that no cluster holds, each kind apart (the last two when any)."""
    body = ego_body(estimator, n)
    parts = [plural(int(estimator.outlier_mask_.sum()) - int(body.sum()), "outlier")]
    if body.any():
        parts.append(f"{int(body.sum()):,} on the ego vehicle's body")
    if no_returns is not None and no_returns.n + no_returns.n_sweep:
        parts.append(
            f"{no_returns.n:,} + {no_returns.n_sweep:,} rows without a return left out "
            "(first + second sweep)"
        )
    return ", ".join(parts)


def npy_bytes(array):
    """The bytes of ``array`` as an ``.npy`` file."""
    import io

    import numpy as np

    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def check_labels(labels, n, path, what="labels"):
    """Integer labels, one per correspondence, or a CLIError on ``path``."""
    import numpy as np

    labels = np.asarray(labels)
    if labels.ndim != 1:
        raise CLIError(
            f"{path}: {what} must be one column, one per correspondence; got {labels.shape}"
        )
    if len(labels) != n:
        raise CLIError(f"{path}: {len(labels)} {what} for {n} correspondences")
    if labels.dtype.kind == "f":
        if not np.all(np.isfinite(labels)) or not np.all(labels == np.round(labels)):
            raise CLIError(f"{path}: {what} must be integers")
    elif labels.dtype.kind not in "iub":
        raise CLIError(f"{path}: {what} must be integers; got dtype {labels.dtype}")
    return labels.astype(np.intp)


def rotation_angle_deg(rotations):
    """Angle of each rotation matrix, in degrees."""
    import numpy as np

    rotations = np.asarray(rotations, dtype=float).reshape(-1, 3, 3)
    cosine = (np.trace(rotations, axis1=1, axis2=2) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def background_label(labels):
    """The largest cluster (the static world, when the camera moves), or None."""
    from mmreg._array.motion import static_cluster

    label = static_cluster(labels)
    return None if label < 0 else label


def _robust_rms(residual, group, n_clusters):
    """Per group, the RMS of its inliers (median + 3 robust standard deviations)."""
    import numpy as np

    from mmreg._array.motion import _INLIER_SIGMAS, _MAD_TO_SIGMA, _group_median

    median = _group_median(residual, group, n_clusters)
    mad = _group_median(np.abs(residual - median[group]), group, n_clusters)
    inlier = residual <= (median + _INLIER_SIGMAS * _MAD_TO_SIGMA * mad)[group]
    counts = np.bincount(group[inlier], minlength=n_clusters)
    sums = np.bincount(group[inlier], weights=residual[inlier] ** 2, minlength=n_clusters)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, np.sqrt(sums / np.maximum(counts, 1)), np.nan)


def sweep_residuals(a, flow, sweep, workers=1):
    """The distance from each moved point ``a + flow`` to the nearest point of ``sweep``.

    The residual of a result of two sweeps, whose b-points are its own flow (so that
    ``|R a + t - b|`` is 0 by construction). NaN where the flow is (no cluster at all).
    """
    import numpy as np
    from scipy.spatial import cKDTree

    moved = np.asarray(a, dtype=float) + np.asarray(flow, dtype=float)
    residual = np.full(len(moved), np.nan)
    finite = np.isfinite(moved).all(axis=1)
    residual[finite] = cKDTree(sweep).query(moved[finite], workers=workers)[0]
    return residual


def summarize(
    X, labels, rotations, translations, sigmas=None, *, residuals=None, moving=None, interval=None
):
    """One row per cluster: size, motion, residual and motion relative to the background.

    The background is the largest cluster. ``displacement_vs_background`` is the median
    over the cluster's a-points of the distance between where its own motion and the
    background's motion take them, ``residual_scale`` the RMS residual of its inliers
    (median + 3 robust standard deviations, so wrong correspondences do not inflate
    it), ``rms_residual`` the plain RMS of ``|R a + t - b|`` over all its
    correspondences. A cluster is ``moving`` when the displacement exceeds
    :data:`mmreg._array.motion.MOVING_FACTOR` (3) times the residual scale
    (:func:`mmreg._array.motion.moving_clusters`).

    ``translation_norm`` is ``|t|``, the motion of the sensor's origin under the cluster's
    motion (with a moving sensor, not how far the cluster went): ``displacement`` is the
    object's own, how far its motion takes its centroid beyond where the background's
    motion takes it, and ``speed`` that over ``interval`` (seconds between the two
    frames; NaN when unknown).

    ``residuals`` (one per row) replace ``|R a + t - b|`` in the two residual columns:
    for two sweeps, where ``b = a + flow`` is the result's own (:func:`sweep_residuals`).
    ``moving`` (one per cluster) replaces the rule above (the estimator's own).

    Returns a :class:`pandas.DataFrame` (coordinates in the units of the points).
    """
    import numpy as np
    import pandas as pd

    from mmreg._array.geometry import moved_rows
    from mmreg._array.grouping import group_bounds, group_centroids
    from mmreg._array.motion import motion_statistics, moving_from_statistics, static_cluster

    a, b = X[:, :3], X[:, 3:]
    rotations = np.asarray(rotations, dtype=float).reshape(-1, 3, 3)
    translations = np.asarray(translations, dtype=float).reshape(-1, 3)
    n_clusters = len(rotations)
    static = static_cluster(labels)
    displacement, scale = motion_statistics(a, b, labels, rotations, translations, static)
    if moving is None:
        moving = moving_from_statistics(displacement, scale, static)  # moving_clusters' rule
    moving = np.asarray(moving, dtype=bool)
    angles = rotation_angle_deg(rotations)
    clustered = np.flatnonzero(labels >= 0)
    group = labels[clustered]
    sizes = np.bincount(group, minlength=n_clusters)
    own = moved_rows(rotations, translations, group, np.ascontiguousarray(a[clustered].T)).T
    squared = np.sum((own - b[clustered]) ** 2, axis=1)
    if residuals is not None:
        residuals = np.asarray(residuals, dtype=float)[clustered]
        squared = residuals**2
        scale = _robust_rms(residuals, group, n_clusters)
    frame = pd.DataFrame({"label": np.arange(n_clusters), "size": sizes})
    frame["fraction"] = sizes / max(len(labels), 1)
    frame["rotation_angle_deg"] = angles
    frame[["tx", "ty", "tz"]] = translations
    frame["translation_norm"] = np.linalg.norm(translations, axis=1)
    if static >= 0:
        from mmreg.sweeps._motion_bounds import object_motions

        own, _ = object_motions(a, labels, (rotations, translations), static)
        own[static] = 0.0  # the reference, exactly
        frame["displacement"] = np.nan_to_num(np.linalg.norm(own, axis=1), nan=0.0)
    else:
        frame["displacement"] = np.full(n_clusters, np.nan)
    frame["speed"] = frame["displacement"] / interval if interval else np.nan
    frame["sigma"] = (
        np.asarray(sigmas, dtype=float) if sigmas is not None else np.full(n_clusters, np.nan)
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        sums = np.bincount(group, weights=squared, minlength=n_clusters)
        frame["rms_residual"] = np.where(sizes > 0, np.sqrt(sums / np.maximum(sizes, 1)), np.nan)
    centroids, _ = group_centroids(a, labels, n_clusters)
    frame[["centroid_x", "centroid_y", "centroid_z"]] = centroids
    low, high = group_bounds(a[clustered], group, n_clusters)
    extent = np.where(sizes[:, None] > 0, high - low, np.nan)
    frame[["extent_x", "extent_y", "extent_z"]] = extent
    frame["background"] = frame["label"] == static
    relative = np.zeros(n_clusters)
    if static >= 0:
        relative = rotation_angle_deg(rotations @ rotations[static].T)
        relative[static] = 0.0
    frame["relative_rotation_deg"] = relative
    frame["displacement_vs_background"] = np.nan_to_num(displacement, nan=0.0)
    frame["residual_scale"] = scale
    frame["moving"] = moving
    return frame[SUMMARY_COLUMNS]


def format_table(frame, spec):
    """A plain text table of ``frame``: ``spec`` lists ``(column, header, format)``."""
    cells = [[header for _, header, _ in spec]]
    for _, row in frame.iterrows():
        cells.append([format(row[column], fmt) for column, _, fmt in spec])
    widths = [max(len(r[i]) for r in cells) for i in range(len(spec))]
    lines = ["  ".join(cell.rjust(w) for cell, w in zip(r, widths, strict=True)) for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


# Picture formats by extension (those matplotlib writes without extra packages).
PICTURE_FORMATS = {
    ".png": "png",
    ".pdf": "pdf",
    ".svg": "svg",
    ".svgz": "svgz",
    ".eps": "eps",
    ".ps": "ps",
    ".jpg": "jpg",
    ".jpeg": "jpg",
    ".tif": "tif",
    ".tiff": "tif",
    ".webp": "webp",
}


def picture_format(path):
    """The matplotlib format of a picture file by its extension, or a CLIError naming it."""
    suffix = Path(path).suffix.lower()
    if suffix not in PICTURE_FORMATS:
        raise CLIError(
            f"{path}: unknown picture format {suffix or '(no extension)'!r}; use one of "
            f"{', '.join(PICTURE_FORMATS)}"
        )
    return PICTURE_FORMATS[suffix]


def render_picture(fig, fmt="png", dpi=110):
    """The bytes of a matplotlib Figure in the format ``fmt`` (``"png"``, ``"pdf"``, ...)."""
    import io

    buffer = io.BytesIO()
    with warnings.catch_warnings():
        # Layout engines warn when a legend or a long title does not fit: not the user's
        # problem, and the picture is still written.
        warnings.simplefilter("ignore", UserWarning)
        fig.savefig(buffer, format=fmt, dpi=dpi)
    return buffer.getvalue()


def render_png(fig, dpi=110):
    """The PNG bytes of a matplotlib Figure."""
    return render_picture(fig, "png", dpi)


def result_figure(
    X,
    labels,
    motions,
    *,
    moving=None,
    view="auto",
    title=None,
    camera=None,
    frame="auto",
    interval=None,
    range_=None,
    ego_body=None,
):
    """The picture of a result: :func:`mmreg.plotting.plot_result` of its a-points."""
    from mmreg.plotting import plot_result

    return plot_result(
        X[:, :3],
        labels,
        motions,
        moving=moving,
        view=view,
        frame=frame,
        camera=camera,
        interval=interval,
        range_=range_,
        title=title,
        ego_body=ego_body,
    )


def _nearest_existing(path):
    """``path`` or its nearest ancestor that exists."""
    path = Path(os.path.abspath(path))
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def _foreign_files(folder):
    """Names in ``folder`` that a result directory does not hold (sorted)."""
    allowed = {*RESULT_FILES, *EXTRA_RESULT_FILES}
    return sorted(p.name for p in Path(folder).iterdir() if p.name not in allowed)


def check_out(out, *, overwrite, option="--out"):
    """Check, before any work, that a result directory can be written to ``out``.

    ``out`` may be new, an empty folder, or (with ``overwrite``) an earlier result
    directory: a folder holding nothing but result files. Anything else (a file, a
    folder of the user's own files, an earlier result without ``overwrite``, a place
    that cannot be written) is a CLIError naming ``out`` as the user gave it.
    """
    out = Path(out)
    if out.exists() or out.is_symlink():
        if not out.is_dir():
            raise CLIError(f"{out}: exists and is not a folder; choose another {option}")
        try:
            entries = list(out.iterdir())
        except OSError as error:
            raise CLIError(f"{out}: cannot be read: {one_line(error.strerror or error)}") from None
        if entries:
            foreign = _foreign_files(out)
            if foreign:
                shown = ", ".join(foreign[:3]) + (", ..." if len(foreign) > 3 else "")
                raise CLIError(
                    f"{out}: is a folder holding files that mmreg did not write ({shown}); "
                    f"it is left as it is: choose another {option}"
                )
            if not overwrite:
                raise CLIError(
                    f"{out}: a result already exists there; pass --overwrite to replace it, "
                    f"or choose another {option}"
                )
    ancestor = _nearest_existing(Path(os.path.abspath(out)).parent)
    if not ancestor.is_dir():
        raise CLIError(f"{out}: cannot be written: {ancestor} is not a folder")
    try:  # what the staging folder will need (os.access is blind to read-only mounts)
        with _no_interrupts():
            os.rmdir(tempfile.mkdtemp(prefix=".mmreg-check.", dir=ancestor))
    except OSError as error:
        reason = one_line(error.strerror or error).lower()
        raise CLIError(f"{out}: cannot be written: folder {ancestor}: {reason}") from None
    return out


def remove_partial():
    """Remove this process's staging folders (after an interrupt or a failure)."""
    for path in list(_PARTIAL):
        shutil.rmtree(path, ignore_errors=True)
        _PARTIAL.discard(path)


@contextlib.contextmanager
def _no_interrupts():
    """Hold SIGINT back (POSIX) while the block runs; it is delivered afterwards."""
    block = getattr(signal, "pthread_sigmask", None)
    if block is None:
        yield
        return
    previous = block(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        block(signal.SIG_SETMASK, previous)


def _exchange(first, second):
    """Swap two paths in one atomic step (Linux ``renameat2``); False where unsupported."""
    if not sys.platform.startswith("linux"):
        return False
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p]
    renameat2.argtypes += [ctypes.c_uint]
    at_cwd, rename_exchange = -100, 2
    if renameat2(at_cwd, os.fsencode(first), at_cwd, os.fsencode(second), rename_exchange) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP):
        return False  # e.g. a file system without RENAME_EXCHANGE
    raise OSError(code, os.strerror(code), str(second))


def _put_in_place(staging, out):
    """Move the finished ``staging`` folder to ``out`` in one rename.

    A new ``out`` or an empty folder is replaced by ``rename``; an earlier result is
    swapped with the staging folder in one atomic exchange where the system allows
    (Linux), else moved aside, replaced and removed (restored if the replacement fails).
    Returns the path of what is left to remove, or None.
    """
    try:
        os.rename(staging, out)  # new, or an empty folder: one atomic rename
        return None
    except OSError as error:
        if error.errno not in (errno.ENOTEMPTY, errno.EEXIST):
            raise
    if _exchange(staging, out):
        return staging  # now holding the earlier result
    aside = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=out.parent))
    _PARTIAL.add(aside)
    os.rename(out, aside / "result")
    try:
        os.rename(staging, out)
    except OSError:
        os.rename(aside / "result", out)
        raise
    return aside


def write_result_dir(
    out,
    X,
    labels,
    rotations,
    translations,
    sigmas,
    summary,
    png,
    run,
    extra_files=None,
    *,
    overwrite=False,
    save_input=True,
):
    """Write a result directory whole: into a staging folder, then put in place at once.

    ``out`` is checked again (:func:`check_out`), so a folder the user filled during the
    run is not replaced either. ``extra_files`` maps more file names to their bytes.
    ``save_input``: write ``X`` as ``X.npy`` too (else only its a-points, in
    ``clusters.ply``). Errors name ``out``, never the staging folder.
    """
    import numpy as np

    from mmreg import io as mmio
    from mmreg.plotting import cluster_colors

    out = check_out(out, overwrite=overwrite)
    staging = None
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        with _no_interrupts():
            staging = tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=out.parent)
            staging = Path(staging)
            _PARTIAL.add(staging)
        mmio.write_labels(staging / "labels.npy", labels)
        mmio.write_motions(
            staging / "motions.json",
            rotations,
            translations,
            sigmas=sigmas,
            sizes=summary["size"].to_numpy(dtype=int),
            moving=summary["moving"].to_numpy(dtype=bool),
        )
        summary.to_csv(staging / "summary.csv", index=False, float_format="%.6g")
        colors = cluster_colors(labels, background=True)  # as in the picture
        mmio.write_point_cloud(staging / "clusters.ply", X[:, :3], colors=colors, labels=labels)
        (staging / "result.png").write_bytes(png)
        if save_input:
            np.save(staging / "X.npy", X)
        (staging / "run.json").write_text(json.dumps(run, indent=2, default=_json_default) + "\n")
        for name, content in dict(extra_files or {}).items():
            (staging / name).write_bytes(content)
        # mkdtemp and mkstemp (atomic writes) create private files; give the usual modes.
        umask = os.umask(0)
        os.umask(umask)
        for path in staging.iterdir():
            path.chmod(0o666 & ~umask)
        staging.chmod(0o777 & ~umask)
        with _no_interrupts():
            leftover = _put_in_place(staging, out)
            _PARTIAL.discard(staging)
            if leftover is not None:
                _PARTIAL.add(leftover)
        if leftover is not None:
            shutil.rmtree(leftover, ignore_errors=True)
            _PARTIAL.discard(leftover)
    except OSError as error:
        reason = one_line(error.strerror or error).lower()
        raise CLIError(f"{out}: cannot write the result: {reason}") from error
    finally:
        if staging is not None and staging in _PARTIAL:
            shutil.rmtree(staging, ignore_errors=True)
            _PARTIAL.discard(staging)


def correspondences_digest(X):
    """The SHA-256 (hex) of correspondences as float64 in C order: the same for the same data."""
    import hashlib

    import numpy as np

    return hashlib.sha256(np.ascontiguousarray(X, dtype=np.float64).data).hexdigest()


def file_digest(path):
    """The SHA-256 (hex) of a file's bytes, read in chunks."""
    import hashlib

    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


# The input files a result may be read again from, by their run.json keys and options.
_INPUT_FILES = (("input", "INPUT"), ("target", "--target"), ("flow", "--flow"))


def input_record(X, input, target=None, flow=None):
    """What ``run.json`` keeps of an input file to read it again: absolute paths, digests.

    ``input_sha256`` is the digest of the correspondences read, ``files_sha256`` that of
    each file's bytes (so that a changed file can be named, see :func:`read_result_input`).
    """
    paths = {"input": input, "target": target, "flow": flow}
    record = {f"{name}_path": str(Path(path).resolve()) for name, path in paths.items() if path}
    # A folder (a ROS 2 bag, a KITTI sequence) has no bytes of its own to digest.
    files = {
        name: file_digest(path) for name, path in paths.items() if path and Path(path).is_file()
    }
    return record | {"input_sha256": correspondences_digest(X), "files_sha256": files}


def _changed_inputs(run, folder):
    """The input files of ``run`` that are missing or differ from what was recorded.

    Returns ``(missing, changed)``: lists of paths. ``changed`` is empty when the record
    has no per-file digests (results of older versions).
    """
    missing, changed = [], []
    recorded = run.get("files_sha256") or {}
    for name, _ in _INPUT_FILES:
        path = run.get(f"{name}_path")
        if not path:
            continue
        if not Path(path).exists():
            missing.append(path)
        elif name in recorded and file_digest(path) != recorded[name]:
            changed.append(path)
    return missing, changed


def read_result_input(folder, n, *, required=True):
    """The correspondences of a result directory: its ``X.npy``, else its input files.

    Without ``X.npy`` the input is read again from the paths in ``run.json`` and must
    still hold the same correspondences (its SHA-256). Returns None when the result
    keeps neither and ``required`` is False; otherwise that, a missing, changed or
    unreadable input, or a length other than ``n`` is a CLIError of one line that names
    the file at fault (the cloud, its ``--target`` or its ``--flow``).
    """
    folder = Path(folder)
    saved = folder / "X.npy"
    if saved.exists():
        with reading(saved):
            X = check_correspondences(load_npy(saved), saved)
        source = saved
    else:
        run = {}
        if (folder / "run.json").exists():
            with reading(folder / "run.json"):
                run = json.loads((folder / "run.json").read_text())
        if not isinstance(run, dict) or "input_path" not in run:
            if not required:
                return None
            raise CLIError(
                f"{saved}: no such file, and {folder / 'run.json'} names no input file (is "
                f"{folder} a result directory?)"
            )
        from mmreg import io as mmio

        again = "run 'mmreg register' again (--save-input keeps a copy in the result)"
        missing, changed = _changed_inputs(run, folder)
        if missing:
            raise CLIError(
                f"{missing[0]}: no such file; {folder} was computed from it (moved or "
                f"deleted since?): put it back, or {again}"
            )
        if changed:
            raise CLIError(
                f"{changed[0]}: changed since {folder} was computed from it; put the "
                f"original back, or {again}"
            )
        source, target, flow = (run.get(f"{k}_path") for k, _ in _INPUT_FILES)
        with reading(source, target, flow):
            X = mmio.read_correspondences(source, target=target, flow=flow)
        X = check_correspondences(X, source)
        if correspondences_digest(X) != run.get("input_sha256"):
            named = " or ".join(str(p) for p in (source, target, flow) if p)
            raise CLIError(
                f"{named}: not the correspondences {folder} was computed from (changed "
                f"since); {again}"
            )
    if len(X) != n:
        raise CLIError(f"{source}: {len(X)} correspondences for {n} labels")
    return X


def _json_default(value):
    import numpy as np

    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
