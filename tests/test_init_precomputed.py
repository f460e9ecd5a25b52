"""PrecomputedMasks, PrecomputedLabels and load_masks: masks mapped to correspondences."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from sklearn.base import clone

from mmreg.init import (
    PrecomputedLabels,
    PrecomputedMasks,
    load_masks,
    masks_to_labels,
)
from mmreg.init._masks import label_image

H, W = 6, 8


def box(r0, r1, c0, c1):
    mask = np.zeros((H, W), dtype=bool)
    mask[r0:r1, c0:c1] = True
    return mask


@pytest.fixture
def nested():
    """A whole (0), a part of it (1), a disjoint piece (2); column 7 covered by none."""
    return [box(0, 6, 0, 5), box(0, 2, 0, 2), box(0, 6, 5, 7)]


def pixels_and_X(pixels):
    pixels = np.asarray(pixels)
    X = np.random.default_rng(0).normal(size=(len(pixels), 6))
    return pixels, X


def reference(masks, pixels, overlap):
    """Mask of each pixel straight from the rule, one pixel at a time."""
    areas = [int(m.sum()) for m in masks]
    out = []
    for col, row in pixels:
        covering = [j for j, m in enumerate(masks) if m[row, col]]
        if not covering:
            out.append(-1)
        elif overlap == "smallest":
            out.append(min(covering, key=lambda j: (areas[j], j)))
        elif overlap == "largest":
            out.append(min(covering, key=lambda j: (-areas[j], j)))
        else:
            out.append(covering[0])
    return np.array(out)


@given(
    seed=st.integers(0, 2**32 - 1),
    n_masks=st.integers(1, 6),
    overlap=st.sampled_from(["smallest", "largest", "first"]),
)
def test_overlap_rules_match_reference(seed, n_masks, overlap):
    rng = np.random.default_rng(seed)
    masks = []
    for _ in range(n_masks):
        r0, c0 = rng.integers(0, H), rng.integers(0, W)
        masks.append(box(r0, rng.integers(r0, H + 1), c0, rng.integers(c0, W + 1)))
    pixels = np.column_stack([rng.integers(0, W, 40), rng.integers(0, H, 40)])
    got = masks_to_labels(masks, pixels, overlap=overlap)
    np.testing.assert_array_equal(got, reference(masks, pixels, overlap))


def test_smallest_mask_wins_and_uncovered_is_unassigned(nested):
    pixels, X = pixels_and_X([[0, 0], [3, 4], [6, 1], [7, 0], [1, 1]])
    init = PrecomputedMasks(nested, pixels).fit(X)
    np.testing.assert_array_equal(init.mask_ids_, [0, 1, 2])
    assert init.labels_.tolist() == [1, 0, 2, -1, 1]
    assert init.n_clusters_ == 3
    assert PrecomputedMasks(nested, pixels, overlap="largest").fit(X).labels_.tolist() == [
        0,
        0,
        1,
        -1,
        0,
    ]


def test_ties_go_to_the_earlier_mask():
    same = box(0, 2, 0, 2)
    for overlap in ("smallest", "largest", "first"):
        assert masks_to_labels([same, same.copy()], [[0, 0]], overlap=overlap).tolist() == [0]


def test_uncovered_nearest(nested):
    # Column 7 is uncovered; its nearest covered pixels are in column 6, mask 2.
    pixels = np.array([[7, 0], [7, 5]])
    assert masks_to_labels(nested, pixels, uncovered="nearest").tolist() == [2, 2]
    only = [box(0, 1, 0, 1)]
    assert masks_to_labels(only, [[7, 5]], uncovered="nearest").tolist() == [0]


def test_uncovered_nearest_matches_brute_force():
    rng = np.random.default_rng(1)
    image = np.where(rng.random((H, W)) < 0.2, rng.integers(0, 3, size=(H, W)), -1)
    image[0, 0] = 1
    rows, cols = np.mgrid[:H, :W]
    pixels = np.column_stack([cols.ravel(), rows.ravel()])
    got = masks_to_labels(image, pixels, uncovered="nearest")
    covered = np.argwhere(image >= 0)
    for (col, row), label in zip(pixels, got, strict=True):
        dist = np.hypot(covered[:, 0] - row, covered[:, 1] - col)
        nearest = covered[dist == dist.min()]
        assert label in {image[r, c] for r, c in nearest}


def test_every_mask_format_gives_the_same_labels(nested):
    pixels, X = pixels_and_X([[0, 0], [3, 4], [6, 1], [7, 0], [1, 1], [4, 5]])
    expected = PrecomputedMasks(nested, pixels).fit(X).labels_
    sam = [
        {"segmentation": m, "area": int(m.sum()), "predicted_iou": 0.9} for m in reversed(nested)
    ]
    # Reversed order: the smallest-mask rule does not depend on it, but mask j is now
    # mask 2 - j, and clusters are numbered by mask id.
    got = PrecomputedMasks(sam, pixels).fit(X)
    np.testing.assert_array_equal(got.labels_, np.where(expected >= 0, 2 - expected, -1))
    np.testing.assert_array_equal(got.mask_ids_, [0, 1, 2])
    stack = np.stack(nested)
    np.testing.assert_array_equal(PrecomputedMasks(stack, pixels).fit(X).labels_, expected)
    as_ints = [m.astype(np.uint8) for m in nested]
    np.testing.assert_array_equal(PrecomputedMasks(as_ints, pixels).fit(X).labels_, expected)
    image = label_image(nested)
    as_image = PrecomputedMasks(image, pixels).fit(X)
    np.testing.assert_array_equal(as_image.labels_, expected)
    np.testing.assert_array_equal(as_image.mask_ids_, [0, 1, 2])
    # Label values need not be 0..K-1; clusters are numbered in their increasing order.
    shifted = PrecomputedMasks(np.where(image >= 0, 10 * image + 5, -3), pixels).fit(X)
    np.testing.assert_array_equal(shifted.labels_, expected)
    np.testing.assert_array_equal(shifted.mask_ids_, [5, 15, 25])


def test_masks_covering_no_correspondence_are_dropped(nested):
    pixels, X = pixels_and_X([[6, 0], [6, 5]])
    init = PrecomputedMasks(nested, pixels).fit(X)
    assert init.labels_.tolist() == [0, 0] and init.n_clusters_ == 1
    np.testing.assert_array_equal(init.mask_ids_, [2])


@pytest.mark.parametrize(
    ("masks", "error", "match"),
    [
        ([], ValueError, "empty"),
        ([box(0, 1, 0, 1), np.zeros((3, 3), bool)], ValueError, "same shape"),
        (np.zeros((2, 2, H, W), bool), ValueError, "H x W"),
        (np.zeros((H, W)), TypeError, "integer label image"),
        ([np.full((H, W), 0.5)], TypeError, "boolean mask"),
        ([{"area": 3}], ValueError, "segmentation"),
        ([{"segmentation": {"counts": "x", "size": [H, W]}}], ValueError, "run-length"),
    ],
)
def test_bad_masks(masks, error, match):
    with pytest.raises(error, match=match):
        masks_to_labels(masks, [[0, 0]])


@pytest.mark.parametrize(
    ("pixels", "error", "match"),
    [
        ([[W, 0]], ValueError, "outside the 6 x 8"),
        ([[0, H]], ValueError, "outside"),
        ([[-1, 0]], ValueError, "outside"),
        ([[0.5, 1.0]], TypeError, "integer"),
        ([[np.nan, 1.0]], TypeError, "integer"),
        ([0, 1], ValueError, r"shape \(n, 2\)"),
        ([[0, 1, 2]], ValueError, r"shape \(n, 2\)"),
        (np.array([["a", "b"]]), TypeError, "integer"),
    ],
)
def test_bad_pixels(nested, pixels, error, match):
    with pytest.raises(error, match=match):
        masks_to_labels(nested, pixels)


def test_integral_float_pixels_are_accepted(nested):
    assert masks_to_labels(nested, [[1.0, 1.0]]).tolist() == [1]


def test_bad_rules_and_lengths(nested):
    pixels, X = pixels_and_X([[0, 0], [1, 1]])
    with pytest.raises(ValueError, match="overlap"):
        PrecomputedMasks(nested, pixels, overlap="newest").fit(X)
    with pytest.raises(ValueError, match="uncovered"):
        PrecomputedMasks(nested, pixels, uncovered="drop").fit(X)
    with pytest.raises(ValueError, match="one pixel per correspondence"):
        PrecomputedMasks(nested, pixels[:1]).fit(X)


def test_masks_are_parameters(nested):
    # Nothing is checked or copied in __init__; clone copies the parameters.
    bad = PrecomputedMasks("not masks", pixels=None)
    assert bad.get_params()["masks"] == "not masks"
    pixels, X = pixels_and_X([[0, 0]])
    init = PrecomputedMasks(nested, pixels)
    assert init.get_params()["masks"] is nested
    copy = clone(init)
    np.testing.assert_array_equal(copy.masks[1], nested[1])
    assert copy.fit(X).labels_.tolist() == [0]


def test_transform_accepts_only_the_fitted_rows(nested):
    pixels, X = pixels_and_X([[0, 0], [7, 0]])
    init = PrecomputedMasks(nested, pixels)
    assert init.fit_transform(X).toarray().tolist() == [[1.0], [0.0]]
    assert init.transform(X).toarray().tolist() == [[1.0], [0.0]]
    with pytest.raises(ValueError, match="fitted on"):
        init.transform(X[:1])


def test_precomputed_labels():
    X = np.random.default_rng(0).normal(size=(5, 6))
    init = PrecomputedLabels(np.array([7, 7, 3, -1, 3])).fit(X)
    assert init.labels_.tolist() == [1, 1, 0, -1, 0] and init.n_clusters_ == 2
    assert init.transform(X).toarray().sum(axis=0).tolist() == [2.0, 2.0]
    assert PrecomputedLabels([0.0, 1.0, 1.0, 0.0, 2.0]).fit_predict(X).tolist() == [0, 1, 1, 0, 2]
    with pytest.raises(ValueError, match="one label per correspondence"):
        PrecomputedLabels([0, 1]).fit(X)
    with pytest.raises(TypeError, match="integers"):
        PrecomputedLabels([0, 0.5, 1, 1, 1]).fit(X)
    with pytest.raises(ValueError, match="1-D"):
        PrecomputedLabels(np.zeros((5, 2), int)).fit(X)


def test_load_masks(tmp_path, nested):
    stack = np.stack(nested)
    np.save(tmp_path / "stack.npy", stack)
    np.testing.assert_array_equal(load_masks(tmp_path / "stack.npy"), stack)
    image = label_image(nested)
    np.save(tmp_path / "image.npy", image)
    np.testing.assert_array_equal(load_masks(tmp_path / "image.npy"), image)
    np.savez(tmp_path / "one.npz", whatever=stack)
    np.testing.assert_array_equal(load_masks(tmp_path / "one.npz"), stack)
    np.savez(tmp_path / "sam.npz", labels=image, masks=stack.astype(np.uint8))
    loaded = load_masks(tmp_path / "sam.npz")
    assert loaded.dtype == bool
    np.testing.assert_array_equal(loaded, stack)
    np.testing.assert_array_equal(load_masks(tmp_path / "sam.npz", key="labels"), image)
    # What the loader returns is what PrecomputedMasks takes.
    pixels, X = pixels_and_X([[0, 0], [6, 1]])
    from_file = PrecomputedMasks(load_masks(tmp_path / "stack.npy"), pixels).fit(X)
    assert from_file.labels_.tolist() == [0, 1]


def test_load_masks_errors(tmp_path, nested):
    np.savez(tmp_path / "two.npz", a=np.zeros((2, 2)), b=np.zeros((2, 2)))
    with pytest.raises(ValueError, match="pass key="):
        load_masks(tmp_path / "two.npz")
    with pytest.raises(KeyError, match="no array 'c'"):
        load_masks(tmp_path / "two.npz", key="c")
    np.save(tmp_path / "flat.npy", np.zeros(4))
    with pytest.raises(ValueError, match="H x W image"):
        load_masks(tmp_path / "flat.npy")
    with pytest.raises(ValueError, match=".npz files only"):
        load_masks(tmp_path / "flat.npy", key="masks")
    records = np.array([{"segmentation": nested[0]}], dtype=object)
    np.save(tmp_path / "sam.npy", records, allow_pickle=True)
    with pytest.raises(ValueError, match="pickle"):
        load_masks(tmp_path / "sam.npy")
    np.save(tmp_path / "counts.npy", np.full((2, H, W), 3))
    with pytest.raises(TypeError, match="boolean mask"):
        load_masks(tmp_path / "counts.npy")
