"""A LiDAR log, frame by frame: the pairs registered, the tracks carried through them.

:class:`LogTracker` is the engine of :class:`mmreg.SequenceRegistration`; a new frame's
step reads like KISS-ICP's ``register_frame``, one line per step (see
:meth:`LogTracker._register_pair`):

1. register the new pair (the last sweep and this one) with the pair estimator, its ego
   motion started from the last one, the car's body carried, each sweep's state kept;
2. predict every track to the first sweep's time (a constant twist);
3. associate the pair's moving clusters with the tracks whose predictions cover them;
4. let each track claim, by its own motion, the points only it explains
   (:mod:`mmreg.tracking._evidence`), and update it;
5. start tentative tracks on the clusters nobody holds, and on the motions claimed from
   the places the ego motion leaves unexplained (:mod:`mmreg.tracking._births`); join
   tracks on pieces of one body;
6. confirm the tracks seen twice, run them backwards into the pending frames, coast or end
   the others;
7. carry the tracks onto the second sweep.

A frame's result is final ``lookahead`` frames later. Only the tracks and the pending
frames are kept.
"""

import dataclasses
import functools
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree
from sklearn.utils import Bunch

from mmreg._array.geometry import rows_in_box
from mmreg._array.neighbors import lookup_tree
from mmreg._array.unique_rows import unique_rows
from mmreg._validation import invalid_points
from mmreg._warnings import warn
from mmreg.sweeps._ambiguous_shapes import slides_along_line
from mmreg.sweeps._explained import EXPLAINED_SPACINGS, spacing_ratio
from mmreg.sweeps._ground import is_z_up_sweep
from mmreg.sweeps._icp import SurfaceNormals
from mmreg.sweeps._islands import voxel_islands
from mmreg.sweeps._level_icp import level_icp, level_part
from mmreg.sweeps._motion_bounds import impossible_motions, max_travel
from mmreg.sweeps._new_places import MIN_NEW_PLACE
from mmreg.sweeps._sensor_frame import warn_if_not_sensor_frame
from mmreg.tracking._births import moved_places, new_place_share, place_starts
from mmreg.tracking._evidence import near_points, on_level, track_claim
from mmreg.tracking._long_span import kept_frames, long_partner, pair_motion, refuted
from mmreg.tracking._motion import (
    compose,
    inverse,
    predicted_motion,
    transform,
    twist_of,
)
from mmreg.tracking._pairs import FEWEST_POINTS, PairChain
from mmreg.tracking._tracks import Track, consistent_motion, overlap_matrix
from mmreg.tracking._visibility import RangeView

__all__ = ["LogFrame", "LogTracker"]


# Where a track's points may be found around their prediction: this share of tau, plus
# a quarter of the predicted displacement (a car brakes, a walker turns).
_NEAR = 0.1
_MODEL_ERROR = 0.25
# A track's points that only its motion explains may lie that far from its predicted
# points (faces come into view); those that the ego motion explains too (a side sliding
# along itself) this far (this share of tau).
_TIGHT = 0.05
# A detection of a moving cluster belongs to the track whose prediction covers at least
# this share of its points.
_MIN_OVERLAP = 0.3
# Two measured motions of one object agree within half the displacement plus this
# share of tau (the pair's motions are centimetres off; a car brakes or turns).
_MOTION_TOLERANCE = 0.04
# The prediction's twist is tried at these shares of its speed.
_SPEEDS = (1.0, 0.75, 1.25, 0.5, 0.25)
# Two tracks' pieces this close (share of tau) that move this alike (share of their
# displacement, and of tau) are one object.
_PIECES = 0.2
_ALIKE = 0.1
_ALIKE_NOISE = 0.01
# The least evidence a track's motion needs, in points (a quarter of a small object's).
_MIN_EVIDENCE = 4
# A place is hidden from a sweep behind a return this much nearer (share of tau).
_HIDDEN = 0.05
# Points kept per track (its shape for the prediction and the association).
_TRACK_POINTS = 2000
# The places the ego motion leaves unexplained are islands of voxels this share of tau.
_PLACE_CELL = 0.05
# A piece of a claim (an island of its points) whose share of evidence is under this share
# of the whole claim's is another body that the motion merely slides along itself (a
# parked car beside a cyclist: 3 of its 573 points against 240 of the claim's 930).
_PIECE_SHARE = 0.1
# The body of a place left is sought this far around it (share of tau: a car's length).
_BODY_SPAN = 1.0
# Where no interval in seconds is known, a place reached lies this share of tau away at
# most (the pair's reach).
_PLACE_REACH = 0.6


@dataclass
class LogFrame:
    """One sweep as the sequence holds it while it is needed."""

    index: int
    points: np.ndarray  # every row the user gave
    valid: np.ndarray  # rows that are returns
    time: float
    pose: np.ndarray | None = None  # estimated sensor pose (world from sensor)
    given_pose: np.ndarray | None = None
    _target: tuple | None = None
    _returns: np.ndarray | None = None
    state: object | None = None  # the pair estimator's per-sweep state (SweepState)
    _view: object | None = None
    # Set by the pair of which this frame is the first sweep:
    pair_labels: np.ndarray | None = None  # the pair's labels of the valid rows
    pair_flow: np.ndarray | None = None
    body: np.ndarray | None = None  # valid rows on the ego vehicle's body
    ground: np.ndarray | None = None  # valid rows on the ground
    scale: float = np.nan  # the ego ICP's robust residual scale, to the next frame
    track_of: np.ndarray | None = None  # track key of each valid row, -1 none
    motions: dict = field(default_factory=dict)  # track key -> 4 x 4 motion to the next
    rows: list = field(default_factory=list)  # per-track table rows (key, ...)
    # Set by the pair of which this frame is the second sweep: the valid rows where the
    # tracks seen in the first sweep land (track key, -1 none), and those tracks' twists.
    carried: np.ndarray | None = None
    carried_twists: dict = field(default_factory=dict)
    ego: np.ndarray | None = None  # 4 x 4 ego motion to the next frame
    up: np.ndarray | None = None  # the vertical, in a z-up LiDAR sweep
    seconds: bool = False  # whether ``time`` is in seconds (else the frame's index)
    point_times: np.ndarray | None = None  # capture times of the valid rows, seconds
    covered: np.ndarray | None = None  # per row: its stand-in among the valid rows, -1 none

    @property
    def returns(self):
        """The valid rows (a copy, made once: every step reads them)."""
        if self._returns is None:
            self._returns = self.points[self.valid]
        return self._returns

    def for_pairs(self):
        """A copy with what a pair reads of a frame (to send to another process)."""
        return LogFrame(
            self.index,
            self.points,
            self.valid,
            self.time,
            given_pose=self.given_pose,
            state=self.state,
            seconds=self.seconds,
            point_times=self.point_times,
            up=self.up,
            covered=self.covered,
        )

    def view(self):
        """The range image of the valid rows, built once."""
        if self._view is None:
            self._view = RangeView(self.returns)
        return self._view

    def target(self):
        """``(points, tree, normals)`` of the valid rows, built once (the pairs' own
        state's, where they keep one)."""
        if self._target is None and self.state is not None:
            self._target = self.state.target()
        if self._target is None:
            points = self.returns
            tree = cKDTree(points)
            self._target = (points, tree, SurfaceNormals(points, tree, 10))
        return self._target


