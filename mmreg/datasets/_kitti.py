"""KITTI Scene Flow 2015: correspondences from ground-truth disparity and optical flow.

The KITTI Scene Flow 2015 benchmark (Menze and Geiger, CVPR 2015) gives, for 200 training
pairs of rectified stereo frames, the disparity of the first frame, the disparity of the
second frame warped to the first frame's pixels and the optical flow, all as 16-bit PNGs.
Each valid pixel thus yields a 3-D point ``a`` at time ``t`` and its position ``b`` at
``t + 1``, both in the (moving) left colour camera's frame: the correspondences of the
paper's KITTI experiment with ground-truth flow in place of a network's.

The development kit's conventions (its readme and ``io_disp.h`` / ``io_flow.h``), which
this module follows:

- ``disp_occ_0/{index:06d}_10.png``: disparity of frame 1 as a 16-bit grey PNG,
  ``d = value / 256``; ``value = 0`` marks a pixel without ground truth.
- ``disp_occ_1/{index:06d}_10.png``: disparity of the same scene point in frame 2, stored
  at its frame-1 pixel, same encoding.
- ``flow_occ/{index:06d}_10.png``: optical flow as a 16-bit 3-channel PNG with channels
  in file order (R, G, B) = (u, v, valid): ``u = (R - 2**15) / 64``,
  ``v = (G - 2**15) / 64``, ground truth where ``B > 0``.
- ``obj_map/{index:06d}_10.png``: 8-bit object map, 0 = background, ``k > 0`` = the k-th
  moving vehicle (training only).
- ``calib_cam_to_cam/{index:06d}.txt`` (from the calibration archive): lines
  ``name: numbers``; ``P_rect_02`` and ``P_rect_03`` are the 3x4 projection matrices of
  the rectified left and right colour cameras, ``P_rect_0x = K [I | t_x]`` with the same
  ``K``; the stereo baseline is ``(P_rect_02[0, 3] - P_rect_03[0, 3]) / f``.
- ``*_noc*`` instead of ``*_occ*``: the same maps restricted to pixels visible in both
  frames.
- Pixels are ``(column, row) = (u, v)``; the camera frame has x right, y down, z forward.

A disparity ``d`` at pixel ``(u, v)`` back-projects to depth ``z = f B / d`` and the point
``z K^-1 [u, v, 1]``; the frame-2 point is the back-projection of the flowed pixel
``(u + flow_u, v + flow_v)`` at depth ``f B / d_1``.

Pillow reads 16-bit grey PNGs exactly but reduces 16-bit colour PNGs to 8 bits, so the
flow maps are read with Open3D (a dependency already), which keeps all 16 bits.
"""

import io
import numbers
import struct
import zlib
from pathlib import Path

import numpy as np
from sklearn.utils import Bunch, check_random_state

from mmreg.datasets._camera import back_project, pinhole_camera, sample_pixels
from mmreg.io._checks import _check_readable

__all__ = ["load_kitti_scene_flow"]

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_SPLITS = ("training", "testing")


# --------------------------------------------------------------------------- file readers
def _check_png_integrity(data, path, what):
    """ValueError naming ``path`` unless the PNG bytes ``data`` are whole and undamaged.

    Walks the chunks from ``IHDR`` to ``IEND`` checking every CRC-32, requires that
    nothing follows ``IEND``, inflates the ``IDAT`` stream (whose Adler-32 zlib checks)
    and requires that it ends exactly, holding ``height * (1 + row bytes)`` bytes (one
    filter byte per row) for a non-interlaced image. PNG checksums every byte, so a
    truncated file, bytes appended and any changed byte are all detected.
    """
    pos, idat, header, ended = len(_PNG_SIGNATURE), [], None, False
    while pos + 12 <= len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        tag = data[pos + 4 : pos + 8]
        body = data[pos + 8 : pos + 8 + length]
        crc = data[pos + 8 + length : pos + 12 + length]
        if len(body) != length or len(crc) != 4:
            break
        if struct.unpack(">I", crc)[0] != zlib.crc32(tag + body) & 0xFFFFFFFF:
            raise ValueError(f"{path}: corrupt PNG ({what}): bad CRC in chunk {tag!r}.")
        if header is None:
            if tag != b"IHDR" or length != 13:
                raise ValueError(f"{path}: corrupt PNG ({what}): no IHDR chunk first.")
            header = struct.unpack(">IIBBBBB", body)
        elif tag == b"IDAT":
            idat.append(body)
        pos += 12 + length
        if tag == b"IEND":
            ended = True
            break
    if not ended or header is None:
        raise ValueError(f"{path}: corrupt PNG ({what}): truncated (no IEND chunk).")
    if pos != len(data):
        raise ValueError(
            f"{path}: corrupt PNG ({what}): {len(data) - pos:,} bytes follow the IEND chunk."
        )
    width, height, bit_depth, color_type, _, _, interlace = header
    channels = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}.get(color_type)
    if channels is None or bit_depth not in (1, 2, 4, 8, 16) or width < 1 or height < 1:
        raise ValueError(f"{path}: corrupt PNG ({what}): invalid IHDR chunk.")
    try:
        inflater = zlib.decompressobj()
        pixels = inflater.decompress(b"".join(idat)) + inflater.flush()
    except zlib.error as exc:
        raise ValueError(f"{path}: corrupt PNG ({what}): {exc}") from exc
    row_bytes = (width * channels * bit_depth + 7) // 8
    expected = height * (1 + row_bytes)
    if not inflater.eof or inflater.unused_data or (interlace == 0 and len(pixels) != expected):
        raise ValueError(
            f"{path}: corrupt PNG ({what}): the pixel data are incomplete or too long "
            f"({len(pixels)} of {expected} bytes)."
        )


