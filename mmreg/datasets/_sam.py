"""Masks like SegmentAnything's automatic mask generator, simulated from an instance image."""

from collections.abc import Iterable
from numbers import Integral, Real

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree
from sklearn.utils import check_random_state

__all__ = ["simulate_sam_masks"]

# A region covering more than this fraction of the valid pixels is background when
# ``background`` is None; no region this large is merged with a neighbour.
_LARGE_FRACTION = 1 / 8
# Background regions are cut into cells of about (min(H, W) * _CELL_SIDE) ** 2 pixels.
_CELL_SIDE = 1 / 4
# Fraction of the unmasked pixels in bands along mask boundaries; the rest are holes.
_BAND_SHARE = 0.7
# Average area, in pixels, of a hole.
_HOLE_AREA = 60
# Probability that a split object also keeps its whole mask (SAM returns nested masks).
_WHOLE_PROBABILITY = 0.5
# Ranges of the scores, above SamAutomaticMaskGenerator's default filters
# (pred_iou_thresh=0.88, stability_score_thresh=0.95), which every kept mask passes.
_PREDICTED_IOU = (0.88, 1.0)
_STABILITY_SCORE = (0.95, 1.0)
# Lloyd iterations of the k-means that cuts a region into parts.
_LLOYD_STEPS = 4
# Pixels the Lloyd steps run on (a random subsample of a larger region).
_KMEANS_SAMPLE = 4000


def _check_fraction(value, name):
    if isinstance(value, bool) or not isinstance(value, Real):
        raise TypeError(f"{name} must be a real number; got {value!r} ({type(value).__name__}).")
    if not 0.0 <= float(value) <= 1.0:
        raise ValueError(f"{name} must be in [0, 1]; got {value!r}.")
    return float(value)


def _check_instance_image(instance_image):
    image = np.asarray(instance_image)
    if image.ndim != 2 or min(image.shape) < 1:
        raise ValueError(f"instance_image must be a non-empty H x W array; got {image.shape}.")
    if image.dtype.kind not in "iu":
        raise TypeError(f"instance_image must hold integer surface ids; got dtype {image.dtype}.")
    if image.min() < -1:
        raise ValueError("instance_image ids must be >= 0, or -1 for no surface.")
    return image.astype(np.int64)


def _check_background(background):
    if background is None:
        return None
    if isinstance(background, (Integral, str)) or not isinstance(background, Iterable):
        raise TypeError(
            f"background must be None or a collection of surface ids; got {background!r}."
        )
    ids = list(background)
    if not all(isinstance(i, Integral) and not isinstance(i, bool) for i in ids):
        raise TypeError(f"background must hold integer surface ids; got {ids!r}.")
    return np.array(ids, dtype=np.int64)


def _regions(image):
    """Connected components (4-connected) of every surface id.

    Returns the region image (-1: no surface), and per region its surface id and area.
    """
    ids, inverse = np.unique(image, return_inverse=True)
    inverse = inverse.reshape(image.shape)
    region_image = np.full(image.shape, -1, dtype=np.intp)
    region_id, n_regions = [], 0
    for index, surface in enumerate(ids):  # one pass per surface id: a handful
        if surface < 0:
            continue
        components, count = ndimage.label(inverse == index)
        inside = components > 0
        region_image[inside] = components[inside] - 1 + n_regions
        region_id.extend([surface] * count)
        n_regions += count
    areas = np.bincount(region_image[region_image >= 0], minlength=n_regions)
    return region_image, np.array(region_id, dtype=np.int64), areas


def _adjacent_pairs(label_image):
    """Unique unordered pairs of different non-negative labels that touch (4-neighbours)."""
    pairs = []
    for a, b in (
        (label_image[:, :-1], label_image[:, 1:]),
        (label_image[:-1, :], label_image[1:, :]),
    ):
        touch = (a != b) & (a >= 0) & (b >= 0)
        pairs.append(np.column_stack([a[touch], b[touch]]))
    pairs = np.sort(np.vstack(pairs), axis=1)
    return np.unique(pairs, axis=0) if len(pairs) else pairs.reshape(0, 2)


