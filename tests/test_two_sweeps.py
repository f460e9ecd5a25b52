"""SweepRegistration and the multi-body ICP on generated pairs of sweeps."""

import json
import warnings

import numpy as np
import pytest
from _surfaces import area_weighted_box
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.base import clone

from mmreg import MultiModelRegistration, SweepRegistration
from mmreg.estimators import ScaleWarning
from mmreg.sweeps._icp import multi_body_icp, rotation_vectors_to_matrices

# Boxes: (centre, size); the first three are the static world, the last two move.
BOXES = [
    ((0.0, 0.0, 0.0), (6.0, 2.0, 3.0)),
    ((0.0, 12.0, 0.0), (4.0, 4.0, 4.0)),
    ((12.0, 6.0, 0.0), (2.0, 8.0, 3.0)),
    ((-9.0, 6.0, 0.0), (4.0, 2.0, 1.5)),
    ((6.0, -9.0, 0.0), (2.0, 4.5, 1.6)),
]
MOVING = (3, 4)
# The sweeps' median nearest-neighbour distance is about 0.1 m; a resampled surface is
# recovered to a small share of it (the normals near the boxes' edges mix two faces).
EXACT = 2e-3


def _motions():
    ego = (rotation_vectors_to_matrices(np.array([[0.0, 0.0, 0.01]]))[0], np.array([0.3, 0.0, 0.0]))
    cars = [
        (rotation_vectors_to_matrices(np.array([[0.0, 0.0, 0.03]]))[0], np.array([1.0, 0.2, 0.0])),
        (rotation_vectors_to_matrices(np.array([[0.0, 0.0, -0.02]]))[0], np.array([0.1, 0.9, 0.0])),
    ]
    return [ego, *cars]


def make_pair(n=4000, m=6000, random_state=0):
    """Two sweeps of the same box surfaces, sampled independently; the second moved."""
    rng = np.random.default_rng(random_state)
    motions = _motions()
    group = np.array([0, 0, 0, 1, 2])
    area = np.array([2 * (s[0] * s[1] + s[1] * s[2] + s[0] * s[2]) for _, s in BOXES])
    counts_a = rng.multinomial(n, area / area.sum())
    counts_b = rng.multinomial(m, area / area.sum())
    a_parts, labels, b_parts = [], [], []
    for k, (center, size) in enumerate(BOXES):
        R, t = motions[group[k]]
        a_parts.append(area_weighted_box(center, size, counts_a[k], rng))
        labels.append(np.full(counts_a[k], group[k]))
        b_parts.append(area_weighted_box(center, size, counts_b[k], rng) @ R.T + t)
    a, labels, sweep = np.vstack(a_parts), np.concatenate(labels), np.vstack(b_parts)
    rotations = np.stack([R for R, _ in motions])
    translations = np.stack([t for _, t in motions])
    b = np.einsum("nij,nj->ni", rotations[labels], a) + translations[labels]
    return a, b, labels, rotations, translations, sweep


def _estimator(**params):
    inner = MultiModelRegistration(variant="sweep", tau=2.0, random_state=0)
    return SweepRegistration(inner, max_distance=1.5, random_state=0, **params)


def _motion_error(est, a, labels, rotations, translations):
    """Largest distance between where the fitted and the true motions take each point."""
    fitted = a + est.flow_
    true = np.einsum("nij,nj->ni", rotations[labels], a) + translations[labels]
    return np.abs(fitted - true).max()


def test_icp_recovers_every_motion_from_a_perturbed_start():
    a, _, labels, rotations, translations, sweep = make_pair()
    start_t = translations + [[0.05, -0.04, 0.03], [0.1, 0.05, -0.05], [-0.08, 0.06, 0.04]]
    turn = rotation_vectors_to_matrices(np.array([[0.0, 0.01, 0.0]] * 3))
    result = multi_body_icp(
        a, labels, turn @ rotations, start_t, sweep, max_distance=1.0, max_iter=50
    )
    moved = np.einsum("nij,nj->ni", result.rotations[labels], a) + result.translations[labels]
    true = np.einsum("nij,nj->ni", rotations[labels], a) + translations[labels]
    assert np.abs(moved - true).max() < EXACT


