"""Pictures of LiDAR sweeps: which frame, the crop, arrows that show, speeds in the legend."""

import json

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from matplotlib.patches import FancyArrowPatch  # noqa: E402

from mmreg._array.frames import detect_frame, looks_down_minus_z  # noqa: E402
from mmreg._cli._common import result_figure  # noqa: E402
from mmreg.cli import main  # noqa: E402
from mmreg.datasets import make_street  # noqa: E402
from mmreg.plotting import (
    _sweep_layout,  # noqa: E402
    plot_sweep,  # noqa: E402
)

INTERVAL = 0.1


def _yaw(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _sweep(seed=0, lift=0.0, n_ground=4000):
    """A z-up sweep: ground all around the sensor, two walls, a car and a slow pedestrian.

    ``lift`` raises the sensor's origin to the ground (z > 0 everywhere when >= 1.9).
    Labels: 0 the static world, 1 the car, 2 the pedestrian.
    """
    rng = np.random.default_rng(seed)
    azimuth = rng.uniform(-np.pi, np.pi, n_ground)
    distance = rng.uniform(3.0, 45.0, n_ground)
    ground = np.c_[distance * np.cos(azimuth), distance * np.sin(azimuth), np.full(n_ground, -1.8)]
    walls = np.c_[
        rng.uniform(-40, 40, 1000), np.repeat([-12.0, 12.0], 500), rng.uniform(-1.8, 4.0, 1000)
    ]
    car = np.c_[rng.uniform(10, 14.5, 300), rng.uniform(2, 4, 300), rng.uniform(-1.5, 0, 300)]
    person = np.c_[rng.normal(-8, 0.2, (20, 2)), rng.uniform(-1.8, 0, 20)]
    points = np.vstack([ground, walls, car, person]) + [0.0, 0.0, lift]
    labels = np.repeat([0, 1, 2], [n_ground + 1000, 300, 20])
    return points, labels


def _motions(ego, car, person):
    """Each object moved by ``d`` in the first frame, then by the ego motion ``(R0, t0)``."""
    r0, t0 = ego
    rotations = np.stack([r0, r0, r0])
    translations = np.stack([t0, r0 @ car + t0, r0 @ person + t0])
    return rotations, translations


def _legend_texts(fig):
    return [t.get_text() for t in fig.axes[0].get_legend().get_texts()]


def _arrow_lengths_px(ax):
    """On-screen length of every motion arrow, in pixels."""
    lengths = []
    for patch in ax.patches:
        if isinstance(patch, FancyArrowPatch):
            start, end = ax.transData.transform(np.array(patch._posA_posB))
            lengths.append(float(np.linalg.norm(end - start)))
    return np.array(lengths)


# Which frame ------------------------------------------------------------------------------


@pytest.mark.parametrize("lift", [0.0, 1.9, 2.5])
@pytest.mark.parametrize("seed", [0, 1])
def test_z_up_sweep_is_lidar_even_when_z_is_positive_everywhere(seed, lift):
    points, _ = _sweep(seed, lift)
    if lift >= 1.9:
        assert np.all(points[:, 2] > 0)  # the case the sign of z got wrong
    assert detect_frame(points) == "lidar"


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    half_fov=st.floats(20, 60),
    backward=st.booleans(),
)
def test_points_in_front_within_a_field_of_view_are_a_camera_frame(seed, half_fov, backward):
    rng = np.random.default_rng(seed)
    depth = rng.uniform(2.0, 40.0, 500)
    spread = np.tan(np.deg2rad(half_fov))
    points = np.c_[
        rng.uniform(-spread, spread, 500) * depth, rng.uniform(-0.5, 0.5, 500) * depth, depth
    ]
    if backward:  # OpenGL: y up, looking down -z
        points = points * [1.0, -1.0, -1.0]
    assert detect_frame(points) == "camera"
    assert looks_down_minus_z(points) == backward


def test_a_generated_street_is_a_camera_frame():
    scene = make_street(n_points=2000, corruption=False, sam_masks=False, random_state=0)
    assert detect_frame(scene.a) == "camera"


def test_neither_frame_without_the_sensor_among_flat_points_or_a_view_cone():
    rng = np.random.default_rng(0)
    assert detect_frame(rng.uniform(-1, 1, (500, 3))) is None  # an object from all around
    points, _ = _sweep()
    assert detect_frame(points + [2000.0, -500.0, 30.0]) is None  # a map frame, far away
    assert detect_frame(points[:5]) is None


# The picture ------------------------------------------------------------------------------


