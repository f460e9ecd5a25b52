"""Corrupt a clean scene flow the way a learned scene-flow network does.

Three corruptions, each of which can be switched off on its own:

1. Gaussian noise whose standard deviation grows with the square of depth (stereo);
2. gross errors, partly in coherent image blobs, partly isolated;
3. bleeding across object boundaries: points near another surface take its flow.
"""

from numbers import Integral, Real

import numpy as np
from scipy.ndimage import distance_transform_edt
from scipy.spatial import cKDTree
from sklearn.utils import Bunch, check_random_state

__all__ = ["corrupt_scene_flow"]

# About this many points per blob of gross errors: the number of blobs is
# round(n_blob_points / _POINTS_PER_BLOB), at least 1.
_POINTS_PER_BLOB = 200
# Nearest blob seeds (in the image) a point is tested against; the blobs are ellipses of
# moderate size, so a point is only ever inside one of its nearest seeds' ellipses.
_CANDIDATE_SEEDS = 8
# Ellipses of the blobs: ratio of the long to the short axis, and relative size.
_BLOB_ASPECT = (1.0, 2.5)
_BLOB_SIZE = (0.5, 1.5)
# Magnitude of a gross error, in units of gross_error_scale.
_GROSS_MAGNITUDE = (0.5, 1.5)
# Deviation of each blob member from its blob's mean offset (across it), relative to it.
_BLOB_SPREAD = 1.0


def _check_real(value, name, *, low=0.0, high=None, allow_none=False):
    """A real number in ``[low, high]`` (``None`` is 0 when allowed)."""
    if value is None and allow_none:
        return 0.0
    if isinstance(value, bool) or not isinstance(value, Real):
        raise TypeError(f"{name} must be a real number; got {value!r} ({type(value).__name__}).")
    value = float(value)
    if not np.isfinite(value) or value < low or (high is not None and value > high):
        bounds = f"[{low}, {high}]" if high is not None else f"[{low}, inf)"
        raise ValueError(f"{name} must be a finite number in {bounds}; got {value!r}.")
    return value


def _check_image_shape(image_shape):
    try:
        height, width = image_shape
    except (TypeError, ValueError):
        raise ValueError(
            f"image_shape must be a pair (height, width); got {image_shape!r}."
        ) from None
    for name, size in (("height", height), ("width", width)):
        if isinstance(size, bool) or not isinstance(size, Integral) or size < 1:
            raise ValueError(f"image_shape {name} must be a positive integer; got {size!r}.")
    return int(height), int(width)


def _check_arrays(points, flow, pixels, instance, image_shape):
    height, width = _check_image_shape(image_shape)
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3); got {points.shape}.")
    n = len(points)
    if points.dtype.kind not in "iuf" or not np.all(np.isfinite(points)):
        raise ValueError("points must be finite real numbers.")
    flow = np.asarray(flow)
    if flow.shape != (n, 3):
        raise ValueError(f"flow must have shape ({n}, 3) like points; got {flow.shape}.")
    if flow.dtype.kind not in "iuf" or not np.all(np.isfinite(flow)):
        raise ValueError("flow must be finite real numbers.")
    pixels = np.asarray(pixels)
    if pixels.shape != (n, 2):
        raise ValueError(f"pixels must have shape ({n}, 2), (row, column); got {pixels.shape}.")
    if pixels.dtype.kind not in "iu":
        raise TypeError(f"pixels must be integer (row, column) indices; got dtype {pixels.dtype}.")
    pixels = pixels.astype(np.intp)
    outside = (
        (pixels[:, 0] < 0) | (pixels[:, 0] >= height) | (pixels[:, 1] < 0) | (pixels[:, 1] >= width)
    )
    if np.any(outside):
        first = np.flatnonzero(outside)[0]
        raise ValueError(
            f"{outside.sum()} pixel(s) lie outside the {height} x {width} image, e.g. "
            f"pixels[{first}] = {pixels[first].tolist()}; pixels are (row, column), not "
            "(column, row)."
        )
    instance = np.asarray(instance)
    if instance.shape != (n,):
        raise ValueError(f"instance must have shape ({n},); got {instance.shape}.")
    if instance.dtype.kind not in "iu":
        raise TypeError(f"instance must hold integer ids; got dtype {instance.dtype}.")
    if n and instance.min() < 0:
        raise ValueError("instance ids must be >= 0.")
    return points, flow, pixels, instance.astype(np.intp), (height, width)


