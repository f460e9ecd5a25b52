"""Tests of mmreg.io: round trips of every format, bad input, atomic writes."""

import json

import numpy as np
import pytest

from mmreg.io import (
    atomic_write,
    read_correspondences,
    read_labels,
    read_motions,
    read_point_cloud,
    write_correspondences,
    write_labels,
    write_motions,
    write_point_cloud,
)


@pytest.fixture
def X():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(25, 3)) * 7
    return np.hstack([a, a + rng.normal(size=(25, 3))])


def _listing(folder):
    return sorted(p.name for p in folder.iterdir())


# --------------------------------------------------------------------------- correspondences
@pytest.mark.parametrize("ext", [".npy", ".npz", ".csv", ".txt"])
def test_correspondences_round_trip_exact(tmp_path, X, ext):
    path = tmp_path / f"pairs{ext}"
    write_correspondences(path, X)
    np.testing.assert_array_equal(read_correspondences(path), X)
    assert _listing(tmp_path) == [path.name]


def test_csv_has_header_and_str_path(tmp_path, X):
    path = tmp_path / "pairs.csv"
    write_correspondences(str(path), X)
    assert path.read_text().splitlines()[0] == "ax,ay,az,bx,by,bz"
    np.testing.assert_array_equal(read_correspondences(str(path)), X)


@pytest.mark.parametrize(
    "text",
    [
        "1,2,3,4,5,6\n7,8,9,10,11,12\n",
        "ax,ay,az,bx,by,bz\n1,2,3,4,5,6\n7,8,9,10,11,12\n",
        "1 2 3 4 5 6\n7 8 9 10 11 12\n",
        "a_x\ta_y\ta_z\tb_x\tb_y\tb_z\n1\t2\t3\t4\t5\t6\n7\t8\t9\t10\t11\t12\n",
        "# comment\n\n1, 2, 3, 4, 5, 6\n7,  8,9,10,11,12\n",
        "1  2\t3 4 5 6\r\n7 8 9 10 11 12\r\n",
        "\ufeffax,ay,az,bx,by,bz\n1,2,3,4,5,6\n\n7,8,9,10,11,12\n  \n",
    ],
)
def test_text_delimiters_and_headers(tmp_path, text):
    path = tmp_path / "pairs.txt"
    path.write_text(text)
    np.testing.assert_array_equal(read_correspondences(path), np.arange(1.0, 13).reshape(2, 6))


def test_text_without_a_final_line_break_may_be_cut_short(tmp_path):
    path = tmp_path / "pairs.txt"
    path.write_text("1 2 3 4 5 6\n7 8 9 10 11 12")
    with pytest.raises(ValueError, match="pairs.txt: the last line does not end with a line break"):
        read_correspondences(path)


def test_single_row_text(tmp_path):
    path = tmp_path / "one.csv"
    path.write_text("1,2,3,4,5,6\n")
    assert read_correspondences(path).shape == (1, 6)


def test_npz_with_a_and_b(tmp_path, X):
    path = tmp_path / "pairs.npz"
    np.savez(path, a=X[:, :3], b=X[:, 3:])
    np.testing.assert_array_equal(read_correspondences(path), X)


def test_integer_npy_is_read_as_float(tmp_path):
    path = tmp_path / "ints.npy"
    np.save(path, np.arange(12).reshape(2, 6))
    X = read_correspondences(path)
    assert X.dtype == float and X[1, 0] == 6.0


