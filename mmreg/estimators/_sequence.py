"""A whole LiDAR log in, tracks out: every moving object carried from sweep to sweep.

:class:`SequenceRegistration` registers each pair of consecutive sweeps with a pair
estimator (:class:`~mmreg.SweepRegistration` by default), starting its ego motion from the
last one (constant velocity, as KISS-ICP does), and keeps the moving objects as tracks in
the world frame. A track lives inside the registration: its predicted motion is tested
point by point against the static world's in the next pair, so an object that pair alone
misses is still found, and a motion that no second pair confirms (a ghost) is never
reported. The steps are :class:`mmreg.tracking._log.LogTracker`'s; this module is the
scikit-learn estimator around them.
"""

from numbers import Integral, Real

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator, clone
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import HasMethods, Interval

from mmreg._array.neighbors import query_workers
from mmreg._validation import ROTATION_TOLERANCE, are_rotations, invalid_points
from mmreg._warnings import warn
from mmreg.estimators._multi_model_registration import ScaleWarning, warn_if_tau_off_scale
from mmreg.sweeps._sensor_frame import SensorFrameWarning
from mmreg.tracking._log import LogTracker
from mmreg.tracking._pair_process import PairsAhead

__all__ = ["SequenceRegistration"]

# The default pair estimator keeps its islands' clusters: the tracks' claims re-assign the
# points one by one, and the multi-model estimator changed no label of the shared logs.
_PAIR_ESTIMATOR = "passthrough"
# Gauss-Newton steps of the default pair estimator's ICPs (SweepRegistration's own: 30).
_PAIR_ICP_ITER = 15
# The default pair estimator's islands search once, within the reach (see
# SweepRegistration's widen_reach).
_PAIR_WIDEN_REACH = False
# The default pair estimator's smallest island (SweepRegistration's min_island_size).
_MIN_ISLAND_SIZE = 12
# A LiDAR log's frames come 2-20 times a second. Frames this many seconds apart or more
# leave nothing to track (a car drives 100 m or more between them): such times
# are milliseconds or finer, most likely.
_MAX_FRAME_INTERVAL = 10.0


