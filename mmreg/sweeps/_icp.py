"""Multi-body ICP: every cluster's rigid motion refined on a second point set at once.

Each cluster ``j`` carries a motion ``(R_j, t_j)``; its points ``a_i`` are moved by it,
matched to their nearest neighbour ``q_i`` in the target (one KD-tree, built once), and
the motions are updated by one Gauss-Newton step of the robust point-to-plane cost

    sum_i rho( n_i . (R_j a_i + t_j - q_i) / s_j ),

``n_i`` the unit normal of the target at ``q_i`` (PCA of its ``k`` nearest neighbours),
``rho`` Tukey's biweight and ``s_j`` the cluster's robust residual scale (1.4826 times
the median absolute residual, re-estimated every iteration). The 6x6 normal equations of
all clusters are summed with one sparse product and solved as one ``(K, 6, 6)`` stack.

Directions the surface does not constrain (a flat wall slides within its plane) get no
gradient; a small damping keeps them where the start put them, so a cluster's motion
from its correspondences survives there.

Everything is vectorised over points and clusters; the only loop is over iterations.
"""

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree
from sklearn.utils import check_random_state

# The same median as the command line's motion statistics (the mean of the two middle values).
from mmreg._array.motion import _group_median
from mmreg._array.symmetric3 import least_eigenvectors

__all__ = ["ICPResult", "SurfaceNormals", "multi_body_icp", "rotation_vectors_to_matrices"]

_MAD_TO_SIGMA = 1.4826
# Directions of the step whose curvature is below this share of the largest are left
# unchanged (see _constrained_step).
_DEGENERATE = 1e-3
# A cluster needs this many matched points to move (6 unknowns, and a margin).
_MIN_MATCHES = 12
# The kernel's scale shrinks by this factor per iteration until it reaches the robust one.
_ANNEAL = 0.7
# The lower triangle of a 6x6 matrix, row by row: a Hessian is summed there and mirrored
# (numpy's eigh reads the lower triangle only).
_LOWER = np.tril_indices(6)


def rotation_vectors_to_matrices(omega):
    """Rotation matrices ``exp([w]_x)`` of rotation vectors (Rodrigues), batched.

    Parameters
    ----------
    omega : ndarray of shape (K, 3)

    Returns
    -------
    rotations : ndarray of shape (K, 3, 3)

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.sweeps._icp import rotation_vectors_to_matrices
    >>> R = rotation_vectors_to_matrices(np.array([[0.0, 0.0, np.pi / 2]]))
    >>> np.round(R[0] @ [1.0, 0.0, 0.0], 12) + 0.0
    array([0., 1., 0.])
    """
    omega = np.asarray(omega, dtype=float)
    angle = np.linalg.norm(omega, axis=1)
    small = angle < 1e-12
    axis = omega / np.where(small, 1.0, angle)[:, None]
    x, y, z = axis.T
    zero = np.zeros_like(x)
    cross = np.stack(
        [np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1), np.stack([-y, x, zero], -1)],
        axis=1,
    )
    sin = np.sin(angle)[:, None, None]
    cos = np.cos(angle)[:, None, None]
    rotations = np.eye(3) + sin * cross + (1 - cos) * (cross @ cross)
    rotations[small] = np.eye(3)
    return rotations


