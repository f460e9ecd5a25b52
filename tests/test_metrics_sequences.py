"""Measures over a LiDAR log: moving_iou and tracking_scores."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from mmreg.metrics import dynamic_iou, moving_iou, tracking_scores

# --------------------------------------------------------------------------- moving_iou


@st.composite
def mask_frames(draw):
    """Per-frame (truth, prediction, ignore) boolean masks of random lengths."""
    frames = []
    for _ in range(draw(st.integers(1, 4))):
        n = draw(st.integers(0, 30))
        frames.append(tuple(draw(hnp.arrays(bool, n)) for _ in range(3)))
    return [list(column) for column in zip(*frames, strict=True)]


def _reference_iou(truth, pred, ignore):
    t, p, i = (np.concatenate(x) for x in (truth, pred, ignore))
    tp = np.sum(t & p & ~i)
    fp = np.sum(~t & p & ~i)
    fn = np.sum(t & ~p & ~i)
    return tp / (tp + fp + fn) if tp + fp + fn else np.nan


@given(frames=mask_frames())
def test_moving_iou_is_tp_over_tp_fp_fn_summed_over_frames(frames):
    truth, pred, ignore = frames
    np.testing.assert_equal(moving_iou(truth, pred, ignore=ignore), _reference_iou(*frames))


@given(frames=mask_frames(), seed=st.integers(0, 2**16))
def test_moving_iou_does_not_depend_on_the_order_of_points(frames, seed):
    truth, pred, ignore = frames
    rng = np.random.default_rng(seed)
    orders = [rng.permutation(len(t)) for t in truth]
    shuffled = [[x[o] for x, o in zip(column, orders, strict=True)] for column in frames]
    np.testing.assert_equal(
        moving_iou(*shuffled[:2], ignore=shuffled[2]), moving_iou(truth, pred, ignore=ignore)
    )


@given(frames=mask_frames())
def test_moving_iou_of_a_perfect_prediction_is_one(frames):
    truth, _, ignore = frames
    expected = 1.0 if any(np.any(t & ~i) for t, i in zip(truth, ignore, strict=True)) else np.nan
    np.testing.assert_equal(moving_iou(truth, truth, ignore=ignore), expected)


def test_moving_iou_sums_frames_instead_of_averaging_them():
    truth = [np.array([1, 0, 0, 0], bool), np.ones(8, bool)]
    pred = [np.array([0, 1, 0, 0], bool), np.ones(8, bool)]
    # Frame IoUs 0 and 1 (mean 0.5); the counts: TP 8, FP 1, FN 1.
    assert moving_iou(truth, pred) == pytest.approx(0.8)


def test_moving_iou_of_one_frame_agrees_with_dynamic_iou():
    rng = np.random.default_rng(0)
    truth, pred = rng.random(50) < 0.3, rng.random(50) < 0.4
    assert moving_iou(truth, pred) == dynamic_iou(truth, pred)["dynamic"]
    # A 2-D array is a list of frames.
    assert moving_iou(truth.reshape(5, 10), pred.reshape(5, 10)) == moving_iou(truth, pred)


@pytest.mark.parametrize(
    ("truth", "pred", "ignore", "error", "message"),
    [
        ([[1, 0], [1]], [[1, 0]], None, ValueError, "1 frame.*truth holds 2"),
        ([[1, 0], [1]], [[1, 0], [1, 1]], None, ValueError, r"y_pred_moving\[1\] has 2 points"),
        ([1, 0], [1, 2], None, ValueError, "booleans"),
        ([1, 0], ["a", "b"], None, TypeError, "booleans"),
        ([1, 0], [1, 0], [1], ValueError, "ignore has 1 points"),
        ([], [], None, ValueError, "no frames"),
    ],
)
def test_moving_iou_errors(truth, pred, ignore, error, message):
    with pytest.raises(error, match=message):
        moving_iou(truth, pred, ignore=ignore)


# --------------------------------------------------------------------------- tracking


def test_a_hand_counted_sequence():
    # Objects 4 and 9; points in the same places in every frame for readability.
    #              obj 4 obj 4 obj 4 obj 9 obj 9 world world
    truth = [
        [4, 4, 4, 9, 9, 0, 0],  # 0: 4 by track 1 (2 of 3), 9 by track 2
        [4, 4, 4, 9, 9, 0, 0],  # 1: 4 by track 2 (a switch), 9 by track 1 (a switch)
        [4, 4, 4, 0, 0, 0, 0],  # 2: 9 hidden; 4 by track 2; track 5 on the world
        [4, 4, 4, 9, 9, 0, 0],  # 3: 4 held by no track (1 of 3 each); 9 by track 1
        [4, 4, 4, 9, 9, 0, 0],  # 4: 4 by track 1 (back: a switch, a fragmentation)
    ]
    tracks = [
        [1, 1, 0, 2, 2, 0, 0],
        [2, 2, 2, 1, 1, 0, 0],
        [2, 2, 2, 0, 0, 5, 5],
        [1, 3, 0, 1, 1, 0, 0],
        [1, 1, 1, 1, 0, 3, 3],
    ]
    scores = tracking_scores(truth, tracks)
    assert scores.objects.tolist() == [4, 9]
    assert scores.matches.tolist() == [[1, 2], [2, 1], [2, 0], [0, 1], [1, 0]]
    assert scores.visible[:, 1].tolist() == [True, True, False, True, True]
    # Frame 4: track 1 holds 3 of object 4 and 1 of object 9's 2 points: one object per
    # track, so it goes to object 4 and object 9 is not found.
    assert scores.id_switches.tolist() == [2, 1]
    # Object 9 is missed only after its last find: no interruption.
    assert scores.fragmentations.tolist() == [1, 0]
    assert scores.found_share.tolist() == [0.8, 0.75]
    assert scores.n_tracks.tolist() == [2, 2, 2, 2, 2]
    # Frame 3: track 3 lies on object 4 (not false) but finds nothing (unmatched).
    assert scores.false_tracks.tolist() == [0, 0, 1, 0, 1]
    assert scores.unmatched_tracks.tolist() == [0, 0, 1, 1, 1]
    summary = scores.summary()
    assert summary == {
        "objects": 2,
        "frames": 5,
        "found_share": 7 / 9,
        "mean_found_share": 0.775,
        "id_switches": 3,
        "fragmentations": 1,
        "false_tracks": 2,
        "false_tracks_per_frame": 0.4,
        "unmatched_tracks": 3,
    }
    table = scores.per_object()
    assert table["frames_visible"].tolist() == [5, 4]
    assert table["first_frame"].tolist() == [0, 0] and table["last_frame"].tolist() == [4, 4]


@st.composite
def tracked_sequences(draw):
    """Per-frame true object ids and predicted track ids (a noisy copy), and ignore masks."""
    n_objects = draw(st.integers(1, 4))
    truth, tracks, ignore = [], [], []
    for _ in range(draw(st.integers(1, 6))):
        n = draw(st.integers(0, 25))
        t = draw(hnp.arrays(np.int64, n, elements=st.integers(-1, n_objects)))
        p = draw(hnp.arrays(np.int64, n, elements=st.integers(-1, 5)))
        keep = draw(hnp.arrays(bool, n))
        truth.append(t)
        tracks.append(np.where(keep, np.maximum(t, 0), p))
        ignore.append(draw(hnp.arrays(bool, n, elements=st.sampled_from([False, False, True]))))
    return truth, tracks, ignore


def _same_scores(a, b):
    assert a.objects.tolist() == b.objects.tolist()
    np.testing.assert_array_equal(a.visible, b.visible)
    np.testing.assert_array_equal(a.found, b.found)
    for name in ("id_switches", "fragmentations", "n_tracks", "false_tracks"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


@given(
    sequence=tracked_sequences(),
    names=st.lists(st.integers(1, 10**6), min_size=5, max_size=5, unique=True),
)
def test_renaming_the_tracks_changes_nothing(sequence, names):
    truth, tracks, ignore = sequence
    rename = np.array([0, *names])
    renamed = [np.where(p >= 1, rename[np.maximum(p, 0)], p) for p in tracks]
    a = tracking_scores(truth, tracks, ignore=ignore)
    b = tracking_scores(truth, renamed, ignore=ignore)
    _same_scores(a, b)
    np.testing.assert_array_equal(b.matches, np.where(a.found, rename[a.matches], 0))


@given(sequence=tracked_sequences(), seed=st.integers(0, 2**16))
def test_the_order_of_points_changes_nothing_but_ties(sequence, seed):
    rng = np.random.default_rng(seed)
    orders = [rng.permutation(len(t)) for t in sequence[0]]
    shuffled = [[x[o] for x, o in zip(column, orders, strict=True)] for column in sequence]
    a = tracking_scores(*sequence[:2], ignore=sequence[2])
    b = tracking_scores(*shuffled[:2], ignore=shuffled[2])
    for name in ("visible", "n_tracks", "false_tracks"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    # A tie (two tracks holding as many points of an object, or two objects of a track)
    # is broken by which point comes first; without one, nothing changes.
    if not _has_ties(*sequence):
        _same_scores(a, b)


def _has_ties(truth, tracks, ignore):
    for t, p, i in zip(truth, tracks, ignore, strict=True):
        both = ~i & (t >= 1) & (p >= 1)
        pairs, shared = np.unique(np.c_[t[both], p[both]], axis=0, return_counts=True)
        for side in (0, 1):
            for key in np.unique(pairs[:, side]):
                counts = np.sort(shared[pairs[:, side] == key])
                if len(counts) > 1 and counts[-1] == counts[-2]:
                    return True
    return False


@given(sequence=tracked_sequences(), data=st.data())
def test_perfect_tracks_have_no_switches_nor_false_tracks(sequence, data):
    truth, _, ignore = sequence
    names = np.array([0, *data.draw(st.permutations(range(1, 5)))])
    perfect = [np.where(t >= 1, names[np.maximum(t, 0)], 0) for t in truth]
    scores = tracking_scores(truth, perfect, ignore=ignore)
    assert scores.found.sum() == scores.visible.sum()
    assert not scores.id_switches.any() and not scores.fragmentations.any()
    assert not scores.false_tracks.any() and not scores.unmatched_tracks.any()


@given(
    n_frames=st.integers(2, 8),
    switch_at=st.integers(1, 7),
    size=st.integers(1, 6),
    tracks=st.lists(st.integers(1, 50), min_size=2, max_size=2, unique=True),
)
def test_a_handover_is_one_switch(n_frames, switch_at, size, tracks):
    switch_at = min(switch_at, n_frames - 1)
    first, second = tracks
    truth = [np.r_[np.full(size, 3), np.zeros(4, int)] for _ in range(n_frames)]
    pred = [
        np.r_[np.full(size, first if k < switch_at else second), np.zeros(4, int)]
        for k in range(n_frames)
    ]
    scores = tracking_scores(truth, pred)
    assert scores.id_switches.tolist() == [1]
    assert scores.fragmentations.tolist() == [0]
    # Handing it back is a second switch.
    pred[-1][:size] = first if switch_at < n_frames - 1 else pred[-1][:size]
    expected = 2 if switch_at < n_frames - 1 else 1
    assert tracking_scores(truth, pred).id_switches.tolist() == [expected]


def test_a_switch_is_counted_across_frames_the_object_is_missed_or_hidden():
    truth = [[1, 1], [1, 1], [0, 0], [1, 1]]
    pred = [[5, 5], [0, 0], [0, 0], [6, 6]]
    scores = tracking_scores(truth, pred)
    assert scores.id_switches.tolist() == [1]
    assert scores.fragmentations.tolist() == [1]  # missed in frame 1, hidden in frame 2


def test_min_overlap():
    truth = [[1, 1, 1, 1, 1, 0, 0, 0, 0, 0]]
    pred = [[2, 2, 2, 3, 3, 2, 2, 4, 4, 4]]  # track 2: 3 of 5 of object 1, 3 of 5 points on it
    assert tracking_scores(truth, pred).found.tolist() == [[True]]
    assert tracking_scores(truth, pred, min_overlap=0.7).found.tolist() == [[False]]
    # False tracks: track 4 (none on the object); at 0.7 track 2 (3 of 5) too.
    assert tracking_scores(truth, pred).false_tracks.tolist() == [1]
    assert tracking_scores(truth, pred, min_overlap=0.7).false_tracks.tolist() == [2]


def test_ignored_points_are_left_out():
    truth = [[1, 1, 1, 0, 0]]
    pred = [[2, 0, 0, 3, 3]]
    ignore = [[False, True, True, True, True]]
    scores = tracking_scores(truth, pred, ignore=ignore)
    assert scores.found.tolist() == [[True]]
    assert scores.n_tracks.tolist() == [1] and scores.false_tracks.tolist() == [0]


def test_no_objects():
    scores = tracking_scores([[0, 0], [-1]], [[1, 0], [0]])
    assert scores.objects.tolist() == [] and scores.matches.shape == (2, 0)
    summary = scores.summary()
    assert np.isnan(summary["found_share"]) and summary["false_tracks"] == 1


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"min_overlap": 0}, ValueError, r"\(0, 1\]"),
        ({"min_overlap": 1.5}, ValueError, r"\(0, 1\]"),
        ({"min_overlap": "half"}, TypeError, "number"),
        ({"ignore": [[0, 1]]}, ValueError, "ignore holds 1 frame"),
    ],
)
def test_tracking_argument_errors(kwargs, error, message):
    with pytest.raises(error, match=message):
        tracking_scores([[1, 1], [1]], [[1, 1], [1]], **kwargs)


@pytest.mark.parametrize(
    ("truth", "pred", "error", "message"),
    [
        ([[1, 1], [1]], [[1, 1], [1, 1]], ValueError, r"track_ids\[1\] has 2 points"),
        ([[1.5, 1]], [[1, 1]], TypeError, "integers"),
        ([[1, 1]], [[True, False]], TypeError, "integers"),
        ([[1, np.nan]], [[1, 1]], ValueError, "NaN"),
    ],
)
def test_tracking_input_errors(truth, pred, error, message):
    with pytest.raises(error, match=message):
        tracking_scores(truth, pred)