class SequenceRegistration(BaseEstimator):
    """Moving objects of a LiDAR log, tracked from sweep to sweep.

    Each pair of consecutive sweeps is registered by ``pair_estimator`` (the ego motion
    started from the last pair's, or from the poses given), and its moving clusters are
    detections of tracks in the world frame. A track is predicted by a constant twist
    (velocity and turn rate), associated with the detections that cover its prediction,
    and tested point by point against the static world in every pair: the points near
    its prediction that its motion explains on the next sweep and the ego motion does
    not are its own, even where the pair left them in the static world. Where no pair
    saw a motion, the places an object left and reached (points each sweep leaves
    unexplained in the other) start a track, if a motion between them explains them
    (:mod:`mmreg.tracking._births`). A track is confirmed once its motion holds into a
    second pair; only confirmed tracks label
    points, so a motion seen in one pair only is never reported. A confirmed track
    coasts through up to ``max_misses`` frames without evidence (an occlusion) and keeps
    its id.

    Parameters
    ----------
    pair_estimator : estimator or None, default=None
        Registers two raw sweeps: ``fit(points1, sweep=points2, ego_motion=(R, t))`` with
        ``labels_``, ``moving_``, ``static_cluster_``, ``rotations_``, ``translations_``,
        ``flow_`` and ``ego_motion_``; cloned for every pair, and seeded from
        ``random_state`` when its own is None. None:
        ``SweepRegistration("passthrough", tau=tau, max_icp_iter=15, widen_reach=False)``:
        in a log the ego motion starts from the last one and the tracks refine their own
        motions (half the ICP steps gave the same figures on the shared nuScenes and
        generated logs in 10-25 % less time), a mover beyond the islands' reach is found
        from the places it leaves and reaches (the wider search found nothing more), and
        the tracks' claims re-assign the points one by one (without the multi-model
        estimator the shared logs' labels are the same, in 11-14 % less time).
    tau : float, default=5.0
        The one length, in the points' units (5 for metres): the tracks' and the default
        pair estimator's (a ``pair_estimator`` given keeps its own).
    lookahead : int, default=2
        Frames after frame ``k`` whose pairs may still change its labels: a track born
        in frame ``k`` is confirmed in frame ``k + 1``, and once confirmed it claims the
        object in the frames before its birth that are still this recent (its motion run
        backwards). ``partial_fit`` gives frame ``k``'s result once frame
        ``k + lookahead + 1`` is in; 0 labels each frame by its own pair and the past.
    max_misses : int, default=3
        Frames a confirmed track coasts on its prediction without evidence.
    frame_rate : float or None, default=None
        Frames per second, for velocities in units per second when ``times`` are not
        given; None: velocities per frame.
    voxel_size : float or None, default=None
        Register one point of each voxel of this side (in the points' units), as
        KISS-ICP thins its frames; every point takes the labels and flow of its voxel's.
        None: every point. Measured with 0.1 (metres): a generated 64-beam 10 Hz log
        (113k points a frame) takes a third less time and loses a few objects (moving
        IoU 0.92 -> 0.90, object-frames found 79 -> 72 of 97); on the nuScenes logs
        (32 beams, 2 Hz) it loses many (scene-0004's IoU 0.76 -> 0.59). A dense sensor's
        trade, not a default.
    n_jobs : int or None, default=None
        Processes: with 2 or more (-1: every core, if there are two), the pairs are
        registered in a process of their own, ahead of the tracks, which run in this one.
        The results are the same, in 0.6-0.8 of the time on two cores; online,
        each frame's result comes one frame later. None: one (scikit-learn's
        convention).
    random_state : int, RandomState instance or None, default=None
        Seeds two streams: one seeds the pairs' estimators, the other draws the points
        a track keeps (so that what a track keeps does not change the pairs' draws).

    Attributes
    ----------
    labels_ : list of ndarray
        Per frame, per point: 0 the static world, ``k >= 1`` a track (the same object in
        every frame), -1 outliers, the ego vehicle's body and invalid returns.
    moving_ : list of ndarray of bool
        Per frame, per point: whether it belongs to a moving track.
    flows_ : list of ndarray
        Per frame, per point: its motion to the next frame (NaN in the last frame and
        for invalid returns).
    ego_body_masks_ : list of ndarray of bool
        Per frame, per point: returns from the ego vehicle's own body (labelled -1).
    ego_poses_ : ndarray of shape (n_frames, 4, 4)
        The sensor's pose in each frame (world from sensor), the first the identity or
        the first pose given.
    tracks_ : pandas.DataFrame
        One row per confirmed track and frame it is seen in: ``track``, ``frame``,
        ``time``, centroid ``x, y, z`` (world), box ``length, width, height, yaw``,
        velocity ``vx, vy, vz``, ``speed``, ``yaw_rate`` and ``points``.
    n_frames_ : int
    n_tracks_ : int
        Confirmed tracks.

    See Also
    --------
    mmreg.SweepRegistration : The pair estimator.
    mmreg.metrics.moving_iou, mmreg.metrics.tracking_scores : What to score a log with.

    Notes
    -----
    The steps of a frame are described in ``docs/algorithm.md`` ("A whole log"). Each
    frame costs a pair's registration and the tracks' steps (about two thirds of that
    again); with ``n_jobs=2`` the two run side by side. Memory is the tracks,
    ``lookahead + 2`` frames and, with times in seconds, those of the last half second
    (whose comparison finds walkers too slow for their pairs).

    Examples
    --------
    Five frames of a generated street at 10 Hz with cars at 8 m/s; one is seen moving
    in every frame:

    >>> from mmreg import SequenceRegistration
    >>> from mmreg.datasets import make_lidar_sequence
    >>> log = make_lidar_sequence(5, n_moving=2, n_braking=0, n_overtaking=0, n_walkers=0,
    ...                           n_cyclists=0, n_standing=0, car_speed=8.0, n_azimuths=512,
    ...                           random_state=1)
    >>> est = SequenceRegistration(random_state=0).fit(log.frames, times=log.times)
    >>> est.n_tracks_, round(float(est.tracks_["speed"].median()))
    (1, 8)
    """

    _parameter_constraints: dict = {
        "pair_estimator": [HasMethods(["fit"]), None],
        "tau": [Interval(Real, 0, None, closed="neither")],
        "lookahead": [Interval(Integral, 0, None, closed="left")],
        "max_misses": [Interval(Integral, 0, None, closed="left")],
        "frame_rate": [Interval(Real, 0, None, closed="neither"), None],
        "voxel_size": [Interval(Real, 0, None, closed="neither"), None],
        "n_jobs": [Integral, None],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        pair_estimator=None,
        *,
        tau=5.0,
        lookahead=2,
        max_misses=3,
        frame_rate=None,
        voxel_size=None,
        n_jobs=None,
        random_state=None,
    ):
        self.pair_estimator = pair_estimator
        self.tau = tau
        self.lookahead = lookahead
        self.max_misses = max_misses
        self.frame_rate = frame_rate
        self.voxel_size = voxel_size
        self.n_jobs = n_jobs
        self.random_state = random_state

    def fit(self, frames, y=None, *, times=None, poses=None, point_times=None):
        """Register a whole log.

        Parameters
        ----------
        frames : sequence of array-like of shape (n_k, 3)
            The sweeps in order, each in its sensor's frame, or a sequence from
            :func:`mmreg.datasets.open_sequence` (whose frames' timestamps and points'
            capture times are used where ``times`` and ``point_times`` are None).
        y : Ignored
        times : array-like of shape (n_frames,) or None
            Each frame's time in seconds.
        poses : array-like of shape (n_frames, 4, 4) or None
            Known sensor poses (odometry): the ego motions start from them.
        point_times : sequence of array-like of shape (n_k,) or None
            Each point's capture time, seconds after its frame's time (Argoverse 2's
            ``offset_ns * 1e-9``, a bag's ``t`` field): the pairs deskew the moving
            objects with them (see :class:`~mmreg.SweepRegistration`). Needs ``times``.

        Returns
        -------
        self

        Warns
        -----
        ScaleWarning
            Where ``tau`` does not fit the first frame's points, or the times (or
            ``frame_rate``) put the frames 10 s or more apart: other units than the
            points' and seconds, most likely.
        SensorFrameWarning
            Where a frame is not in its sensor's frame: the origin far outside it (a
            map's or world frame; asked of every frame), or the first frame with
            another axis than z up. Once a log.
        """
        self._validate_params()
        n = len(frames)
        if n < 2:
            raise ValueError(f"a log needs at least 2 frames; got {n}.")
        if times is None and all(getattr(f, "timestamp", None) is not None for f in frames):
            times = [f.timestamp for f in frames]
        times = self._check_times(times, n)
        poses = self._check_poses(poses, n)
        if times is not None:
            _warn_if_not_seconds(np.diff(times))
        else:
            _warn_if_period(self.frame_rate)
        if point_times is None and all(getattr(f, "times", None) is not None for f in frames):
            point_times = [f.times for f in frames]
        if point_times is not None and (times is None or len(point_times) != n):
            raise ValueError(
                "point_times goes with times: one array of capture times per frame, and "
                "each frame's time in seconds."
            )
        # A log of two frames is one pair: nothing to run beside the tracks.
        self._reset(processes=query_workers(self.n_jobs) if n > 2 else 1)
        run = self._run
        del self._run  # a later partial_fit starts a log of its own
        try:
            results = []
            for k in range(n):
                frame = frames[k]
                points = getattr(frame, "points", frame)
                if k == 0:
                    _warn_if_off_scale(points, self.tau)
                results += run.add(
                    points,
                    None if times is None else times[k],
                    None if poses is None else poses[k],
                    None if point_times is None else point_times[k],
                )
            results += run.close()
        finally:
            run.end()
        self.finished_ = []
        self.labels_ = [r.labels for r in results]
        self.moving_ = [r.moving for r in results]
        self.flows_ = [r.flow for r in results]
        self.ego_body_masks_ = [r.body for r in results]
        self.ego_poses_ = np.stack([r.pose for r in results])
        tables = [r.tracks for r in results if len(r.tracks)]
        self.tracks_ = (
            pd.concat(tables, ignore_index=True).sort_values(["track", "frame"], ignore_index=True)
            if tables
            else LogTracker._table([])
        )
        self.n_frames_ = n
        self.n_tracks_ = int(self.tracks_["track"].nunique()) if len(self.tracks_) else 0
        return self

    def partial_fit(self, points, y=None, *, time=None, pose=None, point_times=None):
        """Add the next frame of a log, causally, in bounded memory.

        Frame ``k``'s result is final once frame ``k + lookahead + 1`` is in: each call
        puts the frames it makes final in ``finished_`` (a list, usually of one, of
        Bunches with ``index``, ``time``, ``labels``, ``moving``, ``flow``, ``body``,
        ``valid``, ``pose`` and ``tracks``, as ``fit`` stores them), and
        :meth:`finish` ends the log. With ``n_jobs`` of 2 or more, once the pairs run in
        their own process, frame ``k``'s result comes a frame later still, with frame
        ``k + lookahead + 2``. Only the tracks, the last ``lookahead + 2`` frames
        and those of the last half second (at most 10) are kept, so a log of any length
        takes the memory of a few frames.

        Parameters
        ----------
        points : array-like of shape (n, 3)
            The next sweep, in its sensor's frame.
        y : Ignored
        time : float or None
            Its time in seconds (None: ``frame_rate``, else its index).
        pose : array-like of shape (4, 4) or None
            Its known sensor pose (odometry), from which its ego motion starts.
        point_times : array-like of shape (n,) or None
            Each point's capture time, seconds after ``time`` (see :meth:`fit`).

        Returns
        -------
        self
        """
        if not hasattr(self, "_run"):
            self._validate_params()
            _warn_if_off_scale(points, self.tau)
            if time is None:
                _warn_if_period(self.frame_rate)
            self._reset(processes=query_workers(self.n_jobs))
        elif self._run.n_frames and (time is None) != (self._first_time is None):
            raise ValueError(
                f"frame {self._run.n_frames} has {'no time' if time is None else 'a time'} "
                f"and frame 0 {'had one' if time is None else 'had none'}: give every "
                "frame of a log its time, or none (frame_rate then times them)."
            )
        elif self._run.n_frames == 1 and time is not None:
            _warn_if_not_seconds([time - self._first_time])
        if pose is not None:
            pose = self._check_poses(np.asarray(pose, dtype=float)[None], 1)[0]
        if point_times is not None and time is None:
            raise ValueError("point_times goes with time: the frame's time in seconds.")
        if self._run.n_frames == 0:
            self._first_time = time
        self.finished_ = self._run.add(points, time, pose, point_times)
        return self

    def finish(self):
        """End an online log: ``finished_`` holds the frames still pending, the last one
        included (its labels carried from the frame before, its flow NaN), and the next
        :meth:`partial_fit` starts a new log."""
        if not hasattr(self, "_run"):
            raise ValueError("finish() ends a log that partial_fit() started; none was.")
        run = self._run
        del self._run
        self.finished_ = run.close()
        return self

    def _reset(self, processes):
        tracker = LogTracker(
            _PairMaker(self.pair_estimator, self.tau),
            tau=self.tau,
            lookahead=self.lookahead,
            max_misses=self.max_misses,
            frame_rate=self.frame_rate,
            min_points=self._min_points(),
            rng=check_random_state(self.random_state),
            voxel_size=self.voxel_size,
        )
        self._run = PairsAhead(tracker, processes)
        self.finished_ = []

    def _check_times(self, times, n):
        if times is None:
            return None
        given = np.asarray(times)
        times = given.astype(float)
        if times.shape != (n,) or not np.all(np.isfinite(times)):
            raise ValueError(f"times must be {n} finite numbers, one per frame.")
        if np.any(np.diff(times) <= 0):
            lost = ""
            if given.dtype == np.float32 and np.any(np.diff(times) == 0):
                # Epoch seconds (1.7e9) in float32 keep 128 s steps: every frame's time
                # rounds to the same few values.
                step = float(np.spacing(np.float32(np.max(np.abs(times)))))
                lost = (
                    f" They are float32, which holds times of {np.max(np.abs(times)):.3g} "
                    f"only to {step:g} s: pass them as float64 (or seconds from the log's "
                    "start)."
                )
            raise ValueError("times must increase from frame to frame." + lost)
        return times

    def _check_poses(self, poses, n):
        if poses is None:
            return None
        poses = np.asarray(poses, dtype=float)
        if poses.shape != (n, 4, 4) or not np.all(np.isfinite(poses)):
            raise ValueError(f"poses must have shape ({n}, 4, 4) and be finite.")
        # A pose is rigid: a rotation (to the pairs' tolerance) and a last row 0 0 0 1.
        rigid = are_rotations(poses[:, :3, :3]) & np.all(
            np.abs(poses[:, 3] - [0.0, 0.0, 0.0, 1.0]) <= ROTATION_TOLERANCE, axis=1
        )
        if not rigid.all():
            k = int(np.flatnonzero(~rigid)[0])
            raise ValueError(
                f"poses[{k}] is not a rigid motion (a rotation, R^T R = I and det R = 1 "
                f"within {ROTATION_TOLERANCE:g}, and a last row 0 0 0 1); got "
                f"{np.array2string(poses[k], precision=4, separator=', ')}. poses are the "
                "sensor's poses, world from sensor, as 4 x 4 matrices."
            )
        return poses

    def _min_points(self):
        """The pair estimator's smallest island: the most evidence a track needs."""
        estimator = self.pair_estimator
        if estimator is not None:
            value = estimator.get_params(deep=False).get("min_island_size")
            if isinstance(value, Integral):
                return int(value)
        return _MIN_ISLAND_SIZE


