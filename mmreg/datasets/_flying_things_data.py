"""FlyingThings3D: correspondences from the data set's disparity, disparity change and flow.

FlyingThings3D (Mayer et al., CVPR 2016) renders ShapeNet objects flying along random
trajectories in front of a stereo camera, with exact disparity, disparity change and
optical flow; the paper (Section V) back-projects its disparity maps to point clouds.
This module reads the "DispNet/FlowNet2.0 subset" release, whose layout is::

    root/{train,val}/disparity/left/0000000.pfm
    root/{train,val}/disparity_change/left/into_future/0000000.pfm
    root/{train,val}/flow/left/into_future/0000000.flo
    root/{train,val}/flow_occlusions/left/into_future/0000000.png      (optional)
    root/{train,val}/disparity_occlusions/left/0000000.png             (optional)
    root/{train,val}/object_index/left/0000000.pfm                     (optional)

(the subset ships no object index; the full release's ``object_index`` PFMs can be placed
there or passed through ``paths``). Any file can be given explicitly with ``paths``, which
also reads the full release (``disparity/TRAIN/A/0000/left/0006.pfm``, optical flow as
3-channel PFM ``optical_flow/.../OpticalFlowIntoFuture_0006_L.pfm``, of which the first two
channels are the flow).

Conventions of the data set: focal length 1050 px, baseline 1.0 (scene units), principal
point at the centre of the 960 x 540 images. Disparity ``d`` gives depth ``1050 / d``;
``d + disparity_change`` is the same scene point's disparity in the next frame, seen at the
flowed pixel ``(u + flow_u, v + flow_v)``. The full release stores positive disparities,
the subset stores them negated; ``disparity_sign="auto"`` reads either.
"""

import numbers
from pathlib import Path

import numpy as np
from sklearn.utils import Bunch, check_random_state

from mmreg.datasets._camera import pinhole_camera
from mmreg.datasets._kitti import (
    check_index,
    check_options,
    check_same_shape,
    read_png,
    stereo_correspondences,
)
from mmreg.datasets._pfm import read_flo, read_pfm

__all__ = ["FLYING_THINGS_FILES", "load_flying_things"]

#: Files of one frame in the subset layout, relative to ``root/split``; ``{camera}`` and
#: ``{index}`` (7 digits) are filled in. Optional files may be absent.
FLYING_THINGS_FILES = {
    "disparity": "disparity/{camera}/{index}.pfm",
    "disparity_change": "disparity_change/{camera}/into_future/{index}.pfm",
    "flow": "flow/{camera}/into_future/{index}.flo",
    "flow_occlusions": "flow_occlusions/{camera}/into_future/{index}.png",
    "disparity_occlusions": "disparity_occlusions/{camera}/{index}.png",
    "object_index": "object_index/{camera}/{index}.pfm",
}
_REQUIRED = ("disparity", "disparity_change", "flow")
_FOCAL, _BASELINE = 1050.0, 1.0