def _kmeans_parts(coords, n_parts, rng):
    """Cut pixels into ``n_parts`` compact cells: k-means on their coordinates.

    Seeds are random pixels of the region; a few Lloyd steps on a random subsample make
    the cells compact, so that the cuts are straight lines between neighbouring cells (a
    Voronoi partition of the region by the final centres).
    """
    sample = coords
    if len(coords) > _KMEANS_SAMPLE:
        sample = coords[rng.choice(len(coords), size=_KMEANS_SAMPLE, replace=False)]
    sample = sample.astype(float)
    centres = sample[rng.choice(len(sample), size=n_parts, replace=False)]
    for _ in range(_LLOYD_STEPS):
        _, part = cKDTree(centres).query(sample)
        counts = np.bincount(part, minlength=n_parts)
        filled = counts > 0
        for axis in range(2):
            sums = np.bincount(part, weights=sample[:, axis], minlength=n_parts)
            centres[filled, axis] = sums[filled] / counts[filled]
    _, part = cKDTree(centres).query(coords)
    return part


def _smallest(scores, count, rng):
    """Indices of the ``count`` smallest ``scores + U(0, 1)``: ragged edges, no ties."""
    jittered = scores + rng.uniform(0.0, 1.0, len(scores))
    if count >= len(scores):
        return np.arange(len(scores))
    return np.argpartition(jittered, count - 1)[:count]


