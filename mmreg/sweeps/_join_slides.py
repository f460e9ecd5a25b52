"""The static world takes back every cluster that only slides along its own surfaces."""

import numpy as np
from scipy.spatial import cKDTree

from mmreg._array.motion import _group_median
from mmreg.sweeps._ambiguous_shapes import ACROSS, is_line
from mmreg.sweeps._explained import spacing_ratio
from mmreg.sweeps._icp import SurfaceNormals
from mmreg.sweeps._new_places import MIN_NEW_PLACE, new_place_shares

__all__ = ["join_slides"]

# A cluster whose motion moves its points off their own surfaces (relative to the static
# world) by fewer than this many of the ego ICP's robust residual scales only slides
# along them.
_SLIDE_SCALES = 3.0


def join_slides(a, labels, motions, static, sigma, target, reach, whole=None, own_normals=None):
    """The static world takes back every cluster that only slides along its own surfaces.

    A planar patch (a wall, a kerb, a strip of road) constrains only motion along its
    normals: an ICP slides it along itself at no cost, and the slide reads as motion.
    What shows that a cluster moved is how far its motion carries its points off their
    own surfaces relative to the static world's motion: the RMS, over its points, of the
    displacement ``M_k a - E a`` along each point's normal (PCA of its 10 nearest
    points of the first sweep). Below 3 robust residual scales of the ego-motion ICP
    (``sigma``, the same point-to-plane residual) the data cannot tell the cluster from
    the static world: it joins it, with the static world's motion. So does a cluster
    whose motion moves its points (median) by less than half the second sweep's sampling
    spacing where they land (``target``: the second sweep, its cKDTree and its
    SurfaceNormals): no sweep can show such a motion, whatever the noise. And so does
    a cluster that its motion shows at a new place with fewer than a tenth of its
    points (:mod:`mmreg.sweeps._new_places`) while moving along its own surfaces
    (normal component under half the displacement): a wall slid up or down along itself
    lands on surfaces the first sweep held already. And so does a line of points (a
    pole, a ring of road), whatever it shows.

    ``motions`` is ``(rotations, translations, ...)``, per-cluster arrays; ``reach``:
    the ICP's gate with capture times, else None; ``whole``:
    both sweeps with their ground, for the new places (see
    :func:`mmreg.sweeps._new_places.new_place_shares`); ``own_normals``: the
    :class:`~mmreg.sweeps._icp.SurfaceNormals` of ``a`` (10 neighbours) where the caller
    keeps them, else None; returns the labels, the
    same arrays without the joined clusters, and the static world's new index.
    """
    rotations, translations = motions[:2]
    others = np.flatnonzero((labels >= 0) & (labels != static))
    if not len(others):
        return labels, motions, static
    if own_normals is None:
        own_normals = SurfaceNormals(a, cKDTree(a), 10)
    normals, _, _ = own_normals(others)
    group = labels[others]
    points = a[others]
    moved = np.einsum("nij,nj->ni", rotations[group], points) + translations[group]
    displacement = moved - (points @ rotations[static].T + translations[static])
    along = np.einsum("ni,ni->n", np.nan_to_num(normals), displacement)
    n_clusters = len(rotations)
    counts = np.maximum(np.bincount(group, minlength=n_clusters), 1)
    evidence = np.sqrt(np.bincount(group, weights=along**2, minlength=n_clusters) / counts)
    sweep, tree, sweep_normals = target
    _, _, spacing = spacing_ratio(moved, tree, sweep, sweep_normals)
    departure = _group_median(np.linalg.norm(displacement, axis=1), group, n_clusters)
    unseen = departure < 0.5 * _group_median(spacing, group, n_clusters)
    # A cluster whose motion shows none of it at a new place slid onto static surfaces.
    shares = new_place_shares(
        a, labels, motions[:2], static, sigma, target, reach=reach, whole=whole, own=own_normals
    )
    # Only where its surfaces' normals lie across the motion (a wall, a building's
    # corner slid along itself): a car seen from behind that drives on by less than its
    # length lands within its old footprint too (its rear face among its old roof and
    # sides), but moves across its rear face.
    squared = np.einsum("ni,ni->n", displacement, displacement)
    length = np.sqrt(np.bincount(group, weights=squared, minlength=n_clusters) / counts)
    nowhere = (shares < MIN_NEW_PLACE) & (evidence < ACROSS * length)
    # A line of points (a pole, a ring of road) slides along itself and onto any other.
    line = is_line(points, group, n_clusters)
    slides = np.bincount(group, minlength=n_clusters) > 0
    # Sliding along itself shows nothing where the slide lands on places the first sweep
    # held already; a walker crossing the view slides its face along itself too, but
    # arrives where the first sweep saw through.
    slid = (evidence < _SLIDE_SCALES * sigma) & (shares < MIN_NEW_PLACE)
    slides &= slid | unseen | nowhere | line
    if not slides.any():
        return labels, motions, static
    kept = ~slides
    index = np.cumsum(kept) - 1
    labels = np.where(labels >= 0, labels, -1)
    labels = np.where(slides[np.maximum(labels, 0)] & (labels >= 0), static, labels)
    labels = np.where(labels >= 0, index[np.maximum(labels, 0)], -1)
    return labels, tuple(values[kept] for values in motions), int(index[static])