def read_png(path, what="image"):
    """Read a PNG as an integer array, keeping 16 bits per channel.

    8-bit and 16-bit grey images (and 8-bit colour and palette images) are read with
    Pillow; 16-bit colour images, which Pillow reduces to 8 bits, with Open3D.

    Parameters
    ----------
    path : str or path-like
    what : str
        What the file is, for the error messages.

    Returns
    -------
    image : ndarray of shape (H, W) or (H, W, C)
        uint8 or uint16 (palette images: the palette indices).

    Raises
    ------
    FileNotFoundError
        If the file is missing.
    ValueError
        If it is not a PNG file or is corrupt.
    """
    path = _check_readable(path, what)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ValueError(f"{path}: cannot be read ({what}): {exc}") from exc
    head = data[:26]
    if len(head) < 26 or not head.startswith(_PNG_SIGNATURE) or head[12:16] != b"IHDR":
        raise ValueError(f"{path}: is not a PNG file ({what}).")
    # Decoders fill a damaged file with zeros (Open3D, with only a printed warning) or
    # ignore what follows the image: check every checksum first.
    _check_png_integrity(data, path, what)
    bit_depth, color_type = head[24], head[25]
    if bit_depth == 16 and color_type in (2, 6):  # 16-bit RGB / RGBA
        import open3d as o3d

        image = np.asarray(o3d.io.read_image(str(path)))
        if image.size == 0 or image.dtype != np.uint16:
            raise ValueError(f"{path}: corrupt 16-bit colour PNG ({what}).")
        return np.array(image)
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as image:
            image.load()
            array = np.array(image)
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError, zlib.error) as exc:
        raise ValueError(f"{path}: corrupt PNG ({what}): {exc}") from exc
    if bit_depth == 16 and array.dtype != np.uint16:
        array = array.astype(np.uint16)  # mode "I" (int32) holding 16-bit values
    return array


def read_kitti_calibration(path):
    """Intrinsics ``K`` and stereo baseline from a KITTI ``calib_cam_to_cam`` file.

    Parameters
    ----------
    path : str or path-like
        A text file with lines ``name: numbers``, holding ``P_rect_02`` and ``P_rect_03``
        (or ``P2`` and ``P3``, the object benchmark's names), twelve numbers each.

    Returns
    -------
    K : ndarray of shape (3, 3)
        Intrinsics of the rectified left colour camera.
    baseline : float
        Distance between the rectified colour cameras, in metres.

    Raises
    ------
    FileNotFoundError
        If the file is missing.
    ValueError
        If a matrix is missing or malformed or the baseline is not positive.
    """
    path = _check_readable(path, "calibration")
    entries = {}
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: is not a text calibration file: {exc}") from exc
    for line in text.splitlines():
        name, sep, values = line.partition(":")
        if sep:
            entries[name.strip()] = values.split()
    matrices = []
    for names in (("P_rect_02", "P2"), ("P_rect_03", "P3")):
        name = next((n for n in names if n in entries), None)
        if name is None:
            raise ValueError(f"{path}: no {names[0]} line in the calibration file.")
        try:
            matrix = np.array([float(v) for v in entries[name]])
        except ValueError:
            raise ValueError(f"{path}: {name} holds a value that is not a number.") from None
        if matrix.shape != (12,) or not np.all(np.isfinite(matrix)):
            raise ValueError(
                f"{path}: {name} must hold 12 finite numbers (a 3x4 matrix); got {len(matrix)}."
            )
        matrices.append(matrix.reshape(3, 4))
    left, right = matrices
    K = left[:, :3].copy()
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(f"{path}: the focal lengths of P_rect_02 must be positive.")
    baseline = float((left[0, 3] - right[0, 3]) / K[0, 0])
    if baseline <= 0:
        raise ValueError(
            f"{path}: the baseline (P_rect_02[0, 3] - P_rect_03[0, 3]) / f = {baseline} "
            "must be positive (the right camera lies to the right of the left one)."
        )
    return K, baseline