@pytest.mark.parametrize("cloud_ext", [".ply", ".pcd", ".xyz"])
@pytest.mark.parametrize("target_ext", [".ply", ".npy", ".csv"])
def test_point_cloud_with_target(tmp_path, X, cloud_ext, target_ext):
    a, b = X[:, :3], X[:, 3:]
    source = tmp_path / f"source{cloud_ext}"
    write_point_cloud(source, a)
    target = tmp_path / f"target{target_ext}"
    if target_ext == ".ply":
        write_point_cloud(target, b)
    elif target_ext == ".npy":
        np.save(target, b)
    else:
        np.savetxt(target, b, delimiter=",", fmt="%.17g")
    result = read_correspondences(source, target=target)
    # .pcd stores float32 coordinates, the others round-trip exactly.
    atol = 1e-5 * np.abs(a).max() if cloud_ext == ".pcd" else 0.0
    np.testing.assert_allclose(result[:, :3], a, rtol=0, atol=atol)
    np.testing.assert_array_equal(result[:, 3:], b)


@pytest.mark.parametrize("flow_ext", [".npy", ".csv", ".txt"])
def test_point_cloud_with_flow(tmp_path, X, flow_ext):
    a, b = X[:, :3], X[:, 3:]
    source = tmp_path / "source.ply"
    write_point_cloud(source, a)
    flow = tmp_path / f"flow{flow_ext}"
    if flow_ext == ".npy":
        np.save(flow, b - a)
    else:
        np.savetxt(flow, b - a, delimiter="," if flow_ext == ".csv" else " ", fmt="%.17g")
    result = read_correspondences(source, flow=flow)
    np.testing.assert_array_equal(result[:, :3], a)
    np.testing.assert_array_equal(result[:, 3:], a + (b - a))


# --------------------------------------------------------------------------- bad input
def test_missing_file_names_it(tmp_path):
    with pytest.raises(FileNotFoundError, match="absent.npy"):
        read_correspondences(tmp_path / "absent.npy")
    for reader in (read_labels, read_motions, read_point_cloud):
        with pytest.raises(FileNotFoundError, match="absent.xyz"):
            reader(tmp_path / "absent.xyz")


def test_folder_is_not_a_file(tmp_path):
    folder = tmp_path / "pairs.npy"
    folder.mkdir()
    with pytest.raises(ValueError, match="pairs.npy: is a folder"):
        read_correspondences(folder)


def test_path_of_wrong_type():
    with pytest.raises(TypeError, match="path"):
        read_correspondences(42)


@pytest.mark.parametrize("name", ["pairs.json", "pairs", "pairs.ply.gz"])
def test_unknown_extension(tmp_path, name):
    path = tmp_path / name
    path.write_text("1,2,3,4,5,6\n")
    with pytest.raises(ValueError, match="unknown extension"):
        read_correspondences(path)
    with pytest.raises(ValueError, match="unknown extension"):
        write_correspondences(tmp_path / "out.json", np.zeros((1, 6)))


@pytest.mark.parametrize("ext", [".npy", ".npz"])
def test_corrupt_binary(tmp_path, ext):
    path = tmp_path / f"broken{ext}"
    path.write_bytes(b"\x93NUMPY garbage that is not an array" * 3)
    with pytest.raises(ValueError, match=f"broken\\{ext}.*corrupt"):
        read_correspondences(path)


def test_truncated_npy(tmp_path, X):
    path = tmp_path / "cut.npy"
    np.save(path, X)
    path.write_bytes(path.read_bytes()[:-40])
    with pytest.raises(ValueError, match="cut.npy"):
        read_correspondences(path)


def test_object_npy_refused(tmp_path):
    path = tmp_path / "objects.npy"
    np.save(path, np.array([{"a": 1}, None], dtype=object), allow_pickle=True)
    with pytest.raises(ValueError, match="objects.npy.*Python objects"):
        read_correspondences(path)


def test_text_npy_is_a_type_error(tmp_path):
    path = tmp_path / "words.npy"
    np.save(path, np.array([["x"] * 6]))
    with pytest.raises(TypeError, match="words.npy.*numeric"):
        read_correspondences(path)


