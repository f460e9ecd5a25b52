"""Which cluster is the static world when no motion holds the majority of the scene.

The static world is the ego motion's cluster: the background a camera or a LiDAR sees
behind the moving objects. Most often it also holds most of the points, which is how
:func:`~mmreg.em._steps.merge_static_world` names it first. In a crowded
scene (FlyingThings3D frames whose background holds 3-47 % of the points) it does not,
and two other things tell it from an object:

* it *spans the scene*: an object is a thing of a few metres, the background reaches
  across the view, behind every object. The RMS distance of a cluster's a-points from
  their centroid (its spread) is at least half the spread of all the clustered a-points
  for the background of every FlyingThings3D frame and Argoverse 2 sweep we measured
  (0.54-1.0 with its ground-truth points; 0.67-0.86 in generated crowded scenes,
  :func:`~mmreg.datasets.make_flying_things` with 20-80 objects), and at most 0.36 for
  every object, in those frames and in scenes of objects alone
  (:func:`~mmreg.datasets.make_scene`, 2-7 objects, with or without shared motions;
  0.07 in the crowded scenes). A majority whose cluster does not span the scene (an
  object near a camera, filling half of its view) gives way to one that does;
* it moves with the *ego motion*, when the caller knows it (odometry, the poses of a
  data set): :func:`agrees_with_ego_motion`.

The background can also come in pieces that no single one spans: a backdrop cut in two by
the objects in front of it, or met at two depths (FlyingThings3D, 8192 points: its two
pieces 5.6 m apart, beyond tau = 5 m, span 0.34 and 0.11 of the scene, together 0.54).
Its pieces move alike, so :func:`spanning_union` reads, for each cluster, the union of the
pieces the static world would gather with it (:func:`~mmreg.em._steps.merge_static_world`:
its motion within their noise, or slower than ``min_motion`` beyond their scatter). Objects
that share one motion span the scene as readily (three of Table I's seven objects: 0.8-0.96
of it), so the union must also lie *behind* the other clusters: seen from the sensor, at
the origin of the points' frame, the background is what the objects stand in front of
(FlyingThings3D: its RMS range exceeds every object's in every frame measured, and that of
all the objects together 1.4-5 times). Behind
means something only in a view from one side (a camera's, every cluster in front of the
origin); amid the scene (a LiDAR's origin, Table I's objects around it) no union is named.

Both read the clusters' sufficient statistics (:class:`~mmreg._array.moments.Moments`) only.
"""

from dataclasses import dataclass

import numpy as np

__all__ = [
    "StaticWorldRule",
    "agrees_with_ego_motion",
    "spanning_union",
    "static_world_rule",
    "widest_cluster",
]

# A cluster whose spread is at least this share of the scene's spans the scene. One half:
# the background of every real frame measured spans 0.54-1.0 of it, objects at most 0.36.
SPANS_THE_SCENE = 0.5


@dataclass(frozen=True)
class StaticWorldRule:
    """How the robust loop names the static world.

    ``share``: the dominant motion is the static world when it holds this share of the
    clustered correspondences; below it, the cluster that spans the scene
    (:func:`widest_cluster`) is. ``ego_motion``: ``(R, t)`` of the static world from the
    a-points' frame to the b-points' (``b = R a + t``); when given, the static world is
    the clusters that move with it, whatever their share or spread.
    """

    share: float = 0.5
    ego_motion: tuple = None
    points: np.ndarray = None
    """The a-points, whose spread (every row weighted 1) :func:`widest_cluster` reads."""


def static_world_rule(share, ego_motion, points):
    """The :class:`StaticWorldRule` of ``share`` and ``ego_motion``, or None (no static
    world) when both are None."""
    if share is None and ego_motion is None:
        return None
    return StaticWorldRule(share, ego_motion, points)


def widest_cluster(moments, candidates=None):
    """The cluster that spans the scene, or -1 if none does.

    A cluster spans the scene when the RMS distance of its a-points from their centroid
    is at least :data:`SPANS_THE_SCENE` of that of all the clustered a-points (the
    clusters' moments summed). Only the widest cluster can; ``candidates`` (indices)
    restricts the choice, the scene still being every cluster.

    Parameters
    ----------
    moments : Moments
        The clusters' statistics (empty ones have a zero count).
    candidates : array-like of int, default=None

    Returns
    -------
    int

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.moments import group_moments
    >>> from mmreg.em._static_world import widest_cluster
    >>> wall = np.column_stack([np.linspace(-10, 10, 50), np.zeros(50), np.full(50, 20.0)])
    >>> box = np.random.default_rng(0).uniform(-1, 1, (150, 3)) + [0.0, 0.0, 8.0]
    >>> a = np.vstack([wall, box])
    >>> labels = np.repeat([0, 1], [50, 150])
    >>> widest_cluster(group_moments(a, a, labels, 2))
    0
    >>> two_boxes = np.vstack([box, box + [10.0, 0.0, 0.0]])  # objects alone
    >>> widest_cluster(group_moments(two_boxes, two_boxes, np.repeat([0, 1], 150), 2))
    -1
    """
    # Each cluster's spread is its weighted mean (the rows' weights are inverse noise
    # variances); the scene counts every cluster by its rows, whatever its noise.
    count = np.asarray(moments.count, dtype=float)
    size = np.asarray(moments.size, dtype=float)
    present = (count > 0) & (size > 0)
    if np.count_nonzero(present) < 2:
        return -1
    own = np.where(present, moments.scatter_a / np.where(present, count, 1.0), -1.0)
    means = moments.mean_a[present]
    centre = size[present] @ means / size[present].sum()
    apart = np.einsum("ij,ij->i", means - centre, means - centre)
    scene = size[present] @ (own[present] + apart) / size[present].sum()
    if candidates is not None:
        allowed = np.zeros(len(count), dtype=bool)
        allowed[np.asarray(candidates, dtype=np.intp)] = True
        own = np.where(allowed, own, -1.0)
    widest = int(np.argmax(own))
    if own[widest] <= 0 or own[widest] < SPANS_THE_SCENE**2 * scene:
        return -1
    return widest


