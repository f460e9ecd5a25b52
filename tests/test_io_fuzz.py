"""Every reader against damaged files: cut short, with bytes appended, with a byte changed.

Each valid file is written by the tests, then damaged in seeded random ways. A reader must
end in a clean error (``ValueError``, or ``TypeError`` for text where numbers belong) that
names the file, or return data whose damage is of the kind its format cannot detect; it
must never crash with another exception. What each format guarantees (documented in
:mod:`mmreg.io`):

* every format: a file cut short is an error, except a text table cut exactly at a line
  end (``.csv``, ``.txt``, ``.xyz`` hold no row count; then the result is the first whole
  rows, never a changed value); bytes appended are an error (a text table: an error, or
  the original rows followed by whole new rows);
* checksummed formats (``.npz``: CRC-32 per array; ``.png``: CRC-32 per chunk and
  Adler-32): any changed byte is an error or leaves the data unchanged;
* text (``.csv``, ``.txt``, ``.xyz``, ascii ``.ply`` and ``.pcd``): a changed byte is an
  error, leaves the data unchanged, or changes exactly one number (a digit, a sign or an
  exponent can make another valid number: text has no checksum); in a one-column table
  (labels) it can also add or remove a line break, changing the number of rows by one
  (``mmreg register`` then finds one label too many or too few);
* raw binary (``.npy``, binary ``.ply`` and ``.pcd``, ``.pfm``, ``.flo``): a changed byte
  is an error or gives data of the same shape (the values have no checksum).
"""

import numpy as np
import pytest

from mmreg.datasets._kitti import read_png
from mmreg.datasets._pfm import read_flo, read_pfm, write_flo, write_pfm
from mmreg.io import (
    read_correspondences,
    read_labels,
    read_point_cloud,
    write_correspondences,
    write_labels,
    write_point_cloud,
)

N_CUTS, N_FLIPS, N_APPENDS = 120, 160, 12


def _data():
    rng = np.random.default_rng(0)
    a = rng.uniform(-20, 20, (30, 3)).round(3)
    return np.hstack([a, a + rng.normal(0, 0.5, (30, 3)).round(3)])


def _ascii_ply(points):
    header = "ply\nformat ascii 1.0\nelement vertex {}\nproperty double x\nproperty double y\n"
    header += "property double z\nend_header\n"
    rows = "".join(" ".join(repr(float(v)) for v in row) + "\n" for row in points)
    return (header.format(len(points)) + rows).encode()


def _ascii_pcd(points):
    header = (
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
        f"WIDTH {len(points)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(points)}\n"
        "DATA ascii\n"
    )
    rows = "".join(" ".join(repr(float(np.float32(v))) for v in row) + "\n" for row in points)
    return (header + rows).encode()


def _compressed_pcd(points, path):
    o3d = pytest.importorskip("open3d")
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    assert o3d.io.write_point_cloud(str(path), cloud, compressed=True)
    return path.read_bytes()


def _png16(path, image):
    from PIL import Image

    Image.fromarray(image).save(path)
    return path.read_bytes()


def _png16_colour(path, image):
    o3d = pytest.importorskip("open3d")
    assert o3d.io.write_image(str(path), o3d.geometry.Image(image))
    return path.read_bytes()


def _case(name, tmp_path):
    """``(file name, valid bytes, reader, guarantee)`` of one format."""
    X = _data()
    points = X[:, :3]
    path = tmp_path / "original"
    path.mkdir(exist_ok=True)
    grey = (np.arange(48, dtype=np.uint16).reshape(6, 8) * 1000 + 7).astype(np.uint16)
    if name in ("pairs.npy", "pairs.npz", "pairs.csv", "pairs.txt"):
        write_correspondences(path / name, X)
        return name, (path / name).read_bytes(), read_correspondences, _kind(name)
    if name == "labels.csv":
        write_labels(path / name, np.arange(30) % 4 - 1)
        return name, (path / name).read_bytes(), read_labels, "text"
    if name in ("cloud.ply", "cloud.pcd", "cloud.xyz"):
        write_point_cloud(path / name, points)
        return name, (path / name).read_bytes(), read_point_cloud, _kind(name)
    if name in ("ascii.ply", "ascii.pcd"):
        (path / name).write_bytes((_ascii_ply if name.endswith("ply") else _ascii_pcd)(points))
        return name, (path / name).read_bytes(), read_point_cloud, "text"
    if name == "compressed.pcd":
        return name, _compressed_pcd(points, path / name), read_point_cloud, "binary"
    if name == "image.pfm":
        write_pfm(path / name, grey.astype(np.float32) / 7)
        return name, (path / name).read_bytes(), read_pfm, "binary"
    if name == "flow.flo":
        write_flo(path / name, np.stack([grey, -grey], axis=-1).astype(np.float32) / 3)
        return name, (path / name).read_bytes(), read_flo, "binary"
    if name == "disparity.png":
        return name, _png16(path / name, grey), read_png, "checksum"
    if name == "flow.png":
        colour = np.stack([grey, grey + 1, np.ones_like(grey)], axis=-1)
        return name, _png16_colour(path / name, colour), read_png, "checksum"
    raise AssertionError(name)