def test_sweep_is_cropped_to_the_range_around_the_sensor():
    points, labels = _sweep()
    car_moved = np.array([1.0, 0.0, 0.0])
    motions = _motions((np.eye(3), np.zeros(3)), car_moved, np.array([0.1, 0.0, 0.0]))
    fig = plot_sweep(points, labels, motions, range_=10.0, center=(1.0, -2.0))
    ax = fig.axes[0]
    assert ax.get_xlim() == (-9.0, 11.0) and ax.get_ylim() == (-12.0, 8.0)
    # The static world is stamped (StampedPoints, an artist), the objects scattered.
    drawn = np.vstack([c.get_offsets() for c in [*ax.collections, *ax.artists]])
    assert 0 < len(drawn) < len(points)
    assert np.all(np.abs(drawn - [1.0, -2.0]) <= 10.0)
    # The car (centroid at x = 12.25) is out of view: said so, not listed.
    texts = _legend_texts(fig)
    assert "1 moving beyond 10 m, not drawn" in texts
    assert not any(t.startswith("cluster 1:") for t in texts)


@pytest.mark.parametrize("ego_yaw", [0.0, 0.3])
def test_legend_gives_each_object_speed_relative_to_the_static_world(ego_yaw):
    points, labels = _sweep()
    ego = (_yaw(ego_yaw), np.array([1.2, -0.3, 0.05]))  # the sensor moves and turns
    motions = _motions(ego, np.array([0.9, 1.2, 0.0]), np.array([0.0, 0.14, 0.0]))
    texts = _legend_texts(plot_sweep(points, labels, motions, interval=INTERVAL))
    # |(0.9, 1.2, 0)| = 1.5 m in 0.1 s; 0.14 m in 0.1 s.
    assert "cluster 1: 15.0 m/s (300 pts)" in texts
    assert "cluster 2: 1.4 m/s (20 pts)" in texts
    per_frame = _legend_texts(plot_sweep(points, labels, motions))
    assert "cluster 1: 1.50 m/frame (300 pts)" in per_frame


def test_arrow_scale_is_round_and_named_in_the_legend():
    points, labels = _sweep()
    motions = _motions((np.eye(3), np.zeros(3)), np.array([0.5, 0.0, 0.0]), [0.0, 0.5, 0.0])
    # Median 0.5 m in a 100 m window: 8 m wanted, x16, rounded down to x10.
    texts = _legend_texts(plot_sweep(points, labels, motions, interval=INTERVAL))
    assert "arrow: travel in 1 s (motion x10)" in texts
    texts = _legend_texts(plot_sweep(points, labels, motions))
    assert "arrow: motion between the sweeps x10" in texts


@pytest.mark.parametrize("slow", [0.003, 0.02])
def test_slow_objects_get_arrows_long_enough_to_see(slow):
    points, labels = _sweep()
    motions = _motions((np.eye(3), np.zeros(3)), np.array([2.5, 0.0, 0.0]), [0.0, slow, 0.0])
    fig = plot_sweep(points, labels, motions, interval=INTERVAL)
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig).draw()
    ax = fig.axes[0]
    lengths = _arrow_lengths_px(ax)
    assert len(lengths) == 2  # the car's and the pedestrian's
    minimum = _sweep_layout.ARROW_MIN * ax.bbox.width
    assert np.all(lengths >= minimum * 0.999)
    assert minimum > 20  # pixels: more than an arrow head
    assert any("at least 4 m long" in t for t in _legend_texts(fig))


def test_static_clusters_join_the_static_world_and_outliers_are_counted():
    points, labels = _sweep()
    labels = labels.copy()
    labels[:7] = -1
    motions = _motions((np.eye(3), np.zeros(3)), np.array([1.0, 0.0, 0.0]), [0.0, 0.0, 0.0])
    texts = _legend_texts(plot_sweep(points, labels, motions, moving=[False, True, False]))
    assert texts[0].startswith("static world and 1 static clusters (5,013 pts)")
    assert "outliers (7 pts)" in texts
    assert not any(t.startswith("cluster 2") for t in texts)


def test_bad_arguments_get_one_clear_error():
    points, labels = _sweep()
    with pytest.raises(ValueError, match="range_"):
        plot_sweep(points, labels, range_=-5)
    with pytest.raises(ValueError, match="interval"):
        plot_sweep(points, labels, interval=0.0)
    with pytest.raises(ValueError, match="moving"):
        plot_sweep(points, labels, moving=[False])
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        plot_sweep(points[:, :2], labels)