def _length(points):
    """The largest extent of ``points`` along their own principal axes: a body's length
    whichever way it faces (along the sensor's axes, a car seen diagonally is shorter)."""
    centred = points - points.mean(axis=0)
    _, axes = np.linalg.eigh(centred.T @ centred)
    return float(np.ptp(centred @ axes, axis=0).max())


def _box(points):
    """Length, width, height and yaw of the points' box (principal axes in x-y)."""
    xy = points[:, :2] - points[:, :2].mean(axis=0)
    if len(points) < 3:
        yaw = 0.0
    else:
        _, vectors = np.linalg.eigh(xy.T @ xy)
        yaw = float(np.arctan2(vectors[1, 1], vectors[0, 1]))
    c, s = np.cos(yaw), np.sin(yaw)
    along = xy @ [c, s]
    across = xy @ [-s, c]
    return (
        float(np.ptp(along)),
        float(np.ptp(across)),
        float(np.ptp(points[:, 2])),
        yaw,
    )


class LogTracker:
    """The state of one log and its steps (see the module's docstring).

    Parameters
    ----------
    make_pair : callable
        ``make_pair(seed)`` returns a fresh pair estimator (``fit(points1, sweep=points2,
        ...)``, as :class:`~mmreg.SweepRegistration`).
    tau : float
        The one length (5 for metres).
    lookahead : int
        Frames after a frame whose pairs may still change its labels.
    max_misses : int
        Frames a confirmed track coasts without evidence.
    frame_rate : float or None
        Frames per second where a frame comes without a time.
    min_points : int
        The pair estimator's smallest island: the most evidence a track needs.
    rng : numpy.random.RandomState
        Seeds two streams of its own: one seeds the pairs' estimators, the other draws
        the points a track keeps. Apart, a change to what a track keeps leaves every
        pair's draws as they were.
    voxel_size : float or None
        Register one point per voxel of this side (every point takes its voxel's labels);
        None: every point.
    """

    def __init__(
        self,
        make_pair,
        *,
        tau,
        lookahead,
        max_misses,
        frame_rate,
        min_points,
        rng,
        voxel_size=None,
    ):
        self._make_pair = make_pair
        self.voxel_size = voxel_size
        self.tau = tau
        self.lookahead = lookahead
        self.max_misses = max_misses
        self.frame_rate = frame_rate
        self.min_points = min_points
        pairs, samples = rng.randint(2**31 - 1, size=2)
        self._state = _LogState(rng=np.random.RandomState(samples))
        self.pairs = PairChain(make_pair, tau=tau, rng=np.random.RandomState(pairs))

    def _time(self, index, time):
        if time is not None:
            return float(time)
        return index / self.frame_rate if self.frame_rate is not None else float(index)

    def step(self, points, time, pose, point_times=None):
        """Add one frame; the results (Bunches) of the frames it makes final."""
        return self.add(self.new_frame(self._state.n_frames, points, time, pose, point_times))

    def new_frame(self, index, points, time, pose, point_times=None):
        """Frame ``index`` of the log as the steps hold it (its valid rows, the rows it is
        registered on, its time, whether it is z-up); it changes nothing of the log but
        what the log has warned of: where frames are not in their sensor's frame
        (:func:`~mmreg.sweeps._sensor_frame.warn_if_not_sensor_frame`), once a log;
        which axis is up is asked of the first frame, where the sensor is of every frame
        (a log in a world frame leaves the origin as it drives)."""
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] < 3:
            raise ValueError(f"a frame must have shape (n, 3); got {points.shape}.")
        points = points[:, :3]
        valid = ~invalid_points(points)
        used, covered = self._voxels(points, valid)
        frame = LogFrame(index, points, used, self._time(index, time), given_pose=pose)
        frame.covered = covered
        if point_times is not None:
            point_times = np.asarray(point_times, dtype=float)
            if point_times.shape != (len(points),) or not np.all(np.isfinite(point_times)):
                raise ValueError(
                    f"frame {index}: point_times must be {len(points)} finite numbers, "
                    "one per point."
                )
            frame.point_times = point_times[used]
        frame.seconds = time is not None or self.frame_rate is not None
        returns = points[valid]
        wanted = ({"away"} if index else {"away", "up"}) - self._state.told
        if wanted:
            self._state.told |= warn_if_not_sensor_frame(returns, f"frame {index}", wanted)
        if len(returns) >= 3 and is_z_up_sweep(returns):
            frame.up = np.array([0.0, 0.0, 1.0])
        return frame

    def add(self, frame, pair=None):
        """Add the next frame (:meth:`new_frame`); ``pair``: the :class:`PairFit` of the
        last frame and this one where it was fitted elsewhere (a process of its own),
        else None. The results (Bunches) of the frames it makes final."""
        state = self._state
        index = frame.index
        if state.previous is None:
            frame.pose = (
                np.eye(4) if frame.given_pose is None else np.asarray(frame.given_pose, dtype=float)
            )
        else:
            if frame.time <= state.previous.time:
                raise ValueError(f"frame {index}: its time does not follow the last frame's.")
            self._register_pair(state.previous, frame, pair)
            state.pending.append(state.previous)
        state.previous = frame
        state.n_frames += 1
        chain = [*state.pending, frame]  # each pending frame and the one after it
        finished = [
            self._result(f, after)
            for f, after in zip(chain, chain[1:], strict=False)
            if f.index <= index - 1 - self.lookahead
        ]
        state.pending = [f for f in state.pending if f.index > index - 1 - self.lookahead]
        # When a track was last seen matters only against the frames still pending: an
        # older sighting reads as none (memory stays bounded over a long log).
        oldest = state.pending[0].index if state.pending else index
        state.last_seen = {k: f for k, f in state.last_seen.items() if f >= oldest}
        return finished

    def _voxels(self, points, valid):
        """The rows a frame is registered on, and which of them stands for each row.

        Without ``voxel_size``, every valid row. With it, the first valid row in each voxel
        (KISS-ICP's thinning): ``used`` marks them and ``covered[i]`` is, for every valid
        row ``i``, the place among the used rows of the one in its voxel (-1: invalid).
        """
        covered = np.full(len(points), -1, dtype=np.intp)
        rows = np.flatnonzero(valid)
        if self.voxel_size is None or not len(rows):
            covered[rows] = np.arange(len(rows))
            return valid, covered
        keys = np.floor(points[rows] / self.voxel_size).astype(np.int64)
        _, first, inverse = unique_rows(keys, return_index=True, return_inverse=True)
        used = np.zeros(len(points), dtype=bool)
        used[rows[first]] = True
        place = np.cumsum(used) - 1  # each used row's place among the used rows
        covered[rows] = place[rows[first]][inverse.ravel()]
        return used, covered

    def close(self):
        """End the log: the results of every frame still pending, the last included."""
        state = self._state
        chain = [*state.pending, state.previous] if state.previous is not None else []
        state.pending = []
        return [self._result(f, after) for f, after in zip(chain, [*chain[1:], None], strict=True)]

    def _register_pair(self, previous, frame, fit=None):
        """One step: register the pair (or take its ``fit``), then predict, associate
        and update the tracks.

        ``previous`` is the first sweep; its labels are what this pair and the tracks
        say of it. ``frame`` (the second sweep) gets its pose.
        """
        state = self._state
        state.last_first = previous
        dt = frame.time - previous.time
        if fit is None:
            fit = self.pairs.fit(previous, frame)
        else:
            _take_states(fit.states, previous, frame)
            for message, category in fit.warnings:
                warn(message, category)
        if fit.gap:
            self._gap(previous, frame, fit)
            return
        pair = self._take_pair(previous, frame, fit)
        first = previous.returns
        span = self._span(previous)
        predictions = self._predict(previous.time, previous.pose)
        detections = pair.detections
        overlap = overlap_matrix(
            [first[rows] for rows, _ in detections.values()],
            [points for points, _ in predictions],
            [radius for _, radius in predictions],
        )
        column = {j: i for i, j in enumerate(detections)}
        free = ~(pair.ground | previous.body)
        for rows, _ in detections.values():
            free[rows] = False
        previous.track_of = np.full(len(first), -1, dtype=np.intp)
        seen = {}  # track key -> points detected in ``previous``
        # The confirmed and longest-lived tracks choose first: two tracks born on two
        # pieces of one object must not take it in turns.
        tracks = state.tracks
        order = sorted(range(len(tracks)), key=lambda i: (not tracks[i].confirmed, -tracks[i].hits))
        for i in order:
            track = tracks[i]
            mine = [j for j in detections if overlap[column[j], i] >= _MIN_OVERLAP]
            found = self._track_detection(
                track, previous, frame, pair, [detections[j] for j in mine], predictions[i], free
            )
            if found is not None:  # the pair shows it moving
                track.stopped = False
            if found is None and (track.slow or not track.confirmed) and span is not None:
                # Too slow for its pairs (a walker): its motion over the long span.
                found = self._long_detection(
                    track,
                    previous,
                    frame,
                    span,
                    [detections[j] for j in mine],
                    predictions[i],
                    free,
                )
                track.slow |= found is not None
            if found is None:
                continue
            rows, motion = found
            free[rows] = False
            self._observe(track, previous, frame, rows, motion, dt)
            seen[track.key] = len(rows)
            for j in mine:
                del detections[j]
        # Moving clusters no track holds: tentative tracks. One over the prediction of a
        # confirmed track that this pair missed is that object, seen with another motion
        # (a car leaving the view, whose pair's motion follows its last visible part).
        heirs = set()
        for j, (rows, motion) in detections.items():
            track = self._born(previous, frame, rows, motion, dt)
            seen[track.key] = len(rows)
            self._inherit(track, overlap[column[j]], order, seen, heirs)
        # Objects the pair's clusters called static that left a place and reached one.
        for rows, motion in self._moved_places(previous, frame, pair, free, dt):
            track = self._born(previous, frame, rows, motion, dt)
            seen[track.key] = len(rows)
        if span is not None:
            # ... and half a second back, but where a confirmed track that this pair
            # missed is predicted: that object coasts (a car going out of view).
            open_ = free.copy()
            for i in order:
                if tracks[i].confirmed and tracks[i].key not in seen:
                    points, radius = predictions[i]
                    open_[near_points(first, points, radius, np.flatnonzero(open_))] = False
            for rows, motion in self._long_places(previous, frame, span, open_, dt):
                track = self._born(previous, frame, rows, motion, dt, refit=False)
                track.slow = True
                seen[track.key] = len(rows)
        self._join_pieces(previous, seen, dt)
        if previous.seconds:
            self._state.recent = kept_frames(self._state.recent, previous)
        for track in self._confirm_and_end(previous, seen):
            self._extend_back(track, previous)
        self._carry(previous, frame, pair.sweep_ground)

    def _inherit(self, track, cover, order, seen, heirs):
        """Make the new ``track`` the heir of the confirmed track, not seen in this pair
        (``seen``) nor inherited yet (``heirs``, which it joins), whose prediction covers
        the most of its points (``cover``: share per track, in ``order``), if any covers
        ``_MIN_OVERLAP``."""
        tracks = self._state.tracks
        missed = [
            i
            for i in order
            if tracks[i].confirmed
            and tracks[i].key not in seen
            and tracks[i].key not in heirs
            and cover[i] >= _MIN_OVERLAP
        ]
        if missed:
            track.heir_of = tracks[max(missed, key=lambda i: cover[i])].key
            heirs.add(track.heir_of)

    def _moved_places(self, previous, frame, pair, free, dt):
        """Motions claimed from the places the ego motion leaves unexplained
        (:mod:`mmreg.tracking._births`): ``[(rows, 4 x 4 motion)]`` of ``previous``'s
        ``free`` rows, which they then leave.

        Each island of the first sweep's free points that the second sweep does not
        explain (a place left) tries the shifts onto the nearest such islands of the
        second sweep (places reached) within a road user's reach, and a track's claim
        decides, as it does for a track's prediction. Such a track is tentative: a
        second pair must confirm it.
        """
        # A road user's reach in the interval.
        reach = max_travel(self.tau, dt) if frame.seconds else _PLACE_REACH * self.tau

        def possible(claim):
            return claim.motion if self._possible(previous, claim.rows, claim.motion, dt) else None

        taken = ~(pair.sweep_ground | frame.body)
        return self._place_claims(
            previous, frame, pair.ego, pair.scale, taken, reach, free, possible
        )

    def _long_places(self, previous, frame, span, free, dt):
        """Motions claimed as in :meth:`_moved_places` from the places that ``previous`` and
        the frame of ``span`` (:data:`~mmreg.tracking._long_span.LONG_SPAN` back) leave each
        other unexplained; each the pair's motion at the constant twist of the span's, where
        the pair does not refute it."""
        old = span.frame
        reach = max_travel(self.tau, previous.time - old.time)

        def accepted(claim):
            motion = self._pair_motion(previous, frame, span, claim.motion, claim.rows)
            if motion is None:
                return None
            return motion if self._possible(previous, claim.rows, motion, dt) else None

        taken = ~(old.ground | old.body)
        return self._place_claims(
            previous, old, span.back, span.scale, taken, reach, free, accepted
        )

    def _place_claims(self, previous, other, ego, scale, taken, reach, free, accept):
        """The claims of :meth:`_moved_places` between ``previous`` and ``other`` (the
        next sweep, or one further off): ``ego`` carries ``previous`` onto ``other``,
        ``scale`` is its residual scale, ``taken`` marks ``other``'s rows that may have
        moved there and ``reach`` bounds a road user's shift. ``accept(claim)`` gives
        the motion a claim stands for, or None."""
        first, second = previous.returns, other.returns
        cell, margin = _PLACE_CELL * self.tau, _HIDDEN * self.tau
        left, _ = moved_places(
            first, np.flatnonzero(free), ego, other.target(), scale,
            other.view(), margin, cell, self.min_points,
        )  # fmt: skip
        if not left:
            return []
        reached, new = moved_places(
            second, np.flatnonzero(taken), inverse(ego), previous.target(), scale,
            previous.view(), margin, cell, self.min_points,
        )  # fmt: skip
        arrived = np.zeros(len(second), dtype=bool)
        arrived[new] = True
        # Each place's body: where it left only its rear, a car's whole island.
        bodies = [self._body_of(first, rows, free, cell) for rows in left]
        # The shifts of the bodies, and of the places themselves (a walker's body may be
        # a wall's too).
        body_starts = place_starts(
            [first[rows] for rows in bodies],
            [second[self._body_of(second, rows, taken, cell)] for rows in reached],
            ego,
            reach,
        )
        own_starts = place_starts(
            [first[rows] for rows in left], [second[rows] for rows in reached], ego, reach
        )
        starts = [a + b for a, b in zip(body_starts, own_starts, strict=True)]
        found = []
        for rows, body, tries in zip(left, bodies, starts, strict=True):
            rows = rows[free[rows]]
            if not tries or len(rows) < self.min_points:
                continue
            near = near_points(first, first[rows], _NEAR * self.tau, np.flatnonzero(free))
            tight = np.union1d(near_points(first, first[rows], _TIGHT * self.tau, near), body)
            tight = tight[free[tight]]
            claim = self._claim(previous, other, ego, scale, near, tight, tries, self.min_points)
            # A line slid along itself is no motion: one scan ring across a far wall,
            # where the rings lie far apart, travels with the sensor along the wall.
            if claim is None or _slides_along_line(first[claim.rows], claim.motion, ego):
                continue
            motion = accept(claim)
            if motion is None:
                continue
            # A repeated structure slid onto itself by one period lands on no new place.
            landed = new_place_share(first[claim.rows], claim.motion, other.target(), arrived)
            if landed < MIN_NEW_PLACE:
                continue
            rows = _off_the_ground(previous, claim.rows, claim.shown, _TIGHT * self.tau)
            free[rows] = False
            found.append((rows, motion))
        return found

    def _claim(self, frame, other, ego, scale, near, tight, starts, min_evidence):
        """A track's claim (:func:`~mmreg.tracking._evidence.track_claim`) of ``frame``'s
        points ``near`` (``tight``, its own reach) moved by one of ``starts`` onto
        ``other``, the sweep after it or one further off; ``ego`` carries the static world
        there and ``scale`` is its residual scale."""
        return track_claim(
            frame.returns,
            near,
            tight,
            starts,
            ego,
            other.target(),
            scale,
            max_distance=0.2 * self.tau,
            min_evidence=min_evidence,
            up=frame.up,
            view=other.view(),
            margin=_HIDDEN * self.tau,
            surface=frame.target()[2],
        )

    def _span(self, previous):
        """The long span of the pair whose first sweep is ``previous``, or None (no frame
        half a second back, or times not in seconds): the frame, the ego motion from
        ``previous`` to it (4 x 4, the chained poses') and its residual scale (the pairs'
        scales added).

        The poses' errors add up over the span, but registering the span's ego motion
        again (GICP from the chained poses') changed no figure: not on the generated
        10 Hz logs, nor on the nuScenes logs run with times at 10 Hz, whose spans then
        hold 2.5 s of real motion and 10-25 m of the car's travel.
        """
        old = long_partner(self._state.recent, previous) if previous.seconds else None
        if old is None:
            return None
        back = compose(inverse(old.pose), previous.pose)
        scale = (previous.index - old.index) * max(previous.scale, old.scale)
        return _Span(old, back, scale)

    def _pair_motion(self, previous, frame, span, back, rows, ties=False):
        """The pair's motion of ``previous``'s ``rows`` at the twist of ``back``, their
        motion to the frame of ``span``; None where the pair refutes it (the object has
        stopped since, :func:`~mmreg.tracking._long_span.refuted`; with ``ties``, also
        where it says as much for the motion as against it)."""
        old = span.frame
        centre = transform(previous.pose, previous.returns[rows]).mean(axis=0)
        poses = (previous.pose, frame.pose, old.pose)
        motion = pair_motion(
            back, poses, centre, previous.time - old.time, frame.time - previous.time
        )
        if refuted(previous.returns[rows], previous.ego, motion, frame.target(), ties=ties):
            return None
        return motion

    def _long_detection(self, track, previous, frame, span, clusters, prediction, free):
        """``track``'s points in ``previous`` and their pair motion, claimed over the long
        ``span`` (its frame to ``previous``) where the pair showed none, or None.
        ``clusters``: the pair's moving clusters over its prediction."""
        old = span.frame
        first = previous.returns
        _, near, tight, starts, needed = self._around_prediction(
            track, previous, old, old.time - previous.time, prediction, clusters, free
        )
        # Its whole body, as for a place left: a track born on a car's rear (its only
        # place left in a pair) grows to the car that the span shows moving (no longer
        # than a car: a walker's body would be the wall beside it).
        tight = self._grown(first, tight, free)
        claim = self._claim(previous, old, span.back, span.scale, near, tight, starts, needed)
        if claim is None:
            return None
        rows = _off_the_ground(previous, claim.rows, claim.shown, _TIGHT * self.tau)
        if not len(rows):
            return None
        # Half a second averages a braking car's motion: once the pair has shown it
        # stopped, a stand-off (a motion too slow for the pair to tell from rest) does
        # not set it moving again.
        motion = self._pair_motion(previous, frame, span, claim.motion, rows, track.stopped)
        track.stopped = motion is None
        if motion is None:
            return None
        dt = frame.time - previous.time
        if not self._follows(track, previous, frame, rows, motion):
            return None
        if not self._possible(previous, rows, motion, dt):
            return None
        return rows, motion

    def _body_of(self, points, rows, free, cell):
        """The ``free`` points of the islands (voxels of side ``cell``) that hold ``rows``,
        within a car's reach of them: the body whose place ``rows`` left (of a car that
        moved less than its length, only its rear is a place left)."""
        low = points[rows].min(axis=0) - _BODY_SPAN * self.tau
        high = points[rows].max(axis=0) + _BODY_SPAN * self.tau
        around = rows_in_box(points, low, high)
        around = around[free[around]]
        labels, _ = voxel_islands(points[around], cell)
        holding = np.isin(around, rows)
        return around[np.isin(labels, np.unique(labels[holding]))]

    def _grown(self, points, rows, free):
        """``rows`` and their body (:meth:`_body_of`), where the two are no longer than a
        car (``_BODY_SPAN``): a walker's body would be the wall beside it, which its level
        motion slides along itself."""
        if not len(rows):
            return rows
        grown = np.union1d(rows, self._body_of(points, rows, free, _PLACE_CELL * self.tau))
        if _length(points[grown]) > _BODY_SPAN * self.tau:
            return rows
        return grown

    def _gap(self, previous, frame, fit):
        """A pair with a sweep too sparse to register (an empty message, a dropped
        frame): the ego motion is predicted (``fit.ego``: constant velocity, else none),
        nothing is labelled but by the tracks carried, and the tracks coast."""
        warn(
            f"frame {frame.index if len(previous.returns) >= FEWEST_POINTS else previous.index}"
            f": fewer than {FEWEST_POINTS} valid points; the pair of frames "
            f"{previous.index} and {frame.index} is not registered."
        )
        ego = fit.ego
        previous.ego = ego
        frame.pose = compose(previous.pose, inverse(ego))
        n = len(previous.returns)
        previous.pair_labels = np.zeros(n, dtype=np.intp)
        previous.pair_flow = transform(ego, previous.returns) - previous.returns
        previous.body = fit.body
        previous.ground = np.zeros(n, dtype=bool)
        previous.scale = 0.002 * self.tau
        previous.track_of = np.full(n, -1, dtype=np.intp)
        frame.body = fit.sweep_body
        self._confirm_and_end(previous, {})
        frame.carried = np.full(len(frame.returns), -1, dtype=np.intp)

    def _join_pieces(self, previous, seen, dt):
        """Tracks seen on pieces within a fifth of tau of each other that move alike (their
        displacements within a tenth of each other and a hundredth of tau) are one object
        (a pair may cut a far car in two): the younger joins the older, and its key names
        the older from now on, in the pending frames too."""
        state = self._state
        tracks = sorted(
            (t for t in state.tracks if t.key in seen),
            key=lambda t: (not t.confirmed, -t.hits, t.key),
        )
        first = previous.returns
        joined = set()
        for i, keep in enumerate(tracks):
            if keep.key in joined:
                continue
            for other in tracks[i + 1 :]:
                if other.key in joined:
                    continue
                # Pieces of one body move as one: far more alike than two tracks' motions
                # that merely follow each other (asked first: it costs no tree).
                apart = np.linalg.norm((keep.velocity - other.velocity) * dt)
                if apart > _ALIKE * np.linalg.norm(keep.velocity * dt) + _ALIKE_NOISE * self.tau:
                    continue
                mine = first[previous.track_of == keep.key]
                theirs = first[previous.track_of == other.key]
                distance, _ = lookup_tree(mine).query(
                    theirs, distance_upper_bound=_PIECES * self.tau
                )
                if not np.isfinite(distance).any():
                    continue
                previous.track_of[previous.track_of == other.key] = keep.key
                previous.motions.pop(other.key, None)
                state.alias[other.key] = keep.key
                seen[keep.key] += seen.pop(other.key)
                points = transform(previous.pose, first[previous.track_of == keep.key])
                keep.points = _sample(points, state.rng)
                keep.hits = max(keep.hits, other.hits)
                joined.add(other.key)
        state.tracks = [t for t in state.tracks if t.key not in joined]

    def _joined(self, key):
        """Track ``key`` and the tracks it joined, in turn."""
        keys = [key]
        while keys[-1] in self._state.alias:
            keys.append(self._state.alias[keys[-1]])
        return keys

    def _seen(self, key):
        """The last frame in which track ``key`` (or a track it joined) was seen."""
        return max(self._state.last_seen.get(k, -1) for k in self._joined(key))

    def _identity(self, key):
        """The public id of track ``key`` (0: none), through the tracks it joined."""
        return self._state.identity.get(self._joined(key)[-1], 0)

    def _carry(self, previous, frame, ground):
        """Where each track seen in ``previous`` lands in ``frame``: the points of the
        second sweep within two of its spacings (and a twentieth of tau) of the track's
        points moved by its motion. They are the track's in ``frame`` where the next pair
        does not say otherwise (it may miss the object, or there may be no next pair).
        Where they are the road alone (``ground``, the pair's), the object has gone: a car
        that left the view would leave its label on the road it drove on. A car's
        lowest points, which the ground's segmentation may take, stay its."""
        points, tree, normals = frame.target()
        frame.carried = np.full(len(points), -1, dtype=np.intp)
        free = ~frame.body
        for key, motion in previous.motions.items():
            moved = transform(motion, previous.returns[previous.track_of == key])
            near = near_points(points, moved, _TIGHT * self.tau, np.flatnonzero(free))
            if not len(near):
                continue
            distance, _ = lookup_tree(moved).query(points[near])
            near = near[distance <= EXPLAINED_SPACINGS * normals.spacing(near)]
            if np.count_nonzero(~ground[near]) < _MIN_EVIDENCE:  # a few points are no object's
                continue
            frame.carried[near] = key
            free[near] = False
            track = next((t for t in self._state.tracks if t.key == key), None)
            if track is not None:
                frame.carried_twists[key] = (track.omega.copy(), track.velocity.copy())

    def _take_pair(self, previous, frame, fit):
        """The pair's fit on the two frames: the first sweep's labels, flow, body and
        ground, the second sweep's pose, and what the step reads of it."""
        previous.ego = fit.ego
        frame.pose = compose(previous.pose, inverse(fit.ego))
        previous.pair_labels = fit.labels
        previous.pair_flow = fit.flow
        previous.body = fit.body
        frame.body = fit.sweep_body
        scale = fit.scale
        previous.scale = scale if np.isfinite(scale) and scale > 0 else 0.002 * self.tau
        previous.ground = fit.ground
        # The step takes the detections it associates out of its own copy.
        return dataclasses.replace(fit, scale=previous.scale, detections=dict(fit.detections))

    def _predict(self, time, pose):
        """Every track's points predicted to ``time``, in the sensor frame at ``pose``,
        and how far from them its points may be found."""
        to_sensor = inverse(pose)
        # The first prediction repeats the motion the last pair measured: only the
        # object's shape changes (faces come into view). Coasting adds the model's error.
        return [
            (
                transform(to_sensor, track.predicted_points(time)),
                _NEAR * self.tau * (1 + track.misses)
                + _MODEL_ERROR
                * np.linalg.norm(track.velocity)
                * (time - track.time)
                * track.misses,
            )
            for track in self._state.tracks
        ]

    def _track_detection(self, track, previous, frame, pair, clusters, prediction, free):
        """The points of ``previous`` that are ``track``'s, and their motion, or None.

        ``clusters`` are the pair's moving clusters that cover its prediction. The
        track's motion is refined from its prediction (and the clusters' motions) on
        the points no other track holds near the prediction (``free``) and the
        clusters' (see :func:`mmreg.tracking._evidence.track_claim`); it claims the
        points it alone explains, and those of its own shape it explains too.
        """
        dt = frame.time - previous.time
        first = previous.returns
        own, near, tight, predicted, needed = self._around_prediction(
            track, previous, frame, dt, prediction, clusters, free
        )
        # Its whole body, as for a place left: a car coming into view grows past the
        # part its track was born on.
        tight = self._grown(first, tight, free)
        claim_from = functools.partial(
            self._claim, previous, frame, pair.ego, pair.scale, near, tight, min_evidence=needed
        )
        claim = claim_from(predicted + [motion for _, motion in clusters])
        if (
            clusters
            and claim is not None
            and not self._follows(track, previous, frame, claim.rows, claim.motion)
        ):
            # Two cars in a line, one interval apart: the pair lays the first where the
            # second will be, a motion that explains more points than the true one. The
            # track's past says which motion: its prediction tries alone (without
            # clusters it just did). The pair's clusters over the prediction are still
            # the object's points.
            claim = claim_from(predicted)
        if claim is not None:
            rows, motion = np.union1d(claim.rows, own), claim.motion
            # A piece that the ego motion explains (a side sliding along itself) is the
            # track's only where its evidence is on it too: a parked car beside a
            # cyclist slides along itself under the cyclist's motion. (A piece the next
            # sweep could not see holds no evidence either, but the ego motion does not
            # explain it.)
            sweep, tree, normals = frame.target()
            ratio, _, _ = spacing_ratio(transform(pair.ego, first[rows]), tree, sweep, normals)
            rows = _on_evidence(
                first, rows, claim.shown, ratio <= EXPLAINED_SPACINGS, _PLACE_CELL * self.tau
            )
            rows = _off_the_ground(previous, rows, claim.shown, _TIGHT * self.tau)
        elif clusters and track.confirmed:
            # The pair's own motion for its largest cluster, level as a new track's is.
            rows, motion = own, max(clusters, key=lambda c: len(c[0]))[1]
            motion = self._level(previous, frame, rows, motion)
        else:
            return None
        # A track takes a detection only where its motion follows the track's.
        if not self._follows(track, previous, frame, rows, motion):
            return None
        if not self._possible(previous, rows, motion, dt):
            return None
        return rows, motion

    def _around_prediction(self, track, previous, other, dt, prediction, clusters, free):
        """What a claim of ``track`` in ``previous`` onto ``other``, ``dt`` later (or
        earlier), starts from: the rows of its ``clusters``; the ``free`` rows near its
        ``prediction`` (and the clusters'), and those within its own points' reach; the
        motions of its twist at each of ``_SPEEDS``; and the evidence it needs."""
        first = previous.returns
        points, radius = prediction
        centre = transform(previous.pose, points).mean(axis=0)
        own = (
            np.concatenate([rows for rows, _ in clusters])
            if clusters
            else np.zeros(0, dtype=np.intp)
        )
        near = np.union1d(near_points(first, points, radius, np.flatnonzero(free)), own)
        tight = np.union1d(near_points(first, points, _TIGHT * self.tau, near), own)
        # The prediction, the same twist slower or faster (a car brakes at a light,
        # pulls away): starts for the track's ICP.
        starts = [
            compose(
                inverse(other.pose),
                predicted_motion(track.omega, track.velocity, centre, dt * speed),
                previous.pose,
            )
            for speed in _SPEEDS
        ]
        # A confirmed track needs less new evidence (its past shows it moves), and a
        # small object (a walker of 20 points) a quarter of its points.
        needed = self.min_points // 2 if track.confirmed else self.min_points
        needed = min(needed, max(_MIN_EVIDENCE, len(track.points) // 4))
        return own, near, tight, starts, needed

    def _follows(self, track, previous, frame, rows, motion):
        """Whether ``motion`` of ``previous``'s points ``rows`` follows ``track``'s."""
        dt = frame.time - previous.time
        world = compose(frame.pose, motion, inverse(previous.pose))
        points = transform(previous.pose, previous.returns[rows])
        _, velocity = twist_of(world, points.mean(axis=0), dt)
        return consistent_motion(track, velocity, dt, _MOTION_TOLERANCE * self.tau)

    def _observe(self, track, previous, frame, rows, motion, dt):
        """``track`` seen at ``rows`` of ``previous``, moving by ``motion`` to ``frame``."""
        world = compose(frame.pose, motion, inverse(previous.pose))
        points = transform(previous.pose, previous.returns[rows])
        track.update(_sample(points, self._state.rng), previous.time, previous.index, world, dt)
        previous.track_of[rows] = track.key
        previous.motions[track.key] = motion

    def _born(self, previous, frame, rows, motion, dt, refit=True):
        """A tentative track for a moving cluster no track holds; unless ``refit`` is
        False, the cluster's motion fitted again, level (:meth:`_level`)."""
        state = self._state
        if refit:
            motion = self._level(previous, frame, rows, motion)
        world = compose(frame.pose, motion, inverse(previous.pose))
        points = transform(previous.pose, previous.returns[rows])
        omega, velocity = twist_of(world, points.mean(axis=0), dt)
        track = Track(
            key=state.next_key,
            points=_sample(points, state.rng),
            time=previous.time,
            frame=previous.index,
            omega=omega,
            velocity=velocity,
        )
        state.next_key += 1
        state.tracks.append(track)
        previous.track_of[rows] = track.key
        previous.motions[track.key] = motion
        return track

    def _level(self, previous, frame, rows, motion):
        """A pair's motion of ``previous``'s points ``rows`` fitted again, level (a turn
        about the vertical and a shift, :mod:`mmreg.sweeps._level_icp`), in z-up sweeps:
        a far car's few points fit a free motion that tilts it by tens of degrees, and
        a track that took it would predict the car sinking into the road."""
        if previous.up is None:
            return motion
        first = previous.returns
        level = level_part(motion, previous.ego, first[rows].mean(axis=0), previous.up)
        return level_icp(
            first[rows],
            level,
            previous.ego,
            frame.target(),
            max_distance=0.2 * self.tau,
            up=previous.up,
        ).motion

    def _confirm_and_end(self, previous, seen):
        """Confirm the tentative tracks seen twice; coast the others, ending those that
        missed too many frames (a tentative one at its first miss)."""
        state = self._state
        alive, confirmed, ended = [], [], set()
        for track in state.tracks:
            if track.key in seen:
                state.last_seen[track.key] = previous.index
                if not track.confirmed and track.hits >= 2:
                    track.identity = self._inherited(track, seen)
                    if track.identity:
                        ended.add(track.heir_of)
                    else:
                        state.n_confirmed += 1
                        track.identity = state.n_confirmed
                    state.identity[track.key] = track.identity
                    confirmed.append(track)
                previous.rows.append(
                    _row(
                        track.key,
                        track.points,
                        track.omega,
                        track.velocity,
                        previous,
                        seen[track.key],
                    )
                )
            else:
                track.coast(previous.time, previous.index)
                if track.misses > (self.max_misses if track.confirmed else 0):
                    continue
            alive.append(track)
        state.tracks = [track for track in alive if track.key not in ended]
        return confirmed

    def _inherited(self, track, seen):
        """The id ``track`` goes on with, or 0: that of the confirmed track it was born
        over when a pair missed that one (:attr:`Track.heir_of`), if that one has not
        been seen since (``seen``: the tracks seen in this pair); that track then ends."""
        old = track.heir_of
        if old < 0 or old in seen or self._seen(old) >= track.first_frame:
            return 0
        return self._identity(old)

    def _extend_back(self, track, latest):
        """A newly confirmed track's points in the frames before its first detection,
        while they are pending: its twist run backwards, claimed as in a forward pair.

        A pair often sees an object move only once it is near; the frames before, still
        within ``lookahead``, get what the track's motion claims there.
        """
        frames = {f.index: f for f in (*self._state.pending, latest)}
        later = frames.get(track.first_frame)
        while later is not None and track.first_frame - 1 in frames:
            frame = frames[track.first_frame - 1]
            seen = later.track_of == track.key
            if frame.track_of is None or seen.sum() < _MIN_EVIDENCE:
                return
            points = transform(later.pose, later.returns[seen])
            dt = later.time - frame.time
            centre = points.mean(axis=0)
            starts, predicted = [], []
            for speed in _SPEEDS:
                # The world motion that brought the object from ``frame`` to ``later``.
                before = centre - track.velocity * dt * speed
                motion = predicted_motion(track.omega, track.velocity, before, dt * speed)
                starts.append(compose(inverse(later.pose), motion, frame.pose))
                predicted.append(transform(inverse(motion), points))
            prediction = transform(inverse(frame.pose), predicted[0])
            first = frame.returns
            free = ~(frame.ground | frame.body) & (frame.track_of < 0)
            near = near_points(first, prediction, _NEAR * self.tau, np.flatnonzero(free))
            tight = near_points(first, prediction, _TIGHT * self.tau, near)
            needed = min(self.min_points, max(_MIN_EVIDENCE, len(points) // 4))
            claim = self._claim(frame, later, frame.ego, frame.scale, near, tight, starts, needed)
            if claim is None or not self._possible(frame, claim.rows, claim.motion, dt):
                return
            frame.track_of[claim.rows] = track.key
            frame.motions[track.key] = claim.motion
            world = compose(later.pose, claim.motion, inverse(frame.pose))
            found = transform(frame.pose, first[claim.rows])
            omega, velocity = twist_of(world, found.mean(axis=0), dt)
            frame.rows.append(_row(track.key, found, omega, velocity, frame, len(claim.rows)))
            track.first_frame -= 1
            later = frame

    def _possible(self, frame, rows, motion, dt):
        """Whether ``motion`` of ``frame``'s points ``rows`` is one a road user can make
        (:mod:`mmreg.sweeps._motion_bounds`: speed and turn with the interval in seconds,
        no level sheet sliding along itself in a z-up sweep)."""
        points = frame.returns[rows]
        labels = np.ones(len(rows), dtype=np.intp)
        rotations = np.stack([frame.ego[:3, :3], motion[:3, :3]])
        translations = np.stack([frame.ego[:3, 3], motion[:3, 3]])
        impossible, _ = impossible_motions(
            points,
            labels,
            (rotations, translations),
            0,
            scale=self.tau,
            reach=np.inf,
            interval=dt if frame.seconds else None,
            up=frame.up,
        )
        return not impossible[1]

    def _result(self, frame, after=None):
        """Frame ``frame``'s final labels, moving flags, flow and table rows.

        A point is a confirmed track's where the pair of which ``frame`` is the first
        sweep gave it to the track, else where the pair before carried the track onto it
        (:meth:`_carry`). ``after`` is the next frame (None for the last one: no flow).
        """
        n_valid = int(frame.valid.sum())

        def ids(keys):
            if keys is None:
                return np.zeros(n_valid, dtype=np.intp)
            keys = np.ravel(keys)
            if not len(keys):
                return np.zeros(0, dtype=np.intp)
            # Track keys are a counter (-1: none): a table over their range names them,
            # without the sort of np.unique (tens of milliseconds at 120k points).
            low = int(keys.min())
            offset = keys - low
            present = np.flatnonzero(np.bincount(offset))
            names = np.zeros(int(present[-1]) + 1, dtype=np.intp)
            names[present] = [self._identity(int(k) + low) for k in present]
            return names[offset]

        # A few points (fewer than the smallest object) on which a track that no pair
        # sees after this frame ends are what it left behind as it went out of view or
        # stopped: the static world's. The last frame has no pair after it.
        ending = after is not None
        own_keys, remnants = self._without_remnants(frame.track_of, frame, ending)
        carried_keys, _ = self._without_remnants(frame.carried, frame, ending)
        own, carried = ids(own_keys), ids(carried_keys)
        if frame.pair_labels is not None:
            valid_labels = np.where(frame.pair_labels >= 0, 0, -1)
        else:
            valid_labels = np.zeros(n_valid, dtype=np.intp)
        valid_labels = np.where(own > 0, own, np.where(carried > 0, carried, valid_labels))
        if frame.body is not None:
            valid_labels[frame.body] = -1
        # Every valid row takes what the row registered for it (itself, or its voxel's).
        rows = frame.covered >= 0
        stand_in = frame.covered[rows]
        labels = np.full(len(frame.points), -1, dtype=np.intp)
        labels[rows] = valid_labels[stand_in]
        body = np.zeros(len(frame.points), dtype=bool)
        if frame.body is not None:
            body[rows] = frame.body[stand_in]
        flow = np.full((len(frame.points), 3), np.nan)
        if after is not None:
            flow[rows] = self._flow(frame, after, own, carried, remnants)[stand_in]
        # One row per track: pieces joined later keep the row with the most points.
        best = {}
        for r in frame.rows:
            if r["key"] in remnants:
                continue
            r["track"] = self._identity(r["key"])
            if r["track"] > 0 and r["points"] > best.get(r["track"], {"points": -1})["points"]:
                best[r["track"]] = r
        rows = list(best.values())
        return Bunch(
            index=frame.index,
            time=frame.time,
            labels=labels,
            moving=labels > 0,
            flow=flow,
            body=body,
            valid=rows,
            pose=frame.pose,
            tracks=self._table(rows),
        )

    def _without_remnants(self, keys, frame, ending):
        """``keys`` (track key per valid row, -1 none) without the tracks that hold fewer
        than ``min_points`` rows and are seen in no frame after ``frame`` (only when
        ``ending``), and those tracks' keys."""
        if keys is None or not ending:
            return keys, set()
        present, counts = np.unique(keys[keys >= 0], return_counts=True)
        gone = {
            int(k)
            for k, n in zip(present, counts, strict=True)
            if n < self.min_points and self._seen(int(k)) <= frame.index
        }
        if not gone:
            return keys, gone
        return np.where(np.isin(keys, list(gone)), -1, keys), gone

    def _flow(self, frame, after, own, carried, remnants=frozenset()):
        """The flow of ``frame``'s valid rows to ``after``: the pair's, a confirmed track's
        own motion on its points (but a track's ``remnants``), and for a track carried
        onto points the pair missed, its last twist (constant velocity)."""
        first = frame.returns
        flow = frame.pair_flow.copy()
        for key, motion in frame.motions.items():
            rows = frame.track_of == key
            # A ghost, never confirmed, moves with the static world; so do remnants.
            confirmed = self._identity(key) > 0 and key not in remnants
            moved = motion if confirmed else frame.ego
            flow[rows] = transform(moved, first[rows]) - first[rows]
        for key, (omega, velocity) in frame.carried_twists.items():
            rows = (frame.carried == key) & (own <= 0) & (carried > 0)
            if not rows.any():
                continue
            world = transform(frame.pose, first[rows])
            dt = after.time - frame.time
            motion = predicted_motion(omega, velocity, world.mean(axis=0), dt)
            moved = compose(inverse(after.pose), motion, frame.pose)
            flow[rows] = transform(moved, first[rows]) - first[rows]
        return flow

    @staticmethod
    def _table(rows):
        """The tracks' table of ``rows`` (dicts), by track and frame."""
        columns = [
            "track", "frame", "time", "x", "y", "z", "length", "width", "height", "yaw",
            "vx", "vy", "vz", "speed", "yaw_rate", "points",
        ]  # fmt: skip
        rows = list(rows)
        table = pd.DataFrame([{c: r[c] for c in columns} for r in rows], columns=columns)
        return table.sort_values(["track", "frame"], ignore_index=True)


@dataclass
class _LogState:
    rng: np.random.RandomState  # the points a track keeps
    tracks: list = field(default_factory=list)
    identity: dict = field(default_factory=dict)
    alias: dict = field(default_factory=dict)  # a joined track's key -> the track it joined
    last_seen: dict = field(default_factory=dict)  # track key -> the last frame it was seen in
    pending: list = field(default_factory=list)
    previous: LogFrame | None = None
    n_frames: int = 0
    next_key: int = 0
    n_confirmed: int = 0

    last_first: LogFrame | None = None  # the last frame that was a pair's first sweep
    recent: list = field(default_factory=list)  # past first sweeps, for the long span
    told: set = field(default_factory=set)  # SensorFrameWarning kinds warned (once a log)


class _Span(NamedTuple):
    """A pair's long span: the frame half a second back, and the ego motion to it."""

    frame: LogFrame
    back: np.ndarray  # 4 x 4, the pair's first sweep to ``frame``
    scale: float  # its residual scale, the pairs' added


def _take_states(states, previous, frame):
    """Keep the sweeps' states that a pair fitted in another process gave back
    (``states``: the first sweep's and the second's): a frame with a state of its own
    takes the surface normals it lacks from the one given."""
    if states is None:
        return
    for sweep, state in zip((previous, frame), states, strict=True):
        if sweep.state is None:
            sweep.state = state
        elif state is not None:
            sweep.state.learn(state)


def _on_evidence(points, rows, shown, still, cell):
    """The ``rows`` but the islands (voxels of side ``cell``) of ``points[rows]`` that
    the ego motion mostly explains (``still``: per row) and whose share of ``shown``
    rows is under ``_PIECE_SHARE`` of the whole's."""
    labels, n = voxel_islands(points[rows], cell)
    held = np.isin(rows, shown)
    sizes = np.bincount(labels, minlength=n)
    share = np.bincount(labels, weights=held, minlength=n) / sizes
    resting = np.bincount(labels, weights=still, minlength=n) / sizes > 0.5
    other = resting & (share < _PIECE_SHARE * held.mean())
    return rows[~other[labels]]


def _slides_along_line(points, motion, ego):
    """Whether ``points`` lie along a line that ``motion`` (4 x 4) slides along itself,
    relative to ``ego`` (4 x 4)."""
    motions = (motion[None, :3, :3], motion[None, :3, 3])
    groups = np.zeros(len(points), dtype=np.intp)
    return bool(slides_along_line(points, groups, 1, motions, (ego[:3, :3], ego[:3, 3]))[0])


def _off_the_ground(frame, rows, shown, margin):
    """``rows`` of ``frame`` but the ground beneath a road user: in a z-up sweep, the
    level points no higher than ``margin`` above its lowest evidence (``shown``, its
    upright points).

    The ground around a walker's feet that the ground segmentation left joins its claim:
    the walker's level motion slides it along itself, and where the walker's shadow hid
    it from the next sweep it reads as evidence too. A car's roof and bonnet are level
    but stand above its lowest evidence.
    """
    if frame.up is None or not len(rows):
        return rows
    level = on_level(frame.target()[2], rows, frame.up)
    upright = np.isin(rows, shown) & ~level
    if not upright.any():
        return rows
    height = frame.returns[rows] @ frame.up
    beneath = level & (height <= height[upright].min() + margin)
    return rows[~beneath]


def _sample(points, rng):
    if len(points) <= _TRACK_POINTS:
        return points
    return points[rng.choice(len(points), _TRACK_POINTS, replace=False)]


def _row(key, points, omega, velocity, frame, n_points):
    """One row of the tracks' table: track ``key`` seen at ``frame`` (world ``points``)."""
    centre = points.mean(axis=0)
    length, width, height, yaw = _box(points)
    return {
        "key": key,
        "frame": frame.index,
        "time": frame.time,
        "x": centre[0],
        "y": centre[1],
        "z": centre[2],
        "length": length,
        "width": width,
        "height": height,
        "yaw": yaw,
        "vx": velocity[0],
        "vy": velocity[1],
        "vz": velocity[2],
        "speed": float(np.linalg.norm(velocity)),
        "yaw_rate": float(omega[2]),
        "points": n_points,
    }