def _blob_members(pixels, n_members, rng):
    """Exactly ``n_members`` point indices forming coherent elliptic blobs in the image.

    Seeds are drawn among the points; every blob is an ellipse around its seed, of random
    orientation, aspect ratio and relative size; all blobs grow together (the same
    normalised radius) until they hold ``n_members`` points. Returns the members and the
    blob of each member.
    """
    n = len(pixels)
    n_blobs = min(n_members, max(1, int(round(n_members / _POINTS_PER_BLOB))))
    seeds = pixels[rng.choice(n, size=n_blobs, replace=False)].astype(float)
    angle = rng.uniform(0.0, np.pi, n_blobs)
    aspect = rng.uniform(*_BLOB_ASPECT, n_blobs)
    size = rng.uniform(*_BLOB_SIZE, n_blobs)
    k = min(n_blobs, _CANDIDATE_SEEDS)
    _, candidates = cKDTree(seeds).query(pixels, k=k)
    candidates = candidates.reshape(n, k)
    offset = pixels[:, np.newaxis, :] - seeds[candidates]  # (n, k, 2)
    cos, sin = np.cos(angle[candidates]), np.sin(angle[candidates])
    along = cos * offset[..., 0] + sin * offset[..., 1]
    across = (-sin * offset[..., 0] + cos * offset[..., 1]) * aspect[candidates]
    radius = np.hypot(along, across) / size[candidates]
    nearest = np.argmin(radius, axis=1)
    radius = radius[np.arange(n), nearest]
    blob = candidates[np.arange(n), nearest]
    # A tiny jitter breaks ties (points at the same normalised radius) at random.
    order = np.argsort(radius + rng.uniform(0.0, 1e-9, n), kind="stable")
    members = order[:n_members]
    return members, blob[members], n_blobs


def _random_offsets(count, scale, rng):
    """``count`` offsets of random direction and magnitude ``scale * U(0.5, 1.5)``."""
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return direction * (scale * rng.uniform(*_GROSS_MAGNITUDE, count))[:, np.newaxis]


def _bleeding_donors(pixels, instance, image_shape, width):
    """For each point, the point whose flow bleeds into it, or -1.

    The instance image is rebuilt from the points (each pixel without a point takes the
    instance of the nearest point, so that a sparse sampling of a rendered image still
    has closed surfaces); a point bleeds when a pixel of another instance lies within
    ``width`` pixels (Euclidean) of its own, and its donor is the point owning the nearest
    such pixel.
    """
    n = len(pixels)
    donors = np.full(n, -1, dtype=np.intp)
    if n == 0 or width < 1 or len(np.unique(instance)) < 2:
        return donors
    height, width_px = image_shape
    owner = np.full(image_shape, -1, dtype=np.intp)
    owner[pixels[:, 0], pixels[:, 1]] = np.arange(n)
    if np.any(owner < 0):
        nearest = distance_transform_edt(owner < 0, return_distances=False, return_indices=True)
        owner = owner[tuple(nearest)]
    surface = instance[owner]
    reach = int(np.floor(width))
    dr, dc = np.mgrid[-reach : reach + 1, -reach : reach + 1]
    dist2 = (dr**2 + dc**2).ravel()
    keep = (dist2 > 0) & (dist2 <= width**2)
    order = np.argsort(dist2[keep], kind="stable")
    offsets = np.column_stack([dr.ravel()[keep], dc.ravel()[keep]])[order]
    undecided = np.ones(n, dtype=bool)
    for row_step, col_step in offsets:  # a few dozen offsets, each vectorised over points
        rows, cols = pixels[:, 0] + row_step, pixels[:, 1] + col_step
        inside = (rows >= 0) & (rows < height) & (cols >= 0) & (cols < width_px)
        rows, cols = np.clip(rows, 0, height - 1), np.clip(cols, 0, width_px - 1)
        hit = undecided & inside & (surface[rows, cols] != instance)
        donors[hit] = owner[rows[hit], cols[hit]]
        undecided &= ~hit
    return donors