# Layout numbers ---------------------------------------------------------------------------


@settings(max_examples=40, deadline=None)
@given(
    angle=st.floats(-np.pi, np.pi),
    length=st.floats(2.0, 6.0),
    width=st.floats(1.2, 1.9),
    seed=st.integers(0, 1000),
)
def test_oriented_box_of_a_turned_rectangle_is_that_rectangle(angle, length, width, seed):
    rng = np.random.default_rng(seed)
    local = np.vstack(
        [
            [[-length / 2, -width / 2], [length / 2, -width / 2]],
            [[length / 2, width / 2], [-length / 2, width / 2]],
            rng.uniform([-length / 2, -width / 2], [length / 2, width / 2], (50, 2)),
        ]
    )
    turn = _yaw(angle)[:2, :2]
    corners = _sweep_layout.oriented_box(local @ turn.T + [5.0, -3.0])
    sides = np.linalg.norm(np.diff(np.vstack([corners, corners[:1]]), axis=0), axis=1)
    assert sorted(np.round(sides, 9)[:2]) == pytest.approx(sorted([length, width]))
    assert np.allclose(corners.mean(axis=0), [5.0, -3.0])


def test_oriented_box_is_never_smaller_than_its_minimum():
    corners = _sweep_layout.oriented_box(np.array([[1.0, 2.0], [1.2, 2.0]]), min_size=1.0)
    sides = np.linalg.norm(np.diff(np.vstack([corners, corners[:1]]), axis=0), axis=1)
    assert np.allclose(sides, 1.0)


@pytest.mark.parametrize(
    ("value", "expected"), [(16.0, 10.0), (0.7, 0.5), (3.3, 2.0), (250.0, 200.0), (1.0, 1.0)]
)
def test_nice_floor(value, expected):
    assert _sweep_layout.nice_floor(value) == pytest.approx(expected)


def test_marker_diameter_grows_where_points_are_sparse():
    rng = np.random.default_rng(0)
    dense = rng.uniform(-5, 5, (20_000, 2))
    sparse = rng.uniform(-50, 50, (2000, 2))
    small, large = (_sweep_layout.marker_diameter(p, 10.0) for p in (dense, sparse))
    assert small < large


# The command line -------------------------------------------------------------------------


def _result_dir(tmp_path, lift):
    """A result directory of a z-up sweep (true labels and motions, through register)."""
    points, labels = _sweep(lift=lift, n_ground=1500)
    motions = _motions((np.eye(3), np.zeros(3)), np.array([1.0, 0.0, 0.0]), [0.0, 0.2, 0.0])
    rotations, translations = motions
    b = np.einsum("nij,nj->ni", rotations[labels], points) + translations[labels]
    np.save(tmp_path / "pairs.npy", np.hstack([points, b]))
    np.save(tmp_path / "init.npy", labels)
    out = tmp_path / "result"
    argv = ["register", str(tmp_path / "pairs.npy"), "--init", str(tmp_path / "init.npy")]
    assert main([*argv, "--out", str(out), "--save-input", "--quiet"]) == 0
    return out


def test_view_bev_draws_a_z_up_sweep_from_above(tmp_path, monkeypatch):
    out = _result_dir(tmp_path, lift=1.9)  # z > 0 everywhere
    figures = []
    import mmreg._cli.view as view

    render = view.render_picture
    monkeypatch.setattr(
        view, "render_picture", lambda fig, *a, **k: figures.append(fig) or render(fig, *a, **k)
    )
    argv = ["view", str(out), "--out", str(tmp_path / "bev.png"), "--view", "bev"]
    assert main([*argv, "--range", "20", "--interval", "0.1"]) == 0
    ax = figures[-1].axes[0]
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x [m]", "y [m]")
    assert ax.get_xlim() == (-20.0, 20.0)
    assert any(t.endswith("m/s (300 pts)") for t in _legend_texts(figures[-1]))
    # auto: the same from above; --frame camera: the camera's street layout.
    assert main(["view", str(out), "--out", str(tmp_path / "auto.png")]) == 0
    assert figures[-1].axes[0].get_xlabel() == "x [m]"
    assert main(["view", str(out), "--out", str(tmp_path / "c.png"), "--frame", "camera"]) == 0
    assert [a.get_title() for a in figures[-1].axes][:1] == ["bird's-eye view (metres)"]


