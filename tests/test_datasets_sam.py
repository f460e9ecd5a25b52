"""Tests of simulate_sam_masks: SAM's format, coverage, rules, and use by PrecomputedMasks."""

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

from mmreg.datasets._sam import simulate_sam_masks
from mmreg.init import PrecomputedMasks, masks_to_labels
from mmreg.init._masks import label_image

HEIGHT, WIDTH = 60, 80
SAM_KEYS = {
    "segmentation",
    "area",
    "bbox",
    "predicted_iou",
    "point_coords",
    "stability_score",
    "crop_box",
}


def toy_image():
    """Sky (-1) on top, background surface 0, rectangles 1 and 2 touching, 3 apart."""
    image = np.zeros((HEIGHT, WIDTH), dtype=int)
    image[:5] = -1
    image[10:25, 5:25] = 1
    image[10:25, 25:40] = 2
    image[35:50, 50:70] = 3
    return image


def _surfaces(image, mask):
    return set(np.unique(image[mask["segmentation"]]).tolist())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_records_have_sams_format(seed):
    masks = simulate_sam_masks(toy_image(), random_state=seed)
    assert len(masks) > 4
    for mask in masks:
        assert set(mask) == SAM_KEYS
        segmentation = mask["segmentation"]
        assert isinstance(segmentation, np.ndarray) and segmentation.dtype == bool
        assert segmentation.shape == (HEIGHT, WIDTH)
        assert type(mask["area"]) is int and mask["area"] == segmentation.sum() > 0
        rows, cols = np.nonzero(segmentation)
        x, y, w, h = mask["bbox"]
        assert all(type(v) is int for v in mask["bbox"])
        # SAM's XYWH: box_xyxy_to_xywh of a box whose right/bottom are the last col/row.
        assert (x, y) == (cols.min(), rows.min())
        assert (x + w, y + h) == (cols.max(), rows.max())
        assert type(mask["predicted_iou"]) is float and 0.88 <= mask["predicted_iou"] <= 1
        assert type(mask["stability_score"]) is float and 0.95 <= mask["stability_score"] <= 1
        [[px, py]] = mask["point_coords"]
        assert segmentation[int(py), int(px)]
        assert mask["crop_box"] == [0, 0, WIDTH, HEIGHT]


@pytest.mark.parametrize("unmasked_fraction", [0.0, 0.05, 0.2])
def test_coverage_fraction_is_the_requested(unmasked_fraction):
    image = toy_image()
    masks = simulate_sam_masks(image, unmasked_fraction=unmasked_fraction, random_state=0)
    covered = np.any([m["segmentation"] for m in masks], axis=0)
    assert not covered[image < 0].any()
    assert abs(covered[image >= 0].mean() - (1 - unmasked_fraction)) < 0.01


def test_uncovered_pixels_lie_mostly_along_mask_boundaries():
    image = toy_image()
    for seed in range(3):
        masks = simulate_sam_masks(image, part_fraction=0.0, merge_fraction=0.0, random_state=seed)
        labels = label_image(masks)
        gaps = (image >= 0) & (labels < 0)
        # The partition before uncovering, roughly: each gap takes its nearest mask.
        nearest = distance_transform_edt(gaps, return_distances=False, return_indices=True)
        filled = np.where(image >= 0, labels[tuple(nearest)], -1)
        edge = np.zeros(image.shape, dtype=bool)
        for step in ((slice(None), slice(1, None)), (slice(1, None), slice(None))):
            back = tuple(slice(None, -1) if s.start == 1 else s for s in step)
            change = filled[step] != filled[back]
            edge[step] |= change
            edge[back] |= change
        # 70 % of the gaps are in bands along boundaries, 30 % in holes anywhere.
        assert edge[gaps].mean() > 0.6
        assert edge[gaps].mean() > 2.5 * edge.mean()


def test_without_merges_no_mask_straddles_two_surfaces():
    image = toy_image()
    for seed in range(5):
        masks = simulate_sam_masks(image, merge_fraction=0.0, random_state=seed)
        assert all(len(_surfaces(image, m)) == 1 for m in masks)


def test_merges_join_only_touching_foreground_objects():
    image = toy_image()
    masks = simulate_sam_masks(image, merge_fraction=1.0, random_state=0)
    joined = [_surfaces(image, m) for m in masks if len(_surfaces(image, m)) > 1]
    assert joined == [{1, 2}]  # rectangles 1 and 2 touch; 3 and the background never join
    for seed in range(5):  # the documented rule at the default rate
        for mask in simulate_sam_masks(image, random_state=seed):
            assert _surfaces(image, mask) in ({0}, {1}, {2}, {3}, {1, 2})


