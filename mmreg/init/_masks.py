"""Image masks (e.g. SegmentAnything's) turned into labels of correspondences."""

from collections.abc import Mapping
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt

__all__ = ["OVERLAP_RULES", "UNCOVERED_RULES", "label_image", "load_masks", "masks_to_labels"]

OVERLAP_RULES = ("smallest", "largest", "first")
UNCOVERED_RULES = ("unassigned", "nearest")
# Keys tried, in this order, in an .npz file holding several arrays.
_NPZ_KEYS = ("masks", "segmentation", "labels")


def _as_mask(mask, name):
    mask = np.asarray(mask)
    if mask.dtype == bool:
        return mask
    if mask.dtype.kind in "iuf" and np.all((mask == 0) | (mask == 1)):
        return mask.astype(bool)
    raise TypeError(f"{name} must be a boolean mask (or 0/1 values); got dtype {mask.dtype}.")


def _mask_stack(masks):
    """The masks as a boolean array of shape (n_masks, H, W)."""
    if len(masks) == 0:
        raise ValueError("masks is empty: give at least one mask or a label image.")
    if isinstance(masks[0], Mapping):
        arrays = []
        for i, record in enumerate(masks):
            if not isinstance(record, Mapping) or "segmentation" not in record:
                raise ValueError(f"masks[{i}] has no 'segmentation' entry (SAM's mask format).")
            segmentation = record["segmentation"]
            if isinstance(segmentation, Mapping):
                raise ValueError(
                    f"masks[{i}]['segmentation'] is run-length encoded; generate the masks "
                    "with output_mode='binary_mask' or decode them to arrays first."
                )
            arrays.append(segmentation)
        masks = arrays
    arrays = [_as_mask(mask, f"masks[{i}]") for i, mask in enumerate(masks)]
    shapes = {mask.shape for mask in arrays}
    if len(shapes) > 1 or arrays[0].ndim != 2:
        raise ValueError(f"every mask must be one H x W image of the same shape; got {shapes}.")
    return np.stack(arrays)


def label_image(masks, *, overlap="smallest"):
    """Paint masks into one image of mask ids.

    Parameters
    ----------
    masks : list of ndarray, list of dict, or ndarray
        A list of ``H x W`` boolean masks, SAM's automatic-mask-generator output (dicts
        with a boolean ``"segmentation"``), an array of shape ``(n_masks, H, W)``, or an
        ``H x W`` integer label image (negative: no mask), which is returned as it is.
    overlap : {"smallest", "largest", "first"}, default="smallest"
        Which mask a pixel in several masks belongs to: the one of fewest pixels, of most
        pixels, or the first in the list; ties go to the earlier mask.

    Returns
    -------
    image : ndarray of shape (H, W)
        Id of the mask covering each pixel (its index in the list, or the label image's
        value); -1 where no mask does.
    """
    if overlap not in OVERLAP_RULES:
        raise ValueError(f"overlap must be one of {OVERLAP_RULES}; got {overlap!r}.")
    listed = isinstance(masks, (list, tuple)) and len(masks) > 0
    if not listed or (not isinstance(masks[0], Mapping) and np.ndim(masks[0]) < 2):
        # Nested lists of numbers: one image, not a list of images.
        masks = np.asarray(masks)
    if isinstance(masks, np.ndarray) and masks.ndim == 2 and masks.dtype != bool:
        if masks.dtype.kind not in "iu":
            raise TypeError(
                f"A 2-D array of masks must be an integer label image; got dtype {masks.dtype}."
            )
        return masks.astype(np.intp)
    if isinstance(masks, np.ndarray) and masks.ndim == 2:
        masks = masks[np.newaxis]
    stack = _mask_stack(masks)
    index = np.arange(len(stack))
    areas = stack.sum(axis=(1, 2))
    # Painted in turn, so the mask painted last wins: order them so that it is the right one.
    if overlap == "smallest":
        order = np.lexsort((-index, -areas))
    elif overlap == "largest":
        order = np.lexsort((-index, areas))
    else:
        order = index[::-1]
    image = np.full(stack.shape[1:], -1, dtype=np.intp)
    for mask_id in order:
        image[stack[mask_id]] = mask_id
    return image


