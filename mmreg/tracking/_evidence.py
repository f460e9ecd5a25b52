"""A track's predicted motion, tested point by point against the static world's.

A pair of sweeps alone misses many moving objects: most of their points sit in the
static cluster (a car the islands' search did not start near, a walker whose island a
wall holds). A track knows where such an object should be and how it should move. Its
evidence in a pair is the set of points near where it should be that its motion
explains on the second sweep and the ego motion does not (the same "explained" rule the
slow movers use, :mod:`mmreg.sweeps._explained`). A parked car gives none: the ego motion
explains it.
"""

from dataclasses import dataclass, replace

import numpy as np

from mmreg._array.geometry import rows_in_box
from mmreg._array.neighbors import lookup_tree
from mmreg.sweeps._explained import EXPLAINED_SPACINGS, spacing_ratio, unexplained_at
from mmreg.sweeps._icp import multi_body_icp
from mmreg.sweeps._level_icp import level_icps, level_part
from mmreg.tracking._motion import transform

# Points of a claim's candidates on which its starts are judged and refined.
_SAMPLE = 500
# Starts refined by ICP, those with the most evidence.
_REFINED_STARTS = 2
# A surface whose normal lies within about 26 degrees of the vertical (the absolute
# cosine above this) is level: a road user's level motion slides it along itself.
LEVEL_COSINE = 0.9

__all__ = ["Claim", "claimed_points", "near_points", "on_level", "track_claim"]


def near_points(points, where, radius, candidates=None):
    """Indices of ``points`` within ``radius`` of any of ``where`` (among ``candidates``).

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.tracking._evidence import near_points
    >>> points = np.array([[0.0, 0, 0], [1.0, 0, 0], [5.0, 0, 0]])
    >>> near_points(points, np.array([[0.9, 0.0, 0.0]]), 0.5).tolist()
    [1]
    """
    if candidates is None:
        candidates = np.arange(len(points))
    if not len(where) or not len(candidates):
        return np.zeros(0, dtype=np.intp)
    low, high = where.min(axis=0) - radius, where.max(axis=0) + radius
    box = rows_in_box(points, low, high, candidates)
    if not len(box):
        return box
    distance, _ = lookup_tree(where).query(points[box], distance_upper_bound=radius)
    return box[np.isfinite(distance)]


def claimed_points(points, motion, ego, target, scale, view=None, margin=0.0):
    """Which ``points`` ``motion`` explains on the second sweep and ``ego`` does not.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
        Points of the first sweep, in its frame.
    motion, ego : ndarray of shape (4, 4)
        The track's motion and the ego motion, first sweep to second.
    target : tuple
        ``(sweep, tree, normals)``: the second sweep, its cKDTree and SurfaceNormals.
    scale : float
        The ego ICP's robust point-to-plane residual scale.
    view : RangeView or None
        The second sweep's range image (:mod:`mmreg.tracking._visibility`): a point that
        ``ego`` puts where the second sweep could not see (a return more than ``margin``
        nearer in its direction) is no evidence.
    margin : float

    Returns
    -------
    claimed : ndarray of shape (n,), bool

    Examples
    --------
    A floor and a box's face on it, the face moved 1 m along x between the sweeps. At rest,
    its bottom row lies on the floor, which explains it; the nine rows above are claimed.

    >>> import numpy as np
    >>> from scipy.spatial import cKDTree
    >>> from mmreg.sweeps._icp import SurfaceNormals
    >>> from mmreg.tracking._evidence import claimed_points
    >>> from mmreg.tracking._motion import to_matrix
    >>> g = np.arange(-3.0, 3.0, 0.1)
    >>> floor = np.stack(np.meshgrid(g, g, [0.0], indexing="ij"), -1).reshape(-1, 3)
    >>> h = np.arange(0.05, 1.0, 0.1)
    >>> face = np.stack(np.meshgrid([0.0], h - 0.5, h, indexing="ij"), -1).reshape(-1, 3)
    >>> sweep = np.vstack([floor, face + [1.0, 0.0, 0.0]])
    >>> tree = cKDTree(sweep)
    >>> target = (sweep, tree, SurfaceNormals(sweep, tree, 10))
    >>> moved = to_matrix(np.eye(3), [1.0, 0.0, 0.0])
    >>> claimed = claimed_points(np.vstack([face, floor[:5]]), moved, np.eye(4), target, 0.01)
    >>> int(claimed[: len(face)].sum()), int(claimed[len(face) :].sum())
    (90, 0)
    """
    return _Answers(points, target, scale, view, margin).claimed(motion, ego)