def corrupt_scene_flow(
    points,
    flow,
    pixels,
    instance,
    *,
    image_shape,
    noise=0.01,
    noise_depth=5e-5,
    gross_error_fraction=0.1,
    blob_fraction=0.5,
    gross_error_scale=1.0,
    bleeding_width=2.0,
    random_state=None,
):
    """Corrupt a clean scene flow as a learned scene-flow estimator would.

    Three corruptions are applied in this order, each one off when its parameter is 0:

    1. **Depth-dependent Gaussian noise** on every point, isotropic, of standard deviation
       ``sigma_i = noise + noise_depth * z_i**2`` per coordinate (``z_i = points[i, 2]``,
       the depth in metres). This is the stereo error model
       ``dz ~ z**2 * d_disp / (f * B)``; with KITTI's ``f = 721`` px and ``B = 0.54`` m the
       default ``5e-5 * z**2`` is a disparity error ``d_disp`` of 0.02 px (the KITTI
       point-cloud benchmarks below use ground-truth disparity: the network, not the
       stereo, makes most of the error).
    2. **Boundary bleeding**: a point within ``bleeding_width`` pixels of a pixel of
       another instance takes the clean flow of that instance's nearest point (image
       distance), plus its own Gaussian noise, as a network's receptive field smears
       motion across an occlusion boundary.
    3. **Gross errors**: exactly ``round(gross_error_fraction * n)`` points get the
       wrong flow ``clean flow + offset`` (bleeding and noise are discarded for them), the
       offset of random direction and magnitude ``gross_error_scale * U(0.5, 1.5)``.
       ``round(blob_fraction * n_gross)`` of them form coherent elliptic blobs in the
       image (about 200 points per blob) that share one mean offset per blob, each point
       deviating from it across its direction by as much as its size, as a network fails
       on a whole textureless or occluded region (errors correlated over the region, but
       no rigid motion of their own: a blob of one exact offset would be a moving object
       in all but name); the rest are independent points anywhere, each with its own
       offset. Blob errors are thus ``sqrt(2)`` times their blob's offset, at 45 degrees
       to it.

    Parameters
    ----------
    points : array-like of shape (n, 3)
        a-points in the camera frame: x right, y down, z forward (depth), in metres.
    flow : array-like of shape (n, 3)
        Clean scene flow: ``b = points + flow``.
    pixels : array-like of shape (n, 2)
        Integer ``(row, column)`` pixel of each point in the image. Note that
        :class:`~mmreg.init.PrecomputedMasks` takes ``(column, row)``:
        pass ``pixels[:, ::-1]`` there.
    instance : array-like of shape (n,)
        Surface (instance) id of each point, ``>= 0``.
    image_shape : tuple of int
        ``(height, width)`` of the image.
    noise : float, default=0.01
        Standard deviation of the Gaussian noise at depth 0, in metres, per coordinate.
    noise_depth : float, default=5e-5
        Growth of the standard deviation with the square of depth, in 1/m: the standard
        deviation is ``noise + noise_depth * z**2`` (0.015 m at 10 m, 0.03 m at 20 m,
        0.09 m at 40 m with the defaults).
    gross_error_fraction : float, default=0.1
        Fraction of points with a gross error, in ``[0, 1]``.
    blob_fraction : float, default=0.5
        Fraction of the gross errors that lie in coherent image blobs, in ``[0, 1]``.
    gross_error_scale : float, default=1.0
        Typical size of a gross error, in metres (magnitudes are uniform in
        ``[0.5, 1.5]`` times it); about the per-frame flow of a car at 10 Hz.
    bleeding_width : float or None, default=2.0
        Image distance, in pixels, up to which a point takes the flow of a neighbouring
        surface; 0 or None: no bleeding.
    random_state : int, RandomState instance or None, default=None
        Seeds every random choice (noise, blob seeds and shapes, gross errors).

    Returns
    -------
    corrupted : sklearn.utils.Bunch
        ``flow`` (n, 3) the corrupted flow; ``outlier_mask`` (n,) bool, the gross
        errors; ``bled_mask`` (n,) bool, points (not gross errors) whose flow was replaced
        by a different one of a neighbouring surface; ``noise_sigma`` (n,) the standard
        deviation of the Gaussian noise of each point.

    Notes
    -----
    The defaults sit between published errors of learned scene-flow methods on KITTI
    Scene Flow 2015 (HPLFlowNet's preprocessing: 142 scenes, points within 35 m), where
    EPE3D is the mean end-point error in metres and Outliers3D the fraction of points
    with an error above 0.3 m or 10 % of the flow:

    - FlowNet3D (Liu et al., CVPR 2019), as evaluated in PointPWC-Net Table 1 (Wu et
      al., ECCV 2020): EPE3D 0.177 m, Outliers3D 52.7 %;
    - HPLFlowNet (Gu et al., CVPR 2019), same table: EPE3D 0.117 m, Outliers3D 41.0 %;
    - PointPWC-Net, same table: EPE3D 0.069 m, Outliers3D 26.5 %;
    - RCP (Gu et al., CVPR 2022), its released model: EPE3D 0.048 m, Outliers3D 12.3 %.

    RAFT-3D (Teed & Deng, CVPR 2021) and CamLiFlow (Liu et al., CVPR 2022) are scored
    on the KITTI benchmark by the fraction of wrong pixels instead (SF-all 5.77 % and
    4.43 %): errors on a few per cent of the pixels, in compact regions.

    With the defaults, a street scene 5-35 m deep has a mean Gaussian end-point error of
    ``1.6 * sigma`` (0.02-0.12 m) and 10 % gross errors of about 1 m: a mean EPE3D of
    about 0.15 m, between FlowNet3D and HPLFlowNet, and 11 % of points off by more than
    0.3 m, at the level of RCP's Outliers3D. A scene of FlyingThings-like depth (a few metres) is
    dominated by the gross errors. The stereo baseline in the model above is KITTI's
    (Geiger et al., CVPR 2012).

    Cost: ``O(n log n)`` for the blobs, ``O(H W)`` for rebuilding the instance image
    (only when ``bleeding_width > 0``), ``O(n bleeding_width**2)`` for the bleeding.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.datasets._flow_noise import corrupt_scene_flow
    >>> rows, cols = np.mgrid[:20, :30]
    >>> pixels = np.column_stack([rows.ravel(), cols.ravel()])
    >>> instance = (pixels[:, 1] >= 15).astype(int)   # two surfaces, left and right
    >>> points = np.column_stack([pixels[:, ::-1] * 0.1, np.full(600, 5.0)])
    >>> flow = np.where(instance[:, None] == 1, [1.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    >>> out = corrupt_scene_flow(points, flow, pixels, instance, image_shape=(20, 30),
    ...                          random_state=0)
    >>> out.flow.shape, int(out.outlier_mask.sum()), int(out.bled_mask.sum()) > 0
    ((600, 3), 60, True)
    >>> off = corrupt_scene_flow(points, flow, pixels, instance, image_shape=(20, 30),
    ...                          noise=0, noise_depth=0, gross_error_fraction=0,
    ...                          bleeding_width=0)
    >>> bool(np.array_equal(off.flow, flow))
    True
    """
    points, flow, pixels, instance, image_shape = _check_arrays(
        points, flow, pixels, instance, image_shape
    )
    noise = _check_real(noise, "noise")
    noise_depth = _check_real(noise_depth, "noise_depth")
    gross_error_fraction = _check_real(gross_error_fraction, "gross_error_fraction", high=1.0)
    blob_fraction = _check_real(blob_fraction, "blob_fraction", high=1.0)
    gross_error_scale = _check_real(gross_error_scale, "gross_error_scale")
    if gross_error_fraction > 0 and gross_error_scale == 0:
        raise ValueError("gross_error_scale must be > 0 when gross_error_fraction > 0; got 0.")
    bleeding_width = _check_real(bleeding_width, "bleeding_width", allow_none=True)
    rng = check_random_state(random_state)

    n = len(points)
    clean = flow.astype(float) if flow.dtype.kind != "f" else flow
    corrupted = np.array(clean, copy=True)
    outlier_mask = np.zeros(n, dtype=bool)
    bled_mask = np.zeros(n, dtype=bool)

    # 1. Gaussian noise, sigma = s0 + s1 z^2 (skipped entirely when off: bit for bit).
    noise_sigma = noise + noise_depth * points[:, 2].astype(float) ** 2
    gaussian = None
    if n and np.any(noise_sigma > 0):
        gaussian = rng.normal(size=(n, 3)) * noise_sigma[:, np.newaxis]
        corrupted += gaussian

    # 2. Bleeding across instance boundaries in the image.
    if bleeding_width > 0:
        donors = _bleeding_donors(pixels, instance, image_shape, bleeding_width)
        candidates = np.flatnonzero(donors >= 0)
        changed = np.any(clean[donors[candidates]] != clean[candidates], axis=1)
        bled = candidates[changed]
        corrupted[bled] = clean[donors[bled]]
        if gaussian is not None:
            corrupted[bled] += gaussian[bled]
        bled_mask[bled] = True

    # 3. Gross errors: blobs first, then independent points among the rest.
    n_gross = int(round(gross_error_fraction * n))
    if n_gross:
        n_blob = int(round(blob_fraction * n_gross))
        offsets = np.empty((n_gross, 3))
        gross = np.empty(n_gross, dtype=np.intp)
        if n_blob:
            members, blob, n_blobs = _blob_members(pixels, n_blob, rng)
            gross[:n_blob] = members
            # One mean offset per blob, and each member its own deviation of half that
            # size: correlated like a network's failure on a region, but no rigid motion
            # (a blob of one exact offset would be a moving object in all but name).
            offsets[:n_blob] = _random_offsets(n_blobs, gross_error_scale, rng)[blob]
            # Deviation across the mean offset, as large as it: never a smaller error.
            mean = offsets[:n_blob]
            deviation = rng.normal(size=(n_blob, 3))
            deviation -= (
                np.sum(deviation * mean, axis=1, keepdims=True)
                / np.sum(mean * mean, axis=1, keepdims=True)
                * mean
            )
            deviation /= np.linalg.norm(deviation, axis=1, keepdims=True)
            size = _BLOB_SPREAD * np.linalg.norm(mean, axis=1, keepdims=True)
            offsets[:n_blob] = mean + size * deviation
        rest = np.setdiff1d(np.arange(n), gross[:n_blob], assume_unique=True)
        gross[n_blob:] = rng.choice(rest, size=n_gross - n_blob, replace=False)
        offsets[n_blob:] = _random_offsets(n_gross - n_blob, gross_error_scale, rng)
        corrupted[gross] = clean[gross] + offsets
        outlier_mask[gross] = True
        bled_mask &= ~outlier_mask

    return Bunch(
        flow=corrupted,
        outlier_mask=outlier_mask,
        bled_mask=bled_mask,
        noise_sigma=noise_sigma,
    )
