"""Tests of the real-data loaders: KITTI Scene Flow 2015, FlyingThings3D, PFM and .flo.

Every test writes tiny files in the data sets' own formats from known 3-D points and known
rigid motions, then checks that the loaders give those points back.
"""

import struct
import zlib

import numpy as np
import pytest
from PIL import Image
from scipy.spatial.transform import Rotation

from mmreg.datasets import (
    load_correspondences,
    load_flying_things,
    load_kitti_scene_flow,
    read_pfm,
    write_pfm,
)
from mmreg.datasets._kitti import read_kitti_calibration, read_png
from mmreg.datasets._pfm import read_flo, write_flo
from mmreg.io import read_correspondences


# --------------------------------------------------------------------------- ground truth
def _ground_truth(height, width, fx, fy, cx, cy, baseline, seed):
    """A plane of depths 8-15 m seen by the camera; a box-shaped object moves on its own.

    Returns per-pixel a, b (H, W, 3), instance map, and the exact disparities and flow.
    """
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[:height, :width].astype(float)
    z = 8.0 + 5.0 * cols / width + 2.0 * rows / height
    a = np.stack([(cols - cx) * z / fx, (rows - cy) * z / fy, z], axis=-1)
    instance = np.zeros((height, width), dtype=np.intp)
    instance[2 : height // 2 + 2, 3 : width // 2 + 1] = 1
    instance[height - 3 :, width - 5 : width - 1] = 2
    motions = {
        0: (Rotation.from_euler("y", 1.0, degrees=True).as_matrix(), np.array([0.0, 0, -0.5])),
        1: (Rotation.from_euler("xyz", [2, 6, -3], degrees=True).as_matrix(), [0.4, 0.1, -0.9]),
        2: (Rotation.from_euler("z", 10, degrees=True).as_matrix(), np.array([-0.3, 0, 0.6])),
    }
    b = np.empty_like(a)
    for k, (rotation, translation) in motions.items():
        mask = instance == k
        b[mask] = a[mask] @ rotation.T + translation
    u_next = fx * b[..., 0] / b[..., 2] + cx
    v_next = fy * b[..., 1] / b[..., 2] + cy
    flow = np.stack([u_next - cols, v_next - rows], axis=-1)
    disparity = fx * baseline / a[..., 2]
    disparity_next = fx * baseline / b[..., 2]
    invalid = rng.random((3, height, width)) < 0.1  # per map: disp 0, disp 1, flow
    return {
        "a": a,
        "b": b,
        "instance": instance,
        "disparity": disparity,
        "disparity_next": disparity_next,
        "flow": flow,
        "invalid": invalid,
        "motions": motions,
    }


def _write_png16_rgb(path, image):
    """A 16-bit RGB PNG written byte by byte (zlib), as KITTI's devkit writes its flow."""
    height, width, _ = image.shape
    raw = b"".join(b"\x00" + image[r].astype(">u2").tobytes() for r in range(height))

    def chunk(tag, data):
        crc = zlib.crc32(tag + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", crc)

    header = struct.pack(">IIBBBBB", width, height, 16, 2, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(raw))
        + chunk(b"IEND", b"")
    )


# --------------------------------------------------------------------------- KITTI
KITTI_SHAPE = (12, 18)
P2 = [721.5377, 0, 8.3, 44.85728, 0, 721.5377, 5.7, 0.2163791, 0, 0, 1, 0.002745884]
P3 = [721.5377, 0, 8.3, -339.5242, 0, 721.5377, 5.7, 2.199936, 0, 0, 1, 0.002729905]
KITTI_BASELINE = (P2[3] - P3[3]) / P2[0]
KITTI_CALIB = (
    "calib_time: 09-Jan-2012 13:57:47\n"
    "corner_dist: 9.950000e-02\n"
    "S_02: 1.392000e+03 5.120000e+02\n"
    "K_02: 9.597910e+02 0.000000e+00 6.960217e+02 0.000000e+00 9.569251e+02 "
    "2.241806e+02 0.000000e+00 0.000000e+00 1.000000e+00\n"
    "S_rect_02: 1.242000e+03 3.750000e+02\n"
    f"P_rect_02: {' '.join(f'{v:e}' for v in P2)}\n"
    f"P_rect_03: {' '.join(f'{v:e}' for v in P3)}\n"
)


def _write_kitti(root, truth, index=0, kind="occ", with_obj_map=True, with_semantic=False):
    folder = root / "training"
    name = f"{index:06d}_10.png"
    for sub in (f"disp_{kind}_0", f"disp_{kind}_1", f"flow_{kind}", "calib_cam_to_cam"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    (folder / "calib_cam_to_cam" / f"{index:06d}.txt").write_text(KITTI_CALIB)
    for key, sub, invalid in (
        ("disparity", f"disp_{kind}_0", truth["invalid"][0]),
        ("disparity_next", f"disp_{kind}_1", truth["invalid"][1]),
    ):
        encoded = np.round(truth[key] * 256).astype(np.uint16)
        encoded[invalid] = 0
        Image.fromarray(encoded).save(folder / sub / name)
    flow = np.empty(truth["flow"].shape[:2] + (3,), dtype=np.uint16)
    flow[..., :2] = np.round(truth["flow"] * 64 + 2**15).astype(np.uint16)
    flow[..., 2] = ~truth["invalid"][2]
    _write_png16_rgb(folder / f"flow_{kind}" / name, flow)
    if with_obj_map:
        (folder / "obj_map").mkdir(exist_ok=True)
        Image.fromarray(truth["instance"].astype(np.uint8)).save(folder / "obj_map" / name)
    if with_semantic:
        (folder / "semantic").mkdir(exist_ok=True)
        semantic = np.where(truth["instance"] > 0, 26, 7).astype(np.uint8)
        Image.fromarray(semantic).save(folder / "semantic" / name)
    return folder


@pytest.fixture
def kitti_truth():
    f, cx, cy = P2[0], P2[2], P2[6]
    return _ground_truth(*KITTI_SHAPE, f, f, cx, cy, KITTI_BASELINE, seed=0)


@pytest.fixture
def kitti_root(tmp_path, kitti_truth):
    _write_kitti(tmp_path, kitti_truth, with_semantic=True)
    return tmp_path


def _quantisation_bound(points, disparity):
    """Worst-case error of a point back-projected from a disparity stored to 1/256 px.

    A point is proportional to 1 / d, so a disparity error of at most 1/512 moves it by
    at most |p| (1/512) / (d - 1/512).
    """
    return np.linalg.norm(points, axis=1) * (1 / 512) / (disparity - 1 / 512)


def test_kitti_points_and_correspondences(kitti_root, kitti_truth):
    scene = load_kitti_scene_flow(kitti_root, 0)
    truth = kitti_truth
    expected_valid = ~truth["invalid"].any(axis=0)
    np.testing.assert_array_equal(scene.valid_mask, expected_valid)
    n = int(expected_valid.sum())
    assert scene.X.shape == (n, 6) and scene.a.shape == scene.b.shape == (n, 3)
    np.testing.assert_array_equal(scene.X, np.hstack([scene.a, scene.b]))
    np.testing.assert_allclose(scene.flow, scene.b - scene.a)
    # Pixels are (column, row) of the valid pixels, in raster order.
    rows, cols = np.nonzero(expected_valid)
    np.testing.assert_array_equal(scene.pixels, np.column_stack([cols, rows]))
    a_true, b_true = truth["a"][rows, cols], truth["b"][rows, cols]
    f = P2[0]
    # a: only the 1/256 disparity quantisation; b: that plus the 1/64 flow quantisation.
    bound_a = _quantisation_bound(a_true, truth["disparity"][rows, cols])
    flow_bound = np.sqrt(2) * (1 / 128) * b_true[:, 2] / f
    bound_b = _quantisation_bound(b_true, truth["disparity_next"][rows, cols]) + flow_bound
    error_a = np.linalg.norm(scene.a - a_true, axis=1)
    error_b = np.linalg.norm(scene.b - b_true, axis=1)
    assert np.all(error_a <= 2 * bound_a)
    assert np.all(error_b <= 2 * bound_b)
    # The known rigid motion of every object maps a to b up to that quantisation.
    for k, (rotation, translation) in truth["motions"].items():
        mask = scene.instance_labels == k
        assert mask.any()
        predicted = scene.a[mask] @ rotation.T + translation
        residual = np.linalg.norm(predicted - scene.b[mask], axis=1)
        assert np.all(residual <= 2 * (bound_a[mask] + bound_b[mask]))


def test_kitti_decoding_is_exact(kitti_root, kitti_truth):
    """From the stored integers: z = f B / (value / 256), u' = u + (R - 2**15) / 64."""
    scene = load_kitti_scene_flow(kitti_root, 0)
    cols, rows = scene.pixels[:, 0], scene.pixels[:, 1]
    f, cx = P2[0], P2[2]
    stored = np.round(kitti_truth["disparity"] * 256)[rows, cols]
    z = f * KITTI_BASELINE / (stored / 256)
    np.testing.assert_allclose(scene.a[:, 2], z, rtol=1e-12)
    np.testing.assert_allclose(scene.a[:, 0], (cols - cx) * z / f, rtol=1e-12, atol=1e-12)
    stored_flow = np.round(kitti_truth["flow"] * 64 + 2**15)[rows, cols]
    u_next = cols + (stored_flow[:, 0] - 2**15) / 64
    stored_next = np.round(kitti_truth["disparity_next"] * 256)[rows, cols]
    z_next = f * KITTI_BASELINE / (stored_next / 256)
    np.testing.assert_allclose(scene.b[:, 0], (u_next - cx) * z_next / f, rtol=1e-12, atol=1e-12)


def test_kitti_camera_and_maps(kitti_root, kitti_truth):
    scene = load_kitti_scene_flow(kitti_root, 0)
    assert scene.image_shape == KITTI_SHAPE
    np.testing.assert_allclose(scene.K, np.array(P2).reshape(3, 4)[:, :3])
    assert scene.baseline == pytest.approx(KITTI_BASELINE, rel=1e-12)
    assert 0.5 < scene.baseline < 0.6  # KITTI's 54 cm stereo rig
    assert scene.camera.fx == P2[0] and scene.camera.cx == P2[2]
    cols, rows = scene.pixels[:, 0], scene.pixels[:, 1]
    np.testing.assert_array_equal(scene.instance_labels, kitti_truth["instance"][rows, cols])
    np.testing.assert_array_equal(scene.instance_image, kitti_truth["instance"])
    np.testing.assert_array_equal(scene.semantic_labels == 26, scene.instance_labels > 0)
    assert set(scene.files) == {
        "disparity", "disparity_next", "flow", "calibration", "instance", "semantic",
    }  # fmt: skip


def test_kitti_without_object_map(tmp_path, kitti_truth):
    _write_kitti(tmp_path, kitti_truth, with_obj_map=False)
    scene = load_kitti_scene_flow(tmp_path, 0)
    assert scene.instance_labels is None and scene.instance_image is None
    assert scene.semantic_labels is None


def test_kitti_noc_maps(tmp_path, kitti_truth):
    _write_kitti(tmp_path, kitti_truth, index=7, kind="noc")
    with pytest.raises(FileNotFoundError, match="disp_occ_0"):
        load_kitti_scene_flow(tmp_path, 7)
    scene = load_kitti_scene_flow(tmp_path, 7, occluded=False)
    assert len(scene.X) == int((~kitti_truth["invalid"].any(axis=0)).sum())
    assert "000007_10.png" in scene.files["flow"]


def test_kitti_sampling_and_depth_cap(kitti_root):
    full = load_kitti_scene_flow(kitti_root, 0)
    sample = load_kitti_scene_flow(kitti_root, 0, n_points=50, random_state=0)
    again = load_kitti_scene_flow(kitti_root, 0, n_points=50, random_state=0)
    np.testing.assert_array_equal(sample.X, again.X)
    assert sample.X.shape == (50, 6)
    # Every sampled point is the full load's point at the same pixel.
    lookup = {tuple(p): i for i, p in enumerate(full.pixels)}
    rows = [lookup[tuple(p)] for p in sample.pixels]
    np.testing.assert_array_equal(sample.X, full.X[rows])
    with pytest.raises(ValueError, match="exceeds"):
        load_kitti_scene_flow(kitti_root, 0, n_points=10**6)
    max_depth = float(np.median(full.a[:, 2]))
    capped = load_kitti_scene_flow(kitti_root, 0, max_depth=max_depth)
    keep = (full.a[:, 2] <= max_depth) & (full.b[:, 2] <= max_depth)
    np.testing.assert_array_equal(capped.X, full.X[keep])


@pytest.mark.parametrize(
    "missing",
    [
        "disp_occ_0/000000_10.png",
        "disp_occ_1/000000_10.png",
        "flow_occ/000000_10.png",
        "calib_cam_to_cam/000000.txt",
    ],
)
def test_kitti_missing_file_names_it(kitti_root, missing):
    (kitti_root / "training" / missing).unlink()
    with pytest.raises(FileNotFoundError, match=missing):
        load_kitti_scene_flow(kitti_root, 0)


def test_kitti_testing_split_has_no_ground_truth(kitti_root):
    with pytest.raises(FileNotFoundError, match="testing/disp_occ_0/000000_10.png"):
        load_kitti_scene_flow(kitti_root, 0, split="testing")
    with pytest.raises(FileNotFoundError, match="000003_10.png"):
        load_kitti_scene_flow(kitti_root, 3)


def test_kitti_corrupt_and_wrong_files(kitti_root):
    folder = kitti_root / "training"
    flow_path = folder / "flow_occ/000000_10.png"
    good_flow = flow_path.read_bytes()
    flow_path.write_bytes(good_flow[:60])  # truncated
    with pytest.raises(ValueError, match="flow_occ/000000_10.png"):
        load_kitti_scene_flow(kitti_root, 0)
    Image.fromarray(np.zeros((*KITTI_SHAPE, 3), dtype=np.uint8)).save(flow_path)
    with pytest.raises(ValueError, match="flow_occ/000000_10.png.*16-bit 3-channel"):
        load_kitti_scene_flow(kitti_root, 0)
    flow_path.write_bytes(good_flow)
    disp_path = folder / "disp_occ_1/000000_10.png"
    disp_path.write_text("not a png")
    with pytest.raises(ValueError, match="disp_occ_1/000000_10.png.*not a PNG"):
        load_kitti_scene_flow(kitti_root, 0)
    Image.fromarray(np.ones((5, 5), dtype=np.uint16)).save(disp_path)
    with pytest.raises(ValueError, match="disp_occ_1/000000_10.png.*size"):
        load_kitti_scene_flow(kitti_root, 0)
    Image.fromarray(np.ones(KITTI_SHAPE, dtype=np.uint8)).save(disp_path)
    with pytest.raises(ValueError, match="disp_occ_1/000000_10.png.*16-bit grey"):
        load_kitti_scene_flow(kitti_root, 0)


def test_kitti_all_invalid(kitti_root):
    path = kitti_root / "training/disp_occ_0/000000_10.png"
    Image.fromarray(np.zeros(KITTI_SHAPE, dtype=np.uint16)).save(path)
    with pytest.raises(ValueError, match="no pixel has valid ground truth"):
        load_kitti_scene_flow(kitti_root, 0)


def test_kitti_calibration_errors(tmp_path):
    path = tmp_path / "calib.txt"
    path.write_text(KITTI_CALIB.replace("P_rect_03", "P_rect_13"))
    with pytest.raises(ValueError, match="calib.txt.*no P_rect_03"):
        read_kitti_calibration(path)
    path.write_text("P_rect_02: 1 2 3\nP_rect_03: 1 2 3\n")
    with pytest.raises(ValueError, match="calib.txt.*12 finite numbers"):
        read_kitti_calibration(path)
    path.write_text(KITTI_CALIB.replace("P_rect_02: 7", "P_rect_02: x"))
    with pytest.raises(ValueError, match="calib.txt.*not a number"):
        read_kitti_calibration(path)
    swapped = KITTI_CALIB.replace("P_rect_02", "TMP").replace("P_rect_03", "P_rect_02")
    path.write_text(swapped.replace("TMP", "P_rect_03"))
    with pytest.raises(ValueError, match="calib.txt.*baseline"):
        read_kitti_calibration(path)
    path.write_text("P2: " + " ".join(map(str, P2)) + "\nP3: " + " ".join(map(str, P3)))
    K, baseline = read_kitti_calibration(path)
    assert baseline == pytest.approx(KITTI_BASELINE, rel=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "error"),
    [
        ({"index": -1}, ValueError),
        ({"index": 1.0}, TypeError),
        ({"index": True}, TypeError),
        ({"index": 0, "split": "validation"}, ValueError),
        ({"index": 0, "occluded": "yes"}, ValueError),
        ({"index": 0, "n_points": 0}, ValueError),
        ({"index": 0, "max_depth": -1.0}, ValueError),
    ],
)
def test_kitti_bad_options(kitti_root, kwargs, error):
    with pytest.raises(error):
        load_kitti_scene_flow(kitti_root, **kwargs)


def test_png_reader_keeps_16_bits(tmp_path):
    image = np.array([[[0, 1, 65535], [256, 32768, 7]]], dtype=np.uint16)
    _write_png16_rgb(tmp_path / "rgb16.png", image)
    np.testing.assert_array_equal(read_png(tmp_path / "rgb16.png"), image)
    grey = np.array([[0, 1, 65535, 258]], dtype=np.uint16)
    Image.fromarray(grey).save(tmp_path / "grey16.png")
    result = read_png(tmp_path / "grey16.png")
    assert result.dtype == np.uint16
    np.testing.assert_array_equal(result, grey)


def test_png_reader_refuses_damaged_16_bit_colour(tmp_path):
    """Open3D would decode these into zeros with only a printed warning."""
    image = np.arange(2 * 3 * 3, dtype=np.uint16).reshape(2, 3, 3) * 1000
    path = tmp_path / "flow.png"
    _write_png16_rgb(path, image)
    data = bytearray(path.read_bytes())
    data[45] ^= 0xFF  # a byte of the compressed pixels: the chunk's CRC no longer holds
    (tmp_path / "crc.png").write_bytes(bytes(data))
    with pytest.raises(ValueError, match="crc.png.*bad CRC"):
        read_png(tmp_path / "crc.png")
    (tmp_path / "cut.png").write_bytes(path.read_bytes()[:-12])  # no IEND
    with pytest.raises(ValueError, match="cut.png.*truncated"):
        read_png(tmp_path / "cut.png")
    _write_png16_rgb(tmp_path / "short.png", image[:, :2])  # header says 2 columns
    data = bytearray((tmp_path / "short.png").read_bytes())
    data[16:20] = (3).to_bytes(4, "big")  # now it claims 3: the CRC is fixed below
    data[29:33] = zlib.crc32(bytes(data[12:29])).to_bytes(4, "big")
    (tmp_path / "short.png").write_bytes(bytes(data))
    with pytest.raises(ValueError, match="short.png.*incomplete"):
        read_png(tmp_path / "short.png")


def test_png_reader_refuses_damaged_grey_pngs_and_bytes_after_the_end(tmp_path):
    """Pillow ignored what follows IEND and read some damaged grey PNGs without a word."""
    grey = (np.arange(40, dtype=np.uint16).reshape(5, 8) * 1500).astype(np.uint16)
    path = tmp_path / "disparity.png"
    Image.fromarray(grey).save(path)
    good = path.read_bytes()
    (tmp_path / "long.png").write_bytes(good + b"\x00" * 16)
    with pytest.raises(ValueError, match="long.png.*16 bytes follow the IEND chunk"):
        read_png(tmp_path / "long.png")
    data = bytearray(good)
    data[-20] ^= 0x01  # inside the compressed pixels
    (tmp_path / "flip.png").write_bytes(bytes(data))
    with pytest.raises(ValueError, match="flip.png.*corrupt PNG"):
        read_png(tmp_path / "flip.png")
    (tmp_path / "cut.png").write_bytes(good[:30])  # inside IHDR
    with pytest.raises(ValueError, match="cut.png.*corrupt PNG"):
        read_png(tmp_path / "cut.png")


# --------------------------------------------------------------------------- PFM / .flo
@pytest.mark.parametrize("little_endian", [True, False])
@pytest.mark.parametrize("shape", [(4, 5), (4, 5, 3)])
def test_pfm_round_trip(tmp_path, little_endian, shape):
    image = np.random.default_rng(0).normal(size=shape).astype(np.float32)
    image.flat[3] = np.inf  # FlyingThings3D has infinite disparities at infinity
    path = tmp_path / "image.pfm"
    write_pfm(path, image, little_endian=little_endian)
    header = path.read_bytes().split(b"\n")[:3]
    assert header[0] == (b"PF" if len(shape) == 3 else b"Pf")
    assert float(header[2]) == (-1.0 if little_endian else 1.0)
    result = read_pfm(path)
    assert result.dtype == np.float32
    np.testing.assert_array_equal(result, image)


@pytest.mark.parametrize("endian", ["<", ">"])
def test_pfm_rows_are_stored_bottom_to_top(tmp_path, endian):
    """A file written by hand: the first stored row is the bottom row of the image."""
    stored = np.array([[1, 2, 3], [4, 5, 6]], dtype=f"{endian}f4")
    scale = b"-1.0" if endian == "<" else b"1.0"
    path = tmp_path / "hand.pfm"
    path.write_bytes(b"Pf\n3 2\n" + scale + b"\n" + stored.tobytes())
    np.testing.assert_array_equal(read_pfm(path), [[4, 5, 6], [1, 2, 3]])
    path.write_bytes(b"Pf 3 2 " + scale + b"\n" + stored.tobytes())  # one-line header
    np.testing.assert_array_equal(read_pfm(path), [[4, 5, 6], [1, 2, 3]])


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        (b"P6\n3 2\n255\n" + bytes(18), "not a PFM"),
        (b"Pf\nthree 2\n-1.0\n" + bytes(24), "malformed"),
        (b"Pf\n3 2\n0\n" + bytes(24), "malformed"),
        (b"Pf\n3 2\n-1.0\n" + bytes(20), "24 bytes.*20"),
        (b"PF\n3 2\n-1.0\n" + bytes(24), "72 bytes.*24"),
        (b"", "not a PFM"),
    ],
)
def test_corrupt_pfm(tmp_path, content, problem):
    path = tmp_path / "bad.pfm"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=f"bad.pfm.*{problem}"):
        read_pfm(path)