def _kind(name):
    if name.endswith((".csv", ".txt", ".xyz")):
        return "text"
    return "checksum" if name.endswith(".npz") else "binary"


FORMATS = [
    "pairs.npy",
    "pairs.npz",
    "pairs.csv",
    "pairs.txt",
    "labels.csv",
    "cloud.ply",
    "cloud.pcd",
    "cloud.xyz",
    "ascii.ply",
    "ascii.pcd",
    "compressed.pcd",
    "image.pfm",
    "flow.flo",
    "disparity.png",
    "flow.png",
]


def _read(reader, path):
    """The data read, or None after a clean error naming the file; anything else fails."""
    try:
        return np.asarray(reader(path))
    except (ValueError, TypeError) as error:
        assert path.name in str(error), f"the error does not name the file: {error}"
        return None


def _rows(data):
    return np.asarray(data).reshape(len(data), -1)


def _is_prefix_of_whole_rows(result, original):
    rows, full = _rows(result), _rows(original)
    return len(rows) < len(full) and np.array_equal(rows, full[: len(rows)])


def _one_value_changed(result, original):
    """One number changed; in a one-column table also a line break added or removed."""
    if result.shape == original.shape:
        return np.sum(result != original) == 1
    return _rows(original).shape[1] == 1 and abs(len(result) - len(original)) == 1


@pytest.mark.parametrize("name", FORMATS)
def test_damaged_files_fail_cleanly_or_keep_their_guarantee(tmp_path, name):
    name, valid, reader, kind = _case(name, tmp_path)
    suffix = name[name.index(".") :]
    original = np.asarray(reader(tmp_path / "original" / name))
    rng = np.random.default_rng(sum(map(ord, name)))
    damaged = tmp_path / f"damaged{suffix}"
    outcomes = {"error": 0, "same": 0, "changed": 0}

    def check(data, allowed, same_allowed=True):
        damaged.write_bytes(data)
        result = _read(reader, damaged)
        if result is None:
            outcomes["error"] += 1
            return
        if result.shape == original.shape and np.array_equal(result, original):
            assert same_allowed, f"{name}: bytes after the end went unnoticed"
            outcomes["same"] += 1
            return
        outcomes["changed"] += 1
        assert allowed(result), f"{name}: silent damage with {data[-60:]!r}"

    # Cut short: header cuts, then random ones. Only a text table cut at a line end reads.
    cuts = list(range(min(len(valid), 200))) + list(rng.integers(0, len(valid), N_CUTS))
    for cut in cuts:
        at_line_end = kind == "text" and valid[cut - 1 : cut] == b"\n" and "ascii" not in name
        check(valid[:cut], lambda r, e=at_line_end: e and _is_prefix_of_whole_rows(r, original))
    # Bytes appended: random bytes, a stray newline, a copy of the file's end.
    tails = [bytes(rng.integers(0, 256, int(rng.integers(1, 40)), dtype=np.uint8))]
    tails += [b"\x00", b"\n1", valid[-13:], b"garbage\n"]
    tails += [bytes(rng.integers(0, 256, 4, dtype=np.uint8)) for _ in range(N_APPENDS)]
    for tail in tails:
        check(
            valid + tail,
            lambda r: (
                kind == "text"
                and "ascii" not in name
                and len(r) > len(original)
                and np.array_equal(_rows(r)[: len(original)], _rows(original))
            ),
            same_allowed=kind == "text" and not tail.strip(),  # a text table's blank lines
        )
    # One byte changed.
    for position in rng.integers(0, len(valid), N_FLIPS):
        value = int(rng.integers(0, 255))
        value += value >= valid[position]  # a different byte
        data = valid[:position] + bytes([value]) + valid[position + 1 :]
        if kind == "checksum":
            check(data, lambda r: False)
        elif kind == "text":
            check(data, lambda r: _one_value_changed(r, original))
        else:
            check(data, lambda r: r.shape == original.shape)
    assert outcomes["error"] > 0


def test_a_cut_at_a_line_end_is_what_text_cannot_detect(tmp_path):
    """The one damage a text table hides: a cut right after a line break (no row count)."""
    X = _data()
    path = tmp_path / "pairs.csv"
    write_correspondences(path, X)
    lines = path.read_bytes().splitlines(keepends=True)
    path.write_bytes(b"".join(lines[:11]))
    np.testing.assert_array_equal(read_correspondences(path), X[:10])
    path.write_bytes(b"".join(lines[:11]) + lines[11][:7])  # inside a line: detected
    with pytest.raises(ValueError, match="pairs.csv: the last line does not end"):
        read_correspondences(path)
