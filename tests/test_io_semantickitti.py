"""SemanticKITTI .label files (uint32, and nuScenes conversions' uint8) and moving masks."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from mmreg.io import (
    moving_from_labels,
    read_semantickitti_labels,
    semantickitti_mos_labels,
    write_semantickitti_labels,
)

uint16 = hnp.arrays(np.int64, st.integers(0, 60), elements=st.integers(0, 0xFFFF))


@given(semantic=uint16, data=st.data())
def test_uint32_round_trip(tmp_path_factory, semantic, data):
    instance = data.draw(hnp.arrays(np.int64, len(semantic), elements=st.integers(0, 0xFFFF)))
    path = tmp_path_factory.mktemp("labels") / "000000.label"
    write_semantickitti_labels(path, semantic, instance)
    assert path.stat().st_size == 4 * len(semantic)
    for n_points in (None, len(semantic)):
        back = read_semantickitti_labels(path, n_points=n_points)
        assert back.convention == "semantickitti"
        np.testing.assert_array_equal(back.semantic, semantic)
        np.testing.assert_array_equal(back.instance, instance)


def test_the_bytes_are_little_endian_instance_over_class(tmp_path):
    path = tmp_path / "a.label"
    write_semantickitti_labels(path, [251, 9, 0, 252], instance=[1, 0, 0, 0x1234])
    assert path.read_bytes() == bytes.fromhex("fb0001000900000000000000fc003412")
    # Without instances the upper half is zero.
    write_semantickitti_labels(path, [40])
    assert path.read_bytes() == bytes.fromhex("28000000")


def test_a_one_byte_file_is_told_by_the_point_count(tmp_path):
    # A nuScenes log converted to the SemanticKITTI layout: one uint8 a point.
    values = np.array([24, 31, 32, 39, 0, 9, 31, 17], dtype=np.uint8)
    path = tmp_path / "000000.label"
    values.tofile(path)
    labels = read_semantickitti_labels(path, n_points=8)
    assert labels.convention == "nuscenes"
    assert labels.instance is None
    assert labels.semantic.tolist() == values.tolist()
    # The same 8 bytes are two SemanticKITTI labels when the scan has 2 points.
    two = read_semantickitti_labels(path, n_points=2)
    assert two.convention == "semantickitti"
    assert two.semantic.tolist() == [31 << 8 | 24, 9 << 8 | 0]
    assert two.instance.tolist() == [39 << 8 | 32, 17 << 8 | 31]


def test_a_size_that_fits_neither_names_the_file(tmp_path):
    path = tmp_path / "000007.label"
    np.zeros(10, dtype=np.uint8).tofile(path)
    with pytest.raises(ValueError, match=r"000007\.label.*10 bytes.*neither.*7 points"):
        read_semantickitti_labels(path, n_points=7)
    np.zeros(7, dtype=np.uint8).tofile(path)
    with pytest.raises(ValueError, match=r"000007\.label.*not a multiple of 4.*n_points"):
        read_semantickitti_labels(path)


def test_reading_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.label"):
        read_semantickitti_labels(tmp_path / "missing.label")
    wrong = tmp_path / "labels.npy"
    wrong.write_bytes(b"\0" * 8)
    with pytest.raises(ValueError, match=r"extension '\.npy'"):
        read_semantickitti_labels(wrong)
    path = tmp_path / "a.label"
    path.write_bytes(b"\0" * 8)
    with pytest.raises(ValueError, match="n_points must be >= 0"):
        read_semantickitti_labels(path, n_points=-1)
    with pytest.raises(TypeError, match="n_points must be an integer"):
        read_semantickitti_labels(path, n_points=2.0)


@pytest.mark.parametrize(
    ("semantic", "instance", "error", "message"),
    [
        ([1, 70000], None, ValueError, r"\[0, 65535\]"),
        ([-1, 9], None, ValueError, r"\[0, 65535\]"),
        ([9, 9], [1, 1 << 16], ValueError, r"instance must lie in \[0, 65535\]"),
        ([9, 9], [1], ValueError, "instance has length 1 but semantic has 2"),
        ([9.5], None, TypeError, "integers"),
        ([[9]], None, ValueError, "1-D"),
    ],
)
def test_writing_errors_leave_no_file(tmp_path, semantic, instance, error, message):
    path = tmp_path / "a.label"
    with pytest.raises(error, match=message):
        write_semantickitti_labels(path, semantic, instance)
    assert not any(tmp_path.iterdir())


def test_mos_labels_of_tracks():
    labels = np.array([0, 0, 3, 3, 3, 8, -1, -1, 0])
    moving = np.array([0, 0, 1, 1, 1, 0, 1, 0, 1], dtype=bool)
    semantic, instance = semantickitti_mos_labels(labels, moving)
    # outliers: 0 whatever moving says; the static world may be flagged moving (a wrong
    # estimate) and is written as it is; a track at rest keeps its id.
    assert semantic.tolist() == [9, 9, 251, 251, 251, 9, 0, 0, 251]
    assert instance.tolist() == [0, 0, 3, 3, 3, 8, 0, 0, 0]


@given(
    labels=hnp.arrays(np.int64, st.integers(0, 40), elements=st.integers(-1, 9)),
    data=st.data(),
)
def test_mos_labels_written_and_read_give_the_moving_mask_back(tmp_path_factory, labels, data):
    moving = data.draw(hnp.arrays(bool, len(labels)))
    path = tmp_path_factory.mktemp("mos") / "000000.label"
    write_semantickitti_labels(path, *semantickitti_mos_labels(labels, moving))
    back = read_semantickitti_labels(path, n_points=len(labels))
    truth, ignore = moving_from_labels(back.semantic, back.convention)
    np.testing.assert_array_equal(ignore, labels < 0)
    np.testing.assert_array_equal(truth, moving & (labels >= 0))
    np.testing.assert_array_equal(back.instance, np.maximum(labels, 0))


@pytest.mark.parametrize(
    ("labels", "moving", "error", "message"),
    [
        ([1, 2], [True], ValueError, r"moving must have shape \(2,\)"),
        ([1.0, 2.0], [True, False], TypeError, "labels must be integers"),
        ([1, 2], [0.5, 1.0], TypeError, "moving must be booleans"),
        ([1, 1 << 16], [True, True], ValueError, "16 bits"),
    ],
)
def test_mos_labels_errors(labels, moving, error, message):
    with pytest.raises(error, match=message):
        semantickitti_mos_labels(labels, moving)


def test_semantickitti_moving_classes():
    semantic = np.arange(300)
    moving, ignore = moving_from_labels(semantic, "semantickitti")
    assert np.flatnonzero(moving).tolist() == list(range(251, 260))
    assert np.flatnonzero(ignore).tolist() == [0, 1]
    # A raw uint32 value (instance in the upper bits) is read by its class.
    raw = (np.array([5, 5, 5]) << 16) | np.array([252, 9, 1])
    moving, ignore = moving_from_labels(raw, "semantickitti")
    assert moving.tolist() == [True, False, False]
    assert ignore.tolist() == [False, False, True]


def test_nuscenes_moving_and_ego_body():
    semantic = np.arange(256)
    moving, ignore = moving_from_labels(semantic, "nuscenes")
    assert np.flatnonzero(moving).tolist() == list(range(32, 256))
    assert np.flatnonzero(ignore).tolist() == [31]


@pytest.mark.parametrize(
    ("semantic", "convention", "error", "message"),
    [
        ([1, 2], "kitti", ValueError, "convention must be one of"),
        ([1, 256], "nuscenes", ValueError, r"\[0, 255\]"),
        ([-1, 2], "semantickitti", ValueError, "from -1"),
        ([1.0], "nuscenes", TypeError, "integers"),
        ([[1]], "nuscenes", ValueError, "1-D"),
    ],
)
def test_moving_from_labels_errors(semantic, convention, error, message):
    with pytest.raises(error, match=message):
        moving_from_labels(semantic, convention)
