"""Surface samples of real meshes, shipped with mmreg, for :func:`make_scene`.

``data/meshes.npz`` holds, for each of 16 object-like triangle meshes from CGAL's sample data
(animals, a human figure, a hand, a bone, mechanical parts), 2048 evenly spread samples of
its surface (Poisson-disk sample elimination), centred at the centre of their bounding box
and scaled to diameter 1: the largest distance between two samples is 1. The file and its
attribution (``data/meshes_ATTRIBUTION.md``: source, licence and author of every mesh) are
written by ``scripts/derive_meshes.py``; nothing is downloaded at run time.
"""

from functools import cache
from importlib import resources

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["MESH_NAMES", "load_mesh_points"]

MESH_NAMES = (
    "anchor",
    "bear",
    "bull",
    "bunny",
    "cactus",
    "coupling",
    "dino",
    "diplodocus",
    "elk",
    "femur",
    "hand",
    "knot",
    "man",
    "pig",
    "pinion",
    "spool",
)
# Extra points beyond the stored samples lie on segments from a sample to one of its
# _NEIGHBOURS nearest samples (see _surface_points).
_NEIGHBOURS = 6


@cache
def _stored_points():
    """Every mesh's stored samples, read once: name -> read-only float32 (m, 3) array."""
    path = resources.files("mmreg.datasets").joinpath("data").joinpath("meshes.npz")
    with path.open("rb") as f, np.load(f) as data:
        points = {name: data[name] for name in MESH_NAMES}
    for array in points.values():
        array.flags.writeable = False
    return points


def _check_name(name):
    if name not in MESH_NAMES:
        raise ValueError(f"name must be one of {MESH_NAMES} or None; got {name!r}.")


def load_mesh_points(name=None):
    """Surface samples of the real meshes shipped with mmreg.

    Each mesh's 2048 samples are spread evenly over its surface (neighbouring samples are
    about equally far apart), centred at the centre of their bounding box and scaled to
    diameter 1 (the largest distance between two samples), in the mesh's own frame. They
    are the surfaces of ``make_scene(shapes="meshes")``. Sources, licences and authors
    are listed in ``mmreg/datasets/data/meshes_ATTRIBUTION.md``; all meshes are CC0 1.0
    except ``"bunny"``, the Stanford Bunny, which keeps the Stanford 3D Scanning
    Repository's terms.

    Parameters
    ----------
    name : str or None, default=None
        One of :data:`MESH_NAMES`, or None for all of them.

    Returns
    -------
    points : ndarray of shape (2048, 3) or dict of str to ndarray
        The float32 samples of mesh ``name``; for ``name=None`` a dict from every name in
        :data:`MESH_NAMES` (in that order) to its samples. The arrays are fresh copies.

    See Also
    --------
    make_scene : Scenes of moving objects whose surfaces are these samples.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.datasets import MESH_NAMES, load_mesh_points
    >>> bunny = load_mesh_points("bunny")
    >>> bunny.shape, bunny.dtype
    ((2048, 3), dtype('float32'))
    >>> meshes = load_mesh_points()
    >>> tuple(meshes) == MESH_NAMES
    True
    """
    if name is None:
        return {key: array.copy() for key, array in _stored_points().items()}
    _check_name(name)
    return _stored_points()[name].copy()


@cache
def _neighbours(name):
    """Indices of each stored sample's ``_NEIGHBOURS`` nearest other samples."""
    points = _stored_points()[name]
    _, index = cKDTree(points).query(points, k=_NEIGHBOURS + 1)
    return index[:, 1:]


def _mesh_radius(name):
    """Largest distance of a stored sample of mesh ``name`` from the mesh's centre (0)."""
    return float(np.linalg.norm(_stored_points()[name], axis=1).max())


def _surface_points(name, n, rng):
    """``n`` points on the surface of mesh ``name`` (diameter 1, centred at 0), float64.

    Up to the 2048 stored samples, a random subset of them. Beyond, all of them plus
    ``n - 2048`` points drawn uniformly on segments from a random sample to one of its
    ``_NEIGHBOURS`` nearest samples (at most about 0.07 apart, typically 0.02-0.03): where
    the surface is smooth they stay within about 1e-4 of it (a chord of length ``d`` on a
    curve of radius ``r`` lies within ``d^2 / (8 r)`` of it); across a part thinner than
    the sampling (a leg, an antler) a segment may cut through the inside. The density of
    points thus follows the surface, and no point is repeated.
    """
    stored = _stored_points()[name].astype(np.float64)
    m = len(stored)
    order = rng.permutation(m)
    if n <= m:
        return stored[order[:n]]
    extra = n - m
    start = rng.randint(0, m, size=extra)
    end = _neighbours(name)[start, rng.randint(0, _NEIGHBOURS, size=extra)]
    step = rng.random_sample(extra)[:, None]
    between = stored[start] + step * (stored[end] - stored[start])
    return np.vstack([stored[order], between])