class SurfaceNormals:
    """Unit normals of a point set from PCA of ``k`` nearest neighbours, computed on demand.

    ICP asks for the normals of the target points that are some point's nearest neighbour,
    a small share of a large sweep; each is computed once, when first asked for.

    Parameters
    ----------
    points : ndarray of shape (m, 3)
    tree : cKDTree of ``points``
    k : int
        Neighbourhood size (the point itself included).
    workers : int
        Threads of the KD-tree queries.
    """

    def __init__(self, points, tree, k, workers=1):
        self.points = points
        self.tree = tree
        self.k = min(int(k), len(points))
        self.workers = workers
        # One row per point: normal, surface variation, flatness (NaN until computed),
        # so that a call gathers its rows once.
        self._table = np.full((len(points), 5), np.nan)
        self._spacing = np.full(len(points), np.nan)

    def learn(self, other):
        """Take the normals and spacings that ``other``, the normals of the same points
        (a copy in another process), computed and these did not."""
        if other._table.shape != self._table.shape:
            raise ValueError("other must hold the normals of the same points.")
        rows = np.isnan(self._table[:, 3]) & ~np.isnan(other._table[:, 3])
        self._table[rows] = other._table[rows]
        rows = np.isnan(self._spacing) & ~np.isnan(other._spacing)
        self._spacing[rows] = other._spacing[rows]

    def _missing(self, index, known):
        """The distinct points of ``index`` (sorted) whose ``known`` value is still NaN."""
        unknown = index[np.isnan(known[index])]
        if not len(unknown):
            return unknown
        flag = np.zeros(len(self.points), dtype=bool)  # a sort of ``unknown`` costs more
        flag[unknown] = True
        return np.flatnonzero(flag)

    def spacing(self, index):
        """Distance from each of ``points[index]`` to its nearest other point.

        The sampling spacing there, as ``tree.query(points[index], k=2)`` gives it; read
        off the normals' neighbourhoods where they are known.
        """
        index = np.asarray(index, dtype=np.intp)
        missing = self._missing(index, self._spacing)
        if len(missing):
            distance, _ = self.tree.query(
                self.points.take(missing, axis=0), k=2, workers=self.workers
            )
            self._spacing[missing] = distance[:, 1]
        return self._spacing[index]

    def __call__(self, index):
        """Normals ``(len(index), 3)``, surface variations and flatness of ``points[index]``.

        The surface variation is ``l_0 / (l_0 + l_1 + l_2)`` of the neighbourhood's
        covariance eigenvalues ``l_0 <= l_1 <= l_2``: 0 on a plane, 1/3 at most; the
        flatness is ``l_1 / l_2``: 0 on a line.
        """
        index = np.asarray(index, dtype=np.intp)
        # ``take`` gathers rows several times faster than fancy indexing (numpy 2.4).
        rows = self._table.take(index, axis=0)
        unknown = np.isnan(rows[:, 3])
        if unknown.any():
            missing = self._missing(index[unknown], self._table[:, 3])
            distance, near = self.tree.query(
                self.points.take(missing, axis=0), k=self.k, workers=self.workers
            )
            near = near.reshape(len(missing), self.k)
            if self.k > 1:  # the nearest other point: the spacing, for free
                self._spacing[missing] = distance.reshape(len(missing), self.k)[:, 1]
            hood = self.points.take(near, axis=0)
            hood -= hood.mean(axis=1, keepdims=True)
            covariance = np.matmul(hood.transpose(0, 2, 1), hood)
            values, normal = least_eigenvectors(covariance)
            self._table[missing, :3] = normal
            total = values.sum(axis=1)
            self._table[missing, 3] = np.where(
                total > 0, values[:, 0] / np.where(total > 0, total, 1.0), 0.0
            )
            self._table[missing, 4] = np.where(
                values[:, 2] > 0, values[:, 1] / np.where(values[:, 2] > 0, values[:, 2], 1.0), 0.0
            )
            rows[unknown] = self._table.take(index[unknown], axis=0)
        return rows[:, :3], rows[:, 3], rows[:, 4]


def _group_sums(values, groups, n_groups):
    """Column sums of ``values`` (n, m) within each group: one sparse product."""
    n = len(groups)
    indicator = sparse.csr_matrix((np.ones(n), (groups, np.arange(n))), shape=(n_groups, n))
    return np.asarray(indicator @ values)


def _sorted_indicator(groups, n_groups):
    """The 0/1 matrix ``(n_groups, n)`` of ``groups`` sorted ascending, built without a sort.

    Its product with ``values`` sums each group's rows in their order, one after the
    other, as :func:`_group_sums` does (the same floats).
    """
    n = len(groups)
    ends = np.cumsum(np.bincount(groups, minlength=n_groups))
    indptr = np.concatenate([[0], ends])
    return sparse.csr_matrix((np.ones(n), np.arange(n), indptr), shape=(n_groups, n))