def _check_pixels(pixels, shape):
    pixels = np.asarray(pixels)
    if pixels.ndim != 2 or pixels.shape[1] != 2:
        raise ValueError(
            f"pixels must have shape (n, 2), the (column, row) of each a-point; got {pixels.shape}."
        )
    if pixels.dtype.kind == "f":
        if not np.all(np.isfinite(pixels)) or not np.all(pixels == np.round(pixels)):
            raise TypeError(
                "pixels must be integer (column, row) indices; round projected coordinates "
                "first (e.g. np.floor)."
            )
    elif pixels.dtype.kind not in "iu":
        raise TypeError(f"pixels must be integer (column, row) indices; got dtype {pixels.dtype}.")
    pixels = pixels.astype(np.intp)
    height, width = shape
    outside = np.flatnonzero(
        (pixels[:, 0] < 0) | (pixels[:, 0] >= width) | (pixels[:, 1] < 0) | (pixels[:, 1] >= height)
    )
    if len(outside):
        first = outside[0]
        raise ValueError(
            f"{len(outside)} pixel(s) lie outside the {height} x {width} (rows x columns) "
            f"image, e.g. pixels[{first}] = (column {pixels[first, 0]}, row {pixels[first, 1]})."
        )
    return pixels


def masks_to_labels(masks, pixels, *, overlap="smallest", uncovered="unassigned"):
    """Mask id of each correspondence, from the pixel of its a-point.

    Parameters
    ----------
    masks : list of ndarray, list of dict, or ndarray
        See :func:`label_image`.
    pixels : array-like of shape (n, 2)
        Integer pixel ``(column, row)`` of each a-point in the masks' image.
    overlap : {"smallest", "largest", "first"}, default="smallest"
        See :func:`label_image`.
    uncovered : {"unassigned", "nearest"}, default="unassigned"
        Label of a pixel no mask covers: -1, or the mask of the nearest covered pixel
        (Euclidean distance in the image).

    Returns
    -------
    labels : ndarray of shape (n,)
        Mask id (index in the list, or label-image value) of each correspondence; -1 for
        none.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.init import masks_to_labels
    >>> whole = np.ones((2, 3), dtype=bool)
    >>> part = np.zeros((2, 3), dtype=bool)
    >>> part[0, 0] = True
    >>> masks_to_labels([whole, part], [[0, 0], [2, 1]])
    array([1, 0])
    """
    if uncovered not in UNCOVERED_RULES:
        raise ValueError(f"uncovered must be one of {UNCOVERED_RULES}; got {uncovered!r}.")
    image = label_image(masks, overlap=overlap)
    pixels = _check_pixels(pixels, image.shape)
    if uncovered == "nearest" and np.any(image >= 0) and np.any(image < 0):
        nearest = distance_transform_edt(image < 0, return_distances=False, return_indices=True)
        image = image[tuple(nearest)]
    return image[pixels[:, 1], pixels[:, 0]]


def load_masks(path, *, key=None):
    """Load masks saved with :func:`numpy.save` or :func:`numpy.savez`.

    Parameters
    ----------
    path : str or path-like
        An ``.npy`` file holding one array, or an ``.npz`` file.
    key : str, default=None
        The array to read from an ``.npz`` file. None: its only array, else the first of
        ``"masks"``, ``"segmentation"``, ``"labels"`` that it holds.

    Returns
    -------
    masks : ndarray
        An ``(n_masks, H, W)`` boolean stack, a single ``H x W`` boolean mask, or an
        ``H x W`` integer label image, ready for :class:`PrecomputedMasks`.

    Notes
    -----
    Files are read without pickle, so SAM's list of dicts must be saved as arrays, e.g.
    ``np.savez(path, masks=np.stack([m["segmentation"] for m in sam_masks]))``.
    """
    path = Path(path)
    try:
        data = np.load(path, allow_pickle=False)
    except ValueError as error:
        raise ValueError(
            f"{path} holds Python objects (pickle), which are not loaded; save the masks "
            "as an (n_masks, H, W) boolean array or an H x W integer label image."
        ) from error
    if isinstance(data, np.lib.npyio.NpzFile):
        with data:
            names = list(data.keys())
            if key is None:
                found = [name for name in _NPZ_KEYS if name in names]
                if len(names) == 1:
                    key = names[0]
                elif found:
                    key = found[0]
                else:
                    raise ValueError(f"{path} holds arrays {names}; pass key= to choose the masks.")
            if key not in names:
                raise KeyError(f"{path} has no array {key!r}; it holds {names}.")
            data = data[key]
    elif key is not None:
        raise ValueError(f"key={key!r} applies to .npz files only; {path} holds one array.")
    if data.ndim not in (2, 3):
        raise ValueError(
            f"{path}: masks must be an H x W image or an (n_masks, H, W) stack; got an "
            f"array of shape {data.shape}."
        )
    if data.ndim == 3:
        data = _as_mask(data, f"the masks in {path}")
    return data
