"""KITTI-like street scenes: a driving camera, parked and moving cars.

KITTI Scene Flow 2015 (Menze & Geiger, CVPR 2015) pairs stereo frames 0.1 s apart taken
from a car driving through a town; the paper (Section V) back-projects its depth, takes
the flow from a network and calls every non-car point background. This module renders a
scene of the same kind with Open3D: a road with raised sidewalks, buildings, poles and
trees on both sides, parked and moving cars, seen by KITTI's camera moving forward.
"""

import numpy as np
from sklearn.utils import check_random_state

from mmreg.datasets._camera import (
    box_mesh,
    check_bool,
    check_count,
    check_image_size,
    compose_motions,
    invert_motion,
    merge_meshes,
    observe,
    pinhole_camera,
    transform_mesh,
)

__all__ = ["SURFACE_KINDS", "make_street"]

SURFACE_KINDS = ("road", "sidewalk", "building", "pole", "tree", "car")
# KITTI's rectified left colour camera (sequence 2011_09_26), 1242 x 375 images.
_KITTI_SIZE = (375, 1242)
_KITTI_FOCAL, _KITTI_CX, _KITTI_CY = 721.5377, 609.5593, 172.854
_CAMERA_HEIGHT = 1.65  # metres above the road
_MAX_DEPTH = 35.0  # range cap of the KITTI scene-flow point-cloud benchmarks
_FRAME_TIME = 0.1  # seconds between frames (10 Hz)
# Street layout (metres).
_LANE_WIDTH = 3.5
_PARKING_WIDTH = 2.2
_KERB_HEIGHT = 0.15
_SIDEWALK_WIDTH = (2.0, 4.0)
_BUILDING_HEIGHT = (6.0, 20.0)
_BUILDING_LENGTH = (8.0, 25.0)
_BUILDING_SETBACK = (0.0, 2.0)
_STREET_EXTENT = (-10.0, 80.0)  # along z
_FURNITURE_SPACING = (10.0, 25.0)  # between poles and trees along a sidewalk
# Cars: size (m), speed (m/s), yaw (degrees).
_CAR_LENGTH = (3.8, 4.8)
_CAR_WIDTH = (1.7, 1.9)
_CAR_HEIGHT = (1.4, 1.6)
_CAR_DEPTH = (4.0, 32.0)  # along z, centre of a car
_CAR_GAP = 1.0  # at least this between cars one behind the other
_SPEED = (2.0, 12.0)
_YAW_RATE = 2.0  # degrees per frame, at most
_HEADING_JITTER = 3.0
# Ego-motion: forward metres per frame, yaw degrees per frame.
_EGO_FORWARD = (0.5, 1.2)
_EGO_YAW = 2.0
_PLACEMENT_ATTEMPTS = 100


def _yaw(angle_deg):
    """Rotation about the camera's vertical axis (y, down): positive turns z towards x."""
    angle = np.deg2rad(angle_deg)
    cos, sin = np.cos(angle), np.sin(angle)
    return np.array([[cos, 0.0, sin], [0.0, 1.0, 0.0], [-sin, 0.0, cos]])


def _cylinder(radius, height, axis):
    """A closed cylinder centred at 0 whose axis is ``axis`` (0, 1 or 2)."""
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh.create_cylinder(radius, height, resolution=16, split=1)
    vertices = np.asarray(mesh.vertices)  # axis along z
    vertices = np.roll(vertices, axis - 2, axis=1)
    return vertices, np.asarray(mesh.triangles)


def _car(length, width, height, rng):
    """A car in its own frame: x across, y down, z forward; origin on the road below it.

    A body box 0.25 m above the road, a cabin box on it, set back a little, and four
    wheels.
    """
    clearance, wheel = 0.25, 0.33
    body_height = rng.uniform(0.55, 0.7)
    cabin_height = height - clearance - body_height
    cabin_length = rng.uniform(0.45, 0.55) * length
    parts = [
        box_mesh((width, body_height, length), (0.0, -clearance - body_height / 2, 0.0)),
        box_mesh(
            (0.88 * width, cabin_height, cabin_length),
            (0.0, -height + cabin_height / 2, -rng.uniform(0.03, 0.1) * length),
        ),
    ]
    for side in (-1, 1):
        for end in (-1, 1):
            center = (side * (width / 2 - 0.12), -wheel, end * (length / 2 - 0.85))
            parts.append(transform_mesh(_cylinder(wheel, 0.22, axis=0), translation=center))
    return merge_meshes(parts)


