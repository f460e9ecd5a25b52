"""Synthetic dynamic scenes with known objects, motions and outliers.

Scenes follow Definition 1 of the paper: each object is a densely sampled surface, so it is
tau-connected for any ``tau`` above its sampling gap; objects are more than
``separation`` apart; outliers, if any, lie farther than ``separation`` from every object.
The surfaces are geometric primitives or, with ``shapes="meshes"``, real meshes (see
:mod:`mmreg.datasets._meshes`).
"""

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from sklearn.utils import Bunch, check_random_state

from mmreg.datasets._meshes import MESH_NAMES, _mesh_radius, _surface_points

__all__ = ["SHAPES", "make_scene"]

SHAPES = ("sphere", "box", "cylinder", "torus", "plane")
# Farthest reach of any unit shape from its centre: the corners of the 1 x 1 plane.
_UNIT_RADIUS = np.sqrt(0.5)


def _unit_shape(shape, n, rng):
    """``n`` points on the surface of a shape of diameter about 1, centred at 0."""
    if shape == "sphere":
        p = rng.normal(size=(n, 3))
        return 0.5 * p / np.linalg.norm(p, axis=1, keepdims=True)
    if shape == "box":
        half = np.array([0.5, 0.3, 0.2])
        p = rng.uniform(-1, 1, size=(n, 3)) * half
        face = rng.randint(0, 3, n)
        p[np.arange(n), face] = np.where(rng.random(n) < 0.5, -1, 1) * half[face]
        return p
    if shape == "cylinder":
        angle = rng.uniform(0, 2 * np.pi, n)
        return np.column_stack(
            [0.3 * np.cos(angle), 0.3 * np.sin(angle), rng.uniform(-0.5, 0.5, n)]
        )
    if shape == "torus":
        u, v = rng.uniform(0, 2 * np.pi, (2, n))
        r = 0.35 + 0.12 * np.cos(v)
        return np.column_stack([r * np.cos(u), r * np.sin(u), 0.12 * np.sin(v)])
    if shape == "plane":
        return np.column_stack([rng.uniform(-0.5, 0.5, (n, 2)), np.zeros(n)])
    raise ValueError(f"shape must be one of {SHAPES}; got {shape!r}.")


def _check_shapes(shapes):
    """The mesh names ``shapes`` asks for, or None for the primitives."""
    if isinstance(shapes, str):
        if shapes == "primitives":
            return None
        if shapes == "meshes":
            return MESH_NAMES
    else:
        try:
            names = tuple(shapes)
        except TypeError:
            names = ()
        if names and all(isinstance(n, str) and n in MESH_NAMES for n in names):
            return tuple(dict.fromkeys(names))
    raise ValueError(
        "shapes must be 'primitives', 'meshes' or a non-empty sequence of names from "
        f"MESH_NAMES {MESH_NAMES}; got {shapes!r}."
    )