def test_pfm_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="absent.pfm"):
        read_pfm(tmp_path / "absent.pfm")
    with pytest.raises(ValueError, match=r"\(H, W\) or \(H, W, 3\)"):
        write_pfm(tmp_path / "flow.pfm", np.zeros((2, 2, 2)))
    assert list(tmp_path.iterdir()) == []


def test_flo_round_trip_and_errors(tmp_path):
    flow = np.random.default_rng(1).normal(size=(3, 4, 2)).astype(np.float32)
    write_flo(tmp_path / "flow.flo", flow)
    np.testing.assert_array_equal(read_flo(tmp_path / "flow.flo"), flow)
    data = (tmp_path / "flow.flo").read_bytes()
    assert data[:4] == b"PIEH"
    (tmp_path / "cut.flo").write_bytes(data[:-4])
    with pytest.raises(ValueError, match="cut.flo.*corrupt"):
        read_flo(tmp_path / "cut.flo")
    (tmp_path / "magic.flo").write_bytes(b"XXXX" + data[4:])
    with pytest.raises(ValueError, match="magic.flo.*magic"):
        read_flo(tmp_path / "magic.flo")


# --------------------------------------------------------------------------- FlyingThings3D
FT_SHAPE = (10, 14)
FT_FOCAL = 1050.0