@pytest.mark.parametrize(
    "array",
    [np.zeros((4, 5)), np.zeros(6), np.zeros((2, 3, 6)), np.zeros((4, 3))],
    ids=["5cols", "1d", "3d", "3cols"],
)
def test_wrong_shape(tmp_path, array):
    path = tmp_path / "shape.npy"
    np.save(path, array)
    with pytest.raises(ValueError, match=r"shape.npy.*shape \(n, 6\)"):
        read_correspondences(path)


def test_no_rows(tmp_path):
    path = tmp_path / "empty.npy"
    np.save(path, np.zeros((0, 6)))
    with pytest.raises(ValueError, match="empty.npy.*no rows"):
        read_correspondences(path)
    for text in ("", "ax,ay,az,bx,by,bz\n", "# only a comment\n\n"):
        csv = tmp_path / "empty.csv"
        csv.write_text(text)
        with pytest.raises(ValueError, match="empty.csv.*no rows"):
            read_correspondences(csv)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite(tmp_path, X, bad):
    X = X.copy()
    X[3, 4] = bad
    path = tmp_path / "nan.npy"
    np.save(path, X)
    with pytest.raises(ValueError, match="nan.npy.*NaN or infinity.*row 3"):
        read_correspondences(path)
    csv = tmp_path / "nan.csv"
    np.savetxt(csv, X, delimiter=",")
    with pytest.raises(ValueError, match="nan.csv.*NaN or infinity"):
        read_correspondences(csv)


def test_ragged_csv(tmp_path):
    path = tmp_path / "ragged.csv"
    path.write_text("1,2,3,4,5,6\n1,2,3,4,5\n")
    with pytest.raises(ValueError, match="ragged.csv"):
        read_correspondences(path)


def test_text_in_data_row(tmp_path):
    path = tmp_path / "words.csv"
    path.write_text("1,2,3,4,5,6\n1,2,three,4,5,6\n")
    with pytest.raises(TypeError, match="words.csv.*not a number"):
        read_correspondences(path)


def test_binary_file_named_csv(tmp_path):
    path = tmp_path / "binary.csv"
    path.write_bytes(bytes(range(128, 256)) * 4)
    with pytest.raises(ValueError, match="binary.csv.*not a text file"):
        read_correspondences(path)


def test_npz_without_known_keys(tmp_path):
    path = tmp_path / "keys.npz"
    np.savez(path, points=np.zeros((2, 6)))
    with pytest.raises(ValueError, match=r"keys.npz.*'X'.*found keys \['points'\]"):
        read_correspondences(path)


def test_npz_a_b_mismatched_lengths(tmp_path):
    path = tmp_path / "mismatch.npz"
    np.savez(path, a=np.zeros((3, 3)), b=np.zeros((4, 3)))
    with pytest.raises(ValueError, match="mismatch.npz.*3 rows.*4"):
        read_correspondences(path)


def test_point_cloud_needs_exactly_one_partner(tmp_path, X):
    source = tmp_path / "cloud.ply"
    write_point_cloud(source, X[:, :3])
    np.save(tmp_path / "b.npy", X[:, 3:])
    with pytest.raises(ValueError, match="cloud.ply.*exactly one.*neither"):
        read_correspondences(source)
    with pytest.raises(ValueError, match="cloud.ply.*exactly one.*both"):
        read_correspondences(source, target=tmp_path / "b.npy", flow=tmp_path / "b.npy")


def test_target_of_other_length(tmp_path, X):
    source = tmp_path / "cloud.ply"
    write_point_cloud(source, X[:, :3])
    np.save(tmp_path / "short.npy", X[:-1, 3:])
    with pytest.raises(ValueError, match="short.npy.*24 points.*25"):
        read_correspondences(source, target=tmp_path / "short.npy")