def _warn_if_off_scale(points, tau):
    """A :class:`~mmreg.estimators.ScaleWarning` where ``tau`` does not fit a log's first
    frame (its valid returns; :func:`~mmreg.estimators._multi_model_registration.
    warn_if_tau_off_scale`)."""
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] < 3:
        return  # the frame's own check names the problem
    points = points[:, :3]
    points = points[~invalid_points(points)]
    if len(points) >= 2:
        warn_if_tau_off_scale(points, tau, "the first frame")


def _warn_if_not_seconds(intervals):
    """A :class:`~mmreg.estimators.ScaleWarning` where frames come
    ``_MAX_FRAME_INTERVAL`` or more apart by their times (the median of ``intervals``): the
    times are milliseconds or finer, most likely, and the velocities and the
    half-second spans would be read in the wrong units."""
    interval = float(np.median(intervals))
    if interval >= _MAX_FRAME_INTERVAL:
        warn(
            f"the frames' times are {interval:.3g} apart, frame to frame: times are in "
            "seconds, and a log's frames come a fraction of a second apart. Are they "
            "milliseconds (times * 1e-3) or nanoseconds (times * 1e-9)? Velocities "
            "(tracks_) and the half-second spans follow the times.",
            ScaleWarning,
        )


def _warn_if_period(frame_rate):
    """A :class:`~mmreg.estimators.ScaleWarning` where ``frame_rate`` puts the frames
    ``_MAX_FRAME_INTERVAL`` seconds or more apart: the seconds between frames given for
    the frames per second, most likely (0.1 for a 10 Hz sensor)."""
    if frame_rate is not None and 1.0 / frame_rate >= _MAX_FRAME_INTERVAL:
        warn(
            f"frame_rate={frame_rate:g} puts the frames {1.0 / frame_rate:.3g} s apart: "
            f"frame_rate is frames per second ({1.0 / frame_rate:.3g} for frames "
            f"{frame_rate:g} s apart), and velocities (tracks_) and the half-second spans "
            "follow it.",
            ScaleWarning,
        )


