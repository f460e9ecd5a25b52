"""Reading and writing correspondences, labels, motions and point clouds.

Every reader checks its file and raises one clear error that names it: ``FileNotFoundError``
when it is missing, ``ValueError`` when it is unreadable, corrupt, truncated, has bytes
after its end, the wrong shape, NaN or infinity, or an unknown extension, ``TypeError``
when it holds the wrong kind of values (text where numbers belong, non-integer labels).
Every writer goes through :func:`atomic_write`: the file appears whole or not at all.

File formats
------------
correspondences
    ``.npy`` (an ``(n, 6)`` array), ``.npz`` (key ``X``, or keys ``a`` and ``b``),
    ``.csv`` / ``.txt`` (6 numeric columns, an optional header row, comma, space or tab
    delimited), or a point cloud ``.ply`` / ``.pcd`` / ``.xyz`` together with the b-points
    (``target``) or the per-point flow (``flow``).
labels
    ``.npy`` or ``.csv`` / ``.txt`` (one integer per line, an optional header row).
capture times
    ``.npy`` or ``.csv`` / ``.txt`` (one number of seconds per line, an optional header
    row).
motions
    JSON: a list with one object per motion (see :func:`write_motions`).
point clouds
    ``.ply`` (ascii, binary little or big endian; the ``vertex`` element's ``x``, ``y``,
    ``z`` and ``red``, ``green``, ``blue``) and ``.pcd`` (``ascii``, ``binary``,
    ``binary_compressed``; ``x``, ``y``, ``z`` and packed ``rgb``), read and written by
    mmreg itself (the files agree with Open3D's); ``.xyz`` (``x y z`` per line) as text;
    ``.npy`` / ``.csv`` / ``.txt`` ``(n, 3)`` arrays for reading.
LiDAR sweeps (reading; see :mod:`mmreg.io._lidar`)
    KITTI velodyne ``.bin`` (float32 ``x y z reflectance``), nuScenes ``.pcd.bin``
    (float32 ``x y z intensity ring``), Argoverse 2 ``.feather`` (``x y z``, and
    ``offset_ns``: the capture times). Invalid returns (NaN or all-zero rows) are kept in
    place; ROS bags hold many frames and are read with
    :func:`mmreg.datasets.open_sequence`.

Text tables
-----------
Blank lines are skipped; lines starting with ``#`` are comments, allowed only before the
data. The first line is a header when none of its fields is a number (a line mixing
names and numbers is an error). The last line must end with a line break.

What a damaged file gives
-------------------------
No reader zero-fills, shortens or pads data silently. What each format can detect
follows from what it stores (``tests/test_io_fuzz.py`` checks it on thousands of
damaged files):

* cut short: an error for every format whose header counts its data (``.npy``,
  ``.npz``, ``.ply``, ``.pcd``, and the loaders' ``.png``, ``.pfm``, ``.flo``; the error
  names how many vertices or points the header promised and how many were read). A text
  table (``.csv``, ``.txt``, ``.xyz``) holds no count: a cut inside a line is an error
  (the last line must end with a line break), a cut exactly at a line end leaves a
  valid shorter table (``mmreg register`` then finds the files' lengths differ when
  another file is read with it);
* bytes appended after the end: an error for every binary format and every format with
  a count; for a text table an error unless they form whole valid rows;
* a changed byte: ``.npz`` (a CRC-32 per array) and ``.png`` (a CRC-32 per chunk) detect
  it (an error, or the data are unchanged). A changed byte in the header of the other
  formats is an error or leaves a valid header (e.g. the byte order of a ``.npy`` or
  ``.pfm``); in their values it cannot be detected: raw binary (``.npy``, binary
  ``.ply`` / ``.pcd``, ``.pfm``, ``.flo``) keeps the shape but may change a value; text
  changes at most one number (a digit, sign or exponent), or, in a one-column table,
  the number of rows by one. Values that become NaN or infinite are always an error.
"""

import contextlib
import io
import json
import math
import os
import struct
import tempfile
import warnings
import zipfile
import zlib
from pathlib import Path

import numpy as np

from mmreg.io import _lidar as _lidar_files

__all__ = [
    "atomic_write",
    "read_correspondences",
    "read_labels",
    "read_motions",
    "read_point_cloud",
    "read_times",
    "write_correspondences",
    "write_labels",
    "write_motions",
    "write_point_cloud",
]