class _Answers:
    """The second sweep's answers about one set of first-sweep points, under each motion
    asked, kept: a claim asks of the same points under the ego motion and every start,
    and again under each refined motion (the tree is queried once per motion)."""

    def __init__(self, points, target, scale, view=None, margin=0.0):
        self.points, self.target, self.scale = points, target, scale
        self.view, self.margin = view, margin
        self._moved = {}  # motion's bytes -> (moved points, (ratio, nearest, spacing))
        self._unexplained = {}
        self._occluder = {}  # motion's bytes -> the nearest return towards each point

    def moved(self, motion):
        """The points moved by ``motion`` and their :func:`spacing_ratio`."""
        self.ask([motion])
        return self._moved[motion.tobytes()]

    def ask(self, motions):
        """:meth:`moved` under each of ``motions`` not yet asked, in one query of the
        tree (the same answers: a query answers each point alone)."""
        new = {motion.tobytes(): motion for motion in motions}
        new = [motion for key, motion in new.items() if key not in self._moved]
        if not new:
            return
        sweep, tree, normals = self.target
        moved = [transform(motion, self.points) for motion in new]
        ratio, nearest, spacing = spacing_ratio(np.concatenate(moved), tree, sweep, normals)
        n = len(self.points)
        for k, motion in enumerate(new):
            part = slice(k * n, (k + 1) * n)
            self._moved[motion.tobytes()] = (moved[k], (ratio[part], nearest[part], spacing[part]))

    def explained(self, motion):
        """Whether ``motion`` puts each point within two spacings of the sweep."""
        return self.moved(motion)[1][0] <= EXPLAINED_SPACINGS

    def unexplained(self, motion):
        """Whether the sweep leaves each point unexplained where ``motion`` puts it."""
        key = motion.tobytes()
        if key not in self._unexplained:
            sweep, _, normals = self.target
            moved, nearest_spacings = self.moved(motion)
            self._unexplained[key] = unexplained_at(
                moved, nearest_spacings, sweep, normals, self.scale
            )
        return self._unexplained[key]

    def _nearest_return(self, motion, rows):
        key = motion.tobytes()
        if key not in self._occluder:
            self._occluder[key] = np.full(len(self.points), np.nan)
        occluder = self._occluder[key]
        ask = rows[np.isnan(occluder[rows])]
        if len(ask):
            occluder[ask] = self.view.nearest_return(self.moved(motion)[0][ask])
        return occluder[rows]

    def claimed(self, motion, ego):
        """:func:`claimed_points` of these points."""
        claimed = self.unexplained(ego) & self.explained(motion)
        if self.view is not None and claimed.any():
            # Hidden, unless what hides it is the point itself where the motion puts it
            # (a car coming closer hides the place it left).
            rows = np.flatnonzero(claimed)
            rest, moved = self.moved(ego)[0][rows], self.moved(motion)[0][rows]
            occluder = self._nearest_return(ego, rows)
            hidden = occluder < np.linalg.norm(rest, axis=1) - self.margin
            itself = np.abs(occluder - np.linalg.norm(moved, axis=1)) <= self.margin
            claimed[rows] = ~hidden | itself
        return claimed


