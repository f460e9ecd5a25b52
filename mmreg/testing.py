"""Hypothesis strategies for the setting of Theorem 1, for property-based tests.

:func:`ground_truth_scenes` draws scenes that satisfy Definition 1 of the paper (objects
of random shape, size, pose, motion and number of points, a known ``tau`` and uniform noise
bound ``sigma``, outliers farther than ``tau`` from every object);
:func:`good_clusterings` draws ``(tau, alpha, m0)``-good initial clusterings of such a
scene (Definition 2), over-segmenting each object into several ``tau``-connected pieces
of which one is more than ``alpha`` times larger than the others.
:func:`scenes_with_good_clusterings` draws both at once.

This module needs `hypothesis <https://hypothesis.readthedocs.io>`_, a test extra of
mmreg (``pip install "mmreg[test]"``); the rest of mmreg does not import it.

Examples
--------
>>> from hypothesis import given, settings
>>> from mmreg.testing import ground_truth_scenes
>>> from mmreg.theory import satisfies_ground_truth
>>> @settings(max_examples=5, deadline=None)
... @given(ground_truth_scenes())
... def test_scenes_satisfy_definition_1(scene):
...     assert satisfies_ground_truth(scene.X, scene.labels, scene, scene.tau, scene.sigma)
>>> test_scenes_satisfy_definition_1()
"""

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import dijkstra, minimum_spanning_tree
from scipy.spatial import cKDTree
from scipy.spatial.distance import pdist, squareform
from scipy.spatial.transform import Rotation
from sklearn.utils import Bunch

from mmreg._array.neighbors import radius_graph
from mmreg.datasets import SHAPES
from mmreg.datasets._scene import _unit_shape

try:
    from hypothesis import strategies as st
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise ImportError(
        'mmreg.testing needs hypothesis; install it with `pip install "mmreg[test]"` '
        "or `pip install hypothesis`."
    ) from exc

__all__ = [
    "OUTLIER_LABELLINGS",
    "Clustering",
    "Scene",
    "good_clusterings",
    "ground_truth_scenes",
    "rotations",
    "scenes_with_good_clusterings",
]

# How good_clusterings labels the outliers: in no cluster, one cluster each, or one
# cluster for all of them (Definition 2 with outliers="exempt" accepts all three).
OUTLIER_LABELLINGS = ("unassigned", "singletons", "one")


@st.composite
def rotations(draw):
    """Rotations of 3-D space, from all of SO(3): an axis and an angle in ``[0, pi]``.

    Shrinks towards the identity; the half-turns (angle ``pi``) are reachable exactly.
    """
    angle = draw(st.floats(0.0, np.pi))
    axis = np.array(draw(st.tuples(*[st.floats(-1.0, 1.0)] * 3)))
    norm = np.linalg.norm(axis)
    axis = axis / norm if norm > 1e-6 else np.array([0.0, 0.0, 1.0])
    return Rotation.from_rotvec(angle * axis).as_matrix()


def _bottleneck(points):
    """Smallest ``tau`` for which ``points`` are ``tau``-connected (longest MST edge)."""
    if len(points) < 2:
        return 0.0
    dist = squareform(pdist(points))
    # A dense csgraph reads zeros as missing edges: keep coincident points joined.
    dist[dist == 0] = np.finfo(float).tiny
    np.fill_diagonal(dist, 0.0)
    return float(minimum_spanning_tree(dist).data.max())


def _place(objects, gap, rng):
    """Translate the objects one by one so that each is exactly ``>= gap`` from the rest.

    Each new object starts far out in a random direction and is pulled back along it by
    the current excess gap; the distance to the placed points is 1-Lipschitz in the
    shift, so it never drops below ``gap`` and it converges to it from above.
    """
    placed = [objects[0] - objects[0].mean(axis=0)]
    for points in objects[1:]:
        existing = np.vstack(placed)
        tree = cKDTree(existing)
        centre = existing.mean(axis=0)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        points = points - points.mean(axis=0)
        reach = (
            np.linalg.norm(existing - centre, axis=1).max() + np.linalg.norm(points, axis=1).max()
        )
        shift = centre + direction * (reach + 2 * gap)
        for _ in range(20):
            excess = tree.query(points + shift, k=1)[0].min() - gap
            if excess <= 1e-3 * gap:
                break
            shift = shift - direction * excess
        placed.append(points + shift)
    return placed


