"""FlyingThings3D-like scenes: random shapes flying in front of a pinhole camera.

FlyingThings3D (Mayer et al., CVPR 2016) renders ShapeNet objects at random poses and
depths, each moving by its own random rigid motion, in front of a background; the paper
(Section V) back-projects its depth maps to point clouds of 32,768 points and takes the
scene flow from a network. This module renders a scene of the same kind with Open3D:
random (combined) primitives of about 3 m at 5-35 m in front of a static backdrop.
"""

import numpy as np
from scipy.spatial.transform import Rotation
from sklearn.utils import check_random_state

from mmreg.datasets._camera import (
    box_mesh,
    check_bool,
    check_count,
    check_image_size,
    compose_motions,
    invert_motion,
    merge_meshes,
    motion_about_center,
    observe,
    pinhole_camera,
    random_rotation,
    transform_mesh,
)

__all__ = ["PRIMITIVES", "make_flying_things"]

PRIMITIVES = (
    "box",
    "sphere",
    "cylinder",
    "cone",
    "torus",
    "arrow",
    "octahedron",
    "icosahedron",
    "tetrahedron",
    "mobius",
    "composite",
)
# FlyingThings3D's camera for 960 x 540 images.
_FOCAL, _WIDTH = 1050.0, 960
# Objects: diameter (m), depth of the centre (m), motion (degrees, metres).
_DIAMETER = (2.0, 4.0)
_DEPTH = (5.0, 35.0)
_ANGLE = (3.0, 20.0)
_SHIFT = (0.1, 2.0)
# Camera ego-motion between the frames (degrees, metres).
_EGO_ANGLE = (0.0, 2.0)
_EGO_SHIFT = (0.0, 0.5)
# Backdrop: a plane this deep (m), tilted by up to this much (degrees).
_BACKDROP_DEPTH = (45.0, 60.0)
_BACKDROP_TILT = 20.0
# Static objects of the background (FlyingThings3D's background holds still objects too):
# diameter and depth of the centre (m).
_STATIC_DIAMETER = (4.0, 8.0)
_STATIC_DEPTH = (20.0, 40.0)
# Attempts at placing an object clear of the others before giving up on clearance.
_PLACEMENT_ATTEMPTS = 100


def _primitive(name, rng):
    """A random primitive as ``(vertices, triangles)``, of unit diameter, centred."""
    import open3d as o3d

    mesh_cls = o3d.geometry.TriangleMesh
    u = lambda low, high: float(rng.uniform(low, high))  # noqa: E731
    if name == "composite":  # two or three smaller primitives stuck together
        parts = []
        for _ in range(rng.randint(2, 4)):
            part = _primitive(PRIMITIVES[rng.randint(len(PRIMITIVES) - 1)], rng)
            offset = rng.normal(size=3)
            offset *= u(0.15, 0.35) / np.linalg.norm(offset)
            parts.append(transform_mesh(part, scale=u(0.5, 0.8), translation=offset))
        vertices, triangles = merge_meshes(parts)
    else:
        if name == "box":
            mesh = mesh_cls.create_box(u(0.3, 1), u(0.3, 1), u(0.3, 1))
        elif name == "sphere":
            mesh = mesh_cls.create_sphere(1.0, resolution=16)
        elif name == "cylinder":
            mesh = mesh_cls.create_cylinder(u(0.2, 0.6), 1.0, resolution=24)
        elif name == "cone":
            mesh = mesh_cls.create_cone(u(0.3, 0.6), 1.0, resolution=24)
        elif name == "torus":
            mesh = mesh_cls.create_torus(1.0, u(0.2, 0.5), 24, 12)
        elif name == "arrow":
            mesh = mesh_cls.create_arrow(u(0.1, 0.2), u(0.25, 0.4), u(0.5, 1.0), u(0.3, 0.5), 16)
        elif name == "octahedron":
            mesh = mesh_cls.create_octahedron()
        elif name == "icosahedron":
            mesh = mesh_cls.create_icosahedron()
        elif name == "tetrahedron":
            mesh = mesh_cls.create_tetrahedron()
        elif name == "mobius":
            mesh = mesh_cls.create_mobius(48, 6, int(rng.randint(1, 3)), 1.0, 1.0, u(0.4, 0.8))
        else:
            raise ValueError(f"shape must be one of {PRIMITIVES}; got {name!r}.")
        vertices, triangles = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
        vertices = vertices * rng.uniform(0.6, 1.0, size=3)  # random proportions
    return _normalise((vertices, triangles))