def _tree(height, crown, rng):
    """A trunk and an icosahedral crown; origin at the foot, y down."""
    import open3d as o3d

    trunk = transform_mesh(_cylinder(0.15, height, axis=1), translation=(0, -height / 2, 0))
    ball = o3d.geometry.TriangleMesh.create_icosahedron(1.0)
    crown_mesh = (np.asarray(ball.vertices), np.asarray(ball.triangles))
    scale = crown * rng.uniform(0.8, 1.2, size=3)
    crown_mesh = transform_mesh(
        (crown_mesh[0] * scale, crown_mesh[1]), translation=(0, -height - 0.6 * crown, 0)
    )
    return merge_meshes([trunk, crown_mesh])


def _street_side(edge, side, rng):
    """Sidewalk, buildings and street furniture on one side of the road.

    ``edge`` is the x of the kerb and ``side`` +1 (right) or -1 (left). Returns a list
    of ``(kind, mesh)``.
    """
    ground = _CAMERA_HEIGHT
    z0, z1 = _STREET_EXTENT
    sidewalk_width = rng.uniform(*_SIDEWALK_WIDTH)
    thickness = 0.5
    surfaces = [
        (
            "sidewalk",
            box_mesh(
                (sidewalk_width, thickness, z1 - z0),
                (
                    edge + side * sidewalk_width / 2,
                    ground - _KERB_HEIGHT + thickness / 2,
                    (z0 + z1) / 2,
                ),
            ),
        )
    ]
    facade = edge + side * sidewalk_width
    z = z0
    while z < z1:  # a handful of buildings per side
        length = rng.uniform(*_BUILDING_LENGTH)
        height = rng.uniform(*_BUILDING_HEIGHT)
        setback = rng.uniform(*_BUILDING_SETBACK)
        depth = 10.0
        center = (
            facade + side * (setback + depth / 2),
            ground - _KERB_HEIGHT - height / 2,
            z + length / 2,
        )
        surfaces.append(("building", box_mesh((depth, height, length), center)))
        z += length
    z = z0 + rng.uniform(*_FURNITURE_SPACING)
    while z < z1:  # a handful of poles and trees per side
        foot = np.array([edge + side * 0.6, ground - _KERB_HEIGHT, z])
        if rng.uniform() < 0.5:
            height = rng.uniform(4.0, 7.0)
            pole = _cylinder(0.08, height, axis=1)
            surfaces.append(("pole", transform_mesh(pole, translation=foot - (0, height / 2, 0))))
        else:
            tree = _tree(rng.uniform(2.0, 3.5), rng.uniform(1.2, 2.0), rng)
            surfaces.append(("tree", transform_mesh(tree, translation=foot)))
        z += rng.uniform(*_FURNITURE_SPACING)
    return surfaces


def _place_cars(n_cars, n_moving, lanes, oncoming, own_lane, parking, rng):
    """Slot (x), depth (z), heading and size of each car, without overlaps.

    Moving cars drive in the lanes (at least 7 m ahead in the camera's own lane), parked
    cars stand in the parking strips along both kerbs.
    """
    cars = []
    for index in range(n_cars):  # a handful of cars
        length = rng.uniform(*_CAR_LENGTH)
        for _ in range(_PLACEMENT_ATTEMPTS):
            if index < n_moving:
                lane = rng.randint(len(lanes))
                x = lanes[lane]
                heading = 180.0 * oncoming[lane] + rng.normal(0.0, 1.0)
                low = 7.0 + length / 2 if lane == own_lane else _CAR_DEPTH[0]
            else:
                side = rng.randint(2)
                x = parking[side]
                heading = 180.0 * rng.randint(2) + rng.uniform(-_HEADING_JITTER, _HEADING_JITTER)
                low = _CAR_DEPTH[0]
            z = rng.uniform(low, _CAR_DEPTH[1])
            clear = all(
                other["x"] != x or abs(other["z"] - z) > (other["length"] + length) / 2 + _CAR_GAP
                for other in cars
            )
            if clear:
                break
        cars.append(
            {
                "x": x,
                "z": z,
                "heading": heading,
                "length": length,
                "width": rng.uniform(*_CAR_WIDTH),
                "height": rng.uniform(*_CAR_HEIGHT),
            }
        )
    return cars