def test_exact_recovery_on_resampled_surfaces():
    a, b, labels, rotations, translations, sweep = make_pair()
    est = _estimator(refine="all").fit(np.hstack([a, b]), sweep=sweep)
    assert est.n_clusters_ == 3
    assert _motion_error(est, a, labels, rotations, translations) < EXACT
    assert est.moving_.sum() == 2 and est.static_cluster_ >= 0


def test_biased_flow_is_corrected_within_the_sampling_spacing():
    a, b, labels, rotations, translations, sweep = make_pair()
    flow = b - a
    biased = np.where(np.isin(labels, (1, 2))[:, None], 0.9 * flow, flow)
    X = np.hstack([a, a + biased])
    before = MultiModelRegistration(variant="sweep", tau=2.0, random_state=0).fit(X)
    error_before = np.abs(a + before.flow_ - b).max()
    est = _estimator().fit(X, sweep=sweep)
    spacing = 0.05  # median nearest-neighbour distance of the sweep is about 0.1 m
    error = _motion_error(est, a, labels, rotations, translations)
    assert error < spacing < error_before


def test_sizes_and_order_of_the_sweep_do_not_matter():
    a, b, labels, rotations, translations, sweep = make_pair(n=3000, m=9000)
    X = np.hstack([a, b])
    order = np.random.default_rng(1).permutation(len(sweep))
    first = _estimator(refine="all").fit(X, sweep=sweep)
    second = _estimator(refine="all").fit(X, sweep=sweep[order])
    np.testing.assert_array_equal(first.labels_, second.labels_)
    np.testing.assert_allclose(first.flow_, second.flow_, atol=1e-9)
    assert _motion_error(first, a, labels, rotations, translations) < EXACT


def test_two_raw_sweeps():
    a, b, labels, rotations, translations, sweep = make_pair()
    est = _estimator(island_radius=1.0, min_island_size=20).fit(a, sweep=sweep)
    assert est.n_features_in_ == 3
    assert _motion_error(est, a, labels, rotations, translations) < EXACT
    assert est.moving_.sum() == 2


def test_passthrough_keeps_the_moving_islands_and_refines_their_motions():
    a, b, labels, rotations, translations, sweep = make_pair()
    est = SweepRegistration(
        "passthrough", tau=2.0, max_distance=1.5, island_radius=1.0, min_island_size=20,
        random_state=0,
    ).fit(a, sweep=sweep)  # fmt: skip
    assert est.estimator_ is None and est.n_iter_ == 0
    assert _motion_error(est, a, labels, rotations, translations) < EXACT
    assert est.moving_.sum() == 2
    for k in np.flatnonzero(est.moving_):  # each moving cluster is one car
        assert len(np.unique(labels[est.labels_ == k])) == 1


@pytest.mark.parametrize("scale", [1e-3, 1e3])
def test_passthrough_in_any_units_given_tau(scale):
    a, b, labels, rotations, translations, sweep = make_pair()
    params = {"max_distance": 1.5, "island_radius": 1.0, "min_island_size": 20}
    metres = SweepRegistration("passthrough", tau=2.0, random_state=0, **params)
    metres = metres.fit(a, sweep=sweep)
    scaled_params = {k: v * scale if isinstance(v, float) else v for k, v in params.items()}
    scaled = SweepRegistration("passthrough", tau=2.0 * scale, random_state=0, **scaled_params)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ScaleWarning)  # tau is in the points' units
        scaled = scaled.fit(a * scale, sweep=sweep * scale)
    assert scaled.max_displacement_ == pytest.approx(metres.max_displacement_ * scale)
    assert np.mean(scaled.labels_ == metres.labels_) > 0.99
    assert np.abs(scaled.flow_ / scale - metres.flow_).max() < EXACT


