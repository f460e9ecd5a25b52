"""Pinhole camera, ray-cast rendering and rigid motions shared by the rendered scenes.

The rendered scene generators (:func:`~mmreg.datasets.make_flying_things`,
:func:`~mmreg.datasets.make_street`) build a list of triangle meshes, render them with
Open3D's ray casting into a depth image and a surface-id image (a z-buffer: only visible
surfaces), back-project a uniform sample of the valid pixels to 3D a-points and move each
a-point by the rigid motion of its surface. This module holds everything they share.

Conventions: the camera frame has x right, y down, z forward (depth), in metres; a pixel
is ``(column, row)`` = ``(u, v)``, the convention of SAM's ``point_coords`` and of
:class:`~mmreg.init.PrecomputedMasks`, and pixel ``(u, v)`` looks along the ray through
``((u - cx) / fx, (v - cy) / fy, 1)``. A motion ``(R, t)`` maps ``a`` to ``R a + t``.
"""

import inspect

import numpy as np
from scipy.spatial.transform import Rotation
from sklearn.utils import Bunch, check_random_state

__all__ = [
    "apply_motion",
    "back_project",
    "box_mesh",
    "check_corruption",
    "compose_motions",
    "invert_motion",
    "merge_meshes",
    "motion_about_center",
    "observe",
    "pinhole_camera",
    "project",
    "random_rotation",
    "render",
    "sample_pixels",
    "transform_mesh",
]


# --------------------------------------------------------------------------- camera
def pinhole_camera(width, height, fx, fy, cx, cy):
    """Intrinsics of a pinhole camera as a Bunch.

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    fx, fy, cx, cy : float
        Focal lengths and principal point, in pixels.

    Returns
    -------
    camera : sklearn.utils.Bunch
        ``width``, ``height``, ``fx``, ``fy``, ``cx``, ``cy`` and ``K`` (3, 3), the matrix
        with ``[u, v, 1] ~ K [x, y, z]``.

    Examples
    --------
    >>> from mmreg.datasets._camera import pinhole_camera
    >>> camera = pinhole_camera(960, 540, 1050.0, 1050.0, 479.5, 269.5)
    >>> camera.K[0].tolist()
    [1050.0, 0.0, 479.5]
    """
    for name, value in (("width", width), ("height", height)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name} must be a positive integer; got {value!r}.")
    for name, value in (("fx", fx), ("fy", fy)):
        if not np.isfinite(value) or value <= 0:
            raise ValueError(f"{name} must be a positive focal length in pixels; got {value!r}.")
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], dtype=float)
    return Bunch(
        width=int(width),
        height=int(height),
        fx=float(fx),
        fy=float(fy),
        cx=float(cx),
        cy=float(cy),
        K=K,
    )


def _ray_directions(camera):
    """(H, W, 3) directions through every pixel centre, of unit depth (z = 1)."""
    rows, cols = np.mgrid[: camera.height, : camera.width]
    return np.stack(
        [
            (cols - camera.cx) / camera.fx,
            (rows - camera.cy) / camera.fy,
            np.ones(rows.shape),
        ],
        axis=-1,
    )