_CLOUD_EXTENSIONS = (".ply", ".pcd", ".xyz")
_TEXT_EXTENSIONS = (".csv", ".txt")
_CORRESPONDENCE_EXTENSIONS = (
    ".npy",
    ".npz",
    *_TEXT_EXTENSIONS,
    *_CLOUD_EXTENSIONS,
    ".bin",
    ".pcd.bin",
    ".feather",
)
# LiDAR sweep files (".pcd.bin" is told from KITTI's ".bin" by its whole name).
_LIDAR_EXTENSIONS = (".bin", ".pcd.bin", ".feather")
_POINT_EXTENSIONS = (".npy", *_TEXT_EXTENSIONS, *_CLOUD_EXTENSIONS, *_LIDAR_EXTENSIONS)
_ARRAY_EXTENSIONS = (".npy", *_TEXT_EXTENSIONS)
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
def _read_bytes(path):
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise ValueError(f"{path}: cannot be read: {exc}") from exc


def _parse_npy(data, source):
    """The array held by the bytes of a ``.npy`` file, checked strictly.

    The header must parse, describe numbers (no Python objects), and announce exactly
    the number of bytes that follow it: a truncated file or one with bytes appended is an
    error, never a zero-filled or silently shortened array.
    """
    from numpy.lib import format as npy_format

    handle = io.BytesIO(data)
    try:
        version = npy_format.read_magic(handle)
        if version == (1, 0):
            shape, fortran, dtype = npy_format.read_array_header_1_0(handle)
        elif version == (2, 0):
            shape, fortran, dtype = npy_format.read_array_header_2_0(handle)
        else:
            reader = getattr(npy_format, "_read_array_header", None)
            if reader is None:
                raise ValueError(f"unsupported .npy format version {version}")
            shape, fortran, dtype = reader(handle, version)
    except (ValueError, TypeError, SyntaxError, KeyError, IndexError, OverflowError) as exc:
        raise ValueError(
            f"{source}: cannot be read as a .npy array (corrupt header?): {_one_line(exc)}"
        ) from exc
    if dtype.hasobject:
        raise ValueError(
            f"{source}: cannot be read as a .npy array of numbers: it holds Python objects."
        )
    offset = handle.tell()
    count = math.prod(shape)
    expected = count * dtype.itemsize
    found = len(data) - offset
    if found != expected:
        raise ValueError(
            f"{source}: corrupt .npy file: its header announces an array of shape {shape} "
            f"({expected:,} bytes of data) but {found:,} bytes follow the header"
            + (" (truncated)." if found < expected else " (extra bytes at the end).")
        )
    array = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
    return array.reshape(shape, order="F" if fortran else "C")


def _load_npy(path):
    return _parse_npy(_read_bytes(path), path)


def _check_zip_end(data, source):
    """ValueError unless ``data`` ends exactly with a zip archive's end record."""
    start = max(0, len(data) - 22 - 0xFFFF)
    end = data.rfind(b"PK\x05\x06", start)
    if end < 0 or end + 22 > len(data):
        raise ValueError(f"{source}: cannot be read as a .npz file (corrupt or truncated).")
    (comment,) = struct.unpack("<H", data[end + 20 : end + 22])
    if end + 22 + comment != len(data):
        raise ValueError(
            f"{source}: corrupt .npz file: {len(data) - end - 22 - comment:+,} bytes after the "
            "end of the zip archive."
        )


def _load_npz(path):
    """``{key: array}`` of an ``.npz`` archive; every member's CRC-32 is checked."""
    data = _read_bytes(path)
    _check_zip_end(data, path)
    arrays = {}
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            for name in archive.namelist():
                if not name.endswith(".npy"):
                    raise ValueError(f"member {name!r} is not a .npy array")
                arrays[name[: -len(".npy")]] = _parse_npy(archive.read(name), f"{path}[{name}]")
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError, NotImplementedError) as exc:
        raise ValueError(f"{path}: cannot be read as a .npz file (corrupt?): {exc}") from exc
    except (ValueError, KeyError, UnicodeDecodeError, struct.error) as exc:
        message = _one_line(exc)
        if str(path) not in message:
            message = f"{path}: cannot be read as a .npz archive of numeric arrays: {message}"
        raise ValueError(message) from exc
    return arrays


def _one_line(error):
    """The message of ``error`` on one line."""
    return " ".join(str(error).split())


def _is_number(token):
    try:
        float(token)
    except ValueError:
        return False
    return True


def _decode_text(data, source):
    """The text of a UTF-8 file (a byte-order mark is dropped), newlines normalised."""
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{source}: is not a text file (not UTF-8): {exc}") from exc
    if "\x00" in text:
        raise ValueError(f"{source}: is not a text file (it holds NUL bytes).")
    return text.replace("\r\n", "\n").replace("\r", "\n")


def _split_fields(line, delimiter):
    return [f.strip() for f in line.split(delimiter)] if delimiter else line.split()


def _require_final_newline(text, source):
    if text.rstrip(" \t") and not text.rstrip(" \t").endswith("\n"):
        raise ValueError(
            f"{source}: the last line does not end with a line break, so the file may have "
            "been cut short; if it is complete, add a line break at its end."
        )