def test_view_reads_the_interval_from_run_json(tmp_path, monkeypatch):
    out = _result_dir(tmp_path, lift=0.0)
    record = json.loads((out / "run.json").read_text())
    (out / "run.json").write_text(json.dumps(record | {"interval": 0.05}))
    figures = []
    import mmreg._cli.view as view

    render = view.render_picture
    monkeypatch.setattr(
        view, "render_picture", lambda fig, *a, **k: figures.append(fig) or render(fig, *a, **k)
    )
    assert main(["view", str(out), "--out", str(tmp_path / "p.png")]) == 0
    texts = _legend_texts(figures[-1])
    # 1 m in 0.05 s.
    assert any(t.endswith("20.0 m/s (300 pts)") for t in texts), texts


@pytest.mark.parametrize("option", ["--range", "--interval"])
def test_view_rejects_a_range_or_interval_that_is_not_positive(tmp_path, capsys, option):
    with pytest.raises(SystemExit) as stop:
        main(["view", str(tmp_path), option, "-3"])
    assert stop.value.code == 2
    assert "positive" in capsys.readouterr().err


def test_result_figure_keeps_3d_for_points_in_no_sensor_frame():
    rng = np.random.default_rng(0)
    a = rng.uniform(-1, 1, (300, 3))
    X = np.hstack([a, a])
    labels = np.repeat([0, 1], 150)
    motions = (np.stack([np.eye(3)] * 2), np.zeros((2, 3)))
    fig = result_figure(X, labels, motions)
    assert fig.axes[0].name == "3d"


def test_plot_clusters_bev_of_a_z_up_sweep_is_from_above():
    from matplotlib.figure import Figure

    from mmreg.plotting import plot_clusters

    points, labels = _sweep(lift=1.9)
    ax = plot_clusters(points, labels, ax=Figure().add_subplot(), view="bev")
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x [m]", "y [m]")
    ax = plot_clusters(points, labels, ax=Figure().add_subplot(), view="bev", frame="camera")
    assert ax.get_ylabel().startswith("z, ahead of the camera")


def test_an_opengl_camera_is_turned_into_opencv_exactly():
    from scipy.spatial.transform import Rotation

    from mmreg.plotting._result import _turned_to_opencv

    rng = np.random.default_rng(3)
    rotations = Rotation.random(4, random_state=1).as_matrix()
    translations = rng.normal(size=(4, 3))
    a = rng.normal(size=(50, 3))
    labels = rng.integers(0, 4, 50)
    b = np.einsum("nij,nj->ni", rotations[labels], a) + translations[labels]
    turned_a, (turned_r, turned_t) = _turned_to_opencv(a, (rotations, translations))
    turned_b, _ = _turned_to_opencv(b, None)
    moved = np.einsum("nij,nj->ni", turned_r[labels], turned_a) + turned_t[labels]
    np.testing.assert_allclose(moved, turned_b, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(turned_r), 1.0)


def test_plot_result_draws_an_opengl_camera_frame_as_a_street_with_every_point_in_view():
    from mmreg.plotting import plot_result

    rng = np.random.default_rng(0)
    depth = rng.uniform(4.0, 30.0, 800)
    opencv = np.c_[rng.uniform(-0.6, 0.6, 800) * depth, rng.uniform(-0.3, 0.3, 800) * depth, depth]
    labels = np.repeat([0, 1], [600, 200])
    fig = plot_result(opencv * [1.0, -1.0, -1.0], labels)  # as FlyingThings3D's HPLFlowNet dump
    titles = [ax.get_title() for ax in fig.axes]
    assert titles[:2] == ["bird's-eye view (metres)", "camera view (x / z, y / z)"]
    camera_panel = fig.axes[1]
    assert sum(len(c.get_offsets()) for c in camera_panel.collections) == 800


def test_the_static_world_is_the_largest_cluster_left_still_even_when_smaller():
    points, labels = _sweep()
    labels = np.where(labels == 0, 3, labels)  # the static world keeps its points ...
    labels[:4000] = 0  # ... but the largest cluster is now a moving one (label 0)
    ego = (_yaw(0.2), np.array([0.5, 0.0, 0.0]))
    r0, t0 = ego
    rotations = np.stack([r0, r0, r0, r0])
    shifts = np.array([[0.0, 0.4, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    translations = shifts @ r0.T + t0
    texts = _legend_texts(
        plot_sweep(
            points,
            labels,
            (rotations, translations),
            moving=[True, True, True, False],
            interval=INTERVAL,
        )
    )
    assert "cluster 0: 4.0 m/s (4,000 pts)" in texts  # relative to cluster 3, not to itself
    assert "cluster 1: 10.0 m/s (300 pts)" in texts