@pytest.fixture
def ft_truth():
    height, width = FT_SHAPE
    truth = _ground_truth(
        height, width, FT_FOCAL, FT_FOCAL, (width - 1) / 2, (height - 1) / 2, 1.0, seed=1
    )
    truth["disparity"][truth["invalid"][0]] = np.inf  # the sky: no disparity
    truth["flow"][truth["invalid"][2]] = np.nan
    return truth


def _write_flying_things(root, truth, *, index=5, sign=-1, occlusions=True):
    """The subset's layout and formats (negated disparities, .flo flow)."""
    frame = root / "train"
    name = f"{index:07d}"
    paths = {
        "disparity": frame / "disparity/left" / f"{name}.pfm",
        "disparity_change": frame / "disparity_change/left/into_future" / f"{name}.pfm",
        "flow": frame / "flow/left/into_future" / f"{name}.flo",
        "object_index": frame / "object_index/left" / f"{name}.pfm",
        "flow_occlusions": frame / "flow_occlusions/left/into_future" / f"{name}.png",
    }
    for path in paths.values():
        path.parent.mkdir(parents=True, exist_ok=True)
    change = truth["disparity_next"] - truth["disparity"]
    write_pfm(paths["disparity"], sign * truth["disparity"], little_endian=True)
    write_pfm(paths["disparity_change"], sign * change, little_endian=False)
    write_flo(paths["flow"], truth["flow"])
    write_pfm(paths["object_index"], truth["instance"].astype(np.float32))
    if occlusions:
        occluded = np.where(truth["invalid"][1], 255, 0).astype(np.uint8)
        Image.fromarray(occluded).save(paths["flow_occlusions"])
    else:
        del paths["flow_occlusions"]
    return paths