def _read_map(path, what):
    """A float (H, W) or (H, W, C) array from a ``.pfm``, ``.flo`` or ``.png`` file."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file ({what}).")
    suffix = path.suffix.lower()
    if suffix == ".pfm":
        return read_pfm(path)
    if suffix == ".flo":
        return read_flo(path)
    if suffix == ".png":
        return read_png(path, what)
    raise ValueError(
        f"{path}: unknown extension {suffix!r} for the {what}; expected .pfm, .flo or .png."
    )


def _grey(image, path, what):
    """The single channel of a map (the first channel of a 3-channel PFM)."""
    if image.ndim == 3:
        image = image[..., 0]
    if image.ndim != 2:
        raise ValueError(f"{path}: the {what} must be a single-channel image; got {image.shape}.")
    return image


def _resolve_paths(root, index, split, camera, paths):
    paths = {} if paths is None else dict(paths)
    unknown = sorted(set(paths) - set(FLYING_THINGS_FILES))
    if unknown:
        raise ValueError(
            f"paths has unknown keys {unknown}; allowed: {sorted(FLYING_THINGS_FILES)}."
        )
    missing_root = [key for key in _REQUIRED if key not in paths]
    if root is None and missing_root:
        raise ValueError(f"root is None, so paths must give {missing_root}.")
    resolved, explicit = {}, set(paths)
    for key, pattern in FLYING_THINGS_FILES.items():
        if key in paths:
            resolved[key] = Path(paths[key])
        elif root is not None:
            folder = Path(root) if split is None else Path(root) / split
            resolved[key] = folder / pattern.format(camera=camera, index=f"{index:07d}")
    flow = resolved["flow"]
    if "flow" not in explicit and not flow.exists() and flow.with_suffix(".pfm").exists():
        resolved["flow"] = flow.with_suffix(".pfm")  # the full release's PFM flow
    return resolved, explicit


def load_flying_things(
    root,
    index,
    *,
    split="train",
    camera="left",
    paths=None,
    focal_length=_FOCAL,
    baseline=_BASELINE,
    principal_point=None,
    disparity_sign="auto",
    drop_occluded=False,
    max_depth=None,
    n_points=None,
    random_state=None,
):
    """Load one FlyingThings3D frame as 3-D correspondences with ground truth.

    Every pixel with a finite, positive disparity in both frames and a finite flow gives
    a correspondence: ``a`` back-projected from the disparity, ``b`` from the disparity
    plus the disparity change at the flowed pixel (see the module notes for the layout).

    Parameters
    ----------
    root : str or path-like or None
        The folder holding ``train/`` and ``val/`` of the subset (or the files directly
        when ``split=None``). None when ``paths`` gives every required file.
    index : int
        Frame number: files ``{index:07d}.*``.
    split : str or None, default="train"
        Sub-folder of ``root`` (``"train"`` or ``"val"`` in the subset).
    camera : {"left", "right"}, default="left"
    paths : dict, optional
        Explicit files, overriding the layout, for any of the keys ``"disparity"``,
        ``"disparity_change"``, ``"flow"`` (``.flo``, or ``.pfm`` of which the first two
        channels are used), ``"flow_occlusions"``, ``"disparity_occlusions"`` (PNG,
        non-zero = occluded) and ``"object_index"`` (``.pfm`` or ``.png``).
    focal_length : float, default=1050.0
        In pixels.
    baseline : float, default=1.0
        Stereo baseline, in the scene's units.
    principal_point : (float, float), optional
        ``(cx, cy)``; the image centre ``((W - 1) / 2, (H - 1) / 2)`` when None.
    disparity_sign : {"auto", 1, -1}, default="auto"
        Multiply the disparity and its change by this; ``"auto"`` takes -1 when most
        finite non-zero disparities are negative (the subset's convention).
    drop_occluded : bool, default=False
        Drop pixels marked occluded by the occlusion maps, when present.
    max_depth : float, optional
        Drop points deeper than this in either frame (35 is customary).
    n_points : int, optional
        Sample this many valid pixels uniformly without replacement (the paper uses
        32,768); all valid pixels when None.
    random_state : int, RandomState instance or None
        Seed of the sampling.

    Returns
    -------
    scene : sklearn.utils.Bunch
        X : ndarray of shape (n, 6)
            ``[a | b]``.
        a, b : ndarray of shape (n, 3)
            Points in frames 1 and 2, camera frame (x right, y down, z forward).
        flow : ndarray of shape (n, 3)
            ``b - a``.
        pixels : ndarray of shape (n, 2)
            ``(column, row)`` of every point, in raster order.
        instance_labels : ndarray of shape (n,) or None
            Object index of every point, None without an object index map.
        occluded_mask : ndarray of bool, shape (n,) or None
            Points marked occluded by the occlusion maps, None without them.
        instance_image : ndarray of shape (H, W) or None
        valid_mask : ndarray of bool, shape (H, W)
            Pixels that yield a point (before sampling).
        image_shape : tuple of int
        K : ndarray of shape (3, 3)
        baseline : float
        camera : Bunch
        disparity_sign : int
            The sign applied.
        files : dict
            The path of every file read.

    Raises
    ------
    FileNotFoundError
        If a required file (or an explicitly given optional one) is missing; the error
        names it.
    ValueError
        If a file is corrupt, the maps differ in size, no pixel is valid, or an option is
        invalid.

    See Also
    --------
    make_flying_things : A rendered scene of the same kind, without the data set.
    load_kitti_scene_flow : The same from KITTI's ground truth.

    References
    ----------
    N. Mayer et al., "A Large Dataset to Train Convolutional Networks for Disparity,
    Optical Flow, and Scene Flow Estimation", CVPR 2016.

    Examples
    --------
    A 3 x 4 frame written in the subset's formats (a wall at depth 1050 / 105 = 10,
    moving 1 towards the camera; the subset stores negated disparities):

    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.datasets import load_flying_things, write_pfm
    >>> from mmreg.datasets._pfm import write_flo
    >>> with tempfile.TemporaryDirectory() as root:
    ...     frame = Path(root) / "train"
    ...     for sub in ("disparity/left", "disparity_change/left/into_future",
    ...                 "flow/left/into_future"):
    ...         (frame / sub).mkdir(parents=True)
    ...     write_pfm(frame / "disparity/left/0000000.pfm", np.full((3, 4), -105.0))
    ...     write_pfm(frame / "disparity_change/left/into_future/0000000.pfm",
    ...               np.full((3, 4), 105.0 - 1050 / 9))
    ...     write_flo(frame / "flow/left/into_future/0000000.flo", np.zeros((3, 4, 2)))
    ...     scene = load_flying_things(root, 0)
    >>> scene.X.shape, scene.disparity_sign
    ((12, 6), -1)
    >>> np.round(scene.X[0, [2, 5]], 4).tolist()  # depth 10 in frame 1, 9 in frame 2
    [10.0, 9.0]
    """
    index = check_index(index, 7)
    if camera not in ("left", "right"):
        raise ValueError(f"camera must be 'left' or 'right'; got {camera!r}.")
    if split is not None and not isinstance(split, str):
        raise ValueError(f"split must be a folder name or None; got {split!r}.")
    for name, value in (("focal_length", focal_length), ("baseline", baseline)):
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not value > 0:
            raise ValueError(f"{name} must be a positive number; got {value!r}.")
    if disparity_sign not in ("auto", 1, -1) or isinstance(disparity_sign, bool):
        raise ValueError(f"disparity_sign must be 'auto', 1 or -1; got {disparity_sign!r}.")
    if not isinstance(drop_occluded, (bool, np.bool_)):
        raise ValueError(f"drop_occluded must be True or False; got {drop_occluded!r}.")
    check_options(n_points, max_depth)
    rng = check_random_state(random_state)
    files, explicit = _resolve_paths(root, index, split, camera, paths)

    disparity = _grey(_read_map(files["disparity"], "disparity"), files["disparity"], "disparity")
    change = _grey(
        _read_map(files["disparity_change"], "disparity change"),
        files["disparity_change"],
        "disparity change",
    )
    flow = _read_map(files["flow"], "optical flow")
    if flow.ndim != 3 or flow.shape[2] < 2:
        raise ValueError(
            f"{files['flow']}: the optical flow must have 2 or 3 channels; got {flow.shape}."
        )
    flow = flow[..., :2]
    optional = {}
    for key in ("flow_occlusions", "disparity_occlusions", "object_index"):
        path = files.get(key)
        if path is not None and (path.exists() or key in explicit):
            optional[key] = _grey(_read_map(path, key.replace("_", " ")), path, key)
        else:
            files.pop(key, None)
            optional[key] = None
    height, width = check_same_shape(
        {
            files["disparity"]: disparity,
            files["disparity_change"]: change,
            files["flow"]: flow,
            **{files[k]: v for k, v in optional.items() if v is not None},
        }
    )

    if disparity_sign == "auto":
        finite = disparity[np.isfinite(disparity) & (disparity != 0)]
        disparity_sign = -1 if len(finite) and np.median(finite) < 0 else 1
    disparity = disparity_sign * disparity.astype(float)
    with np.errstate(invalid="ignore"):  # inf - inf at pixels without depth: dropped below
        disparity_next = disparity + disparity_sign * change.astype(float)
    occluded = None
    if optional["flow_occlusions"] is not None or optional["disparity_occlusions"] is not None:
        occluded = np.zeros((height, width), dtype=bool)
        for key in ("flow_occlusions", "disparity_occlusions"):
            if optional[key] is not None:
                occluded |= optional[key] != 0
    valid = np.ones((height, width), dtype=bool)
    if drop_occluded and occluded is not None:
        valid &= ~occluded
    instance_image = None
    if optional["object_index"] is not None:
        object_index = optional["object_index"]
        valid &= np.isfinite(object_index)
        instance_image = np.where(np.isfinite(object_index), np.rint(object_index), -1).astype(
            np.intp
        )
    if principal_point is None:
        principal_point = ((width - 1) / 2.0, (height - 1) / 2.0)
    cx, cy = (float(v) for v in principal_point)
    camera_model = pinhole_camera(int(width), int(height), focal_length, focal_length, cx, cy)
    try:
        a, b, pixels, valid = stereo_correspondences(
            disparity,
            disparity_next,
            flow,
            valid,
            camera_model,
            float(baseline),
            n_points=n_points,
            max_depth=max_depth,
            rng=rng,
        )
    except ValueError as exc:
        raise ValueError(f"{files['disparity']}: {exc}") from exc
    cols, rows = pixels[:, 0], pixels[:, 1]
    return Bunch(
        X=np.hstack([a, b]),
        a=a,
        b=b,
        flow=b - a,
        pixels=pixels,
        instance_labels=None if instance_image is None else instance_image[rows, cols],
        occluded_mask=None if occluded is None else occluded[rows, cols],
        instance_image=instance_image,
        valid_mask=valid,
        image_shape=(int(height), int(width)),
        K=camera_model.K,
        baseline=float(baseline),
        camera=camera_model,
        disparity_sign=int(disparity_sign),
        files={k: str(v) for k, v in files.items()},
    )
