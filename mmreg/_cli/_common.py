"""What the subcommands share: errors, progress, the result directory and its summary.

A result directory (written by ``mmreg register`` and ``mmreg demo --out``) holds:

* ``labels.npy``: the cluster of every correspondence, ``-1`` for outliers;
* ``motions.json``: per cluster its label, 4 x 4 ``transform``, ``rotation``,
  ``translation``, ``rotation_angle_deg``, ``sigma``, ``size`` and ``moving``;
* ``summary.csv``: one row per cluster (see :func:`summarize`);
* ``clusters.ply``: the a-points coloured by cluster, outliers grey;
* ``result.png``: the picture;
* ``X.npy``: the input correspondences ``[a | b]`` (for ``mmreg view`` and
  ``mmreg evaluate``);
* ``run.json``: the input, the options and the run's numbers.

It is written whole or not at all: every file goes to a hidden staging folder beside
the result directory first, and is moved into it only when all of them are written.
"""

import contextlib
import json
import os
import shutil
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

# A cluster moves relative to the background when the background's motion would carry
# its a-points, on average, this many times its own RMS residual away from where its
# own motion takes them.
MOVING_FACTOR = 3.0
RESULT_FILES = (
    "labels.npy",
    "motions.json",
    "summary.csv",
    "clusters.ply",
    "result.png",
    "X.npy",
    "run.json",
)


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