def _valid_truth(truth):
    return np.isfinite(truth["disparity"]) & np.all(np.isfinite(truth["flow"]), axis=-1)


def test_flying_things_points(tmp_path, ft_truth):
    _write_flying_things(tmp_path, ft_truth)
    scene = load_flying_things(tmp_path, 5)
    valid = _valid_truth(ft_truth)
    np.testing.assert_array_equal(scene.valid_mask, valid)
    rows, cols = np.nonzero(valid)
    np.testing.assert_array_equal(scene.pixels, np.column_stack([cols, rows]))
    # float32 storage: relative precision about 1e-7 per value.
    np.testing.assert_allclose(scene.a, ft_truth["a"][rows, cols], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(scene.b, ft_truth["b"][rows, cols], rtol=1e-5, atol=1e-5)
    np.testing.assert_array_equal(scene.instance_labels, ft_truth["instance"][rows, cols])
    np.testing.assert_array_equal(scene.occluded_mask, ft_truth["invalid"][1][rows, cols])
    assert scene.disparity_sign == -1
    assert scene.image_shape == FT_SHAPE
    assert scene.camera.cx == (FT_SHAPE[1] - 1) / 2 and scene.camera.fx == FT_FOCAL
    for k, (rotation, translation) in ft_truth["motions"].items():
        mask = scene.instance_labels == k
        np.testing.assert_allclose(
            scene.a[mask] @ rotation.T + translation, scene.b[mask], rtol=1e-5, atol=1e-5
        )


def test_flying_things_drop_occluded_and_sampling(tmp_path, ft_truth):
    _write_flying_things(tmp_path, ft_truth)
    full = load_flying_things(tmp_path, 5)
    visible = load_flying_things(tmp_path, 5, drop_occluded=True)
    np.testing.assert_array_equal(visible.X, full.X[~full.occluded_mask])
    assert not visible.occluded_mask.any()
    sample = load_flying_things(tmp_path, 5, n_points=20, random_state=3)
    lookup = {tuple(p): i for i, p in enumerate(full.pixels)}
    np.testing.assert_array_equal(sample.X, full.X[[lookup[tuple(p)] for p in sample.pixels]])


def test_flying_things_full_release_through_paths(tmp_path, ft_truth):
    """Positive disparities and 3-channel PFM flow, files passed explicitly."""
    change = ft_truth["disparity_next"] - ft_truth["disparity"]
    flow3 = np.concatenate([ft_truth["flow"], np.zeros(FT_SHAPE + (1,))], axis=-1)
    paths = {
        "disparity": tmp_path / "0006.pfm",
        "disparity_change": tmp_path / "change_0006.pfm",
        "flow": tmp_path / "OpticalFlowIntoFuture_0006_L.pfm",
    }
    write_pfm(paths["disparity"], ft_truth["disparity"], little_endian=False)
    write_pfm(paths["disparity_change"], change)
    write_pfm(paths["flow"], flow3)
    scene = load_flying_things(None, 6, paths=paths)
    assert scene.disparity_sign == 1
    assert scene.instance_labels is None and scene.occluded_mask is None
    rows, cols = np.nonzero(_valid_truth(ft_truth))
    np.testing.assert_allclose(scene.a, ft_truth["a"][rows, cols], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(scene.b, ft_truth["b"][rows, cols], rtol=1e-5, atol=1e-5)
    # The wrong sign leaves no positive disparity.
    with pytest.raises(ValueError, match="0006.pfm.*no pixel"):
        load_flying_things(None, 6, paths=paths, disparity_sign=-1)


def test_flying_things_pfm_flow_found_in_layout(tmp_path, ft_truth):
    paths = _write_flying_things(tmp_path, ft_truth, occlusions=False)
    flow3 = np.concatenate([ft_truth["flow"], np.zeros(FT_SHAPE + (1,))], axis=-1)
    paths["flow"].unlink()
    write_pfm(paths["flow"].with_suffix(".pfm"), flow3)
    scene = load_flying_things(tmp_path, 5)
    assert scene.files["flow"].endswith("0000005.pfm")
    assert scene.occluded_mask is None


@pytest.mark.parametrize("key", ["disparity", "disparity_change", "flow"])
def test_flying_things_missing_file_names_it(tmp_path, ft_truth, key):
    paths = _write_flying_things(tmp_path, ft_truth)
    paths[key].unlink()
    with pytest.raises(FileNotFoundError, match=str(paths[key].relative_to(tmp_path))):
        load_flying_things(tmp_path, 5)


def test_flying_things_explicit_optional_file_must_exist(tmp_path, ft_truth):
    _write_flying_things(tmp_path, ft_truth)
    with pytest.raises(FileNotFoundError, match="ids.pfm"):
        load_flying_things(tmp_path, 5, paths={"object_index": tmp_path / "ids.pfm"})


def test_flying_things_bad_files(tmp_path, ft_truth):
    paths = _write_flying_things(tmp_path, ft_truth)
    write_pfm(paths["disparity_change"], np.zeros((3, 3)))
    with pytest.raises(ValueError, match="0000005.pfm.*size"):
        load_flying_things(tmp_path, 5)
    paths["disparity"].write_bytes(b"Pf\n14 10\n-1.0\n" + bytes(8))
    with pytest.raises(ValueError, match="disparity/left/0000005.pfm.*corrupt"):
        load_flying_things(tmp_path, 5)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"camera": "centre"},
        {"paths": {"depth": "x.pfm"}},
        {"disparity_sign": 2},
        {"focal_length": 0},
        {"baseline": -1.0},
        {"drop_occluded": 1},
        {"n_points": -5},
    ],
)
def test_flying_things_bad_options(tmp_path, ft_truth, kwargs):
    _write_flying_things(tmp_path, ft_truth)
    with pytest.raises(ValueError):
        load_flying_things(tmp_path, 5, **kwargs)


def test_flying_things_root_none_needs_paths():
    with pytest.raises(ValueError, match="root is None"):
        load_flying_things(None, 0)


# --------------------------------------------------------------------------- alias
def test_load_correspondences_is_read_correspondences(tmp_path):
    assert load_correspondences is read_correspondences
    path = tmp_path / "pairs.npy"
    np.save(path, np.ones((3, 6)))
    np.testing.assert_array_equal(load_correspondences(path), np.ones((3, 6)))