def render(meshes, camera, *, max_depth=np.inf):
    """Depth and surface-id images of triangle meshes seen by a pinhole camera.

    One ray per pixel centre is cast with Open3D's :class:`RaycastingScene` from the
    camera centre (the origin of the camera frame); the first hit is the visible surface.

    Parameters
    ----------
    meshes : list of (vertices, triangles)
        Each mesh as ``vertices`` (v, 3) in the camera frame and ``triangles`` (f, 3)
        vertex indices; or an ``open3d.geometry.TriangleMesh``. Its index in the list is
        its surface id.
    camera : Bunch
        From :func:`pinhole_camera`.
    max_depth : float, default=inf
        Hits deeper than this are discarded (a range cap, like the 35 m of KITTI's
        point-cloud benchmarks).

    Returns
    -------
    depth_image : ndarray of shape (H, W)
        Depth ``z`` of the visible surface at each pixel, 0 where there is none.
    surface_image : ndarray of shape (H, W)
        Index in ``meshes`` of the visible surface, -1 where there is none.

    Notes
    -----
    Open3D casts in single precision: depths are exact to about ``1e-7 z``. Cost: one
    BVH build over all triangles, then ``O(H W log f)`` for the rays.

    Examples
    --------
    >>> import open3d as o3d
    >>> from mmreg.datasets._camera import pinhole_camera, render
    >>> camera = pinhole_camera(8, 6, 10.0, 10.0, 3.5, 2.5)
    >>> box = o3d.geometry.TriangleMesh.create_box(4.0, 4.0, 1.0).translate((-2, -2, 5))
    >>> depth, surface = render([box], camera)
    >>> round(float(depth[3, 4]), 4), int(surface[3, 4])
    (5.0, 0)
    """
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    for mesh in meshes:  # a handful of meshes
        if isinstance(mesh, o3d.geometry.TriangleMesh):
            vertices, triangles = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
        else:
            vertices, triangles = mesh
        scene.add_triangles(
            o3d.core.Tensor(np.ascontiguousarray(vertices, dtype=np.float32)),
            o3d.core.Tensor(np.ascontiguousarray(triangles, dtype=np.uint32)),
        )
    directions = _ray_directions(camera)
    rays = np.concatenate([np.zeros_like(directions), directions], axis=-1)
    hits = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))
    depth = hits["t_hit"].numpy().astype(float)
    ids = hits["geometry_ids"].numpy().astype(np.int64)
    valid = np.isfinite(depth) & (depth <= max_depth) & (ids != scene.INVALID_ID)
    depth_image = np.where(valid, depth, 0.0)
    surface_image = np.where(valid, ids, -1)
    return depth_image, surface_image


def sample_pixels(valid, n_points, rng):
    """``n_points`` distinct pixels drawn uniformly among the ``True`` pixels of ``valid``.

    Returns an int array (n_points, 2) of ``(column, row)``, sorted in raster order.
    Raises ``ValueError`` naming ``n_points`` when there are fewer valid pixels.
    """
    flat = np.flatnonzero(valid)
    if n_points > len(flat):
        raise ValueError(
            f"n_points={n_points} exceeds the {len(flat)} valid pixels of the "
            f"{valid.shape[0]} x {valid.shape[1]} image; ask for fewer points or a larger "
            "image."
        )
    chosen = np.sort(rng.choice(flat, size=n_points, replace=False))
    rows, cols = np.unravel_index(chosen, valid.shape)
    return np.column_stack([cols, rows]).astype(np.intp)


def back_project(depth, pixels, camera):
    """3D points at depth ``depth`` along the rays of ``pixels`` ``(column, row)``.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.datasets._camera import back_project, pinhole_camera, project
    >>> camera = pinhole_camera(8, 6, 10.0, 10.0, 3.5, 2.5)
    >>> points = back_project(np.array([2.0]), np.array([[7, 0]]), camera)
    >>> points.tolist(), project(points, camera).tolist()
    ([[0.7, -0.5, 2.0]], [[7.0, 0.0]])
    """
    depth = np.asarray(depth, dtype=float)
    pixels = np.asarray(pixels)
    return np.column_stack(
        [
            (pixels[:, 0] - camera.cx) * depth / camera.fx,
            (pixels[:, 1] - camera.cy) * depth / camera.fy,
            depth,
        ]
    )


def project(points, camera):
    """Pixel coordinates ``(column, row)`` (floats) of camera-frame points (z > 0)."""
    points = np.asarray(points, dtype=float)
    z = points[:, 2]
    return np.column_stack(
        [camera.fx * points[:, 0] / z + camera.cx, camera.fy * points[:, 1] / z + camera.cy]
    )