def _bundled_meshes():
    """The bundled real meshes by name, ``{}`` when ``mmreg.datasets._meshes`` is absent."""
    try:
        from mmreg.datasets._meshes import load_meshes
    except ImportError:
        return {}
    return {
        mesh.name: (np.asarray(mesh.vertices), np.asarray(mesh.triangles)) for mesh in load_meshes()
    }


def _check_shapes(shapes):
    """The shapes as a tuple of names, ``"meshes"`` expanded to every bundled mesh."""
    if isinstance(shapes, str):
        shapes = (shapes,)
    try:
        shapes = tuple(shapes)
    except TypeError:
        raise ValueError(f"shapes must be a sequence of shape names; got {shapes!r}.") from None
    bundled = _bundled_meshes()
    expanded = []
    for shape in shapes:  # a handful of names
        expanded.extend(bundled if shape == "meshes" and bundled else [shape])
    allowed = PRIMITIVES + tuple(bundled) + (("meshes",) if bundled else ())
    unknown = sorted({str(shape) for shape in expanded} - set(allowed))
    if not expanded or unknown:
        raise ValueError(
            f"shapes must be a non-empty collection of {allowed}; got {shapes!r} "
            f"(unknown: {unknown})."
        )
    return tuple(expanded), bundled


def _normalise(mesh):
    """Centre a mesh at its bounding box centre and scale it to unit diameter."""
    vertices, triangles = mesh
    vertices = vertices - (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    radius = np.linalg.norm(vertices, axis=1).max()
    return vertices / (2 * radius), triangles


def _place_objects(diameters, camera, rng, depth=_DEPTH, placed=None):
    """Object centres in the view at depths in ``depth``, clear of one another (and of the
    ``placed`` ones, ``(centers, diameters)``) if possible.

    Each centre projects to a pixel uniform in the central 80 % of the image; objects are
    redrawn (up to ``_PLACEMENT_ATTEMPTS`` times) until their bounding balls are disjoint.
    """
    first = 0 if placed is None else len(placed[0])
    centers = np.empty((first + len(diameters), 3))
    sizes = np.concatenate([[] if placed is None else placed[1], diameters])
    if first:
        centers[:first] = placed[0]
    for k in range(first, len(centers)):  # a handful of objects
        for _ in range(_PLACEMENT_ATTEMPTS):
            u = rng.uniform(0.1, 0.9) * camera.width
            v = rng.uniform(0.1, 0.9) * camera.height
            z = rng.uniform(*depth)
            center = np.array([(u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z])
            gap = np.linalg.norm(centers[:k] - center, axis=1) - (sizes[:k] + sizes[k]) / 2
            if np.all(gap > 0):
                break
        centers[k] = center
    return centers[first:]


def make_flying_things(
    n_objects=10,
    n_points=32768,
    *,
    image_size=(540, 960),
    shapes=PRIMITIVES,
    corruption=None,
    sam_masks=True,
    n_static=0,
    random_state=None,
):
    """A FlyingThings3D-like scene: rendered objects flying in front of a camera.

    ``n_objects`` random shapes of 2-4 m (diameter) are placed at random orientations
    and depths of 5-35 m in front of a pinhole camera with FlyingThings3D's intrinsics
    (``fx = fy = 1050``, ``cx = 479.5``, ``cy = 269.5`` for 960 x 540 images), before a
    texture-less backdrop plane 45-60 m deep and tilted by up to 20 degrees. Each object
    turns by 3-20 degrees about a random axis through its centre and moves by 0.1-2 m;
    the camera itself moves a little (up to 2 degrees and 0.5 m), as in FlyingThings3D,
    so the backdrop has a motion of its own.

    The scene is rendered with Open3D's ray casting into a depth image (a z-buffer: only
    visible surfaces are seen, and the density of points falls as ``1 / z**2``), and
    ``n_points`` pixels are drawn uniformly among the valid ones and back-projected: the
    a-points. Their b-points are the same surface points after the motion, in the second
    frame's camera coordinates, with the flow corrupted as a scene-flow network would
    (:func:`~mmreg.datasets._flow_noise.corrupt_scene_flow`).

    Parameters
    ----------
    n_objects : int, default=10
        Number of moving objects, as in FlyingThings3D (about 10 per scene).
    n_points : int, default=32768
        Number of correspondences, the paper's 32,768; drawn without replacement among
        the pixels that see a surface, so at most ``H * W``.
    image_size : (int, int), default=(540, 960)
        ``(height, width)`` of the image. The focal length scales with the width
        (``fx = fy = 1050 * width / 960``, the field of view of FlyingThings3D) and the
        principal point is the image centre; smaller images make faster scenes.
    shapes : sequence of str, default=PRIMITIVES
        Shapes to draw each object from (uniformly): Open3D primitives ``"box"``,
        ``"sphere"``, ``"cylinder"``, ``"cone"``, ``"torus"``, ``"arrow"``,
        ``"octahedron"``, ``"icosahedron"``, ``"tetrahedron"``, ``"mobius"``, and
        ``"composite"`` (2 or 3 of them stuck together). Every shape gets random
        proportions (each axis scaled by 0.6-1) and a random orientation. When the
        bundled meshes (``mmreg.datasets._meshes.load_meshes``) are installed, their
        names are shapes too, and ``"meshes"`` stands for all of them (drawn at their
        own proportions).
    corruption : None, False or dict, default=None
        Keyword arguments of :func:`~mmreg.datasets._flow_noise.corrupt_scene_flow`
        (``noise``, ``noise_depth``, ``gross_error_fraction``, ``blob_fraction``,
        ``gross_error_scale``, ``bleeding_width``); None: its defaults; False: clean
        flow, ``b = R a + t`` exactly.
    sam_masks : bool, default=True
        Whether to simulate SegmentAnything masks of the first image
        (:func:`~mmreg.datasets._sam.simulate_sam_masks`, the backdrop as background).
    n_static : int, default=0
        Still objects of the background (FlyingThings3D's background holds some): random
        shapes of 4-8 m at depths of 20-40 m that move with the backdrop (label 0), so
        that the static world lies in pieces at several depths. Drawn after everything
        else: a scene with ``n_static=0`` is the one drawn before this option existed.
    random_state : int, RandomState instance or None, default=None
        Seeds every random choice (shapes, poses, motions, pixels, corruption, masks).

    Returns
    -------
    scene : sklearn.utils.Bunch
        With ``n = n_points`` and ``K = n_objects``:

        - ``X`` (n, 6): ``[a | b]``, with ``b`` corrupted; also ``a``, ``b`` (n, 3), in
          metres, in each frame's camera coordinates (x right, y down, z forward).
        - ``labels`` (n,): motion group, 0 for the backdrop, ``1..K`` for the objects.
        - ``instance_labels`` (n,): the ground-truth instance (here the same as
          ``labels``: one per object, the backdrop its own; with ``n_static``, each
          still object its own, numbered after the moving ones).
        - ``surface_labels`` (n,): the rendered mesh (here the same again).
        - ``outlier_mask`` (n,): gross errors of the corruption; ``bled_mask`` (n,):
          flows bled across an object boundary.
        - ``rotations`` (K + 1, 3, 3), ``translations`` (K + 1, 3): the motion of every
          group, ``a + flow_clean = R a + t``; objects hidden in the image keep theirs.
        - ``flow`` (n, 3) ``= b - a``; ``flow_clean`` (n, 3), the true scene flow.
        - ``pixels`` (n, 2) int: ``(column, row)`` of each a-point, the convention of
          :class:`~mmreg.init.PrecomputedMasks`.
        - ``depth_image`` (H, W): depth ``z`` of each pixel (0: no surface);
          ``instance_image`` and ``surface_image`` (H, W): instance and mesh of each
          pixel (-1: none).
        - ``masks``: list of SAM-format dicts (None when ``sam_masks=False``).
        - ``camera``: the intrinsics (``fx``, ``fy``, ``cx``, ``cy``, ``width``,
          ``height``, ``K``).

    See Also
    --------
    make_street : A KITTI-like street scene.
    make_scene : Sampled (not rendered) shapes, as the paper's PASCAL3D+ experiments.

    Notes
    -----
    Cost: one ray per pixel (about 0.1 s for 960 x 540 on one core), then ``O(H W)`` for
    the corruption and the masks; a default scene takes about 0.5 s. Objects are drawn
    clear of one another in the first frame when 100 attempts allow it; they may touch
    after their motions. The camera's ego-motion makes the backdrop's motion
    ``rotations[0], translations[0]`` the inverse of the camera's.

    References
    ----------
    N. Mayer et al., "A Large Dataset to Train Convolutional Networks for Disparity,
    Optical Flow, and Scene Flow Estimation", CVPR 2016.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.datasets._flying_things import make_flying_things
    >>> scene = make_flying_things(n_objects=3, n_points=500, image_size=(54, 96),
    ...                            corruption=False, sam_masks=False, random_state=0)
    >>> scene.X.shape, scene.rotations.shape
    ((500, 6), (4, 3, 3))
    >>> R, t = scene.rotations[scene.labels], scene.translations[scene.labels]
    >>> bool(np.allclose(np.einsum("nij,nj->ni", R, scene.a) + t, scene.b))
    True
    """
    n_objects = check_count(n_objects, "n_objects")
    n_points = check_count(n_points, "n_points", low=1)
    height, width = check_image_size(image_size)
    shapes, bundled = _check_shapes(shapes)
    sam_masks = check_bool(sam_masks, "sam_masks")
    rng = check_random_state(random_state)

    focal = _FOCAL * width / _WIDTH
    camera = pinhole_camera(width, height, focal, focal, (width - 1) / 2, (height - 1) / 2)

    # Objects: shape, size, pose.
    diameters = rng.uniform(*_DIAMETER, n_objects)
    centers = _place_objects(diameters, camera, rng)
    meshes = []
    for k in range(n_objects):  # a handful of objects
        shape = shapes[rng.randint(len(shapes))]
        unit = _normalise(bundled[shape]) if shape in bundled else _primitive(shape, rng)
        rotation = Rotation.random(random_state=rng).as_matrix()
        meshes.append(transform_mesh(unit, rotation, centers[k], scale=diameters[k]))

    # Backdrop: a thick slab far behind, tilted about its centre; the camera sees its
    # front face.
    depth = rng.uniform(*_BACKDROP_DEPTH)
    tilt = Rotation.from_euler(
        "xy", rng.uniform(-_BACKDROP_TILT, _BACKDROP_TILT, 2), degrees=True
    ).as_matrix()
    center = np.array([0.0, 0.0, depth + 0.5])
    slab = box_mesh((4.0 * depth, 4.0 * depth, 1.0))
    backdrop = transform_mesh(slab, tilt, center)

    # Motions, first camera frame -> second camera frame.
    ego = (random_rotation(*_EGO_ANGLE, rng), _random_vector(_EGO_SHIFT, rng))
    to_second = invert_motion(ego)
    motions = [to_second]
    for k in range(n_objects):  # a handful of objects
        own = motion_about_center(
            random_rotation(*_ANGLE, rng), centers[k], _random_vector(_SHIFT, rng)
        )
        motions.append(compose_motions(own, to_second))
    rotations = np.stack([m[0] for m in motions])
    translations = np.stack([m[1] for m in motions])

    ids = np.arange(n_objects + 1)
    labels = ids
    n_static = check_count(n_static, "n_static")
    if n_static:
        # Still objects of the background: label 0, an instance each.
        static_diameters = rng.uniform(*_STATIC_DIAMETER, n_static)
        static_centers = _place_objects(
            static_diameters, camera, rng, _STATIC_DEPTH, placed=(centers, diameters)
        )
        for k in range(n_static):
            shape = shapes[rng.randint(len(shapes))]
            unit = _normalise(bundled[shape]) if shape in bundled else _primitive(shape, rng)
            rotation = Rotation.random(random_state=rng).as_matrix()
            meshes.append(
                transform_mesh(unit, rotation, static_centers[k], scale=static_diameters[k])
            )
        labels = np.concatenate([ids, np.zeros(n_static, dtype=ids.dtype)])
        ids = np.arange(n_objects + 1 + n_static)
    return observe(
        [backdrop, *meshes],
        (rotations, translations),
        labels,
        ids,
        camera,
        n_points,
        corruption=corruption,
        sam_masks=sam_masks,
        background=[0],
        random_state=rng,
    )


def _random_vector(magnitude, rng):
    """A vector of uniformly random direction and length uniform in ``magnitude``."""
    direction = rng.normal(size=3)
    return direction / np.linalg.norm(direction) * rng.uniform(*magnitude)