def make_scene(
    n_objects=7,
    n_points=22395,
    *,
    noise=0.0,
    noise_type="gaussian",
    outlier_fraction=0.0,
    object_size=1.0,
    separation=2.0,
    same_motion=0,
    shapes="primitives",
    random_state=None,
):
    """Correspondences ``(a_i, b_i)`` of a scene of rigidly moving objects.

    The default mimics the paper's PASCAL3D+ setup: 7 objects, 22,395 correspondences.
    The objects are geometric primitives (``shapes="primitives"``) or real meshes
    (``shapes="meshes"``): 16 surfaces of animals, a figure, a hand, a bone and
    mechanical parts, 7 of which stand in for the paper's 7 CAD models.

    Parameters
    ----------
    n_objects : int, default=7
        Number of rigid objects (one of them can play the static background).
    n_points : int, default=22395
        Total number of correspondences, outliers included.
    noise : float, default=0.0
        Standard deviation (``"gaussian"``) or bound ``sigma`` of the uniform noise on
        ``[-sigma, sigma]^3`` (``"uniform"``, Definition 1) added to the b-points.
    noise_type : {"gaussian", "uniform"}, default="gaussian"
    outlier_fraction : float, default=0.0
        Fraction of correspondences that are outliers: a-points farther than
        ``separation`` from every object, b-points anywhere in the scene's box.
    object_size : float, default=1.0
        Extent of each object, in metres. Primitives: shapes of width about
        ``object_size``, each within a ball of radius ``object_size / sqrt(2)``. Meshes:
        ``object_size`` is the diameter, the largest distance between two points of the
        surface, in every orientation; the paper's objects are about 3 m across
        (``object_size=3``).
    separation : float, default=2.0
        Smallest gap between objects' a-points (and between outliers and objects). To
        keep objects apart as Definition 1 asks, keep it above the estimator's ``tau``
        (1.5 m in the paper), whatever ``object_size``: the default 2.0 does at the
        paper's scale. Objects sit on a cubic grid of pitch ``2 r object_size +
        separation``, ``r`` the radius of the unit shapes' bounding ball (about 0.71 for
        primitives, at most 0.59 for meshes), so most gaps are wider.
    same_motion : int, default=0
        Number of objects (besides the first) that share the first object's motion, as in
        the paper's Experiment 3; only the distance gate can tell them apart.
    shapes : {"primitives", "meshes"} or sequence of str, default="primitives"
        Surfaces of the objects. ``"primitives"``: object ``k`` is ``SHAPES[k % 5]``
        (sphere, box, cylinder, torus, plane). ``"meshes"``: each object is a mesh of
        :data:`MESH_NAMES` drawn at random, all different unless ``n_objects`` exceeds
        the 16 meshes; a sequence of names draws the same way from those meshes only
        (e.g. to leave out ``"bunny"``, whose licence is not CC0). An object of ``m``
        correspondences takes ``m`` of the mesh's 2048 stored surface samples, or all of
        them and ``m - 2048`` more on segments between neighbouring samples (see
        :func:`load_mesh_points`). Either way every object is rotated at random.
    random_state : int, RandomState instance or None, default=None

    Returns
    -------
    scene : sklearn.utils.Bunch
        ``X`` (n, 6) stacked ``[a | b]``; ``labels`` (n,) object of each correspondence,
        ``-1`` for outliers; ``rotations`` (n_objects, 3, 3) and ``translations``
        (n_objects, 3), with ``b = R a + t (+ noise)`` for the object's rows; ``a``, ``b``;
        ``shapes`` (n_objects,) the primitive or mesh name of each object.

    See Also
    --------
    load_mesh_points : The surface samples behind ``shapes="meshes"``.

    Examples
    --------
    >>> from mmreg.datasets import make_scene
    >>> scene = make_scene(n_objects=3, n_points=300, random_state=0)
    >>> scene.X.shape, sorted(set(scene.labels.tolist()))
    ((300, 6), [0, 1, 2])

    The paper's set-up with real objects 3 m across:

    >>> scene = make_scene(shapes="meshes", object_size=3.0, random_state=0)
    >>> scene.X.shape, len(scene.shapes), len(set(scene.shapes))
    ((22395, 6), 7, 7)
    """
    if n_objects < 1:
        raise ValueError(f"n_objects must be >= 1; got {n_objects}.")
    if not 0 <= outlier_fraction < 1:
        raise ValueError(f"outlier_fraction must be in [0, 1); got {outlier_fraction}.")
    if noise_type not in ("gaussian", "uniform"):
        raise ValueError(f"noise_type must be 'gaussian' or 'uniform'; got {noise_type!r}.")
    if not 0 <= same_motion < n_objects:
        raise ValueError(f"same_motion must be in [0, n_objects); got {same_motion}.")
    mesh_pool = _check_shapes(shapes)
    rng = check_random_state(random_state)
    n_outliers = int(round(outlier_fraction * n_points))
    n_inliers = n_points - n_outliers
    sizes = np.full(n_objects, n_inliers // n_objects)
    sizes[: n_inliers % n_objects] += 1
    if sizes.min() < 1:
        raise ValueError(f"n_points={n_points} is too few for {n_objects} objects.")

    if mesh_pool is None:
        names = [SHAPES[obj % len(SHAPES)] for obj in range(n_objects)]
        radius = _UNIT_RADIUS
    else:
        picks = rng.choice(len(mesh_pool), n_objects, replace=n_objects > len(mesh_pool))
        names = [mesh_pool[p] for p in picks]
        radius = max(_mesh_radius(name) for name in names)

    # Objects on a cubic grid whose pitch keeps every gap above `separation`: each object
    # lies within a ball of radius `radius * object_size` around its centre.
    side = int(np.ceil(n_objects ** (1 / 3)))
    pitch = 2 * radius * object_size + separation
    cells = np.array([(i, j, k) for i in range(side) for j in range(side) for k in range(side)])
    centers = cells[rng.permutation(len(cells))[:n_objects]] * pitch
    a_parts = []
    for obj, size in enumerate(sizes):
        if mesh_pool is None:
            unit = _unit_shape(names[obj], size, rng)
        else:
            unit = _surface_points(names[obj], size, rng)
        local = unit @ Rotation.random(random_state=rng).as_matrix().T
        a_parts.append(object_size * local + centers[obj])
    labels = np.repeat(np.arange(n_objects), sizes)
    a = np.vstack(a_parts)

    rotations = Rotation.random(n_objects, random_state=rng).as_matrix().reshape(n_objects, 3, 3)
    translations = rng.uniform(-2.0, 2.0, size=(n_objects, 3))
    rotations[1 : 1 + same_motion] = rotations[0]
    translations[1 : 1 + same_motion] = translations[0]
    b = np.einsum("nij,nj->ni", rotations[labels], a) + translations[labels]
    if noise > 0:
        if noise_type == "gaussian":
            b += rng.normal(scale=noise, size=b.shape)
        else:
            b += rng.uniform(-noise, noise, size=b.shape)

    if n_outliers:
        low, high = a.min(axis=0) - pitch, a.max(axis=0) + pitch
        tree = cKDTree(a)
        found = []
        while sum(len(f) for f in found) < n_outliers:
            cand = rng.uniform(low, high, size=(2 * n_outliers, 3))
            dist, _ = tree.query(cand, distance_upper_bound=separation)
            found.append(cand[~np.isfinite(dist)])
        out_a = np.vstack(found)[:n_outliers]
        out_b = rng.uniform(b.min(axis=0), b.max(axis=0), size=(n_outliers, 3))
        a = np.vstack([a, out_a])
        b = np.vstack([b, out_b])
        labels = np.concatenate([labels, np.full(n_outliers, -1)])

    return Bunch(
        X=np.hstack([a, b]),
        labels=labels,
        rotations=rotations,
        translations=translations,
        a=a,
        b=b,
        shapes=np.array(names),
    )