def test_passthrough_in_other_units_than_tau_warns():
    # Sweeps sampled every 0.1 m, in millimetres, at the default tau of metres (5): no
    # multi-model estimator to say so, the pair itself does.
    a, b, labels, rotations, translations, sweep = make_pair()
    message = "tau=5 spans fewer than 4 times the median distance between neighbouring points"
    with pytest.warns(ScaleWarning, match=message) as record:
        SweepRegistration("passthrough", random_state=0).fit(a * 1e3, sweep=sweep * 1e3)
    assert record[0].filename == __file__


def test_passthrough_needs_two_raw_sweeps():
    a, b, *_, sweep = make_pair()
    with pytest.raises(ValueError, match="passthrough"):
        SweepRegistration("passthrough").fit(np.hstack([a, b]))
    with pytest.raises(ValueError, match="passthrough"):
        SweepRegistration("passthrough").fit(np.hstack([a, b]), sweep=sweep)


def test_raw_sweeps_start_from_the_islands_unless_the_estimator_s_init_is_asked_for():
    a, b, labels, rotations, translations, sweep = make_pair()
    raw = SweepRegistration(max_distance=1.5, island_radius=1.0, min_island_size=20)
    raw = raw.set_params(random_state=0).fit(a, sweep=sweep)
    init = raw.estimator_.get_params()["init"]
    assert isinstance(init, np.ndarray) and init.shape == (len(a),)
    assert raw.estimator is None  # the parameter itself is left alone
    assert _motion_error(raw, a, labels, rotations, translations) < EXACT
    # A given estimator starts from the islands too (its clone's init), and from its
    # own init with raw_init="estimator".
    given = _estimator(island_radius=1.0, min_island_size=20).fit(a, sweep=sweep)
    assert isinstance(given.estimator_.get_params()["init"], np.ndarray)
    assert given.estimator.get_params()["init"] == "euclidean"
    assert _motion_error(given, a, labels, rotations, translations) < EXACT
    own = _estimator(island_radius=1.0, min_island_size=20, raw_init="estimator")
    own = own.fit(a, sweep=sweep)
    assert own.estimator_.get_params()["init"] == "euclidean"
    assert _motion_error(own, a, labels, rotations, translations) < EXACT


@pytest.mark.parametrize(
    ("sweep", "message"),
    [
        (np.full((50, 3), np.nan), "NaN"),
        (np.zeros((50, 2)), "shape"),
        (np.zeros((5, 3)), "at least"),
        (None, "sweep is required"),
    ],
)
def test_bad_sweeps_are_refused(sweep, message):
    a = np.random.default_rng(0).uniform(size=(40, 3))
    X = a if sweep is None else np.hstack([a, a])
    with pytest.raises(ValueError, match=message):
        SweepRegistration().fit(X, sweep=sweep)


def test_refinement_needs_three_dimensional_points():
    X = np.random.default_rng(0).uniform(size=(40, 4))
    with pytest.raises(ValueError, match="n_features = 4"):
        SweepRegistration().fit(X, sweep=np.zeros((40, 3)))


def test_clone_and_params():
    est = SweepRegistration(max_icp_iter=5)
    assert clone(est).get_params()["max_icp_iter"] == 5
    assert est.get_params()["estimator"] is None


def _write_pair(folder, a, b, sweep):
    from mmreg.io import write_point_cloud

    write_point_cloud(folder / "a.ply", a)
    write_point_cloud(folder / "sweep.ply", sweep)
    np.save(folder / "flow.npy", b - a)