def _outliers(a, n_outliers, tau, margin, rng):
    """``n_outliers`` points in the box around ``a``, all farther than ``tau`` from it."""
    if n_outliers == 0:
        return np.zeros((0, a.shape[1]))
    low, high = a.min(axis=0) - margin, a.max(axis=0) + margin
    tree = cKDTree(a)
    found, total = [], 0
    for _ in range(100):
        candidates = rng.uniform(low, high, size=(4 * n_outliers, a.shape[1]))
        dist, _ = tree.query(candidates, k=1)
        keep = candidates[dist > tau * 1.001]
        found.append(keep)
        total += len(keep)
        if total >= n_outliers:
            break
    return np.vstack(found)[:n_outliers]


class Scene(Bunch):
    """A drawn scene: a :class:`~sklearn.utils.Bunch` with a short summary as its repr.

    Hypothesis prints the repr of failing examples; the arrays would drown it.
    """

    def __repr__(self):
        counts = np.bincount(self.labels[self.labels >= 0]).tolist()
        angles = np.degrees(Rotation.from_matrix(self.rotations).magnitude())
        return (
            f"Scene(shapes={self.shapes}, points={counts}, "
            f"outliers={int(np.sum(self.labels < 0))}, tau={self.tau:.4g}, "
            f"sigma={self.sigma:.4g}, gap={self.gap:.4g}, "
            f"angles={np.round(angles, 1).tolist()})"
        )


class Clustering(Bunch):
    """A drawn initial clustering, with a short summary as its repr."""

    def __repr__(self):
        return (
            f"Clustering(alpha={self.alpha:.4g}, m0={self.m0}, "
            f"pieces per object={self.n_pieces.tolist()}, outliers={self.outliers!r})"
        )


def _range(value):
    return (value, value) if np.isscalar(value) else tuple(value)


def ground_truth_scenes(
    n_objects=(1, 4),
    points_per_object=(30, 120),
    noise=(0.0, 0.05),
    outlier_fraction=(0.0, 0.2),
    object_size=(0.5, 2.0),
    gap_factor=(1.01, 3.0),
    same_motion=True,
):
    """Scenes that satisfy Definition 1, with their ``tau`` and ``sigma``.

    Every argument is a ``(low, high)`` range (or one value) to draw from.

    Parameters
    ----------
    n_objects : (int, int), default=(1, 4)
    points_per_object : (int, int), default=(30, 120)
    noise : (float, float), default=(0.0, 0.05)
        ``sigma``: the b-points get noise drawn uniformly from ``[-sigma, sigma]^3``.
    outlier_fraction : (float, float), default=(0.0, 0.2)
        Outliers as a fraction of the object points.
    object_size : (float, float), default=(0.5, 2.0)
        Diameter of each object; the shape of each is drawn from
        :data:`mmreg.datasets.SHAPES`, its orientation and motion from all of SO(3).
    gap_factor : (float, float), default=(1.01, 3.0)
        Smallest gap between objects as a multiple of ``tau`` (``> 1``).
    same_motion : bool, default=True
        Whether objects may share the first object's motion, so that only the distance
        gate tells them apart.

    Returns
    -------
    strategy
        Draws :class:`Scene` bunches with ``X`` (n, 6), ``a``, ``b``, ``labels``
        (``-1``: outlier), ``rotations``, ``translations``, ``tau`` (between the largest
        gap within an object and the smallest gap between objects), ``sigma``, ``gap``
        (the smallest gap between objects aimed at) and ``shapes``.
    """
    if _range(gap_factor)[0] <= 1:
        raise ValueError(
            f"gap_factor must be above 1 (objects farther than tau); got {gap_factor}."
        )
    return _scenes(
        _range(n_objects),
        _range(points_per_object),
        _range(noise),
        _range(outlier_fraction),
        _range(object_size),
        _range(gap_factor),
        same_motion,
    )


