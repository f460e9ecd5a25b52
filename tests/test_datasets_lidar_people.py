"""Walkers, cyclists and standing things in the ray-cast streets of make_lidar_sweeps.

The boxes the generator placed are recorded by wrapping its private placement helper, so
that every check below is made against the geometry itself (points on box faces, centres
apart), by hand, not against what the generator computed from it.
"""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from mmreg.datasets import _lidar, make_lidar_sweeps

SMALL = {"n_beams": 16, "n_azimuths": 1024}
PEOPLE = {"n_walkers": 4, "n_cyclists": 2, "n_standing": 4}
N_MOVING = 2


@pytest.fixture
def placed(monkeypatch):
    """Every call's small things and its placement arguments, as the generator drew them."""
    calls = []
    place = _lidar._small_things

    def recording(rng, counts, obstacles, sensors, interval):
        things = place(rng, counts, obstacles, sensors, interval)
        calls.append(
            {
                "things": things,
                "obstacles": [list(boxes) for boxes in obstacles],
                "sensors": sensors,
            }
        )
        return things

    monkeypatch.setattr(_lidar, "_small_things", recording)
    return calls


def _in_box_frame(points, box):
    centre, yaw, _ = box
    c, s = np.cos(yaw), np.sin(yaw)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return (points - centre) @ turn  # rows: turn.T @ (p - centre)


def _on_surface(points, box, tol):
    """Whether every point lies on a face of the box, within ``tol``."""
    excess = np.abs(_in_box_frame(points, box)) - box[2]
    return bool(np.all(excess.max(axis=1) <= tol) and np.all(excess.max(axis=1) >= -tol))


def _inside_footprint(points, box):
    q = _in_box_frame(points, box)
    return np.all(np.abs(q[:, :2]) < box[2][:2], axis=1)


def _scene(seed, **kwargs):
    options = {**SMALL, **PEOPLE, "interval": 0.5, **kwargs}
    return make_lidar_sweeps(N_MOVING, random_state=seed, **options)


def _world(points_a, sensor):
    # The first sensor stands upright, facing +x, at ``sensor``: a = world - sensor.
    return points_a + sensor


def _world_after(scene, label, sensor):
    """Where the transform of ``label`` moves its first-sweep points, in world coordinates.

    transforms[0] maps a static point of ``a`` into the second frame, so its inverse maps
    the second frame back into the first sweep's frame.
    """
    points = scene.a[scene.labels == label]
    moved = points @ scene.transforms[label, :3, :3].T + scene.transforms[label, :3, 3]
    back = np.linalg.inv(scene.transforms[0])
    return _world(moved @ back[:3, :3].T + back[:3, 3], sensor)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_walkers_and_cyclists_move_onto_their_second_boxes(placed, seed):
    scene = _scene(seed)
    (call,) = placed
    movers = [thing for thing in call["things"] if thing[0] != "standing"]
    assert scene.kinds.tolist() == ["static"] + ["car"] * N_MOVING + [k for k, _, _ in movers]
    assert len(scene.transforms) == N_MOVING + 1 + len(movers)
    checked = 0
    for k, (kind, box, box2) in enumerate(movers, start=N_MOVING + 1):
        mask = scene.labels == k
        if mask.sum() < 5:
            continue
        checked += 1
        tol = 0.05  # 1 cm range noise, 5 sigma
        assert _on_surface(_world(scene.a[mask], call["sensors"][0]), box, tol)
        after = _world_after(scene, k, call["sensors"][0])
        assert _on_surface(after, box2, tol), kind
        moved = scene.a[mask] @ scene.transforms[k, :3, :3].T + scene.transforms[k, :3, 3]
        np.testing.assert_allclose(scene.a[mask] + scene.flow[mask], moved, atol=1e-9)
    assert checked >= 2


def test_speeds_and_headings():
    interval = 0.5
    for seed in range(3):
        scene = _scene(seed, interval=interval, n_beams=4, n_azimuths=64)
        back = np.linalg.inv(scene.transforms[0])
        for k in range(N_MOVING + 1, len(scene.kinds)):
            motion = back @ scene.transforms[k]  # in the first sweep's (world-aligned) frame
            np.testing.assert_allclose(motion[:3, :3], np.eye(3), atol=1e-12)
            step = motion[:3, 3]
            speed = np.linalg.norm(step) / interval
            assert step[2] == pytest.approx(0.0, abs=1e-12)
            if scene.kinds[k] == "walker":
                assert 1.0 <= speed <= 1.8
            else:
                assert 3.0 <= speed <= 7.0
                assert abs(step[1]) <= np.tan(np.radians(3.0)) * abs(step[0]) + 1e-12