def agrees_with_ego_motion(gap, min_motion):
    """Which clusters move with the ego motion: ``gap`` is how far (RMS) each one's
    motion carries its points from where the ego motion carries them, beyond the
    cluster's own scatter (:func:`~mmreg.em._steps.motion_beyond_scatter`
    read against the ego motion); below ``min_motion`` it moves with it."""
    return np.asarray(gap, dtype=float) < min_motion


def _about_origin(moments):
    """Each cluster's count, first and second moments of its a-points about the origin."""
    count = np.asarray(moments.count, dtype=float)
    first = count[:, None] * moments.mean_a
    second = moments.scatter_a + count * np.einsum("ij,ij->i", moments.mean_a, moments.mean_a)
    return count, first, second


def _in_view(means, squared_ranges, centre):
    """Whether every cluster lies in front of the origin, as in a camera's view.

    Along the scene's mean direction from the origin, each cluster's centroid must lie
    farther than its own RMS radius: the sensor sees every cluster from outside and from
    one side, which is what makes one thing *behind* another. A LiDAR sweep (the sensor
    amid the scene) or Table I's scenes (an object around the origin) are no such view.
    """
    norm = np.linalg.norm(centre)
    if norm == 0:
        return False
    depth = means @ (centre / norm)
    radius_squared = squared_ranges - np.einsum("ij,ij->i", means, means)
    return bool(np.all((depth > 0) & (depth**2 > radius_squared)))


def spanning_union(moments, members):
    """The cluster whose union with the pieces that move with it spans the scene and lies
    behind the other clusters, or -1 if none does.

    Row ``j`` of ``members`` marks the clusters gathered with cluster ``j`` were it the
    static world (itself included). The union spans the scene when its spread (the RMS
    distance of its a-points from their centroid) is at least :data:`SPANS_THE_SCENE` of
    that of all the clustered a-points; it lies behind the other clusters when its RMS
    distance from the origin (the sensor) exceeds theirs, taken together. Of the unions that
    do both, the largest wins. None is named unless the clusters are seen from one side
    (each centroid in front of the origin, along the scene's mean direction, by more than
    the cluster's RMS radius: a camera's view).

    Parameters
    ----------
    moments : Moments
        The clusters' statistics (empty ones have a zero count), every row weighted alike.
    members : ndarray of shape (K, K), dtype bool, or callable
        Or a function of no arguments that returns it, called only when the clusters are
        seen from one side (a camera's view, below): testing every pair of clusters
        costs far more than everything else here, and a LiDAR's sweep never needs it.

    Returns
    -------
    int

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.moments import group_moments
    >>> from mmreg.em._static_world import spanning_union, widest_cluster
    >>> rng = np.random.default_rng(0)
    >>> left = rng.uniform([-12, -3, 28], [-4, 3, 30], (100, 3))  # a backdrop, in two
    >>> right = rng.uniform([4, -3, 28], [12, 3, 30], (100, 3))
    >>> boxes = [rng.uniform(-1, 1, (100, 3)) + [x, 0.0, 15.0] for x in (-8, -3, 3, 8)]
    >>> a = np.vstack([left, right, *boxes])
    >>> moments = group_moments(a, a, np.repeat(np.arange(6), 100), 6)
    >>> widest_cluster(moments)  # neither piece spans the scene alone
    -1
    >>> members = np.eye(6, dtype=bool)
    >>> members[0, 1] = members[1, 0] = True  # the two pieces move alike
    >>> spanning_union(moments, members)
    0
    >>> members[[0, 1]] = np.eye(6, dtype=bool)[[0, 1]]
    >>> members[2, 5] = members[5, 2] = True  # two objects that move alike, in front
    >>> spanning_union(moments, members)
    -1
    """
    count, first, second = _about_origin(moments)
    present = count > 0
    if np.count_nonzero(present) < 2:
        return -1
    total = count[present].sum()
    centre = first[present].sum(axis=0) / total
    scene = second[present].sum() / total - centre @ centre
    squared_range = second / np.where(present, count, 1.0)
    if not _in_view(moments.mean_a[present], squared_range[present], centre):
        return -1
    members = np.asarray(members() if callable(members) else members, dtype=bool)
    members = members & present[None, :] & present[:, None]
    union = members.astype(float)
    union_count = union @ count
    safe = np.where(union_count > 0, union_count, 1.0)
    union_centre = (union @ first) / safe[:, None]
    union_squared_range = (union @ second) / safe
    union_spread = union_squared_range - np.einsum("ij,ij->i", union_centre, union_centre)
    # Behind the other clusters taken together (RMS ranges): one far fragment of the
    # background that fits a motion of its own must not hide the rest of it.
    outside = (~members & present[None, :]).astype(float)
    outside_count = outside @ count
    behind = (outside_count == 0) | (union_squared_range * outside_count > outside @ second)
    spans = union_spread >= SPANS_THE_SCENE**2 * scene
    fit = present & (union_count > 0) & behind & spans & (union_spread > 0)
    if not fit.any():
        return -1
    # The largest such union: a few far points scattered over the backdrop (a fragment
    # whose flow errs alike) can be wider than the backdrop's body, not larger.
    return int(np.argmax(np.where(fit, union_count, -np.inf)))