def test_missing_or_bad_flow_names_it(tmp_path, X):
    source = tmp_path / "cloud.ply"
    write_point_cloud(source, X[:, :3])
    with pytest.raises(FileNotFoundError, match="nowhere.npy"):
        read_correspondences(source, flow=tmp_path / "nowhere.npy")
    flow = X[:, 3:] - X[:, :3]
    flow[0, 0] = np.nan
    np.save(tmp_path / "nanflow.npy", flow)
    with pytest.raises(ValueError, match="nanflow.npy.*the flow.*NaN"):
        read_correspondences(source, flow=tmp_path / "nanflow.npy")
    np.save(tmp_path / "wide.npy", np.zeros((25, 4)))
    with pytest.raises(ValueError, match=r"wide.npy.*the flow.*\(n, 3\)"):
        read_correspondences(source, flow=tmp_path / "wide.npy")


def test_target_or_flow_with_array_file(tmp_path, X):
    path = tmp_path / "pairs.npy"
    np.save(path, X)
    with pytest.raises(ValueError, match="pairs.npy.*only apply"):
        read_correspondences(path, flow=path)


@pytest.mark.parametrize("ext", [".ply", ".pcd"])
def test_corrupt_point_cloud(tmp_path, ext):
    path = tmp_path / f"broken{ext}"
    path.write_bytes(b"not a point cloud\x00\x01\x02")
    with pytest.raises(ValueError, match=f"broken\\{ext}.*no points"):
        read_point_cloud(path)
    with pytest.raises(ValueError, match=f"broken\\{ext}"):
        read_correspondences(path, flow=path)


def test_malformed_xyz_line(tmp_path):
    path = tmp_path / "broken.xyz"
    path.write_text("1 2 3\n4 5\n")
    with pytest.raises(ValueError, match="broken.xyz"):
        read_point_cloud(path)


def test_write_rejects_bad_arrays(tmp_path):
    with pytest.raises(ValueError, match=r"shape \(n, 6\)"):
        write_correspondences(tmp_path / "x.npy", np.zeros((3, 4)))
    with pytest.raises(ValueError, match="NaN"):
        write_correspondences(tmp_path / "x.npy", np.full((3, 6), np.nan))
    assert _listing(tmp_path) == []


# --------------------------------------------------------------------------- labels
@pytest.mark.parametrize("ext", [".npy", ".csv", ".txt"])
def test_labels_round_trip(tmp_path, ext):
    labels = np.array([0, 3, 3, -1, 2, 10])
    path = tmp_path / f"labels{ext}"
    write_labels(path, labels)
    result = read_labels(path)
    np.testing.assert_array_equal(result, labels)
    assert result.dtype == np.intp and result.ndim == 1


def test_labels_text_variants(tmp_path):
    path = tmp_path / "labels.csv"
    path.write_text("cluster\n1\n2\n-1\n")
    np.testing.assert_array_equal(read_labels(path), [1, 2, -1])
    path.write_text("1.0\n2.0\n")
    np.testing.assert_array_equal(read_labels(path), [1, 2])


def test_bad_labels(tmp_path):
    path = tmp_path / "frac.npy"
    np.save(path, np.array([0.5, 1.0]))
    with pytest.raises(TypeError, match="frac.npy.*integers"):
        read_labels(path)
    path = tmp_path / "nan.npy"
    np.save(path, np.array([0.0, np.nan]))
    with pytest.raises(ValueError, match="nan.npy.*NaN"):
        read_labels(path)
    path = tmp_path / "table.csv"
    path.write_text("1,2\n3,4\n")
    with pytest.raises(ValueError, match="table.csv.*1-D"):
        read_labels(path)
    with pytest.raises(ValueError, match="unknown extension"):
        write_labels(tmp_path / "x.json", [1])
    with pytest.raises(TypeError, match="integers"):
        write_labels(tmp_path / "x.npy", [0.5])


# --------------------------------------------------------------------------- motions
@pytest.fixture
def motions():
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(3)
    rotations = Rotation.random(4, random_state=3).as_matrix()
    rotations[0] = np.eye(3)
    translations = rng.normal(size=(4, 3))
    return rotations, translations