def simulate_sam_masks(
    instance_image,
    *,
    part_fraction=0.3,
    merge_fraction=0.1,
    unmasked_fraction=0.05,
    background=None,
    random_state=None,
):
    """Masks in SegmentAnything's output format, simulated from a surface-id image.

    SAM's automatic mask generator follows object boundaries well but not the notion of
    an object: it cuts objects into parts, merges small neighbouring things, cuts large
    background surfaces into many pieces, and leaves thin bands along boundaries and a
    few holes uncovered. These rules reproduce that from the true surfaces:

    1. **Regions.** Each 4-connected component of each surface id is a region.
       Background regions are those of the ids in ``background`` or, when it is None,
       the regions covering more than 1/8 of the valid pixels.
    2. **Merges.** Every pair of touching foreground regions, both at most 1/8 of the
       valid pixels, is merged into one mask with probability ``merge_fraction``
       (pairs in random order; a region merges at most once). This is the only way a
       mask covers two surfaces.
    3. **Parts.** Every other foreground region is cut, with probability
       ``part_fraction``, into 2 or 3 parts (equally likely) by k-means on its pixel
       coordinates (straight cuts between compact cells); such an object also keeps
       its whole mask with probability 1/2, as SAM returns nested masks at several
       granularities. Every background region is cut into ``max(2, area / c)`` cells
       the same way, with ``c = (min(H, W) / 4) ** 2``.
    4. **Uncovered pixels.** Exactly ``round(unmasked_fraction * n_valid)`` valid
       pixels are removed from every mask: 70 % in ragged bands along mask boundaries
       (the pixels of smallest distance to a boundary plus a uniform jitter of up to one
       pixel), 30 % in round holes of about
       60 pixels at random places (same jitter). Masks left empty are dropped.

    Parameters
    ----------
    instance_image : array-like of shape (H, W)
        Integer surface (instance) id of each pixel, ``-1`` where there is no surface
        (sky, invalid depth). Ids are arbitrary non-negative integers.
    part_fraction : float, default=0.3
        Probability that a foreground region is cut into parts, in ``[0, 1]``.
    merge_fraction : float, default=0.1
        Probability that two touching foreground regions are merged, in ``[0, 1]``.
    unmasked_fraction : float, default=0.05
        Fraction of the valid pixels left outside every mask, in ``[0, 1]``.
    background : collection of int or None, default=None
        Surface ids of the background (road, buildings, backdrop), always cut into many
        masks; None: regions larger than 1/8 of the valid pixels.
    random_state : int, RandomState instance or None, default=None
        Seeds every random choice (merges, cuts, holes, scores).

    Returns
    -------
    masks : list of dict
        One record per mask with the keys of ``SamAutomaticMaskGenerator.generate``
        (``output_mode="binary_mask"``): ``segmentation`` boolean (H, W); ``area`` int,
        its number of pixels; ``bbox`` ``[x, y, w, h]`` computed as SAM does (``x, y``
        the first column and row, ``w, h`` the last minus the first); ``predicted_iou``
        float in [0.88, 1]; ``point_coords`` ``[[x, y]]``, a pixel of the mask;
        ``stability_score`` float in [0.95, 1]; ``crop_box`` ``[0, 0, W, H]``.
        Ready for :class:`~mmreg.init.PrecomputedMasks` with (column, row) pixels.

    Notes
    -----
    The scores are uniform over the ranges that pass SAM's default filters
    (``pred_iou_thresh=0.88``, ``stability_score_thresh=0.95``) and carry no
    information. The fractions are modelling choices, not measurements: SAM's paper
    (Kirillov et al., "Segment Anything", ICCV 2023) reports the quality of its masks,
    not how often it splits or merges objects. Cost: ``O(H W)`` per surface id for the
    regions, ``O(H W k)`` for a region cut into ``k`` cells, and ``O(H W)`` per mask
    for its segmentation.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.datasets._sam import simulate_sam_masks
    >>> image = np.zeros((30, 40), dtype=int)        # background surface 0
    >>> image[5:15, 5:15] = 1                         # two objects
    >>> image[18:26, 20:35] = 2
    >>> masks = simulate_sam_masks(image, random_state=0)
    >>> sorted(masks[0])
    ['area', 'bbox', 'crop_box', 'point_coords', 'predicted_iou', 'segmentation', 'stability_score']
    >>> covered = np.any([m["segmentation"] for m in masks], axis=0)
    >>> float(covered.mean())
    0.95
    """
    image = _check_instance_image(instance_image)
    part_fraction = _check_fraction(part_fraction, "part_fraction")
    merge_fraction = _check_fraction(merge_fraction, "merge_fraction")
    unmasked_fraction = _check_fraction(unmasked_fraction, "unmasked_fraction")
    background = _check_background(background)
    rng = check_random_state(random_state)
    height, width = image.shape

    region_image, region_id, areas = _regions(image)
    n_valid = int(areas.sum())
    if n_valid == 0:
        return []
    large = areas > _LARGE_FRACTION * n_valid
    is_background = large if background is None else np.isin(region_id, background)

    # 2. Merges of touching small foreground regions.
    unit = np.arange(len(areas))  # the mask-unit each region belongs to
    merged = np.zeros(len(areas), dtype=bool)
    pairs = _adjacent_pairs(region_image)
    if len(pairs) and merge_fraction > 0:
        eligible = ~is_background & ~large
        pairs = pairs[eligible[pairs[:, 0]] & eligible[pairs[:, 1]]]
        pairs = pairs[rng.permutation(len(pairs))]
        accept = rng.uniform(size=len(pairs)) < merge_fraction
        for (first, second), ok in zip(pairs, accept, strict=True):  # pairs of regions
            if ok and not merged[first] and not merged[second]:
                unit[second] = first
                merged[[first, second]] = True

    # 3. Parts: one label per part in part_image; wholes kept for some split objects.
    part_image = np.full(image.shape, -1, dtype=np.intp)
    wholes = []  # list of part-label lists whose union is a whole-object mask
    n_parts = 0
    cell_area = (min(height, width) * _CELL_SIDE) ** 2
    objects = ndimage.find_objects(region_image + 1)
    for region, box in enumerate(objects):  # one pass per region: a handful
        if box is None:
            continue
        if unit[region] != region:  # merged into another region: shares its label
            continue
        members = np.flatnonzero(unit == region)
        if len(members) > 1:  # a merged pair: the box around both
            boxes = [objects[member] for member in members]
            box = tuple(
                slice(min(b[axis].start for b in boxes), max(b[axis].stop for b in boxes))
                for axis in range(2)
            )
        local = np.isin(region_image[box], members)
        rows, cols = np.nonzero(local)
        area = len(rows)
        if is_background[region]:
            k = max(2, int(round(area / cell_area)))
        elif not merged[region] and rng.uniform() < part_fraction:
            k = int(rng.randint(2, 4))
        else:
            k = 1
        k = min(k, area)
        coords = np.column_stack([rows, cols])
        part = _kmeans_parts(coords, k, rng) if k > 1 else np.zeros(area, dtype=np.intp)
        rows, cols = rows + box[0].start, cols + box[1].start
        part_image[rows, cols] = n_parts + part
        if k > 1 and not is_background[region] and rng.uniform() < _WHOLE_PROBABILITY:
            wholes.append(list(range(n_parts, n_parts + k)))
        n_parts += k

    # 4. Uncovered pixels: bands along mask boundaries, then holes.
    n_unmasked = int(round(unmasked_fraction * n_valid))
    if n_unmasked:
        covered = part_image >= 0
        n_band = int(round(_BAND_SHARE * n_unmasked))
        boundary = np.zeros(image.shape, dtype=bool)
        for a, b, sa, sb in (
            (part_image[:, :-1], part_image[:, 1:], np.s_[:, :-1], np.s_[:, 1:]),
            (part_image[:-1, :], part_image[1:, :], np.s_[:-1, :], np.s_[1:, :]),
        ):
            differ = a != b
            boundary[sa] |= differ
            boundary[sb] |= differ
        boundary &= covered
        flat = np.flatnonzero(covered)
        if n_band and boundary.any():
            distance = ndimage.distance_transform_edt(~boundary).ravel()[flat]
            chosen = flat[_smallest(distance, n_band, rng)]
            part_image.ravel()[chosen] = -1
        else:
            n_band = 0
        n_hole = min(n_unmasked - n_band, int(np.count_nonzero(part_image >= 0)))
        if n_hole:
            flat = np.flatnonzero(part_image >= 0)
            n_seeds = max(1, int(round(n_hole / _HOLE_AREA)))
            seeds = np.ones(image.size, dtype=bool)
            seeds[rng.choice(flat, size=min(n_seeds, len(flat)), replace=False)] = False
            distance = ndimage.distance_transform_edt(seeds.reshape(image.shape)).ravel()
            chosen = flat[_smallest(distance[flat], n_hole, rng)]
            part_image.ravel()[chosen] = -1

    # Records, in SAM's format.
    segmentations = []
    part_boxes = ndimage.find_objects(part_image + 1, max_label=n_parts)
    for label, box in enumerate(part_boxes):  # one pass per mask
        if box is None:
            segmentations.append(None)
            continue
        segmentation = np.zeros(image.shape, dtype=bool)
        segmentation[box] = part_image[box] == label
        segmentations.append(segmentation)
    records = [s for s in segmentations if s is not None]
    for labels in wholes:
        parts = [segmentations[label] for label in labels if segmentations[label] is not None]
        if len(parts) > 1:
            records.append(np.logical_or.reduce(parts))
    return [_record(segmentation, rng) for segmentation in records]


def _record(segmentation, rng):
    """One mask in ``SamAutomaticMaskGenerator.generate``'s format."""
    rows, cols = np.nonzero(segmentation)
    pick = rng.randint(len(rows))
    height, width = segmentation.shape
    return {
        "segmentation": segmentation,
        "area": int(len(rows)),
        # SAM: box_xyxy_to_xywh(batched_mask_to_box(mask)), whose right and bottom edges
        # are the last column and row, so w and h are one less than the extents.
        "bbox": [
            int(cols.min()),
            int(rows.min()),
            int(cols.max() - cols.min()),
            int(rows.max() - rows.min()),
        ],
        "predicted_iou": float(rng.uniform(*_PREDICTED_IOU)),
        "point_coords": [[float(cols[pick]), float(rows[pick])]],
        "stability_score": float(rng.uniform(*_STABILITY_SCORE)),
        "crop_box": [0, 0, int(width), int(height)],
    }