# --------------------------------------------------------------------------- motions
def random_rotation(min_angle, max_angle, rng):
    """Rotation matrix about a uniformly random axis by an angle uniform in the range (deg)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = np.deg2rad(rng.uniform(min_angle, max_angle))
    return Rotation.from_rotvec(angle * axis).as_matrix()


def motion_about_center(rotation, center, displacement):
    """Motion ``(R, t)`` that turns a body by ``rotation`` about ``center``, then moves it.

    The centre goes to ``center + displacement``: ``t = center + displacement - R center``.
    """
    center = np.asarray(center, dtype=float)
    return rotation, center + np.asarray(displacement, dtype=float) - rotation @ center


def compose_motions(first, second):
    """The motion ``second o first``: ``a -> R2 (R1 a + t1) + t2``."""
    (r1, t1), (r2, t2) = first, second
    return r2 @ r1, r2 @ t1 + t2


def invert_motion(motion):
    """The inverse ``(R^T, -R^T t)`` of a motion ``(R, t)``."""
    rotation, translation = motion
    return rotation.T, -rotation.T @ translation


def apply_motion(rotations, translations, labels, points):
    """``R[labels] a + t[labels]`` row by row (vectorised)."""
    return np.einsum("nij,nj->ni", rotations[labels], points) + translations[labels]


def transform_mesh(mesh, rotation=None, translation=None, scale=1.0):
    """A ``(vertices, triangles)`` mesh scaled, then rotated, then translated."""
    vertices, triangles = mesh
    vertices = np.asarray(vertices, dtype=float) * scale
    if rotation is not None:
        vertices = vertices @ np.asarray(rotation).T
    if translation is not None:
        vertices = vertices + np.asarray(translation, dtype=float)
    return vertices, np.asarray(triangles)


def merge_meshes(meshes):
    """One ``(vertices, triangles)`` mesh made of several (indices offset)."""
    offsets = np.cumsum([0] + [len(v) for v, _ in meshes[:-1]])
    vertices = np.vstack([v for v, _ in meshes])
    triangles = np.vstack([f + o for (_, f), o in zip(meshes, offsets, strict=True)])
    return vertices, triangles


def box_mesh(size, center=(0.0, 0.0, 0.0)):
    """An axis-aligned box of ``size`` (sx, sy, sz) centred at ``center``."""
    import open3d as o3d

    box = o3d.geometry.TriangleMesh.create_box(*map(float, size))
    vertices = np.asarray(box.vertices) - np.asarray(size, dtype=float) / 2 + center
    return vertices, np.asarray(box.triangles)


# --------------------------------------------------------------------------- assembly
def check_corruption(corruption):
    """Keyword arguments for ``corrupt_scene_flow``; ``None`` when the flow stays clean.

    ``None`` or ``True``: its defaults; ``False``: no corruption; a dict: its keywords.
    """
    if corruption is None or corruption is True:
        return {}
    if corruption is False:
        return None
    if not isinstance(corruption, dict):
        raise ValueError(
            "corruption must be None (default corruption), False (clean flow) or a dict of "
            f"keyword arguments of corrupt_scene_flow; got {corruption!r}."
        )
    from mmreg.datasets._flow_noise import corrupt_scene_flow

    allowed = set(inspect.signature(corrupt_scene_flow).parameters) - {
        "points",
        "flow",
        "pixels",
        "instance",
        "image_shape",
        "random_state",
    }
    unknown = sorted(set(corruption) - allowed)
    if unknown:
        raise ValueError(
            f"corruption has unknown keys {unknown}; allowed: {sorted(allowed)} "
            "(image_shape and random_state are set by the generator)."
        )
    return dict(corruption)


def check_bool(value, name):
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False; got {value!r}.")
    return bool(value)


def check_count(value, name, low=0):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise ValueError(f"{name} must be an integer >= {low}; got {value!r}.")
    return int(value)


def check_image_size(image_size):
    """``(height, width)`` as positive ints, or ValueError naming ``image_size``."""
    try:
        height, width = image_size
    except (TypeError, ValueError):
        raise ValueError(
            f"image_size must be a pair (height, width); got {image_size!r}."
        ) from None
    height = check_count(height, "image_size height", low=1)
    width = check_count(width, "image_size width", low=1)
    return height, width


def observe(
    meshes,
    motions,
    mesh_labels,
    mesh_instances,
    camera,
    n_points,
    *,
    max_depth=np.inf,
    corruption=None,
    sam_masks=True,
    background=(),
    random_state=None,
):
    """Render meshes, sample correspondences and bundle the ground truth.

    Parameters
    ----------
    meshes : list of (vertices, triangles)
        The surfaces, in the first frame's camera coordinates; a surface's id is its index.
    motions : (rotations (K+1, 3, 3), translations (K+1, 3))
        Motion of every motion group, from the first to the second camera frame.
    mesh_labels, mesh_instances : array of int, one per mesh
        Motion group and instance (ground-truth object) of every mesh.
    camera : Bunch
        From :func:`pinhole_camera`.
    n_points : int
        Number of correspondences, drawn uniformly among the valid pixels.
    max_depth : float, default=inf
        Range cap of the rendering.
    corruption : None, bool or dict
        See :func:`check_corruption`.
    sam_masks : bool
        Whether to simulate SAM masks from the surface image.
    background : collection of int
        Surface ids that SAM cuts into many pieces (road, walls, backdrop).
    random_state : int, RandomState instance or None

    Returns
    -------
    scene : Bunch
        The fields documented in the generators.
    """
    rng = check_random_state(random_state)
    kwargs = check_corruption(corruption)
    rotations, translations = (np.asarray(m, dtype=float) for m in motions)
    mesh_labels = np.asarray(mesh_labels, dtype=np.intp)
    mesh_instances = np.asarray(mesh_instances, dtype=np.intp)

    depth_image, surface_image = render(meshes, camera, max_depth=max_depth)
    valid = surface_image >= 0
    instance_image = np.where(valid, mesh_instances[np.maximum(surface_image, 0)], -1)
    pixels = sample_pixels(valid, n_points, rng)
    cols, rows = pixels[:, 0], pixels[:, 1]
    surface = surface_image[rows, cols]
    a = back_project(depth_image[rows, cols], pixels, camera)
    labels = mesh_labels[surface]
    b_clean = apply_motion(rotations, translations, labels, a)
    flow_clean = b_clean - a

    outlier_mask = np.zeros(n_points, dtype=bool)
    bled_mask = np.zeros(n_points, dtype=bool)
    flow = flow_clean.copy()
    if kwargs is not None:
        from mmreg.datasets._flow_noise import corrupt_scene_flow

        corrupted = corrupt_scene_flow(
            a,
            flow_clean,
            pixels[:, ::-1],  # corrupt_scene_flow takes (row, column)
            surface,
            image_shape=(camera.height, camera.width),
            random_state=rng,
            **kwargs,
        )
        flow, outlier_mask, bled_mask = (
            corrupted.flow,
            corrupted.outlier_mask,
            corrupted.bled_mask,
        )
    b = a + flow

    masks = None
    if sam_masks:
        from mmreg.datasets._sam import simulate_sam_masks

        masks = simulate_sam_masks(
            surface_image, background=[int(s) for s in background], random_state=rng
        )

    return Bunch(
        X=np.hstack([a, b]),
        labels=labels,
        instance_labels=mesh_instances[surface],
        surface_labels=surface,
        outlier_mask=outlier_mask,
        bled_mask=bled_mask,
        rotations=rotations,
        translations=translations,
        a=a,
        b=b,
        flow=flow,
        flow_clean=flow_clean,
        pixels=pixels,
        depth_image=depth_image,
        instance_image=instance_image,
        surface_image=surface_image,
        masks=masks,
        camera=camera,
    )