def test_motions_round_trip_exact(tmp_path, motions):
    rotations, translations = motions
    path = tmp_path / "motions.json"
    sigmas = np.array([0.01, 0.1 / 3, 0.2, 1e-9])
    write_motions(
        path, rotations, translations, sigmas=sigmas, sizes=[100, 7, 8, 9],
        moving=[False, True, True, True],
    )  # fmt: skip
    result = read_motions(path)
    np.testing.assert_array_equal(result["rotations"], rotations)
    np.testing.assert_array_equal(result["translations"], translations)
    np.testing.assert_array_equal(result["sigmas"], sigmas)
    np.testing.assert_array_equal(result["sizes"], [100, 7, 8, 9])
    np.testing.assert_array_equal(result["moving"], [False, True, True, True])
    np.testing.assert_array_equal(result["labels"], np.arange(4))
    assert result["transforms"].shape == (4, 4, 4)
    np.testing.assert_array_equal(result["transforms"][:, :3, :3], rotations)
    np.testing.assert_array_equal(result["transforms"][:, :3, 3], translations)
    np.testing.assert_array_equal(result["transforms"][:, 3], [[0, 0, 0, 1]] * 4)
    assert result["rotation_angles_deg"][0] == 0.0


def test_motions_json_layout(tmp_path, motions):
    rotations, translations = motions
    path = tmp_path / "motions.json"
    write_motions(path, rotations, translations)
    records = json.loads(path.read_text())
    assert isinstance(records, list) and len(records) == 4
    assert set(records[1]) == {
        "label", "transform", "rotation", "translation", "rotation_angle_deg", "sigma",
        "size", "moving",
    }  # fmt: skip
    assert records[1]["label"] == 1
    assert records[1]["sigma"] is None and records[1]["moving"] is None
    np.testing.assert_array_equal(np.array(records[2]["transform"])[:3, 3], translations[2])
    angle = np.degrees(np.arccos((np.trace(rotations[1]) - 1) / 2))
    assert records[1]["rotation_angle_deg"] == pytest.approx(angle, abs=1e-9)
    result = read_motions(path)
    assert result["sigmas"] is None and result["sizes"] is None and result["moving"] is None


def test_unknown_sigmas_are_null(tmp_path, motions):
    rotations, translations = motions
    path = tmp_path / "motions.json"
    write_motions(path, rotations, translations, sigmas=[0.1, np.nan, np.inf, 0.2])
    assert [r["sigma"] for r in json.loads(path.read_text())] == [0.1, None, None, 0.2]
    sigmas = read_motions(path)["sigmas"]
    np.testing.assert_array_equal(sigmas, [0.1, np.nan, np.nan, 0.2])


def test_motions_from_transform_only(tmp_path):
    path = tmp_path / "hand.json"
    transform = [[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]]
    path.write_text(json.dumps([{"transform": transform}]))
    result = read_motions(path)
    np.testing.assert_array_equal(result["translations"], [[1, 2, 3]])
    assert result["rotation_angles_deg"][0] == pytest.approx(90.0, abs=1e-9)


def test_empty_motions(tmp_path):
    path = tmp_path / "none.json"
    write_motions(path, np.zeros((0, 3, 3)), np.zeros((0, 3)))
    result = read_motions(path)
    assert result["rotations"].shape == (0, 3, 3) and result["transforms"].shape == (0, 4, 4)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("{not json", "not valid JSON"),
        ('{"rotation": 1}', "list of motion objects"),
        ('[{"rotation": [[1, 0], [0, 1]], "translation": [0, 0, 0]}]', "shape"),
        ('[{"translation": [0, 0, 0]}]', "motion 0 is malformed"),
        ('[{"transform": [[1, 0, 0, 0]]}]', "motion 0 is malformed"),
        ('[{"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": ["a", 0, 0]}]', "malformed"),
        ('[{"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [NaN, 0, 0]}]', "NaN"),
        (
            '[{"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [0,0,0], "size": 3},'
            ' {"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [0,0,0]}]',
            "motion 1 has no 'size'",
        ),
    ],
)
def test_bad_motions_file(tmp_path, text, problem):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=f"bad.json.*{problem}"):
        read_motions(path)