def _parse_rows(lines, first_line, delimiter, source):
    """A 2-D float array from text rows; errors name the line (``first_line`` is line 1's)."""
    rows = [line for line in lines if line.strip()]
    if not rows:
        return np.zeros((0, 0))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return np.loadtxt(rows, delimiter=delimiter, comments=None, ndmin=2, dtype=float)
    except ValueError:
        pass
    # Find and name the offending line (slow, only on error).
    width = None
    for number, line in enumerate(lines, start=first_line):
        if not line.strip():
            continue
        fields = _split_fields(line, delimiter)
        if width is None:
            width = len(fields)
        if len(fields) != width:
            raise ValueError(
                f"{source}: line {number} has {len(fields)} values but the lines before "
                f"have {width} (rows of different lengths, or a damaged line)."
            )
        for field in fields:
            if not _is_number(field):
                raise TypeError(f"{source}: line {number} holds {field!r}, which is not a number.")
    raise ValueError(f"{source}: malformed rows.")  # pragma: no cover - loadtxt agreed


def _parse_text_table(data, source):
    """A 2-D float array from the bytes of a comma, space or tab delimited text file.

    Blank lines are skipped; lines starting with ``#`` are comments, allowed only before
    the data (a ``#`` among the data rows is an error: it could hide a damaged row). The
    delimiter is a comma when the first data line holds one, otherwise any run of spaces
    and tabs. The first line is a header when none of its fields is a number; a first
    line mixing numbers and text is an error. The last line must end with a line break.
    """
    text = _decode_text(data, source)
    lines = text.split("\n")
    header = None
    delimiter = None
    start = None
    for index, line in enumerate(lines):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            rest = stripped.lstrip("#").replace(",", " ").split()
            if rest and all(_is_number(token) for token in rest):
                raise ValueError(
                    f"{source}: line {index + 1} is a comment holding only numbers (a damaged "
                    "data row?); remove it or put words in it."
                )
            continue
        delimiter = "," if "," in line else None
        fields = _split_fields(line, delimiter)
        numeric = [_is_number(field) for field in fields]
        if all(numeric):
            start = index
            break
        if not any(numeric) and header is None:
            header = index
            continue
        word = next(f for f, is_number in zip(fields, numeric, strict=True) if not is_number)
        raise TypeError(
            f"{source}: line {index + 1} holds {word!r}, which is not a number"
            + (
                " (a header row must hold names only, a data row numbers only)."
                if any(numeric)
                else " (a second header row?)."
            )
        )
    if start is None:
        after = " after the header" if header is not None else ""
        raise ValueError(f"{source}: holds no rows{after}; at least one is needed.")
    _require_final_newline(text, source)
    position = sum(len(line) + 1 for line in lines[:start])
    comment = text.find("#", position)
    if comment >= 0:
        number = text.count("\n", 0, comment) + 1
        raise ValueError(
            f"{source}: line {number} holds '#' among the data rows; comments are allowed "
            "only before the data."
        )
    array = _parse_rows(lines[start:], start + 1, delimiter, source)
    if array.size == 0:  # pragma: no cover - start is a data row
        raise ValueError(f"{source}: holds no rows; at least one is needed.")
    return array


def _load_text_table(path):
    return _parse_text_table(_read_bytes(path), path)


# PLY scalar types (both spellings) and PCD (TYPE, SIZE) pairs as numpy types.
_PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
_MAX_HEADER = 1 << 20


def _header_lines(data, source, end_marker, kind):
    """The header lines of a PLY or PCD file and the offset of the data after it."""
    lines, position = [], 0
    while True:
        newline = data.find(b"\n", position, position + _MAX_HEADER)
        if newline < 0:
            raise ValueError(
                f"{source}: not a {kind} point cloud, or its header is cut short (no "
                f"{end_marker!r} line): no points could be read."
            )
        raw = data[position:newline]
        position = newline + 1
        try:
            line = raw.decode("ascii").strip()
        except UnicodeDecodeError:
            raise ValueError(
                f"{source}: not a {kind} point cloud (its header holds binary bytes): no "
                "points could be read."
            ) from None
        lines.append(line)
        if line.split()[:1] == [end_marker]:
            return lines, position
        if len(lines) > 10_000:
            raise ValueError(f"{source}: {kind} header without an end: no points could be read.")


def _colour_scale(dtype):
    dtype = np.dtype(dtype)
    return float(np.iinfo(dtype).max) if dtype.kind in "iu" else 1.0