def subsample_groups(labels, max_per_group, random_state=None):
    """Indices of at most ``max_per_group`` points of every group (>= 0), chosen at random.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.sweeps._icp import subsample_groups
    >>> labels = np.array([0, 0, 0, 0, 1, 1, -1])
    >>> np.bincount(labels[subsample_groups(labels, 2, random_state=0)]).tolist()
    [2, 2]
    """
    labels = np.asarray(labels)
    members = np.flatnonzero(labels >= 0)
    if max_per_group is None:
        return members
    rng = check_random_state(random_state)
    shuffled = members[rng.permutation(len(members))]
    order = shuffled[np.argsort(labels[shuffled], kind="stable")]
    group = labels[order]
    starts = np.searchsorted(group, group, side="left")
    rank = np.arange(len(order)) - starts
    return np.sort(order[rank < max_per_group])


@dataclass
class ICPResult:
    """What :func:`multi_body_icp` returns."""

    rotations: np.ndarray
    """Refined rotation of every cluster, ``(K, 3, 3)``."""
    translations: np.ndarray
    """Refined translation of every cluster, ``(K, 3)``."""
    scales: np.ndarray
    """Robust point-to-plane residual scale of every cluster, ``(K,)`` (NaN: unmatched)."""
    n_matched: np.ndarray
    """Points of every cluster that found a neighbour within ``max_distance``, ``(K,)``."""
    inlier_share: np.ndarray
    """Share of every cluster's points within the kernel's support, ``(K,)``."""
    n_iter: int
    converged: bool


def _constrained_step(hessian, gradient, spread):
    """Gauss-Newton steps ``(K, 6)`` in the directions the matches constrain.

    A planar face constrains only its normal translation and two rotations; along its
    plane the normal equations are near singular and their solution follows the noise
    (a patch of road or a car's rear slides along itself, tens of metres over an ICP's
    iterations). As in Zhang, Kaess and Singh's solution remapping ("On Degeneracy of
    Optimization-based State Estimation Problems", ICRA 2016), the step is solved in the
    eigenvectors of the Hessian and set to zero along those whose eigenvalue is below
    ``_DEGENERATE`` of the largest: the motion stays where it started there. The
    rotation is measured by how far it moves the points (times ``spread``, their RMS
    distance from the centroid), so the eigenvalues of turns and shifts compare in the
    units of the points, whatever those are.
    """
    scale = np.ones((len(hessian), 6))
    scale[:, :3] = 1.0 / np.maximum(spread, 1e-300)[:, None]
    values, vectors = np.linalg.eigh(hessian * scale[:, :, None] * scale[:, None, :])
    keep = values >= _DEGENERATE * values[:, -1:]
    inverse = np.where(keep, 1.0 / np.where(keep, values, 1.0), 0.0)
    along = np.einsum("kji,kj->ki", vectors, gradient * scale) * inverse
    return -np.einsum("kij,kj->ki", vectors, along) * scale