def test_write_motions_rejects_bad_input(tmp_path, motions):
    rotations, translations = motions
    with pytest.raises(ValueError, match="translations must have shape"):
        write_motions(tmp_path / "m.json", rotations, translations[:2])
    with pytest.raises(ValueError, match="rotations must have shape"):
        write_motions(tmp_path / "m.json", rotations[:, :2], translations)
    with pytest.raises(ValueError, match="sizes must have shape"):
        write_motions(tmp_path / "m.json", rotations, translations, sizes=[1, 2])
    with pytest.raises(ValueError, match="finite"):
        write_motions(tmp_path / "m.json", rotations * np.nan, translations)
    with pytest.raises(TypeError, match="moving must be booleans"):
        write_motions(tmp_path / "m.json", rotations, translations, moving=[1, 0, 1, 0])
    assert _listing(tmp_path) == []


# --------------------------------------------------------------------------- point clouds
@pytest.mark.parametrize("ext", [".ply", ".pcd", ".xyz"])
def test_point_cloud_round_trip(tmp_path, X, ext):
    points = X[:, :3]
    path = tmp_path / f"cloud{ext}"
    write_point_cloud(path, points)
    result = read_point_cloud(path)
    assert result.shape == points.shape
    atol = 1e-5 * np.abs(points).max() if ext == ".pcd" else 0.0
    np.testing.assert_allclose(result, points, rtol=0, atol=atol)
    assert _listing(tmp_path) == [path.name]
    points_again, colors = read_point_cloud(path, colors=True)
    assert colors is None


@pytest.mark.parametrize("ext", [".ply", ".pcd"])
def test_point_cloud_colours(tmp_path, X, ext):
    rng = np.random.default_rng(1)
    colors = rng.integers(0, 256, size=(len(X), 3)) / 255.0  # exact in 8 bits
    path = tmp_path / f"coloured{ext}"
    write_point_cloud(path, X[:, :3], colors=colors)
    points, read_colors = read_point_cloud(path, colors=True)
    assert points.shape == read_colors.shape == (len(X), 3)
    np.testing.assert_allclose(read_colors, colors, rtol=0, atol=1e-6)
    assert read_colors.min() >= 0 and read_colors.max() <= 1


def test_point_cloud_from_array_files(tmp_path, X):
    np.save(tmp_path / "points.npy", X[:, :3])
    np.testing.assert_array_equal(read_point_cloud(tmp_path / "points.npy"), X[:, :3])


def test_write_point_cloud_rejects_bad_input(tmp_path, X):
    points = X[:, :3]
    with pytest.raises(ValueError, match="hold no colours"):
        write_point_cloud(tmp_path / "c.xyz", points, colors=np.zeros_like(points))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        write_point_cloud(tmp_path / "c.ply", points, colors=np.full_like(points, 2.0))
    with pytest.raises(ValueError, match="one colour per point"):
        write_point_cloud(tmp_path / "c.ply", points, colors=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="unknown extension"):
        write_point_cloud(tmp_path / "c.obj", points)
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        write_point_cloud(tmp_path / "c.ply", X)
    assert _listing(tmp_path) == []


# --------------------------------------------------------------------------- atomic writes
def test_atomic_write_leaves_nothing_when_the_writer_fails(tmp_path):
    path = tmp_path / "out.bin"
    with pytest.raises(RuntimeError, match="mid-way"), atomic_write(path) as handle:
        handle.write(b"half of the data")
        raise RuntimeError("mid-way")
    assert _listing(tmp_path) == []


