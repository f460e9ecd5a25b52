"""Arrays in files: ``.npy``, ``.npz`` and text tables (``.csv``, ``.txt``, ``.xyz``)."""

import io
import math
import struct
import warnings
import zipfile
import zlib

import numpy as np

from mmreg.io._checks import _one_line, _read_bytes


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