def test_cli_registers_two_raw_sweeps_and_refines_a_flow(tmp_path):
    from mmreg.cli import main

    a, b, labels, rotations, translations, sweep = make_pair(n=3000, m=4000)
    _write_pair(tmp_path, a, b, sweep)
    common = ["--tau", "2", "--max-distance", "1", "--island-radius", "0.5", "-q", "--seed", "0"]
    raw = ["register", str(tmp_path / "a.ply"), "--sweep", str(tmp_path / "sweep.ply")]
    assert main([*raw, "--out", str(tmp_path / "raw"), *common]) == 0
    refined = [*raw, "--flow", str(tmp_path / "flow.npy"), "--out", str(tmp_path / "ref")]
    assert main([*refined, *common]) == 0
    for out in ("raw", "ref"):
        found = np.load(tmp_path / out / "labels.npy")
        assert len(found) == len(a)
        assert len(np.unique(found[found >= 0])) == 3
        # What was written is the first sweep and where its points move, not the input:
        # view and evaluate read it from the result.
        written = np.load(tmp_path / out / "X.npy")
        np.testing.assert_array_equal(written[:, :3], a)
        picture = tmp_path / f"{out}.png"
        assert main(["view", str(tmp_path / out), "--out", str(picture)]) == 0
        assert picture.stat().st_size > 0
        np.save(tmp_path / "truth.npy", labels)
        assert main(["evaluate", str(tmp_path / out), str(tmp_path / "truth.npy")]) == 0
    # Raw sweeps start from their islands, as SweepRegistration() does, unless --init
    # names a clustering; correspondences from the Euclidean clustering.
    assert json.loads((tmp_path / "raw" / "run.json").read_text())["init"] == "islands"
    assert json.loads((tmp_path / "ref" / "run.json").read_text())["init"] == "euclidean"
    euclidean = [*raw, "--init", "euclidean", "--out", str(tmp_path / "euc"), *common]
    assert main(euclidean) == 0
    assert json.loads((tmp_path / "euc" / "run.json").read_text())["init"] == "euclidean"
    found = np.load(tmp_path / "euc" / "labels.npy")
    assert len(np.unique(found[found >= 0])) == 3


def test_cli_target_of_another_size_points_to_sweep(tmp_path, capsys):
    from mmreg.cli import main

    a, b, _, _, _, sweep = make_pair(n=3000, m=4000)
    _write_pair(tmp_path, a, b, sweep)
    argv = ["register", str(tmp_path / "a.ply"), "--target", str(tmp_path / "sweep.ply")]
    assert main([*argv, "--out", str(tmp_path / "out"), "-q"]) == 2
    assert "--sweep" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_voxel_islands_join_close_points_and_split_far_ones():
    from scipy.sparse.csgraph import connected_components

    from mmreg._array.neighbors import radius_graph
    from mmreg.sweeps._islands import voxel_islands

    rng = np.random.default_rng(1)
    blobs = [rng.normal(c, 0.3, (200, 3)) for c in ((0, 0, 0), (8, 0, 0), (0, 9, 3))]
    points = np.vstack(blobs)
    cell = 0.5
    labels, n = voxel_islands(points, cell)
    # Points within `cell` always share an island; islands are unions of the radius
    # graph's components at `cell` and never join points 2 sqrt(3) cell apart.
    _, fine = connected_components(radius_graph(points, cell), directed=False)
    _, coarse = connected_components(radius_graph(points, 2 * np.sqrt(3) * cell), directed=False)
    for component in np.unique(fine):
        assert len(np.unique(labels[fine == component])) == 1
    for island in range(n):
        assert len(np.unique(coarse[labels == island])) == 1
    assert n == len(np.unique(coarse))
    small, n_small = voxel_islands(points, 0.05, min_size=5)
    assert np.all((small == -1) | (np.bincount(small[small >= 0])[small] >= 5))
    assert n_small == len(np.unique(small[small >= 0]))


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 300),
    spread=st.sampled_from([0.3, 2.0, 20.0]),
    min_size=st.integers(1, 6),
)
def test_voxel_islands_are_the_components_of_touching_voxels(seed, n, spread, min_size):
    """The reference: every pair of occupied voxels compared, touching when their indices
    differ by at most 1 along every axis; islands numbered by their first point."""
    from scipy.sparse.csgraph import connected_components

    from mmreg.sweeps._islands import voxel_islands

    rng = np.random.default_rng(seed)
    # Clumps and gaps at several densities; the reference bins the points as the
    # function does (voxels from the smallest coordinates), then compares every pair.
    points = rng.integers(-5, 6, (n, 3)) * spread + rng.uniform(0.0, 1.0, (n, 3))
    labels, n_islands = voxel_islands(points, 1.0, min_size)
    cells = np.floor(points - points.min(axis=0)).astype(int)
    touching = np.abs(cells[:, None, :] - cells[None, :, :]).max(axis=2) <= 1
    _, component = connected_components(touching, directed=False)
    sizes = np.bincount(component)
    kept = sizes[component] >= min_size
    _, first = np.unique(component, return_index=True)
    order = [c for c in np.argsort(first) if sizes[c] >= min_size]
    expected = np.full(n, -1)
    for number, c in enumerate(order):
        expected[component == c] = number
    assert n_islands == len(order)
    np.testing.assert_array_equal(labels, expected)
    assert np.all(labels[~kept] == -1)