def make_street(
    n_cars=5,
    n_moving=None,
    n_points=16384,
    *,
    image_size=_KITTI_SIZE,
    corruption=None,
    sam_masks=True,
    random_state=None,
):
    """A KITTI-like street scene seen from a driving car.

    The camera is KITTI's (1242 x 375 pixels, ``fx = fy = 721.5377``,
    ``cx = 609.5593``, ``cy = 172.854``) 1.65 m above a road of 2 or 3 lanes of 3.5 m
    (the leftmost oncoming, the camera in one of the others), with a 2.2 m parking strip
    along each kerb, raised sidewalks (0.15 m kerb, 2-4 m wide), a row of buildings
    6-20 m high on each side, poles and trees. Cars are a body box, a cabin box and four
    wheels (3.8-4.8 x 1.7-1.9 x 1.4-1.6 m). ``n_moving`` of them drive in the lanes at
    2-12 m/s, turning by up to 2 degrees per frame; the others are parked. The camera
    drives forward 0.5-1.2 m per frame (5-12 m/s at KITTI's 10 Hz) and turns by up to
    2 degrees.

    Both point clouds are in their own frame's camera coordinates (x right, y down, z
    forward), as KITTI's: the static world, parked cars included, moves by the inverse
    of the ego-motion, the motion group 0. The scene is rendered by ray casting to a
    depth image capped at 35 m (the range of the KITTI point-cloud benchmarks; farther
    surfaces and the sky are invalid pixels), and ``n_points`` valid pixels are drawn
    uniformly and back-projected (the density falls as ``1 / z**2``).

    Parameters
    ----------
    n_cars : int, default=5
        Number of cars, parked and moving. KITTI's scenes have 3-8 visible cars; a car
        may be hidden behind another.
    n_moving : int or None, default=None
        Number of moving cars, at most ``n_cars``; None: uniform in
        ``1..n_cars - 1`` (some of each), or ``n_cars`` when ``n_cars <= 1``.
    n_points : int, default=16384
        Number of correspondences. KITTI scene-flow evaluations on point clouds use 8,192
        (FlowNet3D, HPLFlowNet, PointPWC-Net) or 16,384 points; the paper's KITTI
        experiment follows its FlyingThings3D steps (32,768 points), which is also
        possible (a default scene has about 390,000 valid pixels).
    image_size : (int, int), default=(375, 1242)
        ``(height, width)`` of the image; the intrinsics scale with the width (same
        field of view) and the principal point keeps its relative place.
    corruption : None, False or dict, default=None
        Keyword arguments of :func:`~mmreg.datasets._flow_noise.corrupt_scene_flow`;
        None: its defaults; False: clean flow.
    sam_masks : bool, default=True
        Whether to simulate SegmentAnything masks of the first image (road, sidewalks
        and buildings as the background SAM cuts into many pieces).
    random_state : int, RandomState instance or None, default=None
        Seeds every random choice (layout, cars, motions, pixels, corruption, masks).

    Returns
    -------
    scene : sklearn.utils.Bunch
        The fields of :func:`make_flying_things`, with ``M = n_moving``:

        - ``labels`` (n,): motion group, 0 for the static world (road, sidewalks,
          buildings, poles, trees and parked cars), ``1..M`` for the moving cars.
        - ``instance_labels`` (n,): the paper's ground truth, 0 for everything that is
          not a car, ``1..n_cars`` for the cars (the first ``M`` are the moving ones, so a
          moving car's instance is its motion group).
        - ``rotations`` (M + 1, 3, 3), ``translations`` (M + 1, 3).
        - ``moving`` (n_cars,) bool: whether car ``i + 1`` moves.
        - ``surface_labels`` (n,), ``surface_image`` (H, W): the rendered mesh;
          ``surface_kinds`` (n_surfaces,): the kind of each mesh (one of
          ``SURFACE_KINDS``).
        - ``ego_motion``: ``(R, t)``, the pose of the second camera in the first frame.

    See Also
    --------
    make_flying_things : FlyingThings3D-like scenes.

    Notes
    -----
    Cost: one ray per pixel (about 0.1 s), then ``O(H W)`` for the corruption and the
    masks; a default scene takes well under a second. The road, sidewalks and buildings
    are flat: texture-less planes that make the points of the background exactly
    coplanar in patches.

    References
    ----------
    A. Geiger, P. Lenz and R. Urtasun, "Are we ready for Autonomous Driving? The KITTI
    Vision Benchmark Suite", CVPR 2012. M. Menze and A. Geiger, "Object Scene Flow for
    Autonomous Vehicles", CVPR 2015.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.datasets._street import make_street
    >>> scene = make_street(n_cars=4, n_moving=2, n_points=500, image_size=(75, 248),
    ...                     corruption=False, sam_masks=False, random_state=0)
    >>> scene.X.shape, scene.rotations.shape, scene.moving.tolist()
    ((500, 6), (3, 3, 3), [True, True, False, False])
    >>> R, t = scene.rotations[scene.labels], scene.translations[scene.labels]
    >>> bool(np.allclose(np.einsum("nij,nj->ni", R, scene.a) + t, scene.b))
    True
    """
    n_cars = check_count(n_cars, "n_cars")
    if n_moving is not None:
        n_moving = check_count(n_moving, "n_moving")
        if n_moving > n_cars:
            raise ValueError(f"n_moving must be at most n_cars={n_cars}; got {n_moving}.")
    n_points = check_count(n_points, "n_points", low=1)
    height, width = check_image_size(image_size)
    sam_masks = check_bool(sam_masks, "sam_masks")
    rng = check_random_state(random_state)
    if n_moving is None:
        n_moving = int(rng.randint(1, n_cars)) if n_cars > 1 else n_cars

    scale = width / _KITTI_SIZE[1]
    camera = pinhole_camera(
        width,
        height,
        _KITTI_FOCAL * scale,
        _KITTI_FOCAL * scale,
        (_KITTI_CX + 0.5) * scale - 0.5,
        (_KITTI_CY + 0.5) * height / _KITTI_SIZE[0] - 0.5,
    )

    # Road: lanes, the leftmost oncoming, the camera in another, parking strips at the kerbs.
    n_lanes = int(rng.randint(2, 4))
    own_lane = int(rng.randint(1, n_lanes))
    lanes = _LANE_WIDTH * (np.arange(n_lanes) - own_lane)
    oncoming = np.arange(n_lanes) == 0
    parking = (
        lanes[0] - _LANE_WIDTH / 2 - _PARKING_WIDTH / 2,
        lanes[-1] + _LANE_WIDTH / 2 + _PARKING_WIDTH / 2,
    )
    left_kerb = parking[0] - _PARKING_WIDTH / 2
    right_kerb = parking[1] + _PARKING_WIDTH / 2
    z0, z1 = _STREET_EXTENT
    surfaces = [
        (
            "road",
            box_mesh(
                (right_kerb - left_kerb + 0.2, 0.5, z1 - z0),
                ((left_kerb + right_kerb) / 2, _CAMERA_HEIGHT + 0.25, (z0 + z1) / 2),
            ),
        )
    ]
    surfaces += _street_side(right_kerb, 1, rng)
    surfaces += _street_side(left_kerb, -1, rng)
    n_static = len(surfaces)

    # Cars, and the motions of the moving ones (first camera frame, before ego-motion).
    cars = _place_cars(n_cars, n_moving, lanes, oncoming, own_lane, parking, rng)
    ego_yaw = rng.uniform(-_EGO_YAW, _EGO_YAW)
    ego = (_yaw(ego_yaw), _yaw(ego_yaw / 2) @ [0.0, 0.0, rng.uniform(*_EGO_FORWARD)])
    to_second = invert_motion(ego)
    motions = [to_second]
    for index, car in enumerate(cars):  # a handful of cars
        pose = _yaw(car["heading"])
        center = np.array([car["x"], _CAMERA_HEIGHT, car["z"]])
        mesh = _car(car["length"], car["width"], car["height"], rng)
        surfaces.append(("car", transform_mesh(mesh, pose, center)))
        if index < n_moving:
            turn = rng.uniform(-_YAW_RATE, _YAW_RATE)
            step = rng.uniform(*_SPEED) * _FRAME_TIME
            rotation = _yaw(turn)
            shift = _yaw(car["heading"] + turn / 2) @ [0.0, 0.0, step]
            own = (rotation, center + shift - rotation @ center)
            motions.append(compose_motions(own, to_second))
    rotations = np.stack([m[0] for m in motions])
    translations = np.stack([m[1] for m in motions])

    kinds = np.array([kind for kind, _ in surfaces])
    car_index = np.arange(n_cars)
    mesh_labels = np.concatenate(
        [np.zeros(n_static, dtype=np.intp), np.where(car_index < n_moving, car_index + 1, 0)]
    )
    mesh_instances = np.concatenate([np.zeros(n_static, dtype=np.intp), car_index + 1])
    background = np.flatnonzero(np.isin(kinds, ("road", "sidewalk", "building")))
    scene = observe(
        [mesh for _, mesh in surfaces],
        (rotations, translations),
        mesh_labels,
        mesh_instances,
        camera,
        n_points,
        max_depth=_MAX_DEPTH,
        corruption=corruption,
        sam_masks=sam_masks,
        background=background,
        random_state=rng,
    )
    scene.moving = car_index < n_moving
    scene.surface_kinds = kinds
    scene.ego_motion = ego
    return scene