def on_level(surface, rows, up):
    """Whether the points ``rows`` lie on level surfaces: their normals (``surface``, a
    :class:`~mmreg.sweeps._icp.SurfaceNormals`) within about 26 degrees of ``up``.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.spatial import cKDTree
    >>> from mmreg.sweeps._icp import SurfaceNormals
    >>> from mmreg.tracking._evidence import on_level
    >>> g = np.arange(0.0, 1.0, 0.1)
    >>> floor = np.stack(np.meshgrid(g, g, [0.0], indexing="ij"), -1).reshape(-1, 3)
    >>> wall = floor[:, [2, 0, 1]] + [2.0, 0.0, 0.0]
    >>> points = np.vstack([floor, wall])
    >>> tree = cKDTree(points)
    >>> level = on_level(SurfaceNormals(points, tree, 10), [0, 150], np.array([0, 0, 1.0]))
    >>> level.tolist()
    [True, False]
    """
    normal, _, _ = surface(np.asarray(rows, dtype=np.intp))
    return np.abs(normal @ up) > LEVEL_COSINE


@dataclass
class Claim:
    """What a track's motion claims in a pair (see :func:`track_claim`)."""

    rows: np.ndarray  # the points it claims: its evidence and the points consistent with it
    evidence: int  # how many more of them only its motion explains than only the ego's
    motion: np.ndarray  # 4 x 4, refined on them
    shown: np.ndarray  # the rows only its motion explains (the evidence itself)


def _thin(rows, size=_SAMPLE):
    """At most ``size`` of ``rows``, evenly spread through them (no random draw)."""
    if len(rows) <= size:
        return rows
    return rows[np.linspace(0, len(rows) - 1, size).astype(np.intp)]


