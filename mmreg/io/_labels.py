"""Per-point labels and capture times, one value per row."""

import numpy as np

from mmreg.io._arrays import _load_npy, _load_text_table
from mmreg.io._atomic import atomic_write
from mmreg.io._checks import _TEXT_EXTENSIONS, _as_numeric, _check_readable, _extension


def _check_label_array(labels, source):
    labels = np.asarray(labels)
    if labels.ndim == 2 and labels.shape[1] == 1:
        labels = labels[:, 0]
    if labels.ndim != 1:
        raise ValueError(f"{source}: labels must be 1-D (one per point); got shape {labels.shape}.")
    if labels.dtype.kind == "f":
        if not np.all(np.isfinite(labels)):
            raise ValueError(f"{source}: labels contain NaN or infinity.")
        if not np.all(labels == np.round(labels)):
            raise TypeError(f"{source}: labels must be integers; got non-integer values.")
    elif labels.dtype.kind not in "iub":
        raise TypeError(f"{source}: labels must be integers; got dtype {labels.dtype}.")
    return labels.astype(np.intp)


def read_labels(path):
    """Read one integer label per point (negative = unassigned / outlier).

    Parameters
    ----------
    path : str or path-like
        ``.npy`` (a 1-D integer array) or ``.csv`` / ``.txt`` (one integer per line, an
        optional header row).

    Returns
    -------
    labels : ndarray of shape (n,), dtype intp

    Raises
    ------
    FileNotFoundError
        If the file is missing.
    ValueError
        If it is unreadable, corrupt, not 1-D, holds NaN, or the extension is unknown.
    TypeError
        If the labels are not integers.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from mmreg.io import read_labels, write_labels
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_labels(Path(folder) / "labels.csv", [0, 0, 1, -1])
    ...     print(read_labels(Path(folder) / "labels.csv").tolist())
    [0, 0, 1, -1]
    """
    path = _check_readable(path)
    suffix = _extension(path, (".npy", *_TEXT_EXTENSIONS), "labels")
    labels = _load_npy(path) if suffix == ".npy" else _load_text_table(path)
    return _check_label_array(labels, path)


def write_labels(path, labels):
    """Write one integer label per point, atomically.

    Parameters
    ----------
    path : str or path-like
        ``.npy``, ``.csv`` (a header row ``label``, then one integer per line) or ``.txt``
        (one integer per line).
    labels : array-like of shape (n,)
        Integers (or integral floats).

    Raises
    ------
    ValueError
        If ``labels`` is not 1-D or the extension is unknown.
    TypeError
        If ``labels`` are not integers.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from mmreg.io import read_labels, write_labels
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_labels(Path(folder) / "labels.npy", [2, 2, 0])
    ...     print(read_labels(Path(folder) / "labels.npy").tolist())
    [2, 2, 0]
    """
    suffix = _extension(path, (".npy", *_TEXT_EXTENSIONS), "labels")
    labels = _check_label_array(labels, "labels")
    if suffix == ".npy":
        with atomic_write(path) as handle:
            np.save(handle, labels.astype(np.int64))
    else:
        with atomic_write(path, "w") as handle:
            if suffix == ".csv":
                handle.write("label\n")
            handle.write("".join(f"{int(v)}\n" for v in labels))


# --------------------------------------------------------------------------- times
def read_times(path):
    """Read one capture time per point, in seconds (e.g. after its sweep's reference time).

    Parameters
    ----------
    path : str or path-like
        ``.npy`` (a 1-D or one-column array of numbers) or ``.csv`` / ``.txt`` (one number
        per line, an optional header row).

    Returns
    -------
    times : ndarray of shape (n,), dtype float64

    Raises
    ------
    FileNotFoundError
        If the file is missing.
    ValueError
        If it is unreadable, corrupt, empty, not one column, holds NaN or infinity, or
        the extension is unknown.
    TypeError
        If it does not hold numbers.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.io import read_times
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     np.save(Path(folder) / "times.npy", np.array([0.0, 0.05, 0.1]))
    ...     print(read_times(Path(folder) / "times.npy").tolist())
    [0.0, 0.05, 0.1]
    """
    path = _check_readable(path)
    suffix = _extension(path, (".npy", *_TEXT_EXTENSIONS), "capture times")
    times = _load_npy(path) if suffix == ".npy" else _load_text_table(path)
    times = np.asarray(times)
    if times.ndim == 2 and times.shape[1] == 1:
        times = times[:, 0]
    if times.ndim != 1:
        raise ValueError(
            f"{path}: capture times must be one column (one per point); got shape {times.shape}."
        )
    if times.dtype.kind == "b":
        raise TypeError(f"{path}: capture times must be numbers of seconds; got booleans.")
    times = _as_numeric(times, path, "the capture times")
    if len(times) == 0:
        raise ValueError(f"{path}: holds no capture times; one per point is needed.")
    bad = np.flatnonzero(~np.isfinite(times))
    if len(bad):
        raise ValueError(
            f"{path}: capture times contain NaN or infinity ({len(bad)} rows, the first is row "
            f"{bad[0]})."
        )
    return times