# --------------------------------------------------------------------------- assembly
def check_index(index, width):
    """``index`` as an int that fits a zero-padded file name of ``width`` digits."""
    if isinstance(index, (bool, np.bool_)) or not isinstance(index, numbers.Integral):
        raise TypeError(f"index must be a non-negative integer; got {index!r}.")
    if index < 0 or index >= 10**width:
        raise ValueError(f"index must lie in [0, {10**width}); got {index}.")
    return int(index)


def check_options(n_points, max_depth):
    """Validate the sampling options shared by the real-data loaders."""
    if n_points is not None and (
        isinstance(n_points, (bool, np.bool_))
        or not isinstance(n_points, numbers.Integral)
        or n_points < 1
    ):
        raise ValueError(f"n_points must be None or a positive integer; got {n_points!r}.")
    if max_depth is not None and not (
        isinstance(max_depth, numbers.Real) and not isinstance(max_depth, bool) and max_depth > 0
    ):
        raise ValueError(f"max_depth must be None or a positive number; got {max_depth!r}.")


def check_same_shape(images):
    """All ``{path: image}`` share one (H, W); ValueError naming two that differ."""
    items = [(p, im) for p, im in images.items() if im is not None]
    first_path, first = items[0]
    for path, image in items[1:]:
        if image.shape[:2] != first.shape[:2]:
            raise ValueError(
                f"{path}: image of size {image.shape[:2]} but {first_path} has size "
                f"{first.shape[:2]}; the maps of one frame must have the same size."
            )
    return first.shape[:2]


def stereo_correspondences(
    disparity, disparity_next, flow, valid, camera, baseline, *, n_points, max_depth, rng
):
    """Back-project stereo ground truth to correspondences.

    Parameters
    ----------
    disparity, disparity_next : ndarray of shape (H, W)
        Disparity (pixels) of every pixel's scene point in frame 1 and in frame 2.
    flow : ndarray of shape (H, W, 2)
        Optical flow ``(u, v)`` from frame 1 to frame 2.
    valid : ndarray of bool, shape (H, W)
        Pixels with ground truth; positive disparities are further required.
    camera : Bunch
        From :func:`~mmreg.datasets._camera.pinhole_camera`.
    baseline : float
    n_points : int or None
        Sample this many valid pixels uniformly (all when None).
    max_depth : float or None
        Drop pixels whose point is deeper than this in either frame.
    rng : RandomState

    Returns
    -------
    a, b : ndarray of shape (n, 3)
    pixels : ndarray of shape (n, 2)
        ``(column, row)`` of every point, in raster order.
    valid : ndarray of bool, shape (H, W)
        The pixels that yield a point (before sampling).
    """
    focal_baseline = camera.fx * baseline
    with np.errstate(divide="ignore", invalid="ignore"):
        valid = (
            valid
            & np.isfinite(disparity)
            & np.isfinite(disparity_next)
            & np.all(np.isfinite(flow), axis=-1)
            & (disparity > 0)
            & (disparity_next > 0)
        )
        if max_depth is not None:
            valid &= (focal_baseline / disparity <= max_depth) & (
                focal_baseline / disparity_next <= max_depth
            )
    if n_points is None:
        rows, cols = np.nonzero(valid)
        pixels = np.column_stack([cols, rows]).astype(np.intp)
    else:
        pixels = sample_pixels(valid, n_points, rng)
        cols, rows = pixels[:, 0], pixels[:, 1]
    if len(pixels) == 0:
        raise ValueError("no pixel has valid ground truth (disparities and flow).")
    z = focal_baseline / disparity[rows, cols].astype(float)
    z_next = focal_baseline / disparity_next[rows, cols].astype(float)
    flowed = pixels + flow[rows, cols].astype(float)
    return back_project(z, pixels, camera), back_project(z_next, flowed, camera), pixels, valid