class _PairMaker:
    """Makes each pair's estimator: ``pair_estimator`` cloned (seeded with the pair's
    seed where its ``random_state`` is None), or the default one at ``tau``. Picklable,
    for a log whose pairs run in another process."""

    def __init__(self, pair_estimator, tau):
        self.pair_estimator = pair_estimator
        self.tau = tau
        # The warnings its pairs need not repeat: the log checks its frames' sensor frame
        # and the default pairs' tau, its own, once.
        self.quiet = (ScaleWarning, SensorFrameWarning)
        if pair_estimator is not None:  # it may have another tau
            self.quiet = (SensorFrameWarning,)

    def __call__(self, seed):
        if self.pair_estimator is None:
            return default_pair_estimator(tau=self.tau, random_state=seed)
        estimator = clone(self.pair_estimator)
        if estimator.get_params(deep=False).get("random_state", 0) is None:
            estimator.set_params(random_state=seed)
        return estimator


def default_pair_estimator(**params):
    """The pair estimator a log's pairs get by default: ``SweepRegistration`` with 15 ICP
    steps, searching once within the reach, keeping the islands' clusters (see
    ``pair_estimator``), and ``params``."""
    from mmreg.estimators._two_sweeps import SweepRegistration

    defaults = {
        "estimator": _PAIR_ESTIMATOR,
        "max_icp_iter": _PAIR_ICP_ITER,
        "widen_reach": _PAIR_WIDEN_REACH,
    }
    return SweepRegistration(**{**defaults, **params})