# The first round's EM here alternates between two labellings of 55 of 4,000 rows (the
# second round settles at once): a ConvergenceWarning that this test is not about.
@pytest.mark.filterwarnings("ignore:The EM did not settle")
def test_raw_static_world_keeps_the_ego_motion_exactly():
    a, _, labels, rotations, translations, sweep = make_pair()
    est = _estimator().fit(a, sweep=sweep)
    R, t = est.ego_motion_
    static = est.labels_ == est.static_cluster_
    # Every static box joins one cluster whose motion is the ego ICP's, not a re-fit.
    assert np.all(static[labels == 0])
    np.testing.assert_array_equal(est.rotations_[est.static_cluster_], R)
    np.testing.assert_array_equal(est.translations_[est.static_cluster_], t)
    assert np.abs(t - translations[0]).max() < EXACT
    assert est.moving_.sum() == 2


def test_island_that_only_slides_along_its_surface_stays_static():
    from mmreg.sweeps._icp import SurfaceNormals
    from mmreg.sweeps._island_motions import choose_island_motions

    rng = np.random.default_rng(2)
    wall = rng.uniform(-2, 2, (400, 3))
    wall[:, 2] = 0.0  # a plane: sliding within it explains it as well as the ego motion
    sweep = rng.uniform(-2.5, 2.5, (3000, 3))
    sweep[:, 2] = 0.0
    moved_box = rng.uniform(-0.5, 0.5, (300, 3)) + [10.0, 0, 0]
    moved_box[np.arange(300), rng.integers(0, 3, 300)] = rng.choice([-0.5, 0.5], 300)
    points = np.vstack([wall, moved_box])
    groups = np.repeat([0, 1], [400, 300])
    target_box = rng.uniform(-0.5, 0.5, (2000, 3))
    target_box[np.arange(2000), rng.integers(0, 3, 2000)] = rng.choice([-0.5, 0.5], 2000)
    sweep = np.vstack([sweep, target_box + [11.5, 0, 0]])
    from scipy.spatial import cKDTree

    tree = cKDTree(sweep)
    normals = SurfaceNormals(sweep, tree, 10)
    ego = (np.eye(3), np.zeros(3))
    # Start 0: the ego motion; start 1: the wall slid by 0.4 m, the box moved by 1.5 m.
    rotations = np.broadcast_to(np.eye(3), (4, 3, 3)).copy()
    translations = np.array([[0, 0, 0], [0.4, 0, 0], [0, 0, 0], [1.5, 0, 0]], dtype=float)
    resting = cKDTree(points @ ego[0].T + ego[1])
    moving, pick, _ = choose_island_motions(
        points,
        groups,
        2,
        ego,
        (rotations, translations),
        np.ones((2, 2), dtype=bool),
        0.005,
        (sweep, tree, normals),
        (resting, groups, 0.25),
        max_distance=1.0,
    )
    assert moving.tolist() == [False, True]
    assert pick[1] == 3
