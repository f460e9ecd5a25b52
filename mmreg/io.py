"""Reading and writing correspondences, labels, motions and point clouds.

Every reader checks its file and raises one clear error that names it: ``FileNotFoundError``
when it is missing, ``ValueError`` when it is unreadable, corrupt, of the wrong shape, holds
NaN or infinity, or has an unknown extension, ``TypeError`` when it holds the wrong kind of
values (text where numbers belong, non-integer labels). Every writer goes through
:func:`atomic_write`: the file appears whole or not at all.

File formats
------------
correspondences
    ``.npy`` (an ``(n, 6)`` array), ``.npz`` (key ``X``, or keys ``a`` and ``b``),
    ``.csv`` / ``.txt`` (6 numeric columns, an optional header row, comma, space or tab
    delimited), or a point cloud ``.ply`` / ``.pcd`` / ``.xyz`` together with the b-points
    (``target``) or the per-point flow (``flow``).
labels
    ``.npy`` or ``.csv`` / ``.txt`` (one integer per line, an optional header row).
motions
    JSON: a list with one object per motion (see :func:`write_motions`).
point clouds
    ``.ply`` and ``.pcd`` through Open3D; ``.xyz`` (``x y z`` per line) as text; ``.npy`` /
    ``.csv`` / ``.txt`` ``(n, 3)`` arrays for reading.
"""

import contextlib
import json
import os
import tempfile
import warnings
from pathlib import Path

import numpy as np

__all__ = [
    "atomic_write",
    "read_correspondences",
    "read_labels",
    "read_motions",
    "read_point_cloud",
    "write_correspondences",
    "write_labels",
    "write_motions",
    "write_point_cloud",
]

_CLOUD_EXTENSIONS = (".ply", ".pcd", ".xyz")
_TEXT_EXTENSIONS = (".csv", ".txt")
_CORRESPONDENCE_EXTENSIONS = (".npy", ".npz", *_TEXT_EXTENSIONS, *_CLOUD_EXTENSIONS)
_POINT_EXTENSIONS = (".npy", *_TEXT_EXTENSIONS, *_CLOUD_EXTENSIONS)
_CSV_HEADER = ("ax", "ay", "az", "bx", "by", "bz")


# --------------------------------------------------------------------------- atomic writes
@contextlib.contextmanager
def _atomic_path(path, suffix=""):
    """Yield a temporary path beside ``path``; move it onto ``path`` if the block succeeds.

    The temporary file is created (empty) in the folder of ``path`` with the given suffix,
    so writers that choose a format by extension (Open3D) can write to it. On success it
    is fsynced and renamed onto ``path`` with :func:`os.replace` (atomic on POSIX and
    Windows); on any error it is removed and the error propagates.
    """
    path = Path(path)
    folder = path.parent
    if not folder.is_dir():
        raise FileNotFoundError(f"{path}: cannot write, folder {str(folder)!r} does not exist.")
    if path.is_dir():
        raise ValueError(f"{path}: cannot write, it is a folder.")
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=suffix or ".tmp")
    os.close(fd)
    try:
        yield tmp
        with open(tmp, "rb+") as handle:
            os.fsync(handle.fileno())
        os.chmod(tmp, _file_mode(path))
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _fsync_folder(folder)


def _file_mode(path):
    """The mode of the file being replaced, else the usual ``0o666`` less the umask.

    ``mkstemp`` creates private (``0o600``) files, which would otherwise end up as the
    written file's mode.
    """
    try:
        return os.stat(path).st_mode & 0o7777
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