def multi_body_icp(
    a,
    labels,
    rotations,
    translations,
    target,
    *,
    tree=None,
    normals=None,
    max_distance=1.0,
    max_iter=30,
    tol=1e-6,
    min_scale=1e-9,
    kernel_width=2.0,
    min_flatness=0.2,
    normal_neighbors=10,
    workers=1,
    measure=True,
):
    """Refine every cluster's motion on a target point set by robust point-to-plane ICP.

    Parameters
    ----------
    a : ndarray of shape (n, 3)
        Points; only those with ``labels >= 0`` take part.
    labels : ndarray of shape (n,)
        Cluster of every point in ``0..K-1``, negative for none.
    rotations : ndarray of shape (K, 3, 3)
    translations : ndarray of shape (K, 3)
        The start: ``R_j a + t_j`` should lie near the target for the points of ``j``.
    target : ndarray of shape (m, 3)
        The second point set, any size and order.
    tree : cKDTree of ``target`` or None
        Built when None.
    normals : SurfaceNormals or None
        The target's normals (shared between calls); built when None.
    max_distance : float or ndarray of shape (K,)
        A point whose nearest target point is farther than this (per cluster) is not
        matched in that iteration.
    max_iter : int
        Largest number of Gauss-Newton steps.
    tol : float
        Converged when no step moves any cluster's points by more than this (RMS bound).
    min_scale : float
        Floor of the robust residual scale of every cluster.
    kernel_width : float
        Tukey's biweight is zero beyond this many robust scales (2, 3 and the
        95%-efficient 4.685 gave the same errors within 3 mm, on average, on the moving
        objects of two Argoverse 2 pairs).
    min_flatness : float
        Target points whose neighbourhood's two largest covariance eigenvalues have a
        ratio below this lie on one scan line and are not used.
    normal_neighbors : int
        ``k`` of the normals' neighbourhoods.
    workers : int
        Threads of the KD-tree queries.
    measure : bool
        Whether ``scales``, ``n_matched`` and ``inlier_share`` are measured at the final
        motions (one more query of every point). False: they are those of the last
        step's start, for callers that need only the motions.

    Returns
    -------
    ICPResult

    Examples
    --------
    A plane corner moved by 5 cm and sampled again: the motion is found.

    >>> import numpy as np
    >>> from mmreg.sweeps._icp import multi_body_icp
    >>> rng = np.random.default_rng(0)
    >>> def corner(n):
    ...     p = rng.uniform(0, 2, (n, 3))
    ...     p[np.arange(n), rng.integers(0, 3, n)] = 0.0  # on one of three planes
    ...     return p
    >>> a, target = corner(3000), corner(20000) + [0.05, -0.03, 0.02]
    >>> result = multi_body_icp(a, np.zeros(3000, int), np.eye(3)[None], np.zeros((1, 3)),
    ...                         target, max_distance=0.5)
    >>> np.round(result.translations[0], 2) + 0.0
    array([ 0.05, -0.03,  0.02])
    """
    a = np.asarray(a, dtype=float)
    labels = np.asarray(labels, dtype=np.intp)
    target = np.asarray(target, dtype=float)
    rotations = np.array(rotations, dtype=float)
    translations = np.array(translations, dtype=float)
    n_clusters = len(rotations)
    if tree is None:
        tree = cKDTree(target)
    if normals is None:
        normals = SurfaceNormals(target, tree, normal_neighbors, workers)
    gate = np.broadcast_to(np.asarray(max_distance, dtype=float), (n_clusters,))
    members = np.flatnonzero(labels >= 0)
    points, group = a[members], labels[members]
    scales = np.full(n_clusters, np.nan)
    n_matched = np.zeros(n_clusters, dtype=np.intp)
    inlier_share = np.zeros(n_clusters)
    converged = False
    n_iter = 0
    if not n_clusters or not len(members):
        return ICPResult(rotations, translations, scales, n_matched, inlier_share, 0, True)
    sizes = np.bincount(group, minlength=n_clusters)
    # The points sorted by cluster, stably: every cluster's points keep their order (so
    # do its sums and medians, to the bit), and its sums need no sort of their own.
    order = np.argsort(group, kind="stable")
    every_point, every_group = points[order], group[order]
    # A cluster whose step fell below ``tol`` is done: later iterations leave its points
    # out (hypothesis tests run hundreds of clusters, most of which settle early).
    alive = np.ones(n_clusters, dtype=bool)
    bound = float(gate.max())
    for iteration in range(max_iter + 1):
        final = converged or iteration == max_iter
        if final and not measure and iteration:
            break
        if final or alive.all():
            points, group = every_point, every_group
        else:
            keep = alive[every_group]
            points, group = every_point.compress(keep, axis=0), every_group[keep]
        # ``take`` and ``compress`` gather rows several times faster than fancy indexing.
        moved = np.einsum("nij,nj->ni", rotations.take(group, axis=0), points)
        moved += translations.take(group, axis=0)
        distance, nearest = tree.query(moved, distance_upper_bound=bound, workers=workers)
        matched = distance <= gate[group]
        rows = np.flatnonzero(matched)
        g = group[rows]
        p = moved.take(rows, axis=0)
        normal, _, flatness = normals(nearest[rows])
        # A neighbourhood on one scan line has no normal (any direction across the line
        # fits): its "normal" would pull the points towards the other sweep's rings.
        flat = flatness >= min_flatness
        rows, g = rows[flat], g[flat]
        p, normal = p.compress(flat, axis=0), normal.compress(flat, axis=0)
        residual = np.einsum("ni,ni->n", normal, p - target.take(nearest[rows], axis=0))
        n_matched = np.bincount(g, minlength=n_clusters)
        robust = _MAD_TO_SIGMA * _group_median(np.abs(residual), g, n_clusters)
        # Anneal from the gate down to the robust scale: where most points sit on
        # surfaces that do not constrain the error (a box's other faces), the median
        # residual is near zero and would reject the few points that carry it.
        annealed = np.fmax(robust, _ANNEAL**iteration * gate / kernel_width)
        scales = np.maximum(np.where(np.isnan(robust), np.nan, annealed), min_scale)
        cut = kernel_width * scales[g]
        u = residual / cut
        inside = np.abs(u) < 1
        weight = np.where(inside, (1 - u**2) ** 2, 0.0)
        inlier_share = np.bincount(g[inside], minlength=n_clusters) / np.maximum(sizes, 1)
        if final:  # this pass only measured the final motions
            break
        # Linearise about each cluster's centroid of matched points: a rotation about a
        # far-away origin would couple with the translation and condition badly.
        indicator = _sorted_indicator(g, n_clusters)  # g is sorted: rows ascend
        weight_sums = np.bincount(g, weights=weight, minlength=n_clusters)
        centroid = (
            np.asarray(indicator @ (weight[:, None] * p)) / np.maximum(weight_sums, 1e-300)[:, None]
        )
        lever = p - centroid.take(g, axis=0)
        jacobian = np.hstack([np.cross(lever, normal), normal])  # d r / d (omega, v)
        weighted = weight[:, None] * jacobian
        # One product sums the Hessians' lower triangles (all the eigen-solver reads),
        # the gradients and the levers' squares.
        sums = np.asarray(
            indicator
            @ np.hstack(
                [
                    weighted[:, _LOWER[0]] * jacobian[:, _LOWER[1]],
                    weighted * residual[:, None],
                    np.sum(lever**2, axis=1)[:, None],
                ]
            )
        )
        n_lower = len(_LOWER[0])
        hessian = np.empty((n_clusters, 6, 6))
        hessian[:, _LOWER[0], _LOWER[1]] = sums[:, :n_lower]
        hessian[:, _LOWER[1], _LOWER[0]] = sums[:, :n_lower]
        gradient = sums[:, n_lower : n_lower + 6]
        diagonal = np.einsum("kii->k", hessian) / 6
        active = (n_matched >= _MIN_MATCHES) & (diagonal > 0)
        spread = np.sqrt(sums[:, -1] / np.maximum(n_matched, 1))
        step = np.zeros((n_clusters, 6))
        if active.any():
            step[active] = _constrained_step(hessian[active], gradient[active], spread[active])
        change = np.linalg.norm(step[:, 3:], axis=1) + np.linalg.norm(step[:, :3], axis=1) * spread
        # A trust region: the matches hold within the gate, so no step moves a cluster's
        # points farther. Where the points constrain a direction weakly (a planar face
        # slides along itself), the damped solve would otherwise run away with it.
        shrink = np.minimum(1.0, gate / np.maximum(change, 1e-300))
        step *= shrink[:, None]
        change *= shrink
        turn = rotation_vectors_to_matrices(step[:, :3])
        # x -> turn (x - c) + c + v, composed with the current motion.
        rotations = turn @ rotations
        translations = (
            np.einsum("kij,kj->ki", turn, translations - centroid) + centroid + step[:, 3:]
        )
        n_iter = iteration + 1
        alive &= change > tol
        converged = not alive.any()
    return ICPResult(rotations, translations, scales, n_matched, inlier_share, n_iter, converged)