def test_background_is_cut_into_many_masks():
    image = toy_image()
    for background in (None, [0], (0,)):
        masks = simulate_sam_masks(image, background=background, random_state=0)
        assert sum(_surfaces(image, m) == {0} for m in masks) >= 5
    # Declared foreground and never split: one mask.
    masks = simulate_sam_masks(image, background=[], part_fraction=0.0, random_state=0)
    assert sum(_surfaces(image, m) == {0} for m in masks) == 1


def test_objects_split_into_parts():
    image = toy_image()
    split = simulate_sam_masks(image, part_fraction=1.0, merge_fraction=0.0, random_state=0)
    whole = simulate_sam_masks(image, part_fraction=0.0, merge_fraction=0.0, random_state=0)
    for surface in (1, 2, 3):
        assert sum(_surfaces(image, m) == {surface} for m in split) >= 2
        assert sum(_surfaces(image, m) == {surface} for m in whole) == 1


def test_masks_work_with_precomputed_masks():
    image = toy_image()
    masks = simulate_sam_masks(image, merge_fraction=0.0, random_state=0)
    rng = np.random.default_rng(0)
    rows, cols = np.nonzero(image >= 0)
    pick = rng.choice(len(rows), size=400, replace=False)
    pixels = np.column_stack([cols[pick], rows[pick]])  # (column, row)
    surface = image[rows[pick], cols[pick]]
    X = rng.normal(size=(400, 6))
    init = PrecomputedMasks(masks, pixels).fit(X)
    labels = init.labels_
    assert init.n_clusters_ >= 8
    assert 0.85 < np.mean(labels >= 0) < 1.0  # 5 % of the pixels are uncovered
    for label in np.unique(labels[labels >= 0]):
        assert len(np.unique(surface[labels == label])) == 1
    assert np.array_equal(masks_to_labels(masks, pixels) >= 0, labels >= 0)
    nearest = PrecomputedMasks(masks, pixels, uncovered="nearest").fit(X)
    assert np.all(nearest.labels_ >= 0)


def test_random_state_makes_it_deterministic():
    image = toy_image()
    first = simulate_sam_masks(image, random_state=4)
    again = simulate_sam_masks(image, random_state=np.random.RandomState(4))
    other = simulate_sam_masks(image, random_state=5)
    assert len(first) == len(again)
    for a, b in zip(first, again, strict=True):
        assert np.array_equal(a["segmentation"], b["segmentation"])
        assert a["predicted_iou"] == b["predicted_iou"]
    stack = np.stack([m["segmentation"] for m in first])
    assert len(other) != len(first) or not np.array_equal(
        stack, np.stack([m["segmentation"] for m in other])
    )


def test_arbitrary_ids_and_empty_image():
    image = toy_image()
    relabelled = np.where(image >= 0, image * 1000 + 7, -1)
    masks = simulate_sam_masks(relabelled, random_state=0)
    assert {s for m in masks for s in _surfaces(relabelled, m)} <= {7, 1007, 2007, 3007}
    assert simulate_sam_masks(np.full((4, 5), -1), random_state=0) == []


@pytest.mark.parametrize(
    "params, error, match",
    [
        ({"part_fraction": 1.5}, ValueError, "part_fraction"),
        ({"merge_fraction": -0.1}, ValueError, "merge_fraction"),
        ({"unmasked_fraction": 2}, ValueError, "unmasked_fraction"),
        ({"part_fraction": "many"}, TypeError, "part_fraction"),
        ({"background": 0}, TypeError, "background"),
        ({"background": "road"}, TypeError, "background"),
        ({"background": [0.5]}, TypeError, "background"),
    ],
)
def test_bad_parameters_raise(params, error, match):
    with pytest.raises(error, match=match):
        simulate_sam_masks(toy_image(), **params)


def test_bad_images_raise():
    with pytest.raises(ValueError, match="instance_image"):
        simulate_sam_masks(np.zeros((2, 3, 4), dtype=int))
    with pytest.raises(TypeError, match="instance_image"):
        simulate_sam_masks(np.zeros((5, 5)))
    with pytest.raises(ValueError, match="instance_image"):
        simulate_sam_masks(np.full((5, 5), -2))