def _points_and_colours(fields, source, what):
    """``(points, rgb or None)`` from ``{name: column}`` holding x, y, z (and colours)."""
    missing = [name for name in "xyz" if name not in fields]
    if missing:
        raise ValueError(f"{source}: the {what} have no {', '.join(missing)} coordinate.")
    points = np.column_stack([np.asarray(fields[name], dtype=float) for name in "xyz"])
    for names in (("red", "green", "blue"), ("r", "g", "b")):
        if all(name in fields for name in names):
            columns = [np.asarray(fields[name]) for name in names]
            rgb = np.column_stack([c / _colour_scale(c.dtype) for c in columns]).astype(float)
            return points, rgb
    return points, None


def _parse_ply(data, source):
    """Points and colours of a PLY file (ascii, binary little or big endian), strictly.

    Every element the header declares must be present, whole, and followed by nothing:
    a file cut short names how many vertices the header promised and how many were read.
    """
    if not (data.startswith(b"ply\n") or data.startswith(b"ply\r\n")):
        raise ValueError(
            f"{source}: not a PLY file (no 'ply' line first): no points could be read."
        )
    lines, offset = _header_lines(data, source, "end_header", "PLY")
    form, elements = None, []
    for number, line in enumerate(lines[1:-1], start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        try:
            if words[0] == "format":
                form = {"ascii": "ascii", "binary_little_endian": "<", "binary_big_endian": ">"}[
                    words[1]
                ]
            elif words[0] == "element":
                if len(words) != 3 or int(words[2]) < 0:
                    raise ValueError
                elements.append((words[1], int(words[2]), []))
            elif words[0] == "property":
                if words[1] == "list":
                    if len(words) != 5:
                        raise ValueError
                    prop = (words[4], _PLY_TYPES[words[2]], _PLY_TYPES[words[3]])
                else:
                    if len(words) != 3:
                        raise ValueError
                    prop = (words[2], _PLY_TYPES[words[1]], None)
                elements[-1][2].append(prop)
            else:
                raise ValueError
        except (ValueError, KeyError, IndexError):
            raise ValueError(
                f"{source}: malformed PLY header, line {number}: {line[:80]!r}."
            ) from None
    if form is None:
        raise ValueError(f"{source}: malformed PLY header: no 'format' line.")
    vertex = next((e for e in elements if e[0] == "vertex"), None)
    if vertex is None:
        raise ValueError(f"{source}: the PLY header declares no 'vertex' element: no points.")
    if form == "ascii":
        fields = _ply_ascii_body(data, offset, elements, source)
    else:
        fields = _ply_binary_body(data, offset, elements, form, source)
    return _points_and_colours(fields, source, "PLY vertices")


def _short_elements(source, name, promised, read):
    what = "vertices" if name == "vertex" else f"'{name}' elements"
    return ValueError(
        f"{source}: truncated PLY file: the header promised {promised:,} {what} but "
        f"{read:,} were read."
    )


def _ply_binary_body(data, offset, elements, order, source):
    vertex_fields = None
    for name, count, props in elements:
        if all(p[2] is None for p in props):
            dtype = np.dtype([(p[0], order + p[1]) for p in props])
            size = count * dtype.itemsize
            if offset + size > len(data):
                read = (len(data) - offset) // dtype.itemsize if dtype.itemsize else count
                raise _short_elements(source, name, count, read)
            if name == "vertex":
                block = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
                vertex_fields = {p[0]: block[p[0]].astype(p[1]) for p in props}
            offset += size
        else:
            offset = _skip_binary_lists(data, offset, name, count, props, order, source)
    if offset != len(data):
        raise ValueError(
            f"{source}: corrupt PLY file: {len(data) - offset:,} bytes follow the last "
            "element the header declares."
        )
    return vertex_fields


def _skip_binary_lists(data, offset, name, count, props, order, source):
    """The offset after ``count`` binary rows holding list properties (faces, say)."""
    for row in range(count):
        for _, item, list_type in props:
            if list_type is None:
                offset += np.dtype(item).itemsize
                continue
            size = np.dtype(item).itemsize
            if offset + size > len(data):
                raise _short_elements(source, name, count, row)
            length = int(np.frombuffer(data, order + item, count=1, offset=offset)[0])
            if length < 0:
                raise ValueError(f"{source}: corrupt PLY file: a negative list length.")
            offset += size + length * np.dtype(list_type).itemsize
        if offset > len(data):
            raise _short_elements(source, name, count, row)
    return offset


def _ply_ascii_body(data, offset, elements, source):
    text = _decode_text(data[offset:], source)
    _require_final_newline(text, source)
    lines = [line for line in text.split("\n") if line.strip()]
    position, vertex_fields = 0, None
    for name, count, props in elements:
        rows = lines[position : position + count]
        if len(rows) < count:
            raise _short_elements(source, name, count, len(rows))
        if name == "vertex":
            if any(p[2] is not None for p in props):
                raise ValueError(f"{source}: PLY vertices with list properties are not supported.")
            table = _parse_rows(rows, 1, None, source)
            if table.shape != (count, len(props)):
                raise ValueError(
                    f"{source}: corrupt PLY file: {len(props)} values per vertex expected, "
                    f"got rows of {table.shape[1]}."
                )
            vertex_fields = {}
            for column, (prop, item, _) in enumerate(props):
                values = table[:, column]
                if np.dtype(item).kind in "iu":
                    info = np.iinfo(item)
                    if np.any(values != np.round(values)) or np.any(
                        (values < info.min) | (values > info.max)
                    ):
                        raise ValueError(
                            f"{source}: corrupt PLY file: vertex property {prop!r} holds a "
                            f"value that is not a {item}."
                        )
                vertex_fields[prop] = values.astype(item)
        position += count
    if position != len(lines):
        raise ValueError(
            f"{source}: corrupt PLY file: {len(lines) - position:,} lines follow the last "
            "element the header declares."
        )
    return vertex_fields


def _lzf_decompress(data, size, source):
    """LZF-decompress ``data`` (PCD's ``binary_compressed``) into exactly ``size`` bytes."""
    out = bytearray(size)
    i = o = 0
    n = len(data)
    try:
        while i < n:
            control = data[i]
            i += 1
            if control < 32:  # a run of control + 1 literal bytes
                length = control + 1
                if i + length > n or o + length > size:
                    raise IndexError
                out[o : o + length] = data[i : i + length]
                i += length
                o += length
                continue
            length = control >> 5
            ref = o - ((control & 0x1F) << 8) - 1
            if length == 7:
                length += data[i]
                i += 1
            ref -= data[i]
            i += 1
            length += 2
            if ref < 0 or o + length > size:
                raise IndexError
            distance = o - ref
            if distance >= length:
                out[o : o + length] = out[ref : ref + length]
            else:  # overlapping: the last `distance` bytes repeat
                pattern = bytes(out[ref:o])
                out[o : o + length] = (pattern * (length // distance + 1))[:length]
            o += length
    except IndexError:
        raise ValueError(f"{source}: corrupt PCD file: the compressed data are damaged.") from None
    if o != size:
        raise ValueError(
            f"{source}: corrupt PCD file: the compressed data hold {o:,} of {size:,} bytes."
        )
    return bytes(out)


_PCD_TYPES = {"F": "f", "U": "u", "I": "i"}


def _parse_pcd(data, source):
    """Points and colours of a PCD file (ascii, binary, binary_compressed), strictly."""
    lines, offset = _header_lines(data, source, "DATA", "PCD")
    header = {}
    for line in lines:
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        header[words[0].upper()] = words[1:]
    try:
        names = header["FIELDS"]
        sizes = [int(s) for s in header["SIZE"]]
        types = header["TYPE"]
        counts = [int(c) for c in header.get("COUNT", ["1"] * len(names))]
        width = int(header["WIDTH"][0])
        height = int(header.get("HEIGHT", ["1"])[0])
        n_points = int(header.get("POINTS", [width * height])[0])
        mode = header["DATA"][0].lower()
        if not (len(names) == len(sizes) == len(types) == len(counts)) or min(counts) < 1:
            raise ValueError("FIELDS, SIZE, TYPE and COUNT differ in length")
        dtypes = [np.dtype("<" + _PCD_TYPES[t] + str(s)) for t, s in zip(types, sizes, strict=True)]
        if n_points != width * height or n_points < 0:
            raise ValueError(f"POINTS {n_points} is not WIDTH x HEIGHT = {width * height}")
        if mode not in ("ascii", "binary", "binary_compressed"):
            raise ValueError(f"unknown DATA {mode!r}")
    except (KeyError, IndexError, ValueError, TypeError) as exc:
        raise ValueError(f"{source}: malformed PCD header: {_one_line(exc)}.") from None
    layout = list(zip(names, dtypes, counts, strict=True))
    point_size = sum(dtype.itemsize * count for _, dtype, count in layout)
    fields = {}
    if mode == "ascii":
        text = _decode_text(data[offset:], source)
        _require_final_newline(text, source)
        rows = [line for line in text.split("\n") if line.strip()]
        if len(rows) != n_points:
            if len(rows) < n_points:
                raise ValueError(
                    f"{source}: truncated PCD file: the header promised {n_points:,} points but "
                    f"{len(rows):,} were read."
                )
            raise ValueError(
                f"{source}: corrupt PCD file: {len(rows) - n_points:,} lines follow the "
                f"{n_points:,} points the header promised."
            )
        if n_points:
            table = _parse_rows(rows, 1, None, source)
            column = 0
            for name, dtype, count in layout:
                values = table[:, column]
                if dtype.kind in "iu" and np.any(values != np.round(values)):
                    raise ValueError(f"{source}: corrupt PCD file: field {name!r} is not integer.")
                fields[name] = values.astype(dtype)
                column += count
            if table.shape[1] != column:
                raise ValueError(f"{source}: corrupt PCD file: rows of {table.shape[1]} values.")
    else:
        body = data[offset:]
        if mode == "binary_compressed":
            if len(body) < 8:
                raise ValueError(
                    f"{source}: truncated PCD file: the header promised {n_points:,} points but "
                    "0 were read."
                )
            compressed, uncompressed = struct.unpack("<II", body[:8])
            if uncompressed != n_points * point_size:
                raise ValueError(
                    f"{source}: corrupt PCD file: {uncompressed:,} uncompressed bytes for "
                    f"{n_points:,} points of {point_size} bytes."
                )
            if len(body) - 8 < compressed:
                raise ValueError(
                    f"{source}: truncated PCD file: the header promised {n_points:,} points "
                    f"({compressed:,} compressed bytes) but {len(body) - 8:,} bytes follow."
                )
            if len(body) - 8 > compressed:
                raise ValueError(
                    f"{source}: corrupt PCD file: {len(body) - 8 - compressed:,} bytes follow "
                    "the compressed data."
                )
            raw = _lzf_decompress(body[8:], uncompressed, source) if uncompressed else b""
            start = 0
            for name, dtype, count in layout:  # one field after the other
                size = n_points * count * dtype.itemsize
                block = np.frombuffer(raw, dtype=dtype, count=n_points * count, offset=start)
                fields[name] = block.reshape(n_points, count)[:, 0]
                start += size
        else:
            expected = n_points * point_size
            if len(body) != expected:
                read = len(body) // point_size if point_size else 0
                if len(body) < expected:
                    raise ValueError(
                        f"{source}: truncated PCD file: the header promised {n_points:,} points "
                        f"but {read:,} were read."
                    )
                raise ValueError(
                    f"{source}: corrupt PCD file: {len(body) - expected:,} bytes follow the "
                    f"{n_points:,} points the header promised."
                )
            record = np.dtype([(name, dtype, (count,)) for name, dtype, count in layout])
            block = np.frombuffer(body, dtype=record, count=n_points)
            fields = {name: block[name][:, 0] for name, _, _ in layout}
    points, _ = _points_and_colours(fields, source, "PCD points")
    rgb = None
    for name in ("rgb", "rgba"):
        if name in fields:
            packed = np.ascontiguousarray(fields[name])
            if packed.dtype.itemsize != 4:
                raise ValueError(f"{source}: PCD field {name!r} must be 4 bytes.")
            packed = packed.view("<u4")
            rgb = np.column_stack([(packed >> s) & 0xFF for s in (16, 8, 0)]) / 255.0
            break
    return points, rgb


def _read_cloud_file(path, *, colors=False):
    """Points (and colours or None) of a ``.ply``, ``.pcd`` or ``.xyz`` file."""
    suffix = Path(path).suffix.lower()
    data = _read_bytes(path)
    if suffix == ".xyz":
        return _parse_text_table(data, path), None
    points, rgb = (_parse_ply if suffix == ".ply" else _parse_pcd)(data, path)
    if len(points) == 0:
        raise ValueError(f"{path}: holds no points (its header declares 0).")
    return points, (rgb if colors else None)


def _check_lidar_points(points, source, name):
    """Like :func:`_check_points` for (n, 3) LiDAR returns, but NaN / infinite rows are kept.

    A sensor writes its invalid returns as NaN (or zero) rows; the estimators count and
    drop them, and the rows keep their order (per-point times, flow files).
    """
    points = _as_numeric(points, source, name)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 1:
        raise ValueError(f"{source}: {name} must be an array of shape (n, 3); got {points.shape}.")
    return np.ascontiguousarray(points)


def _read_point_file(path, name, *, colors=False):
    """``(points, rgb or None, times or None)`` of any point file (checked readable).

    Clouds and arrays must be finite; LiDAR sweep files keep their invalid rows.
    """
    suffix = _extension(path, _POINT_EXTENSIONS, name)
    kind = _lidar_files.lidar_kind(path)
    if kind is not None:
        points, times, _ = _lidar_files.read_lidar_file(path, kind)
        return _check_lidar_points(points, path, name), None, times
    rgb = None
    if suffix in _CLOUD_EXTENSIONS:
        points, rgb = _read_cloud_file(path, colors=colors)
    elif suffix == ".npy":
        points = _load_npy(path)
    else:
        points = _load_text_table(path)
    return _check_points(points, path, 3, name), rgb, None


def _read_points(path, name):
    """An (n, 3) array from any point file (a point cloud, an array, a LiDAR sweep)."""
    return _read_point_file(_check_readable(path), name)[0]


def _array_columns(path, suffix):
    """The number of columns of a ``.npy`` / ``.csv`` / ``.txt`` array (None if not 2-D)."""
    array = _load_npy(path) if suffix == ".npy" else _load_text_table(path)
    return array.shape[1] if array.ndim == 2 else None


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
        - the a-points, which need exactly one of ``target`` and ``flow``: a point cloud
          (``.ply`` / ``.pcd`` / ``.xyz``), a LiDAR sweep (``.bin``, ``.pcd.bin``,
          ``.feather``) or an (n, 3) ``.npy`` / ``.csv`` / ``.txt`` array.
    target : str or path-like, optional
        With a-points in ``path``: a second file with the b-points, index-aligned with
        the a-points (row ``i`` corresponds to point ``i``): any point file.
    flow : str or path-like, optional
        With a-points in ``path``: an (n, 3) per-point flow (``.npy`` / ``.csv`` /
        ``.txt``, or a point file whose coordinates are the flow vectors); ``b = a + flow``.

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
    points_only = suffix in _CLOUD_EXTENSIONS or _lidar_files.lidar_kind(path) is not None
    if not points_only and suffix in _ARRAY_EXTENSIONS and (target, flow) != (None, None):
        # An (n, 3) array is a-points (with target= or flow=), an (n, 6) one both.
        columns = _array_columns(path, suffix)
        if columns not in (3, 6):
            raise ValueError(
                f"{path}: target= and flow= need the a-points as an (n, 3) array; this one "
                f"has {'no 2-D shape' if columns is None else f'{columns} columns'}."
            )
        points_only = columns == 3
    if points_only:
        if (target is None) == (flow is None):
            raise ValueError(
                f"{path}: a point cloud holds only the a-points; pass exactly one of "
                "target= (a file with the b-points) or flow= (a file with the per-point "
                f"flow, b = a + flow); got {'both' if target is not None else 'neither'}."
            )
        a = _read_point_file(path, "the a-points")[0]
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
            f"{path}: target= and flow= only apply when path holds only the a-points (a "
            "point cloud, a LiDAR sweep or an (n, 3) array); this file holds both a and b "
            "(6 columns)."
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
def read_point_cloud(path, *, colors=False, times=False):
    """Read the points (and colours, capture times) of a point cloud or LiDAR sweep.

    Parameters
    ----------
    path : str or path-like
        ``.ply`` or ``.pcd``, ``.xyz`` (``x y z`` per line), an (n, 3) ``.npy`` /
        ``.csv`` / ``.txt`` array, or a LiDAR sweep: KITTI velodyne ``.bin`` (float32
        ``x y z reflectance``, 16 bytes a point), nuScenes ``.pcd.bin`` (float32 ``x y z
        intensity ring``, 20 bytes) or Argoverse 2 ``.feather`` (columns ``x y z``, and
        ``offset_ns``).
    colors : bool, default=False
        Also return the colours.
    times : bool, default=False
        Also return the per-point capture times, in seconds after the sweep's timestamp:
        an Argoverse 2 ``.feather``'s ``offset_ns * 1e-9``; ``None`` for every other
        file.

    Returns
    -------
    points : ndarray of shape (n, 3)
        A LiDAR sweep's invalid returns (NaN or all-zero rows) are kept in place; every
        other format must be finite.
    colors : ndarray of shape (n, 3) or None
        Only when ``colors=True``: RGB in ``[0, 1]``, or ``None`` when the file holds no
        colours (always for ``.xyz``, array and LiDAR files).
    times : ndarray of shape (n,) or None
        Only when ``times=True``, after ``colors``.

    Raises
    ------
    FileNotFoundError
        If the file is missing.
    ValueError
        If it is unreadable, corrupt, empty, not a whole number of points (``.bin``,
        ``.pcd.bin``), lacks a column (``.feather``), holds NaN or infinity (except a
        LiDAR sweep), is a ROS bag (many frames: see
        :func:`mmreg.datasets.open_sequence`), or the extension is unknown.

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
    if _lidar_files.lidar_kind(path) == "bag":
        _lidar_files.read_lidar_file(path, "bag")  # raises: a bag holds many frames
    points, rgb, capture = _read_point_file(path, "the points", colors=colors)
    if capture is not None and len(capture) != len(points):  # pragma: no cover - one table
        raise ValueError(f"{path}: holds {len(points)} points but {len(capture)} times.")
    if rgb is not None:
        rgb = _check_points(rgb, path, 3, "the colours")
        if len(rgb) != len(points):
            raise ValueError(f"{path}: holds {len(points)} points but {len(rgb)} colours.")
    out = (points,) + ((rgb,) if colors else ()) + ((capture,) if times else ())
    return out[0] if len(out) == 1 else out


def write_point_cloud(path, points, colors=None, labels=None):
    """Write a point cloud, atomically, with colours and a per-point label if given.

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
    labels : array-like of shape (n,), optional
        An integer per point (a cluster, ``-1`` for outliers), stored as a signed 32-bit
        vertex property ``label`` (``.ply``: ``property int label``; ``.pcd``: field
        ``label``, type ``I``, as PCL's ``PointXYZRGBL``). CloudCompare shows it as a
        scalar field to filter by, Open3D's tensor API reads it as ``pcd.point["label"]``
        (``open3d.t.io.read_point_cloud``), plyfile as ``vertex["label"]``.
        :func:`read_point_cloud` ignores it (it returns points and colours only).

    Raises
    ------
    ValueError
        If the shapes are wrong, a value is NaN or infinity, a colour lies outside
        ``[0, 1]``, a label is not an integer of 32 bits, colours or labels are given for
        ``.xyz``, or the extension is unknown.

    Notes
    -----
    The file is written to a temporary file in the same folder first, which is then
    renamed onto ``path``.

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
    if labels is not None:
        if suffix == ".xyz":
            raise ValueError(f"{path}: .xyz files hold no labels; write .ply or .pcd instead.")
        labels = _check_point_labels(labels, len(points))
    if suffix == ".xyz":
        _write_text_table(path, points, None)
        return
    rgb = None if colors is None else np.round(colors * 255).astype(np.uint8)
    write = _ply_bytes if suffix == ".ply" else _pcd_bytes
    data = write(points, rgb, labels)
    with atomic_write(path) as handle:
        handle.write(data)


def _check_point_labels(labels, n):
    """One integer per point that fits a signed 32-bit property, as int32."""
    array = np.asarray(labels)
    if array.shape != (n,):
        raise ValueError(f"labels must have shape ({n},), one per point; got {array.shape}.")
    if array.dtype.kind == "f":
        if not np.all(np.isfinite(array)) or np.any(array != np.round(array)):
            raise ValueError("labels must be integers.")
    elif array.dtype.kind not in "iub":
        raise ValueError(f"labels must be integers; got dtype {array.dtype}.")
    info = np.iinfo(np.int32)
    if n and (array.min() < info.min or array.max() > info.max):
        raise ValueError("labels must fit in 32 bits (a PLY 'int' property).")
    return array.astype(np.int32)


def _ply_bytes(points, rgb, labels=None):
    """A binary little-endian PLY file: float64 x, y, z, 8-bit red, green, blue, int label."""
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    header = ["ply", "format binary_little_endian 1.0", "comment Created by mmreg"]
    header.append(f"element vertex {len(points)}")
    header += [f"property double {name}" for name in "xyz"]
    if rgb is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
        header += [f"property uchar {name}" for name in ("red", "green", "blue")]
    if labels is not None:
        fields.append(("label", "<i4"))
        header.append("property int label")
    header.append("end_header")
    record = np.empty(len(points), dtype=fields)
    for column, name in enumerate("xyz"):
        record[name] = points[:, column]
    if rgb is not None:
        for column, name in enumerate(("red", "green", "blue")):
            record[name] = rgb[:, column]
    if labels is not None:
        record["label"] = labels
    return ("\n".join(header) + "\n").encode("ascii") + record.tobytes()


def _pcd_bytes(points, rgb, labels=None):
    """A binary PCD v0.7 file: float32 x, y, z, packed 8-bit rgb (as Open3D writes), label."""
    names, sizes, types = ["x", "y", "z"], ["4"] * 3, ["F"] * 3
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if rgb is not None:
        names.append("rgb")
        sizes.append("4")
        types.append("U")
        fields.append(("rgb", "<u4"))
    if labels is not None:
        names.append("label")
        sizes.append("4")
        types.append("I")
        fields.append(("label", "<i4"))
    n = len(points)
    header = [
        "# .PCD v0.7 - Point Cloud Data file format",
        "VERSION 0.7",
        f"FIELDS {' '.join(names)}",
        f"SIZE {' '.join(sizes)}",
        f"TYPE {' '.join(types)}",
        f"COUNT {' '.join(['1'] * len(names))}",
        f"WIDTH {n}",
        "HEIGHT 1",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {n}",
        "DATA binary",
    ]
    record = np.empty(n, dtype=fields)
    for column, name in enumerate("xyz"):
        record[name] = points[:, column]
    if rgb is not None:
        rgb = rgb.astype(np.uint32)
        record["rgb"] = (rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]
    if labels is not None:
        record["label"] = labels
    return ("\n".join(header) + "\n").encode("ascii") + record.tobytes()
