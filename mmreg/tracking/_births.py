"""Where a pair's clusters saw nothing move, the places the ego motion cannot explain.

A pair's search for moving islands starts from a few guesses per island (ICP-Flow's
centroid offsets and vote peaks): a walker whose island a wall holds, or whose few votes
land elsewhere, is called static in one pair and found in the next by chance. Its
evidence does not depend on the guesses: where the ego motion puts its points, the
second sweep has nothing (the place it left), and the second sweep holds points the first
sweep had nothing at (the place it reached), each where the other sweep could have seen
it. :func:`moved_places` finds both as islands; :func:`place_starts` pairs each place
left with the places reached within a road user's reach, as motions for a track's claim
(:func:`mmreg.tracking._evidence.track_claim`), which alone decides.
"""

import numpy as np
from scipy.spatial import cKDTree

from mmreg.sweeps._explained import EXPLAINED_SPACINGS, spacing_ratio, unexplained_mask
from mmreg.sweeps._islands import voxel_islands
from mmreg.tracking._motion import compose, transform

__all__ = ["moved_places", "new_place_share", "place_starts"]

# Places reached tried per place left, the nearest first.
_STARTS = 3


def moved_places(points, candidates, motion, target, scale, view, margin, cell, min_size):
    """Islands of ``candidates`` that ``motion`` leaves unexplained on the other sweep.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
        A sweep, in its frame.
    candidates : ndarray of int
        Rows of ``points`` that may have moved (no ground, no body, nothing a track holds).
    motion : ndarray of shape (4, 4)
        The ego motion from ``points``' sweep to the other sweep.
    target : tuple
        ``(sweep, tree, normals)`` of the other sweep.
    scale : float
        The ego ICP's robust residual scale.
    view : RangeView
        The other sweep's range image: a place it could not see is no evidence.
    margin : float
        A return this much nearer hides a place.
    cell, min_size : float, int
        The islands' voxel side and smallest size.

    Returns
    -------
    places : list of ndarray of int
        The rows of each island, largest first.
    unexplained : ndarray of int
        Every candidate row left unexplained where the other sweep could see it.

    Examples
    --------
    A box of 125 points that moved 1 m along x between two sweeps of a floor: the place it
    left is one island of the first sweep.

    >>> import numpy as np
    >>> from scipy.spatial import cKDTree
    >>> from mmreg.sweeps._icp import SurfaceNormals
    >>> from mmreg.tracking._births import moved_places
    >>> from mmreg.tracking._visibility import RangeView
    >>> g = np.arange(-3.0, 3.0, 0.1)
    >>> floor = np.stack(np.meshgrid(g + 5, g, [-1.0], indexing="ij"), -1).reshape(-1, 3)
    >>> h = np.arange(0.0, 0.5, 0.1)
    >>> box = np.stack(np.meshgrid(h + 4, h, h - 0.5, indexing="ij"), -1).reshape(-1, 3)
    >>> first, second = np.vstack([floor, box]), np.vstack([floor, box + [1.0, 0, 0]])
    >>> tree = cKDTree(second)
    >>> target = (second, tree, SurfaceNormals(second, tree, 10))
    >>> places = moved_places(first, np.arange(len(floor), len(first)), np.eye(4), target,
    ...                       0.01, RangeView(second), 0.25, 0.5, 10)
    >>> [len(p) for p in places[0]]
    [125]
    """
    candidates = np.asarray(candidates, dtype=np.intp)
    if not len(candidates):
        return [], candidates
    sweep, tree, normals = target
    rest = transform(motion, points[candidates])
    unexplained, _ = unexplained_mask(rest, tree, sweep, normals, scale)
    rows = candidates[unexplained]
    if len(rows) and view is not None:
        rows = rows[~view.hidden(rest[unexplained], margin)]
    if len(rows) < min_size:
        return [], rows
    labels, n = voxel_islands(points[rows], cell, min_size)
    islands = [rows[labels == i] for i in range(n)]
    return sorted(islands, key=len, reverse=True), rows


def new_place_share(points, motion, target, reached):
    """Share of ``points`` that ``motion`` lands on a place reached.

    ``target``: the other sweep ``(sweep, tree, normals)``; ``reached``: bool per point
    of that sweep, True where the first sweep (moved by the ego motion) leaves it
    unexplained. A body that moved lands partly where nothing was before; a repeated
    structure (a row of barriers) slid by one period onto itself lands on places the
    first sweep held already (:mod:`mmreg.sweeps._new_places` asks this of a pair's
    clusters).

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.spatial import cKDTree
    >>> from mmreg.sweeps._icp import SurfaceNormals
    >>> from mmreg.tracking._births import new_place_share
    >>> sweep = np.random.default_rng(0).uniform(0, 4, (400, 3))
    >>> tree = cKDTree(sweep)
    >>> target = (sweep, tree, SurfaceNormals(sweep, tree, 10))
    >>> reached = sweep[:, 0] > 2
    >>> float(new_place_share(sweep[sweep[:, 0] > 3], np.eye(4), target, reached))
    1.0
    """
    if not len(points):
        return 0.0
    sweep, tree, normals = target
    ratio, landing, _ = spacing_ratio(transform(motion, points), tree, sweep, normals)
    return float(np.mean((ratio <= EXPLAINED_SPACINGS) & reached[landing]))


def place_starts(left, reached, ego, reach):
    """Motions from each place left to the places reached near it.

    ``left``: points of the first sweep (its frame) per place; ``reached``: points of
    the second sweep (its frame) per place; ``ego``: the ego motion, first sweep to
    second. A start is the ego motion followed by the shift of the left place's centroid
    (where the ego motion puts it) onto a reached place's centroid, for the
    :data:`_STARTS` nearest reached places within ``reach``. Returns a list (one per
    place left) of lists of 4 x 4 motions.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.tracking._births import place_starts
    >>> left = [np.zeros((5, 3))]
    >>> reached = [np.full((5, 3), 9.0), np.array([[1.0, 0, 0]] * 5)]
    >>> starts = place_starts(left, reached, np.eye(4), reach=3.0)
    >>> [s[:3, 3].tolist() for s in starts[0]]
    [[1.0, 0.0, 0.0]]
    """
    if not left:
        return []
    if not reached:
        return [[] for _ in left]
    ends = np.array([p.mean(axis=0) for p in reached])
    tree = cKDTree(ends)
    k = min(_STARTS, len(ends))
    result = []
    for points in left:
        centre = transform(ego, points).mean(axis=0)
        distance, nearest = tree.query(centre, k=k, distance_upper_bound=reach)
        starts = []
        for d, j in zip(np.atleast_1d(distance), np.atleast_1d(nearest), strict=True):
            if not np.isfinite(d):
                continue
            shift = np.eye(4)
            shift[:3, 3] = ends[j] - centre
            starts.append(compose(shift, ego))
        result.append(starts)
    return result