def test_atomic_write_keeps_the_old_file_when_the_writer_fails(tmp_path):
    path = tmp_path / "out.txt"
    path.write_text("old")
    with pytest.raises(RuntimeError), atomic_write(path, "w") as handle:
        handle.write("new and incomplete")
        raise RuntimeError("mid-way")
    assert path.read_text() == "old"
    assert _listing(tmp_path) == ["out.txt"]
    with atomic_write(path, "w") as handle:
        handle.write("new")
    assert path.read_text() == "new"
    assert _listing(tmp_path) == ["out.txt"]


def test_atomic_write_gives_usual_permissions(tmp_path):
    import os
    import stat

    umask = os.umask(0o022)
    try:
        with atomic_write(tmp_path / "new.bin") as handle:
            handle.write(b"x")
    finally:
        os.umask(umask)
    assert stat.S_IMODE((tmp_path / "new.bin").stat().st_mode) == 0o644
    (tmp_path / "new.bin").chmod(0o640)
    with atomic_write(tmp_path / "new.bin") as handle:
        handle.write(b"y")
    assert stat.S_IMODE((tmp_path / "new.bin").stat().st_mode) == 0o640


def test_atomic_write_bad_arguments(tmp_path):
    with (
        pytest.raises(FileNotFoundError, match="does not exist"),
        atomic_write(tmp_path / "missing" / "out.bin"),
    ):
        pass
    with pytest.raises(ValueError, match="mode"), atomic_write(tmp_path / "x", "r"):
        pass
    (tmp_path / "folder").mkdir()
    with pytest.raises(ValueError, match="is a folder"), atomic_write(tmp_path / "folder"):
        pass


@pytest.mark.parametrize("ext", [".ply", ".pcd"])
@pytest.mark.parametrize("with_colors", [False, True])
def test_point_clouds_agree_with_open3d(tmp_path, X, ext, with_colors):
    """Open3D reads what mmreg writes, and mmreg reads what Open3D writes (every encoding)."""
    o3d = pytest.importorskip("open3d")
    points = X[:, :3]
    colors = np.random.default_rng(2).integers(0, 256, (len(X), 3)) / 255.0
    write_point_cloud(tmp_path / f"ours{ext}", points, colors=colors if with_colors else None)
    theirs = o3d.io.read_point_cloud(str(tmp_path / f"ours{ext}"))
    atol = 1e-5 * np.abs(points).max() if ext == ".pcd" else 0.0
    np.testing.assert_allclose(np.asarray(theirs.points), points, rtol=0, atol=atol)
    if with_colors:
        np.testing.assert_allclose(np.asarray(theirs.colors), colors, rtol=0, atol=1e-6)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    if with_colors:
        cloud.colors = o3d.utility.Vector3dVector(colors)
    encodings = [{"write_ascii": False}, {"write_ascii": True}]
    if ext == ".pcd":
        encodings.append({"compressed": True})
    for options in encodings:
        path = tmp_path / f"theirs{ext}"
        assert o3d.io.write_point_cloud(str(path), cloud, **options)
        read, rgb = read_point_cloud(path, colors=True)
        # Open3D's text is rounded to a few digits.
        tol = 1e-4 * np.abs(points).max() if options.get("write_ascii") or ext == ".pcd" else 0
        np.testing.assert_allclose(read, points, rtol=0, atol=tol)
        if with_colors:
            np.testing.assert_allclose(rgb, colors, rtol=0, atol=1e-6)
        else:
            assert rgb is None


@pytest.mark.parametrize(
    "write",
    [
        lambda p: write_correspondences(p / "x.csv", np.zeros((2, 6))),
        lambda p: write_labels(p / "x.csv", [1, 2]),
        lambda p: write_motions(p / "x.json", np.eye(3)[None], np.zeros((1, 3))),
        lambda p: write_point_cloud(p / "x.ply", np.zeros((2, 3))),
    ],
    ids=["correspondences", "labels", "motions", "point_cloud"],
)
def test_writers_fail_mid_way_without_residue(tmp_path, monkeypatch, write):
    """A failure while the data go out leaves neither the file nor a temporary one."""
    import os

    def failing_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", failing_replace)
    with pytest.raises(OSError, match="disk full"):
        write(tmp_path)
    assert _listing(tmp_path) == []