# --------------------------------------------------------------------------- loader
def load_kitti_scene_flow(
    root,
    index,
    *,
    split="training",
    occluded=True,
    n_points=None,
    max_depth=None,
    random_state=None,
):
    """Load one KITTI Scene Flow 2015 frame pair as 3-D correspondences.

    Every pixel with ground-truth disparity in both frames and ground-truth optical flow
    gives a correspondence: ``a`` back-projected from the first disparity map, ``b`` from
    the second one at the flowed pixel (see the module notes for the file formats).

    Parameters
    ----------
    root : str or path-like
        The folder holding ``training/`` (and ``testing/``) of the scene flow archive,
        with the calibration archive unpacked into the same folders
        (``training/calib_cam_to_cam/``).
    index : int
        Frame pair, 0 to 199: files ``{index:06d}_10.png``.
    split : {"training", "testing"}, default="training"
        Only the training split has ground truth; ``"testing"`` fails on the first
        missing map.
    occluded : bool, default=True
        Read the ``*_occ`` maps (every pixel with ground truth); ``False`` reads the
        ``*_noc`` maps (only pixels visible in both frames).
    n_points : int, optional
        Sample this many valid pixels uniformly without replacement (the paper uses
        32,768); all valid pixels when None.
    max_depth : float, optional
        Drop points deeper than this (metres) in either frame (35 m is customary).
    random_state : int, RandomState instance or None
        Seed of the sampling.

    Returns
    -------
    scene : sklearn.utils.Bunch
        X : ndarray of shape (n, 6)
            ``[a | b]``.
        a, b : ndarray of shape (n, 3)
            Points in frames 1 and 2, in the left colour camera's frame (metres).
        flow : ndarray of shape (n, 3)
            ``b - a``.
        pixels : ndarray of shape (n, 2)
            ``(column, row)`` of every point in frame 1, in raster order.
        instance_labels : ndarray of shape (n,) or None
            The object map at every point (0 = background, ``k`` = k-th moving vehicle),
            None without ``obj_map/``.
        semantic_labels : ndarray of shape (n,) or None
            Cityscapes label ids (26 = car) from ``semantic/{index:06d}_10.png`` of the
            KITTI semantics archive when it is unpacked beside the maps, else None.
        instance_image, semantic_image : ndarray of shape (H, W) or None
            The full maps.
        valid_mask : ndarray of bool, shape (H, W)
            Pixels that yield a point (before sampling).
        image_shape : tuple of int
            ``(H, W)``.
        K : ndarray of shape (3, 3)
            Intrinsics of the rectified left colour camera.
        baseline : float
            Stereo baseline (metres).
        camera : Bunch
            The same intrinsics as :func:`~mmreg.datasets._camera.pinhole_camera` gives.
        files : dict
            The path of every file read.

    Raises
    ------
    FileNotFoundError
        If a map or the calibration file is missing (the error names it).
    ValueError
        If a file is corrupt or of the wrong kind, the maps differ in size, no pixel is
        valid, or ``n_points`` exceeds the valid pixels.

    See Also
    --------
    load_flying_things : The same from FlyingThings3D's disparity and flow.
    mmreg.datasets.make_street : A rendered street scene of the same kind.

    Notes
    -----
    The point ``b`` is in the camera frame at ``t + 1``, so the background's motion is the
    inverse of the car's ego-motion. Quantisation: disparities are stored to 1/256 px and
    flow to 1/64 px, so a point at depth ``z`` is known to about
    ``z**2 / (2 * 256 * f * B)`` in depth. Cost: ``O(H W)`` for one frame pair.

    References
    ----------
    M. Menze and A. Geiger, "Object Scene Flow for Autonomous Vehicles", CVPR 2015.

    Examples
    --------
    A tiny frame written in KITTI's formats (a flat wall 10 m away, moving 0.5 m right):

    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from PIL import Image
    >>> import open3d as o3d
    >>> from mmreg.datasets import load_kitti_scene_flow
    >>> f, baseline, (h, w) = 700.0, 0.5, (4, 6)
    >>> calib = "".join(
    ...     f"P_rect_0{cam}: {f} 0 3 {-f * x} 0 {f} 2 0 0 0 1 0\\n" for cam, x in ((2, 0), (3, 0.5))
    ... )
    >>> disparity = np.full((h, w), round(f * baseline / 10 * 256), dtype=np.uint16)
    >>> flow = np.zeros((h, w, 3), dtype=np.uint16)
    >>> flow[..., 0], flow[..., 1], flow[..., 2] = 2**15 + 35 * 64, 2**15, 1
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     for name in ("disp_occ_0", "disp_occ_1", "flow_occ", "calib_cam_to_cam"):
    ...         (Path(folder) / "training" / name).mkdir(parents=True)
    ...     _ = (Path(folder) / "training/calib_cam_to_cam/000000.txt").write_text(calib)
    ...     for name in ("disp_occ_0", "disp_occ_1"):
    ...         Image.fromarray(disparity).save(Path(folder) / "training" / name / "000000_10.png")
    ...     _ = o3d.io.write_image(
    ...         str(Path(folder) / "training/flow_occ/000000_10.png"), o3d.geometry.Image(flow)
    ...     )
    ...     scene = load_kitti_scene_flow(folder, 0)
    >>> scene.X.shape, scene.baseline, np.round(scene.flow[0], 6).tolist()
    ((24, 6), 0.5, [0.5, 0.0, 0.0])
    """
    index = check_index(index, 6)
    if split not in _SPLITS:
        raise ValueError(f"split must be one of {_SPLITS}; got {split!r}.")
    if not isinstance(occluded, (bool, np.bool_)):
        raise ValueError(f"occluded must be True or False; got {occluded!r}.")
    check_options(n_points, max_depth)
    rng = check_random_state(random_state)
    folder = Path(root) / split
    kind = "occ" if occluded else "noc"
    name = f"{index:06d}_10.png"
    files = {
        "disparity": folder / f"disp_{kind}_0" / name,
        "disparity_next": folder / f"disp_{kind}_1" / name,
        "flow": folder / f"flow_{kind}" / name,
        "calibration": folder / "calib_cam_to_cam" / f"{index:06d}.txt",
    }
    optional = {"instance": folder / "obj_map" / name, "semantic": folder / "semantic" / name}

    disparity_png = read_png(files["disparity"], "disparity of frame 1")
    disparity_next_png = read_png(files["disparity_next"], "disparity of frame 2")
    flow_png = read_png(files["flow"], "optical flow")
    for path, image, what in (
        (files["disparity"], disparity_png, "disparity"),
        (files["disparity_next"], disparity_next_png, "disparity"),
    ):
        if image.ndim != 2 or image.dtype != np.uint16:
            raise ValueError(
                f"{path}: a KITTI {what} map must be a 16-bit grey PNG; got shape "
                f"{image.shape} of {image.dtype}."
            )
    if flow_png.ndim != 3 or flow_png.shape[2] < 3 or flow_png.dtype != np.uint16:
        raise ValueError(
            f"{files['flow']}: a KITTI flow map must be a 16-bit 3-channel PNG (u, v, valid); "
            f"got shape {flow_png.shape} of {flow_png.dtype}."
        )
    K, baseline = read_kitti_calibration(files["calibration"])
    extra = {}
    for key, path in optional.items():
        if path.exists():
            image = read_png(path, f"{key} map")
            if image.ndim != 2:
                raise ValueError(f"{path}: the {key} map must be a grey PNG; got {image.shape}.")
            extra[key] = image.astype(np.intp)
            files[key] = path
        else:
            extra[key] = None
    image_shape = check_same_shape(
        {
            files["disparity"]: disparity_png,
            files["disparity_next"]: disparity_next_png,
            files["flow"]: flow_png,
            **{files[k]: v for k, v in extra.items() if v is not None},
        }
    )

    disparity = disparity_png / 256.0
    disparity_next = disparity_next_png / 256.0
    flow = (flow_png[..., :2].astype(float) - 2.0**15) / 64.0
    valid = (disparity_png > 0) & (disparity_next_png > 0) & (flow_png[..., 2] > 0)
    camera = pinhole_camera(
        int(image_shape[1]), int(image_shape[0]), K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    )
    try:
        a, b, pixels, valid = stereo_correspondences(
            disparity,
            disparity_next,
            flow,
            valid,
            camera,
            baseline,
            n_points=n_points,
            max_depth=max_depth,
            rng=rng,
        )
    except ValueError as exc:
        raise ValueError(f"{files['disparity']}: {exc}") from exc
    cols, rows = pixels[:, 0], pixels[:, 1]
    per_point = {k: (None if image is None else image[rows, cols]) for k, image in extra.items()}
    return Bunch(
        X=np.hstack([a, b]),
        a=a,
        b=b,
        flow=b - a,
        pixels=pixels,
        instance_labels=per_point["instance"],
        semantic_labels=per_point["semantic"],
        instance_image=extra["instance"],
        semantic_image=extra["semantic"],
        valid_mask=valid,
        image_shape=tuple(int(s) for s in image_shape),
        K=K,
        baseline=baseline,
        camera=camera,
        files={k: str(v) for k, v in files.items()},
    )