def _fsync_folder(folder):
    """Make the rename durable where the platform allows fsync on a folder (POSIX)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_write(path, mode="wb"):
    """Open a file for writing so that ``path`` appears whole or not at all.

    The data go to a temporary file in the same folder as ``path``; when the ``with``
    block ends without error the file is flushed, fsynced and renamed onto ``path`` with
    :func:`os.replace`, which replaces any previous file in one step. When the block
    raises, the temporary file is removed, ``path`` is left as it was, and the error
    propagates.

    Parameters
    ----------
    path : str or path-like
        The file to write. Its folder must exist.
    mode : {"wb", "w"}, default="wb"
        Binary or text (UTF-8) writing.

    Yields
    ------
    file : file object
        Open for writing.

    Raises
    ------
    FileNotFoundError
        If the folder of ``path`` does not exist.
    ValueError
        If ``mode`` is not a writing mode or ``path`` is a folder.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from mmreg.io import atomic_write
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = Path(folder) / "notes.txt"
    ...     with atomic_write(path, "w") as f:
    ...         _ = f.write("all or nothing")
    ...     print(path.read_text(), sorted(p.name for p in Path(folder).iterdir()))
    all or nothing ['notes.txt']
    """
    if mode not in ("wb", "w", "wt"):
        raise ValueError(f"mode must be 'wb' (binary) or 'w' (text); got {mode!r}.")
    with _atomic_path(path, suffix=".tmp") as tmp:
        text = {} if "b" in mode else {"encoding": "utf-8", "newline": ""}
        handle = open(tmp, "wb" if "b" in mode else "w", **text)  # noqa: SIM115 - closed below
        try:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        finally:
            handle.close()


# --------------------------------------------------------------------------- checks
def _extension(path, allowed, what):
    suffix = Path(path).suffix.lower()
    if suffix not in allowed:
        raise ValueError(
            f"{path}: unknown extension {suffix or '(none)'!r} for {what}; "
            f"expected one of {', '.join(allowed)}."
        )
    return suffix


def _check_readable(path, what=None):
    """``Path(path)``, or FileNotFoundError / ValueError naming it (and ``what`` it holds)."""
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"path must be a str or path-like; got {type(path).__name__}.")
    path = Path(path)
    holds = f" ({what})" if what else ""
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file{holds}.")
    if path.is_dir():
        raise ValueError(f"{path}: is a folder, not a file{holds}.")
    if not os.access(path, os.R_OK):
        raise ValueError(f"{path}: cannot be read (permission denied){holds}.")
    return path


def _as_numeric(array, source, name="the data"):
    """A float array, or TypeError naming ``source`` when ``array`` is not numeric."""
    array = np.asarray(array)
    if array.dtype.kind not in "biuf":
        raise TypeError(f"{source}: {name} must be numeric; got dtype {array.dtype}.")
    return array.astype(float)


def _check_points(array, source, n_columns, name):
    """A finite 2-D float array with ``n_columns`` columns and >= 1 row."""
    array = _as_numeric(array, source, name)
    if array.ndim != 2 or array.shape[1] != n_columns:
        raise ValueError(
            f"{source}: {name} must be an array of shape (n, {n_columns}); got shape {array.shape}."
        )
    if array.shape[0] < 1:
        raise ValueError(f"{source}: {name} holds no rows; at least one is needed.")
    if not np.all(np.isfinite(array)):
        bad = np.flatnonzero(~np.all(np.isfinite(array), axis=1))
        raise ValueError(
            f"{source}: {name} contains NaN or infinity ({len(bad)} rows, the first is row "
            f"{bad[0]})."
        )
    return np.ascontiguousarray(array)


def _check_correspondence_array(X, source="X"):
    return _check_points(X, source, 6, "the correspondences")


# --------------------------------------------------------------------------- readers
def _load_npy(path):
    try:
        return np.load(path, allow_pickle=False)
    except ValueError as exc:
        raise ValueError(
            f"{path}: cannot be read as a .npy array of numbers (corrupt, or it holds Python "
            f"objects): {exc}"
        ) from exc
    except (OSError, EOFError) as exc:
        raise ValueError(f"{path}: cannot be read as a .npy file (corrupt?): {exc}") from exc


def _load_npz(path):
    try:
        with np.load(path, allow_pickle=False) as archive:
            return {key: archive[key] for key in archive.files}
    except ValueError as exc:
        raise ValueError(
            f"{path}: cannot be read as a .npz archive of numeric arrays (corrupt, or it "
            f"holds Python objects): {exc}"
        ) from exc
    except (OSError, EOFError, KeyError) as exc:  # zipfile.BadZipFile is an OSError
        raise ValueError(f"{path}: cannot be read as a .npz file (corrupt?): {exc}") from exc


def _is_number(token):
    try:
        float(token)
    except ValueError:
        return False
    return True


def _load_text_table(path):
    """A 2-D float array from a comma, space or tab delimited file, header row optional.

    Blank lines and lines starting with ``#`` are skipped. The delimiter is a comma when
    the first data line holds one, otherwise any run of spaces and tabs. The first line is
    a header when any of its fields is not a number.
    """
    try:
        with open(path, encoding="utf-8") as handle:
            first, skip = None, 0
            for line in handle:
                skip += 1
                if line.strip() and not line.lstrip().startswith("#"):
                    first = line
                    break
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: is not a text file (not UTF-8): {exc}") from exc
    except OSError as exc:
        raise ValueError(f"{path}: cannot be read: {exc}") from exc
    if first is None:
        raise ValueError(f"{path}: holds no rows; at least one is needed.")
    delimiter = "," if "," in first else None
    fields = [f.strip() for f in first.split(delimiter)]
    header = not all(_is_number(f) for f in fields)
    try:
        with warnings.catch_warnings():  # "input contained no data": reported below
            warnings.simplefilter("ignore", UserWarning)
            array = np.loadtxt(
                path,
                delimiter=delimiter,
                skiprows=skip if header else skip - 1,
                ndmin=2,
                comments="#",
                encoding="utf-8",
            )
    except ValueError as exc:
        if "could not convert" in str(exc):
            raise TypeError(f"{path}: holds a value that is not a number: {exc}") from exc
        raise ValueError(f"{path}: rows of different lengths or malformed: {exc}") from exc
    if array.size == 0:
        raise ValueError(f"{path}: holds no rows after the header; at least one is needed.")
    return array


def _read_cloud_file(path, *, colors=False):
    """Points (and colours or None) of a ``.ply``/``.pcd`` (Open3D) or ``.xyz`` file."""
    suffix = Path(path).suffix.lower()
    if suffix == ".xyz":
        # Open3D's xyz reader silently skips malformed lines; numpy reports them.
        return _load_text_table(path), None
    import open3d as o3d

    cloud = o3d.io.read_point_cloud(
        str(path), format="auto", remove_nan_points=False, remove_infinite_points=False
    )
    points = np.asarray(cloud.points, dtype=float)
    if len(points) == 0:
        raise ValueError(
            f"{path}: no points could be read (corrupt, empty, or not a {suffix} point cloud)."
        )
    rgb = np.asarray(cloud.colors, dtype=float) if (colors and cloud.has_colors()) else None
    return points, rgb


def _read_points(path, name):
    """An (n, 3) finite array from a point cloud or a ``.npy``/``.csv``/``.txt`` file."""
    path = _check_readable(path)
    suffix = _extension(path, _POINT_EXTENSIONS, name)
    if suffix in _CLOUD_EXTENSIONS:
        points, _ = _read_cloud_file(path)
    elif suffix == ".npy":
        points = _load_npy(path)
    else:
        points = _load_text_table(path)
    return _check_points(points, path, 3, name)


def read_correspondences(path, *, target=None, flow=None):
    """Read stacked correspondences ``X = [a | b]`` of shape (n, 6) from a file.

    Also available as :func:`mmreg.datasets.load_correspondences`.

    Parameters
    ----------
    path : str or path-like
        One of

        - ``.npy``: an array of shape (n, 6);
        - ``.npz``: key ``X`` (n, 6), or keys ``a`` and ``b`` (n, 3) each;
        - ``.csv`` / ``.txt``: 6 numeric columns ``ax ay az bx by bz``, with or without a
          header row, delimited by commas, spaces or tabs; ``#`` starts a comment line;
        - ``.ply`` / ``.pcd`` / ``.xyz``: the a-points as a point cloud, which needs exactly
          one of ``target`` and ``flow``.
    target : str or path-like, optional
        With a point-cloud ``path``: a second file with the b-points, index-aligned with
        the a-points (row ``i`` corresponds to point ``i``): a point cloud, or an (n, 3)
        ``.npy`` / ``.csv`` / ``.txt`` array.
    flow : str or path-like, optional
        With a point-cloud ``path``: an (n, 3) per-point flow (``.npy`` / ``.csv`` /
        ``.txt``, or a point cloud whose coordinates are the flow vectors); ``b = a + flow``.

    Returns
    -------
    X : ndarray of shape (n, 6)
        Finite floats, ``n >= 1``.

    Raises
    ------
    FileNotFoundError
        If a file is missing.
    ValueError
        If a file is unreadable or corrupt, has an unknown extension, has the wrong shape,
        no rows, NaN or infinity, if the a- and b-points differ in number, or if
        ``target``/``flow`` are missing, both given, or given for an array file.
    TypeError
        If a file holds values that are not numbers.

    See Also
    --------
    write_correspondences : The inverse, for ``.npy``, ``.npz``, ``.csv`` and ``.txt``.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.io import read_correspondences
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = Path(folder) / "pairs.csv"
    ...     _ = path.write_text("ax,ay,az,bx,by,bz\\n0,0,0,1,0,0\\n1,2,3,2,2,3\\n")
    ...     X = read_correspondences(path)
    >>> X.shape, X[1].tolist()
    ((2, 6), [1.0, 2.0, 3.0, 2.0, 2.0, 3.0])
    """
    path = _check_readable(path)
    suffix = _extension(path, _CORRESPONDENCE_EXTENSIONS, "correspondences")
    if suffix in _CLOUD_EXTENSIONS:
        if (target is None) == (flow is None):
            raise ValueError(
                f"{path}: a point cloud holds only the a-points; pass exactly one of "
                "target= (a file with the b-points) or flow= (a file with the per-point "
                f"flow, b = a + flow); got {'both' if target is not None else 'neither'}."
            )
        points, _ = _read_cloud_file(path)
        a = _check_points(points, path, 3, "the a-points")
        other_path = target if target is not None else flow
        other = _read_points(other_path, "the b-points" if target is not None else "the flow")
        if len(other) != len(a):
            raise ValueError(
                f"{other_path}: holds {len(other)} points but {path} holds {len(a)}; "
                "the files must be index-aligned (one row per point)."
            )
        b = other if target is not None else a + other
        return _check_correspondence_array(np.hstack([a, b]), path)
    if target is not None or flow is not None:
        raise ValueError(
            f"{path}: target= and flow= only apply when path is a point cloud "
            f"({', '.join(_CLOUD_EXTENSIONS)}); a {suffix} file already holds both points."
        )
    if suffix == ".npy":
        X = _load_npy(path)
    elif suffix == ".npz":
        arrays = _load_npz(path)
        if "X" in arrays:
            X = arrays["X"]
        elif "a" in arrays and "b" in arrays:
            a = _check_points(arrays["a"], path, 3, "key 'a'")
            b = _check_points(arrays["b"], path, 3, "key 'b'")
            if len(a) != len(b):
                raise ValueError(
                    f"{path}: key 'a' has {len(a)} rows but key 'b' has {len(b)}; they must match."
                )
            X = np.hstack([a, b])
        else:
            raise ValueError(
                f"{path}: needs key 'X' (n, 6), or keys 'a' and 'b' (n, 3); found keys "
                f"{sorted(arrays)}."
            )
    else:
        X = _load_text_table(path)
    return _check_correspondence_array(X, path)


def _text_float(value):
    """Shortest text that reads back as exactly the same float."""
    return repr(float(value))


def _write_text_table(path, array, header):
    with atomic_write(path, "w") as handle:
        if header is not None:
            handle.write(header + "\n")
        delimiter = "," if Path(path).suffix.lower() == ".csv" else " "
        for row in np.atleast_2d(array):
            handle.write(delimiter.join(_text_float(v) for v in row) + "\n")


def write_correspondences(path, X):
    """Write stacked correspondences ``X = [a | b]`` (n, 6), atomically.

    Parameters
    ----------
    path : str or path-like
        ``.npy`` (the array), ``.npz`` (key ``X``), ``.csv`` (a header row
        ``ax,ay,az,bx,by,bz``, then comma-separated rows) or ``.txt`` (space-separated
        rows, no header). Text is written with round-trip precision.
    X : array-like of shape (n, 6)
        Finite numbers, ``n >= 1``.

    Raises
    ------
    ValueError
        If ``X`` has the wrong shape, no rows or NaN/infinity, or the extension is not one
        of the above.

    See Also
    --------
    read_correspondences : The inverse.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.io import read_correspondences, write_correspondences
    >>> X = np.arange(12.0).reshape(2, 6) / 3
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_correspondences(Path(folder) / "pairs.csv", X)
    ...     same = read_correspondences(Path(folder) / "pairs.csv")
    >>> bool(np.array_equal(same, X))
    True
    """
    suffix = _extension(path, (".npy", ".npz", *_TEXT_EXTENSIONS), "correspondences")
    X = _check_correspondence_array(X)
    if suffix == ".npy":
        with atomic_write(path) as handle:
            np.save(handle, X)
    elif suffix == ".npz":
        with atomic_write(path) as handle:
            np.savez(handle, X=X)
    else:
        _write_text_table(path, X, ",".join(_CSV_HEADER) if suffix == ".csv" else None)


# --------------------------------------------------------------------------- labels
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


# --------------------------------------------------------------------------- motions
def _rotation_angle_deg(rotation):
    cos = (np.trace(rotation) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def _optional(values, n, name, kind):
    """``values`` checked to length ``n`` (or None)."""
    if values is None:
        return None
    values = np.asarray(values)
    if values.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), one per motion; got {values.shape}.")
    if kind == "bool":
        if values.dtype.kind != "b":
            raise TypeError(f"{name} must be booleans; got dtype {values.dtype}.")
        return [bool(v) for v in values]
    if kind == "int":
        return [int(v) for v in _check_label_array(values, name)]
    values = _as_numeric(values, name, name)
    return [float(v) if np.isfinite(v) else None for v in values]  # unknown: JSON null


def write_motions(path, rotations, translations, *, sigmas=None, sizes=None, moving=None):
    """Write rigid motions to a JSON file, atomically.

    The file holds a list with one object per motion ``k``::

        {"label": k, "transform": 4x4, "rotation": 3x3, "translation": 3,
         "rotation_angle_deg": float, "sigma": float or null, "size": int or null,
         "moving": bool or null}

    where ``transform = [[R, t], [0, 0, 0, 1]]`` maps ``a`` to ``R a + t``. Floats are
    written with Python's shortest round-trip representation, so :func:`read_motions`
    returns exactly the arrays written.

    Parameters
    ----------
    path : str or path-like
        The JSON file (any extension; ``.json`` is customary).
    rotations : array-like of shape (K, 3, 3)
    translations : array-like of shape (K, 3)
    sigmas : array-like of shape (K,), optional
        Noise scale of every motion (e.g. a fitted estimator's ``sigmas_``); NaN or
        infinity (unknown) is written as ``null`` and read back as NaN.
    sizes : array-like of shape (K,), optional
        Number of points of every motion.
    moving : array-like of bool, shape (K,), optional
        Whether every motion counts as moving (e.g. differs from the background's).

    Raises
    ------
    ValueError
        If the shapes do not match or a rotation or translation is NaN or infinity.
    TypeError
        If ``sizes`` are not integers or ``moving`` not booleans.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.io import read_motions, write_motions
    >>> rotations = np.stack([np.eye(3), [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]])
    >>> translations = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 0.5]])
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_motions(Path(folder) / "motions.json", rotations, translations,
    ...                   sizes=[120, 30], moving=[False, True])
    ...     motions = read_motions(Path(folder) / "motions.json")
    >>> motions["transforms"].shape, motions["rotation_angles_deg"].tolist()
    ((2, 4, 4), [0.0, 90.0])
    >>> motions["sizes"].tolist(), motions["moving"].tolist(), motions["sigmas"]
    ([120, 30], [False, True], None)
    """
    rotations = _as_numeric(rotations, "rotations", "rotations")
    translations = _as_numeric(translations, "translations", "translations")
    if rotations.ndim != 3 or rotations.shape[1:] != (3, 3):
        raise ValueError(f"rotations must have shape (K, 3, 3); got {rotations.shape}.")
    n_motions = len(rotations)
    if translations.shape != (n_motions, 3):
        raise ValueError(
            f"translations must have shape ({n_motions}, 3) to match rotations; got "
            f"{translations.shape}."
        )
    if not (np.all(np.isfinite(rotations)) and np.all(np.isfinite(translations))):
        raise ValueError("rotations and translations must be finite (no NaN or infinity).")
    sigmas = _optional(sigmas, n_motions, "sigmas", "float")
    sizes = _optional(sizes, n_motions, "sizes", "int")
    moving = _optional(moving, n_motions, "moving", "bool")
    records = []
    for k in range(n_motions):
        transform = np.eye(4)
        transform[:3, :3] = rotations[k]
        transform[:3, 3] = translations[k]
        records.append(
            {
                "label": k,
                "transform": transform.tolist(),
                "rotation": rotations[k].tolist(),
                "translation": translations[k].tolist(),
                "rotation_angle_deg": _rotation_angle_deg(rotations[k]),
                "sigma": None if sigmas is None else sigmas[k],
                "size": None if sizes is None else sizes[k],
                "moving": None if moving is None else moving[k],
            }
        )
    with atomic_write(path, "w") as handle:
        json.dump(records, handle, indent=2, allow_nan=False)
        handle.write("\n")


def _motion_field(records, key, path, convert, missing=None):
    """One optional field of every record: None when null in all, else an array.

    A null among values is ``missing`` when given, else a ValueError.
    """
    values = [record.get(key) for record in records]
    if all(v is None for v in values):
        return None
    if missing is not None:
        values = [missing if v is None else v for v in values]
    if any(v is None for v in values):
        k = next(i for i, v in enumerate(values) if v is None)
        raise ValueError(f"{path}: motion {k} has no {key!r} while others do.")
    try:
        return convert(values)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: field {key!r} is malformed: {exc}") from exc


def read_motions(path):
    """Read rigid motions written by :func:`write_motions`.

    Each object of the list needs ``"rotation"`` and ``"translation"``, or
    ``"transform"`` (4x4); every other field is optional.

    Parameters
    ----------
    path : str or path-like
        A JSON file holding a list of motion objects.

    Returns
    -------
    motions : dict
        ``rotations`` (K, 3, 3), ``translations`` (K, 3), ``transforms`` (K, 4, 4),
        ``labels`` (K,) int, ``rotation_angles_deg`` (K,), and ``sigmas`` (K,) float
        (NaN where null), ``sizes`` (K,) int, ``moving`` (K,) bool, each ``None`` when
        the file has none.

    Raises
    ------
    FileNotFoundError
        If the file is missing.
    ValueError
        If it is not valid JSON, not a list of motion objects, or a matrix has the wrong
        shape or is not finite.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from mmreg.io import read_motions
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = Path(folder) / "motions.json"
    ...     _ = path.write_text('[{"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [1,2,3]}]')
    ...     motions = read_motions(path)
    >>> motions["translations"].tolist(), motions["sizes"]
    ([[1.0, 2.0, 3.0]], None)
    """
    path = _check_readable(path)
    try:
        with open(path, encoding="utf-8") as handle:
            records = json.load(handle)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: is not valid JSON: {exc}") from exc
    except OSError as exc:
        raise ValueError(f"{path}: cannot be read: {exc}") from exc
    if not isinstance(records, list) or not all(isinstance(r, dict) for r in records):
        raise ValueError(f"{path}: must hold a JSON list of motion objects.")
    rotations, translations = [], []
    for k, record in enumerate(records):
        try:
            if "rotation" in record and "translation" in record:
                rotation = np.array(record["rotation"], dtype=float)
                translation = np.array(record["translation"], dtype=float)
            elif "transform" in record:
                transform = np.array(record["transform"], dtype=float)
                if transform.shape != (4, 4):
                    raise ValueError(f"transform has shape {transform.shape}, not (4, 4)")
                rotation, translation = transform[:3, :3], transform[:3, 3]
            else:
                raise ValueError("needs 'rotation' and 'translation', or 'transform'")
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{path}: motion {k} is malformed: {exc}.") from exc
        if rotation.shape != (3, 3) or translation.shape != (3,):
            raise ValueError(
                f"{path}: motion {k} has a rotation of shape {rotation.shape} and a "
                f"translation of shape {translation.shape}; expected (3, 3) and (3,)."
            )
        if not (np.all(np.isfinite(rotation)) and np.all(np.isfinite(translation))):
            raise ValueError(f"{path}: motion {k} contains NaN or infinity.")
        rotations.append(rotation)
        translations.append(translation)
    rotations = np.array(rotations, dtype=float).reshape(-1, 3, 3)
    translations = np.array(translations, dtype=float).reshape(-1, 3)
    transforms = np.tile(np.eye(4), (len(records), 1, 1))
    transforms[:, :3, :3] = rotations
    transforms[:, :3, 3] = translations
    labels = _motion_field(records, "label", path, lambda v: _check_label_array(v, path))
    return {
        "rotations": rotations,
        "translations": translations,
        "transforms": transforms,
        "labels": np.arange(len(records)) if labels is None else labels,
        "rotation_angles_deg": np.array([_rotation_angle_deg(r) for r in rotations]),
        "sigmas": _motion_field(
            records, "sigma", path, lambda v: np.array(v, dtype=float), missing=np.nan
        ),
        "sizes": _motion_field(records, "size", path, lambda v: _check_label_array(v, path)),
        "moving": _motion_field(records, "moving", path, lambda v: np.array(v, dtype=bool)),
    }


# --------------------------------------------------------------------------- point clouds
def read_point_cloud(path, *, colors=False):
    """Read the points (and colours) of a point cloud.

    Parameters
    ----------
    path : str or path-like
        ``.ply`` or ``.pcd`` (read with Open3D), ``.xyz`` (``x y z`` per line), or an
        (n, 3) ``.npy`` / ``.csv`` / ``.txt`` array.
    colors : bool, default=False
        Also return the colours.

    Returns
    -------
    points : ndarray of shape (n, 3)
    colors : ndarray of shape (n, 3) or None
        Only when ``colors=True``: RGB in ``[0, 1]``, or ``None`` when the file holds no
        colours (always for ``.xyz`` and array files).

    Raises
    ------
    FileNotFoundError
        If the file is missing.
    ValueError
        If it is unreadable, corrupt, empty, holds NaN or infinity, or the extension is
        unknown.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.io import read_point_cloud, write_point_cloud
    >>> points = np.array([[0.0, 0.0, 1.0], [0.5, -1.0, 2.0]])
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_point_cloud(Path(folder) / "cloud.ply", points, colors=[[1, 0, 0], [0, 0, 1]])
    ...     same, rgb = read_point_cloud(Path(folder) / "cloud.ply", colors=True)
    >>> bool(np.array_equal(same, points)), rgb.tolist()
    (True, [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    """
    path = _check_readable(path)
    suffix = _extension(path, _POINT_EXTENSIONS, "a point cloud")
    rgb = None
    if suffix in _CLOUD_EXTENSIONS:
        points, rgb = _read_cloud_file(path, colors=colors)
    elif suffix == ".npy":
        points = _load_npy(path)
    else:
        points = _load_text_table(path)
    points = _check_points(points, path, 3, "the points")
    if not colors:
        return points
    if rgb is not None:
        rgb = _check_points(rgb, path, 3, "the colours")
        if len(rgb) != len(points):
            raise ValueError(f"{path}: holds {len(points)} points but {len(rgb)} colours.")
    return points, rgb


def write_point_cloud(path, points, colors=None):
    """Write a point cloud, atomically.

    Parameters
    ----------
    path : str or path-like
        ``.ply`` (binary, float64 coordinates, 8-bit colours) or ``.pcd`` (binary, float32
        coordinates) through Open3D, or ``.xyz`` (text ``x y z`` per line at round-trip
        precision, no colours).
    points : array-like of shape (n, 3)
        Finite coordinates, ``n >= 1``.
    colors : array-like of shape (n, 3), optional
        RGB in ``[0, 1]`` (stored as 8-bit by both formats).

    Raises
    ------
    ValueError
        If the shapes are wrong, a value is NaN or infinity, a colour lies outside
        ``[0, 1]``, colours are given for ``.xyz``, the extension is unknown, or Open3D
        fails to write the file.

    Notes
    -----
    Open3D chooses the format by extension, so the data first go to a temporary file with
    the same extension in the same folder, which is then renamed onto ``path``.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.io import read_point_cloud, write_point_cloud
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_point_cloud(Path(folder) / "cloud.xyz", np.eye(3))
    ...     print(read_point_cloud(Path(folder) / "cloud.xyz").tolist())
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    """
    suffix = _extension(path, _CLOUD_EXTENSIONS, "a point cloud")
    points = _check_points(points, "points", 3, "the points")
    if colors is not None:
        if suffix == ".xyz":
            raise ValueError(f"{path}: .xyz files hold no colours; write .ply or .pcd instead.")
        colors = _check_points(colors, "colors", 3, "the colours")
        if len(colors) != len(points):
            raise ValueError(
                f"colors has {len(colors)} rows but points has {len(points)}; one colour per "
                "point is needed."
            )
        if colors.min() < 0 or colors.max() > 1:
            raise ValueError("colors must lie in [0, 1] (RGB fractions).")
    if suffix == ".xyz":
        _write_text_table(path, points, None)
        return
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    if colors is not None:
        cloud.colors = o3d.utility.Vector3dVector(colors)
    with _atomic_path(path, suffix=suffix) as tmp:
        if not o3d.io.write_point_cloud(tmp, cloud, write_ascii=False):
            raise ValueError(f"{path}: Open3D could not write the point cloud.")