@st.composite
def _scenes(
    draw,
    n_objects,
    points_per_object,
    noise,
    outlier_fraction,
    object_size,
    gap_factor,
    same_motion,
):
    lo, hi = gap_factor
    n = draw(st.integers(*n_objects))
    rng = np.random.RandomState(draw(st.integers(0, 2**32 - 1)))
    shapes = [draw(st.sampled_from(SHAPES)) for _ in range(n)]
    sizes = [draw(st.floats(*object_size)) for _ in range(n)]
    counts = [draw(st.integers(*points_per_object)) for _ in range(n)]
    motions = [draw(rotations()) for _ in range(n)]
    shifts = [np.array(draw(st.tuples(*[st.floats(-3.0, 3.0)] * 3))) for _ in range(n)]
    if same_motion:
        for j in range(1, n):
            if draw(st.booleans()):
                motions[j], shifts[j] = motions[0], shifts[0]
    sigma = draw(st.floats(*noise))
    objects = [
        size * _unit_shape(shape, count, rng) @ Rotation.random(random_state=rng).as_matrix().T
        for shape, size, count in zip(shapes, sizes, counts, strict=True)
    ]
    tau = max(_bottleneck(p) for p in objects) * draw(st.floats(1.001, 1.5))
    gap = tau * draw(st.floats(lo, hi))
    objects = _place(objects, gap, rng)

    labels = np.repeat(np.arange(n), counts)
    a = np.vstack(objects)
    rot, trans = np.array(motions), np.array(shifts)
    b = np.einsum("nij,nj->ni", rot[labels], a) + trans[labels]
    b += rng.uniform(-sigma, sigma, size=b.shape)

    n_outliers = int(round(draw(st.floats(*outlier_fraction)) * len(a)))
    out_a = _outliers(a, n_outliers, tau, margin=gap, rng=rng)
    out_b = rng.uniform(b.min(axis=0) - 1, b.max(axis=0) + 1, size=(len(out_a), 3))
    a = np.vstack([a, out_a])
    b = np.vstack([b, out_b])
    labels = np.concatenate([labels, np.full(len(out_a), -1)])
    return Scene(
        X=np.hstack([a, b]),
        a=a,
        b=b,
        labels=labels,
        rotations=rot,
        translations=trans,
        tau=tau,
        sigma=sigma,
        gap=gap,
        shapes=shapes,
    )


def _merge(cells, into, source):
    cells[cells == source] = into


def _neighbour_cells(cells, graph):
    """Pairs of distinct cells joined by an edge of ``graph``."""
    coo = sparse.coo_matrix(graph)
    cross = cells[coo.row] != cells[coo.col]
    return np.unique(np.column_stack([cells[coo.row][cross], cells[coo.col][cross]]), axis=0)


def _largest_neighbour(cells, graph, cell, sizes):
    pairs = _neighbour_cells(cells, graph)
    neighbours = pairs[pairs[:, 0] == cell, 1]
    return int(neighbours[np.argmax(sizes[neighbours])])


def _split_object(points, tau, n_seeds, alpha, m0, rng):
    """Split one tau-connected object into tau-connected pieces, one identifying.

    Graph-Voronoi cells of random seeds (multi-source Dijkstra on the tau-graph, so each
    cell is a shortest-path tree and thus tau-connected); then neighbouring cells are
    merged, which keeps them connected, until every cell has at least ``m0`` points and
    the largest is more than ``alpha`` times the next.
    """
    graph = sparse.coo_matrix(radius_graph(points, tau))
    length = np.linalg.norm(points[graph.row] - points[graph.col], axis=1)
    # Dijkstra reads zero weights as missing edges; coincident points stay joined.
    weights = sparse.csr_matrix(
        (np.maximum(length, np.finfo(float).tiny), (graph.row, graph.col)), shape=graph.shape
    )
    seeds = rng.choice(len(points), size=min(n_seeds, len(points)), replace=False)
    _, _, cells = dijkstra(
        weights, directed=False, indices=seeds, min_only=True, return_predecessors=True
    )
    cells = cells.astype(np.intp)
    while True:
        sizes = np.bincount(cells, minlength=len(points))
        present = np.flatnonzero(sizes)
        if len(present) == 1:
            break
        smallest = present[np.argmin(sizes[present])]
        if sizes[smallest] < m0:
            _merge(cells, _largest_neighbour(cells, weights, smallest, sizes), smallest)
            continue
        by_size = present[np.argsort(-sizes[present], kind="stable")]
        if sizes[by_size[0]] > alpha * sizes[by_size[1]]:
            break
        _merge(cells, by_size[0], _largest_neighbour(cells, weights, by_size[0], sizes))
    return np.unique(cells, return_inverse=True)[1]