@contextlib.contextmanager
def reported_warnings():
    """Show Python warnings raised inside as one ``mmreg: warning:`` line each (once)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    seen = set()
    for item in caught:
        text = one_line(item.message)
        if text not in seen:
            seen.add(text)
            warn(text)


class Steps:
    """A tqdm progress bar over named steps, on stderr; hidden when quiet or not a terminal."""

    def __init__(self, total, *, quiet=False):
        from tqdm.auto import tqdm

        self._bar = tqdm(
            total=total,
            disable=True if quiet else None,  # None: only on a terminal
            file=sys.stderr,
            leave=False,
            unit="step",
            bar_format="{desc:<34} {bar:20} {n_fmt}/{total_fmt} [{elapsed}]",
        )

    @contextlib.contextmanager
    def step(self, description):
        self._bar.set_description_str(description)
        yield
        self._bar.update(1)

    def close(self):
        self._bar.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def check_correspondences(X, path):
    """``X`` as a finite float array of shape (n, 6) with n >= 1, or a CLIError on ``path``."""
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
    return X


def check_labels(labels, n, path, what="labels"):
    """Integer labels, one per correspondence, or a CLIError on ``path``."""
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
    rotations = np.asarray(rotations, dtype=float).reshape(-1, 3, 3)
    cosine = (np.trace(rotations, axis1=1, axis2=2) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def background_label(labels):
    """The largest cluster (the static world, when the camera moves), or None."""
    ids, sizes = np.unique(labels[labels >= 0], return_counts=True)
    if not len(ids):
        return None
    return int(ids[np.lexsort((ids, -sizes))[0]])


def summarize(X, labels, rotations, translations, sigmas=None):
    """One row per cluster: size, motion, residual and motion relative to the background.

    The background is the largest cluster. A cluster is ``moving`` when
    ``displacement_vs_background`` (the mean distance between where its own motion and
    the background's motion take its a-points) exceeds :data:`MOVING_FACTOR` (3) times
    its ``rms_residual`` (the RMS of ``|R a + t - b|`` over its correspondences), floored
    at 1e-6 times the RMS spread of the b-points so that noiseless data is well posed.

    Returns a :class:`pandas.DataFrame` (coordinates in the units of the points).
    """
    import pandas as pd

    a, b = X[:, :3], X[:, 3:]
    rotations = np.asarray(rotations, dtype=float).reshape(-1, 3, 3)
    translations = np.asarray(translations, dtype=float).reshape(-1, 3)
    reference = background_label(labels)
    floor = 1e-6 * float(np.sqrt(np.mean(np.sum((b - b.mean(axis=0)) ** 2, axis=1))))
    angles = rotation_angle_deg(rotations)
    rows = []
    for label in range(len(rotations)):
        members = labels == label
        pts = a[members]
        size = int(members.sum())
        moved = pts @ rotations[label].T + translations[label]
        residual = np.linalg.norm(moved - b[members], axis=1) if size else np.zeros(0)
        rms = float(np.sqrt(np.mean(residual**2))) if size else float("nan")
        row = {
            "label": label,
            "size": size,
            "fraction": size / len(labels),
            "rotation_angle_deg": float(angles[label]),
            "tx": translations[label, 0],
            "ty": translations[label, 1],
            "tz": translations[label, 2],
            "translation_norm": float(np.linalg.norm(translations[label])),
            "sigma": float(sigmas[label]) if sigmas is not None else float("nan"),
            "rms_residual": rms,
            "centroid_x": float("nan"),
            "centroid_y": float("nan"),
            "centroid_z": float("nan"),
            "extent_x": float("nan"),
            "extent_y": float("nan"),
            "extent_z": float("nan"),
            "background": label == reference,
            "relative_rotation_deg": 0.0,
            "displacement_vs_background": 0.0,
            "moving": False,
        }
        if size:
            row.update(
                zip(("centroid_x", "centroid_y", "centroid_z"), pts.mean(axis=0), strict=True)
            )
            row.update(zip(("extent_x", "extent_y", "extent_z"), np.ptp(pts, axis=0), strict=True))
        if size and reference is not None and label != reference:
            by_background = pts @ rotations[reference].T + translations[reference]
            displacement = float(np.mean(np.linalg.norm(moved - by_background, axis=1)))
            relative = rotations[label] @ rotations[reference].T
            row["relative_rotation_deg"] = float(rotation_angle_deg(relative)[0])
            row["displacement_vs_background"] = displacement
            row["moving"] = displacement > MOVING_FACTOR * max(rms, floor)
        rows.append(row)
    return pd.DataFrame(rows, columns=SUMMARY_COLUMNS)


def format_table(frame, spec):
    """A plain text table of ``frame``: ``spec`` lists ``(column, header, format)``."""
    cells = [[header for _, header, _ in spec]]
    for _, row in frame.iterrows():
        cells.append([format(row[column], fmt) for column, _, fmt in spec])
    widths = [max(len(r[i]) for r in cells) for i in range(len(spec))]
    lines = ["  ".join(cell.rjust(w) for cell, w in zip(r, widths, strict=True)) for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def render_png(fig, dpi=110):
    """The PNG bytes of a matplotlib Figure."""
    import io

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()


def result_figure(X, labels, motions, *, moving=None, view="auto", title=None, camera=None):
    """The picture of a result: a street layout for camera-frame data, else a 3-D view.

    ``moving`` (one bool per cluster) names the clusters "moving" or "static" in the
    legend; the largest is "background".
    """
    from matplotlib.figure import Figure

    from mmreg.plotting import plot_clusters, plot_street

    a = X[:, :3]
    names = None
    if moving is not None:
        reference = background_label(labels)
        names = {
            j: f"cluster {j}: " + ("background" if j == reference else "moving" if m else "static")
            for j, m in enumerate(np.asarray(moving, dtype=bool).tolist())
        }
    if view == "auto":
        view = "street" if np.all(a[:, 2] > 0) else "3d"
    if view == "street":
        fig = Figure(figsize=(13, 5.8))
        plot_street(
            a, labels, motions=motions, camera=camera, fig=fig, title=title, label_names=names
        )
        return fig
    fig = Figure(figsize=(10, 7), layout="constrained")
    ax = fig.add_subplot(projection="3d" if view == "3d" else None)
    # The largest cluster is the reference of "moving": drawn as the background.
    plot_clusters(
        a,
        labels,
        ax=ax,
        view=view,
        motions=motions,
        camera=camera,
        label_names=names,
        background=True,
    )
    if title is not None:
        fig.suptitle(title, fontsize=11)
    return fig


def write_result_dir(
    out, X, labels, rotations, translations, sigmas, summary, png, run, extra_files=None
):
    """Write a result directory whole: into a staging folder, then moved into ``out``.

    ``extra_files`` maps more file names to their bytes.
    """
    from mmreg import io as mmio
    from mmreg.plotting import cluster_colors

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise CLIError(f"{out}: exists and is not a directory")
    parent = out.resolve().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=parent))
    except OSError as error:
        raise error_about(out, error) from error
    try:
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
        mmio.write_point_cloud(staging / "clusters.ply", X[:, :3], colors=colors)
        (staging / "result.png").write_bytes(png)
        np.save(staging / "X.npy", X)
        (staging / "run.json").write_text(json.dumps(run, indent=2, default=_json_default) + "\n")
        extra_files = dict(extra_files or {})
        for name, content in extra_files.items():
            (staging / name).write_bytes(content)
        # mkdtemp and mkstemp (atomic writes) create private files; give the usual modes.
        umask = os.umask(0)
        os.umask(umask)
        for path in staging.iterdir():
            path.chmod(0o666 & ~umask)
        staging.chmod(0o777 & ~umask)
        if not out.exists():
            os.replace(staging, out)  # one rename: the directory appears whole
            return
        for name in (*RESULT_FILES, *extra_files):
            os.replace(staging / name, out / name)
    except OSError as error:
        raise error_about(out, error) from error
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