@pytest.mark.parametrize("seed", [0, 3])
def test_standing_things_are_static_world(placed, seed):
    scene = _scene(seed)
    standing = [box for kind, box, box2 in placed[0]["things"] if kind == "standing"]
    for kind, (centre, yaw, half), (centre2, yaw2, half2) in placed[0]["things"]:
        if kind == "standing":
            assert np.array_equal(centre, centre2) and yaw == yaw2 and np.array_equal(half, half2)
    assert scene.standing.sum() >= 10
    assert np.all(scene.labels[scene.standing] == 0)
    static = scene.a[scene.standing] @ scene.transforms[0, :3, :3].T + scene.transforms[0, :3, 3]
    np.testing.assert_allclose(scene.a[scene.standing] + scene.flow[scene.standing], static)
    # Each standing point lies on one of the standing boxes.
    world = _world(scene.a[scene.standing], placed[0]["sensors"][0])
    for point in world:
        assert any(_on_surface(point[None], box, 0.05) for box in standing)


@pytest.mark.parametrize("seed", range(4))
def test_small_things_keep_apart(placed, seed):
    _scene(seed, n_beams=4, n_azimuths=64, interval=0.1)
    (call,) = placed
    for when in (1, 2):  # the boxes at the first, then the second sweep
        boxes = [thing[when] for thing in call["things"]]
        centres = np.array([box[0][:2] for box in boxes])
        gaps = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
        assert gaps[np.triu_indices(len(boxes), 1)].min() >= 2.0
        sensor = call["sensors"][when - 1][:2]
        assert np.linalg.norm(centres - sensor, axis=1).min() >= 4.0
        for box in boxes:  # its footprint's corners and centre inside no other box
            centre, yaw, half = box
            c, s = np.cos(yaw), np.sin(yaw)
            grid = np.array([[i, j, 0.0] for i in (-1, 0, 1) for j in (-1, 0, 1)]) * half
            corners = grid @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]]) + centre
            assert not any(
                _inside_footprint(corners, other).any() for other in call["obstacles"][when - 1]
            )
    for kind, box, box2 in call["things"]:
        side = abs(box[0][1])
        assert (4.3 <= side <= 6.3) if kind == "cyclist" else (7.3 <= side <= 12.5)
        if kind == "cyclist":  # with the traffic of its side: +x on the right (y < 0)
            assert np.sign(box2[0][0] - box[0][0]) == -np.sign(box[0][1])


@pytest.mark.parametrize("name", ["n_walkers", "n_cyclists", "n_standing"])
@pytest.mark.parametrize("value", [-1, 1.5, True])
def test_counts_are_validated(name, value):
    with pytest.raises(ValueError, match=f"{name} must be a non-negative integer"):
        make_lidar_sweeps(n_beams=4, n_azimuths=64, random_state=0, **{name: value})


def test_a_street_too_small_is_one_clear_error(monkeypatch):
    monkeypatch.setattr(_lidar, "_APART", 500.0)  # no two things fit on the street
    with pytest.raises(ValueError, match="Could not place n_cyclists=2 cyclist objects"):
        make_lidar_sweeps(n_beams=4, n_azimuths=64, random_state=0, n_cyclists=2)


@pytest.mark.parametrize("seed", range(3))
def test_without_small_things_the_street_is_unchanged(seed):
    """Asking for small things changes only the rays that now hit them.

    Noiseless sweeps: every point of the street with small things that is not on one of
    them is a point of the street without them (same place, same label, same ground flag),
    and the points that street loses are no more than the rays the small things now take.
    The ego motion and the cars' motions are the same to the bit.
    """
    plain = make_lidar_sweeps(N_MOVING, noise=0.0, random_state=seed, **SMALL)
    busy = _scene(seed, noise=0.0, interval=0.1)
    np.testing.assert_array_equal(busy.transforms[: N_MOVING + 1], plain.transforms)
    assert plain.kinds.tolist() == ["static"] + ["car"] * N_MOVING
    assert not plain.standing.any()
    new = (busy.labels > N_MOVING) | busy.standing
    assert new.sum() > 0
    distance, index = cKDTree(plain.a).query(busy.a[~new])
    assert distance.max() < 1e-9
    np.testing.assert_array_equal(busy.labels[~new], plain.labels[index])
    np.testing.assert_array_equal(busy.ground[~new], plain.ground[index])
    np.testing.assert_allclose(busy.flow[~new], plain.flow[index], atol=1e-9)
    lost = len(plain.a) - (~new).sum()
    assert 0 <= lost <= new.sum()
    # The second sweep: the points it loses are rays the small things now take.
    near, _ = cKDTree(busy.sweep).query(plain.sweep)
    gained, _ = cKDTree(plain.sweep).query(busy.sweep)
    assert 0 < (near > 1e-9).sum() <= (gained > 1e-9).sum()


@pytest.mark.parametrize("seed", [0, 5])
def test_with_noise_the_world_and_cars_are_drawn_alike(seed):
    plain = make_lidar_sweeps(N_MOVING, random_state=seed, n_beams=4, n_azimuths=64)
    busy = _scene(seed, n_beams=4, n_azimuths=64, interval=0.1)
    np.testing.assert_array_equal(busy.transforms[: N_MOVING + 1], plain.transforms)
