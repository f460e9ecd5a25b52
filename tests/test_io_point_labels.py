"""write_point_cloud's per-point ``label`` property, read back by Open3D and by hand."""

import numpy as np
import pytest

from mmreg.io import read_point_cloud, write_point_cloud


@pytest.mark.parametrize("suffix", [".ply", ".pcd"])
def test_open3d_reads_the_labels_back(tmp_path, suffix):
    o3d = pytest.importorskip("open3d")
    rng = np.random.default_rng(0)
    points = rng.normal(size=(40, 3))
    labels = rng.integers(-1, 6, size=40)
    colors = rng.uniform(size=(40, 3))
    path = tmp_path / f"clusters{suffix}"
    write_point_cloud(path, points, colors=colors, labels=labels)
    cloud = o3d.t.io.read_point_cloud(str(path))
    np.testing.assert_array_equal(cloud.point["label"].numpy().ravel(), labels)
    # mmreg's own reader ignores the label and still returns points and colours.
    same, rgb = read_point_cloud(path, colors=True)
    np.testing.assert_allclose(same, points, atol=1e-6 if suffix == ".pcd" else 0)
    np.testing.assert_allclose(rgb, np.round(colors * 255) / 255)


def test_ply_header_and_rows_by_hand(tmp_path):
    path = tmp_path / "c.ply"
    write_point_cloud(path, [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]], labels=[7, -1])
    data = path.read_bytes()
    header, body = data.split(b"end_header\n")
    assert b"property int label" in header
    rows = np.frombuffer(body, dtype=[("xyz", "<f8", 3), ("label", "<i4")])
    assert rows["label"].tolist() == [7, -1]
    assert rows["xyz"].tolist() == [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]


@pytest.mark.parametrize(
    ("labels", "message"),
    [([0.5, 1], "integers"), ([0], "shape"), ([2**31, 0], "32 bits"), (["a", "b"], "integers")],
)
def test_bad_labels(tmp_path, labels, message):
    with pytest.raises(ValueError, match=message):
        write_point_cloud(tmp_path / "c.ply", np.zeros((2, 3)), labels=labels)


def test_xyz_holds_no_labels(tmp_path):
    with pytest.raises(ValueError, match="no labels"):
        write_point_cloud(tmp_path / "c.xyz", np.zeros((2, 3)), labels=[0, 1])