def good_clusterings(
    scene, alpha=(1.5, 4.0), m0=(4, 30), max_pieces=5, outliers=OUTLIER_LABELLINGS
):
    """Initial clusterings of ``scene`` that are ``(tau, alpha, m0)``-good (Definition 2).

    Each object is over-segmented into up to ``max_pieces`` ``tau``-connected pieces of
    at least ``m0`` correspondences, the largest more than ``alpha`` times the next; the
    cluster labels are shuffled across objects.

    Parameters
    ----------
    scene : Bunch
        From :func:`ground_truth_scenes` (needs ``a``, ``labels`` and ``tau``).
    alpha : (float, float), default=(1.5, 4.0)
        Range of ``alpha`` (``>= 1``).
    m0 : (int, int), default=(4, 30)
        Range of ``m0``; capped by the smallest object.
    max_pieces : int, default=5
        Most pieces per object before the merges that enforce ``alpha`` and ``m0``.
    outliers : sequence of str, default=OUTLIER_LABELLINGS
        Labellings of the outliers to draw from: ``"unassigned"`` (-1), ``"singletons"``
        (one cluster each), ``"one"`` (one cluster for all). The last two are clusters of
        outliers only, which Definition 2 with ``outliers="exempt"`` does not constrain.

    Returns
    -------
    strategy
        Draws :class:`Clustering` bunches with ``labels`` (n,), the ``alpha``
        and ``m0`` the clustering is good for, ``n_pieces`` (clusters per object) and
        ``outliers`` (the labelling used).
    """
    labels = scene.labels
    smallest = int(np.bincount(labels[labels >= 0]).min())
    m0_lo, m0_hi = _range(m0)
    if smallest < m0_lo:
        raise ValueError(f"the scene's smallest object has {smallest} < m0 = {m0_lo} points.")
    if _range(alpha)[0] < 1:
        raise ValueError(f"alpha must be >= 1; got {alpha}.")
    unknown = set(outliers) - set(OUTLIER_LABELLINGS)
    if unknown or not len(outliers):
        raise ValueError(f"outliers must be a non-empty subset of {OUTLIER_LABELLINGS}.")
    return _clusterings(scene, _range(alpha), (m0_lo, min(m0_hi, smallest)), max_pieces, outliers)


@st.composite
def _clusterings(draw, scene, alpha, m0, max_pieces, outliers):
    labels = scene.labels
    m0 = draw(st.integers(*m0))
    alpha = draw(st.floats(*alpha))
    rng = np.random.RandomState(draw(st.integers(0, 2**32 - 1)))
    out = np.full(len(labels), -1, dtype=np.intp)
    n_clusters = 0
    n_pieces = []
    for obj in range(int(labels.max()) + 1):
        idx = np.flatnonzero(labels == obj)
        pieces = _split_object(
            scene.a[idx], scene.tau, draw(st.integers(1, max_pieces)), alpha, m0, rng
        )
        out[idx] = n_clusters + pieces
        n_clusters += int(pieces.max()) + 1
        n_pieces.append(int(pieces.max()) + 1)
    mode = draw(st.sampled_from(tuple(outliers)))
    outlier_idx = np.flatnonzero(labels < 0)
    if mode == "singletons":
        out[outlier_idx] = n_clusters + np.arange(len(outlier_idx))
    elif mode == "one" and len(outlier_idx):
        out[outlier_idx] = n_clusters
    # Shuffle the label values so that no estimator can rely on their order.
    assigned = out >= 0
    permutation = rng.permutation(int(out.max()) + 1 if assigned.any() else 0)
    out[assigned] = permutation[out[assigned]]
    return Clustering(labels=out, alpha=alpha, m0=m0, n_pieces=np.array(n_pieces), outliers=mode)


def scenes_with_good_clusterings(alpha=(1.5, 4.0), m0=(4, 30), max_pieces=5, **scene):
    """Pairs ``(scene, clustering)``: a Definition-1 scene and a good clustering of it.

    ``scene`` keywords go to :func:`ground_truth_scenes`; the smallest number of
    ``points_per_object`` must be at least the smallest ``m0``.
    """
    smallest = _range(scene.get("points_per_object", (30, 120)))[0]
    if smallest < _range(m0)[0]:
        raise ValueError(
            f"points_per_object starts at {smallest} < m0 = {_range(m0)[0]}: objects "
            "could be too small for any cluster of m0 points."
        )
    scenes = ground_truth_scenes(**scene)
    return scenes.flatmap(
        lambda drawn: st.tuples(
            st.just(drawn), good_clusterings(drawn, alpha=alpha, m0=m0, max_pieces=max_pieces)
        )
    )