def track_claim(
    points,
    near,
    tight,
    starts,
    ego,
    target,
    scale,
    *,
    max_distance,
    min_evidence,
    up=None,
    view=None,
    margin=0.0,
    surface=None,
):
    """The points a track's motion claims in a pair, and the motion refined on them.

    ``near`` index the points of ``points`` near where the track should be, ``tight``
    (a subset) those within its own points' reach; ``starts`` are 4 x 4 motions to try
    (the prediction, and the same twist slower or faster: a car brakes). From each
    start, the evidence is the points of ``near`` that the motion explains on the second
    sweep and the ego motion does not; the motion is refined by a point-to-plane ICP
    (Tukey's kernel) on them and on the points of ``tight`` it explains (a car's side
    that slides along itself is no evidence, but it is the car's). Of the refined motions
    with ``min_evidence`` points that move them more than two of the second sweep's
    spacings from where the ego motion puts them (a car that stopped does not), the one
    that explains the most points (its evidence and the points of ``tight``) wins, then
    the one with the most evidence: a long side with a repeated structure fits shifts a
    period apart with like evidence, and only the whole body tells them apart. ``up``:
    the vertical of z-up sweeps, along which a road user's motion is kept level
    (:mod:`mmreg.sweeps._level_icp`); None: free.
    ``view`` and ``margin``: the second sweep's range image; points it could not have
    seen are no evidence either way (see :func:`claimed_points`). ``surface``: the
    first sweep's :class:`~mmreg.sweeps._icp.SurfaceNormals`; with ``up``, points on
    level surfaces (:func:`on_level`) are no evidence. A level motion slides a level
    surface along itself, and a motion that keeps the ground's scan rings where the
    sensor is explains them better than the ego motion, which lays them between the
    next sweep's rings (a ghost that drives with the sensor). Returns a :class:`Claim`
    or None.
    """
    if len(near) < min_evidence:
        return None
    sweep, tree, normals = target
    # The starts are judged, and refined, on evenly spread samples of a large object's
    # points (a car near a 64-beam sensor holds thousands); the winner on them all.
    near_sample, tight_sample = _thin(near), _thin(tight)
    share = len(near) / len(near_sample)
    on_sample = _Answers(points[near_sample], target, scale, view, margin)
    on_tight_sample = _Answers(points[tight_sample], target, scale)
    seeds, motions, counts = [], [], []
    on_sample.ask([ego, *starts])  # the ego motion's and each start's, asked below
    for start in starts:
        evidence = near_sample[on_sample.claimed(start, ego)]
        if share * len(evidence) < min_evidence:
            continue
        seeds.append(np.union1d(evidence, tight_sample[on_tight_sample.explained(start)]))
        motions.append(start)
        counts.append(len(evidence))
    if not seeds:
        return None
    # Only the starts with the most evidence are refined: the others converge to the
    # same motion or to none.
    best_starts = np.argsort(counts, kind="stable")[::-1][:_REFINED_STARTS]
    seeds = [seeds[k] for k in best_starts]
    motions = [motions[k] for k in best_starts]
    if up is not None:  # road users: a turn about the vertical and a shift
        fits = level_icps(
            [points[rows] for rows in seeds],
            [
                level_part(start, ego, points[rows].mean(axis=0), up)
                for rows, start in zip(seeds, motions, strict=True)
            ],
            ego,
            target,
            max_distance=max_distance,
            up=up,
        )
        refined_motions = [fit.motion for fit in fits]
    else:
        rows = np.concatenate(seeds)
        group = np.repeat(np.arange(len(seeds)), [len(s) for s in seeds])
        result = multi_body_icp(
            points[rows],
            group,
            np.stack([m[:3, :3] for m in motions]),
            np.stack([m[:3, 3] for m in motions]),
            sweep,
            tree=tree,
            normals=normals,
            max_distance=max_distance,
            max_iter=15,
            tol=1e-4 * max_distance,
        )
        refined_motions = []
        for k in range(len(seeds)):
            refined = np.eye(4)
            refined[:3, :3], refined[:3, 3] = result.rotations[k], result.translations[k]
            refined_motions.append(refined)
    on_near = _Answers(points[near], target, scale, view, margin)
    on_near.ask([ego, *refined_motions])  # each is asked below
    on_tight = _Answers(points[tight], target, scale)
    sliding = np.zeros(len(near), dtype=bool)
    if up is not None and surface is not None:
        sliding = on_level(surface, near, up)
    best = None
    for refined in refined_motions:
        claimed = on_near.claimed(refined, ego) & ~sliding
        evidence = near[claimed]
        # Noise leaves a few points of a still object unexplained at rest, which a
        # small motion explains: as many as that motion leaves unexplained that the
        # ego motion explains. A moving object's evidence outweighs its counter-evidence
        # (the static things beside it, which its motion leaves unexplained), one for
        # one: two for one vetoed a car passing a static wall half its size, and a car
        # passing the sensor whose side's one scan ring fell between the next sweep's.
        against = np.count_nonzero(on_near.claimed(ego, refined))
        score = len(evidence) - against
        if score < min_evidence:
            continue
        moved = on_near.moved(refined)[0][claimed]
        spacing = on_near.moved(refined)[1][2][claimed]
        departure = np.linalg.norm(moved - on_near.moved(ego)[0][claimed], axis=1)
        if np.median(departure) <= EXPLAINED_SPACINGS * np.median(spacing):
            continue
        rows = np.union1d(evidence, tight[on_tight.explained(refined)])
        # A long side sliding along itself (the aperture problem) fits several shifts
        # with like evidence; the true one explains the whole body, ends included.
        if best is None or (len(rows), score) > (len(best.rows), best.evidence):
            best = Claim(rows, score, refined, evidence)
    if best is not None and view is not None:
        # The body's points that the next sweep could not see where the motion puts them
        # (behind another object) are no evidence either way: they stay the body's.
        hidden = view.hidden(on_tight.moved(best.motion)[0], margin)
        best = replace(best, rows=np.union1d(best.rows, tight[hidden]))
    return best
