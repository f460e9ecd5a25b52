"""PLY and PCD point clouds, parsed and written by mmreg itself (the files agree with Open3D's)."""

import struct

import numpy as np

from mmreg.io._arrays import _decode_text, _parse_rows, _require_final_newline
from mmreg.io._checks import _one_line

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


# A PCD's per-point time fields, as a PointCloud2's (mmreg.io._lidar): Ouster "t",
# velodyne_pointcloud "time", Hesai / Robosense "timestamp", Livox "offset_time".
_PCD_TIME_FIELDS = ("t", "time", "timestamp", "offset_time")
# Float seconds beyond this are absolute (since 1970), not after the sweep's start; integer
# nanoseconds beyond this (about 11.6 days) likewise.
_ABSOLUTE_SECONDS = 1e6
_ABSOLUTE_NANOSECONDS = 1e15


def _pcd_timestamp(fields, source):
    """The sweep's time in seconds (float) from a PCD's absolute per-point time field: its
    earliest finite point's; None without such a field, when its times are relative
    (seconds or nanoseconds after a stamp the file does not hold) or absolute seconds in
    32-bit floats (rounded to minutes: no stamp)."""
    name = next((n for n in _PCD_TIME_FIELDS if n in fields), None)
    if name is None:
        return None
    raw = np.asarray(fields[name])
    if raw.dtype.kind == "f":
        finite = raw[np.isfinite(raw)].astype(np.float64)
        if not len(finite) or np.max(np.abs(finite)) <= _ABSOLUTE_SECONDS:
            return None
        if raw.dtype.itemsize < 8:  # 32-bit seconds since 1970 are rounded to minutes
            return None
        return float(finite.min())
    if raw.dtype.kind in "iu" and len(raw) and int(raw.max()) > _ABSOLUTE_NANOSECONDS:
        return int(raw.min()) * 1e-9
    return None


def _parse_pcd(data, source, *, stamp=False):
    """Points and colours of a PCD file (ascii, binary, binary_compressed), strictly; with
    ``stamp``, also its timestamp (:func:`_pcd_timestamp`)."""
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
    if stamp:
        return points, rgb, _pcd_timestamp(fields, source)
    return points, rgb


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