def test_writers_into_missing_folder(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope"):
        write_correspondences(tmp_path / "nope" / "x.npy", np.zeros((1, 6)))


# --------------------------------------------------------------------------- damaged files
@pytest.mark.parametrize("ext", [".ply", ".pcd"])
def test_truncated_point_cloud_names_promised_and_read(tmp_path, X, ext):
    """Open3D zero-filled the missing vertices; the count now fails the file."""
    path = tmp_path / f"cut{ext}"
    write_point_cloud(path, X[:, :3])
    data = path.read_bytes()
    record = 24 if ext == ".ply" else 12  # float64 or float32 x, y, z
    path.write_bytes(data[: len(data) - 12 * record - 5])  # 12 whole records and a bit
    what = "vertices" if ext == ".ply" else "points"
    with pytest.raises(ValueError, match=f"cut\\{ext}: truncated .*promised 25 {what} but 12"):
        read_point_cloud(path)
    with pytest.raises(ValueError, match=f"cut\\{ext}: truncated"):
        read_correspondences(tmp_path / f"cut{ext}", flow=tmp_path / f"cut{ext}")


def test_truncated_ascii_ply(tmp_path, X):
    path = tmp_path / "cut.ply"
    rows = "".join(f"{x} {y} {z}\n" for x, y, z in X[:, :3])
    header = "ply\nformat ascii 1.0\nelement vertex 25\nproperty float x\nproperty float y\n"
    path.write_text(header + "property float z\nend_header\n" + rows)
    assert read_point_cloud(path).shape == (25, 3)
    path.write_text(header + "property float z\nend_header\n" + rows[: len(rows) // 2])
    with pytest.raises(ValueError, match="cut.ply: "):
        read_point_cloud(path)
    cut = rows.splitlines(keepends=True)
    path.write_text(header + "property float z\nend_header\n" + "".join(cut[:20]))
    with pytest.raises(ValueError, match="cut.ply: truncated .*promised 25 vertices but 20"):
        read_point_cloud(path)


@pytest.mark.parametrize("ext", [".npy", ".npz", ".ply", ".pcd"])
def test_bytes_after_the_end_are_an_error(tmp_path, X, ext):
    path = tmp_path / f"long{ext}"
    if ext in (".ply", ".pcd"):
        write_point_cloud(path, X[:, :3])
        read = read_point_cloud
    else:
        write_correspondences(path, X)
        read = read_correspondences
    path.write_bytes(path.read_bytes() + b"\x00" * 8)
    with pytest.raises(ValueError, match=f"long\\{ext}: corrupt"):
        read(path)


def test_npz_checksum_detects_a_changed_byte(tmp_path, X):
    path = tmp_path / "pairs.npz"
    write_correspondences(path, X)
    data = bytearray(path.read_bytes())
    data[200] ^= 0x10  # inside the stored array
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="pairs.npz: cannot be read as a .npz file.*CRC"):
        read_correspondences(path)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("1,2,3,4,5,6\n# 7,8,9,10,11,12\n1,2,3,4,5,6\n", "line 2 holds '#' among the data"),
        ("#1,2,3,4,5,6\n1,2,3,4,5,6\n", "line 1 is a comment holding only numbers"),
        ("ax,2,az,bx,by,bz\n1,2,3,4,5,6\n", "line 1 holds 'ax', which is not a number"),
    ],
)
def test_text_that_could_hide_a_damaged_row(tmp_path, text, problem):
    path = tmp_path / "pairs.csv"
    path.write_text(text)
    with pytest.raises((ValueError, TypeError), match=f"pairs.csv: {problem}"):
        read_correspondences(path)
