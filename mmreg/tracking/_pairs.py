"""A log's pairs of consecutive sweeps, registered one after another.

:class:`PairChain` is step 1 of :class:`mmreg.tracking._log.LogTracker`: it registers the
pair of frames ``k`` and ``k + 1`` with the pair estimator and gives the tracks what they
read of it (:class:`PairFit`). What a pair needs of the pairs before it is the chain's
own: the last ego motion (the next one's start, constant velocity), the ego vehicle's
body found in the last sweep, whether the log's sensor sees a body at all, and the seeds.
It needs nothing of the tracks, so a log's pairs can run ahead of its tracks, in a
process of their own (:mod:`mmreg.tracking._pair_process`), and give the same fits.
"""

import inspect
import warnings
from dataclasses import dataclass, field

import numpy as np

from mmreg.sweeps._ego_body import carried_body, would_show_body
from mmreg.tracking._motion import compose, inverse, predicted_motion, to_matrix, twist_of

__all__ = ["FEWEST_POINTS", "PairChain", "PairFit"]

# A sweep with fewer valid points is not registered (SweepRegistration needs 10).
FEWEST_POINTS = 10
# A log whose sensor sees no body of its own: this many pairs in a row that would have
# shown one (they moved enough, would_show_body) showed none; later pairs look no more.
BODILESS_PAIRS = 2


@dataclass
class PairFit:
    """What the tracks read of one pair's fit.

    A gap (a sweep too sparse to register) has only ``ego`` (predicted), ``body`` and
    ``sweep_body``.
    """

    ego: np.ndarray  # 4 x 4, first sweep to second
    body: np.ndarray  # the first sweep's rows on the ego vehicle's body
    sweep_body: np.ndarray  # the second sweep's
    gap: bool = False
    labels: np.ndarray | None = None  # the pair's labels of the first sweep's rows
    flow: np.ndarray | None = None
    ground: np.ndarray | None = None  # the first sweep's ground
    sweep_ground: np.ndarray | None = None  # the second sweep's
    scale: float = np.nan  # the ego ICP's robust residual scale (NaN: none given)
    detections: dict = field(default_factory=dict)  # moving cluster -> (rows, 4 x 4 motion)
    # Where the pair ran in another process: the two sweeps' states as it left them, and
    # the warnings it raised (message, category), for this process to give the user.
    states: tuple | None = None
    warnings: list = field(default_factory=list)


class PairChain:
    """Registers a log's consecutive pairs in order (see the module's docstring).

    Parameters
    ----------
    make_pair : callable
        ``make_pair(seed)`` returns a fresh pair estimator (``fit(points1, sweep=points2,
        ...)``, as :class:`~mmreg.SweepRegistration`); picklable, for a chain that runs in
        another process.
    tau : float
        The one length (5 for metres).
    rng : numpy.random.RandomState
        Draws each pair's seed.
    """

    def __init__(self, make_pair, *, tau, rng):
        self.make_pair = make_pair
        self.tau = tau
        self.rng = rng
        self.last_ego = None  # (4 x 4 motion, its interval) of the last pair registered
        self.last_body = None  # the ego body's rows of the last pair's second sweep
        self.bodiless = 0  # pairs in a row that would have shown the ego body and showed none

    def ego_start(self, previous, frame):
        """The ego motion's start: the poses given, else the last ego motion (constant
        velocity), scaled to this interval; None for the first pair."""
        if previous.given_pose is not None and frame.given_pose is not None:
            return compose(inverse(frame.given_pose), previous.given_pose)
        if self.last_ego is None:
            return None
        motion, dt = self.last_ego
        ratio = (frame.time - previous.time) / dt
        omega, velocity = twist_of(motion, np.zeros(3), 1.0)
        return predicted_motion(omega, velocity, np.zeros(3), ratio)

    def fit(self, previous, frame):
        """The :class:`PairFit` of the sweeps ``previous`` and ``frame`` (LogFrames), the
        pair after the last one fitted; each sweep's state is kept on its frame."""
        body = self.last_body
        if min(len(previous.returns), len(frame.returns)) < FEWEST_POINTS:
            start = self.ego_start(previous, frame)
            self.last_body = np.zeros(len(frame.returns), dtype=bool)
            return PairFit(
                ego=np.eye(4) if start is None else start,
                body=np.zeros(len(previous.returns), bool) if body is None else body,
                sweep_body=self.last_body,
                gap=True,
            )
        dt = frame.time - previous.time
        start = self.ego_start(previous, frame)
        first, second = previous.returns, frame.returns
        estimator = self.make_pair(self.rng.randint(2**31 - 1))
        kwargs = {} if start is None else {"ego_motion": (start[:3, :3], start[:3, 3])}
        parameters = _fit_parameters(estimator)
        if frame.seconds and "interval" in parameters:
            kwargs["interval"] = dt  # bounds the objects' motions by what road users do
        # With capture times (any offset at all) the pair deskews the moving objects.
        timed = (
            frame.seconds
            and "times" in parameters
            and previous.point_times is not None
            and frame.point_times is not None
            and (np.any(previous.point_times != 0) or np.any(frame.point_times != 0))
        )
        if timed:
            kwargs.update(times=previous.point_times, sweep_times=frame.point_times)
        if "states" in parameters and hasattr(estimator, "sweep_state"):
            # Each sweep's ground, trees, normals and islands are computed once, for
            # both pairs it is in.
            for sweep in (previous, frame):
                if sweep.state is None:
                    sweep.state = estimator.sweep_state(sweep.returns)
            kwargs["states"] = (previous.state, frame.state)
        if "ego_body" in parameters and body is not None and body.any():
            # The ego vehicle's body is fixed in the sensor's frame: found once, it is
            # the next sweep's points where the last sweep's body points were.
            kwargs["ego_body"] = (body, carried_body(first[body], second, self.tau))
        elif "ego_body" in parameters and self.bodiless >= BODILESS_PAIRS:
            # ... and where pairs that would have shown it showed none, there is none.
            kwargs["ego_body"] = (np.zeros(len(first), bool), np.zeros(len(second), bool))
        with warnings.catch_warnings():
            # Those the log says once itself (make_pair's ``quiet`` categories).
            for category in getattr(self.make_pair, "quiet", ()):
                warnings.simplefilter("ignore", category)
            pair = estimator.fit(first, sweep=second, **kwargs)
        ego = to_matrix(*pair.ego_motion_)
        self.last_ego = (ego, dt)
        body = _mask(getattr(pair, "ego_body_mask_", None), len(first))
        self.last_body = _mask(getattr(pair, "sweep_ego_body_mask_", None), len(second))
        if body.any():
            self.bodiless = 0
        elif would_show_body(pair.ego_motion_, self.tau):
            self.bodiless += 1
        labels = np.asarray(pair.labels_)
        static = int(pair.static_cluster_)
        detections = {
            j: (
                np.flatnonzero(labels == j),
                to_matrix(pair.rotations_[j], pair.translations_[j]),
            )
            for j in np.flatnonzero(np.asarray(pair.moving_, dtype=bool))
            if j != static and np.any(labels == j)
        }
        return PairFit(
            ego=ego,
            body=body,
            sweep_body=self.last_body,
            labels=labels,
            flow=np.asarray(pair.flow_),
            ground=_mask(getattr(pair, "ground_mask_", None), len(first)),
            sweep_ground=_mask(getattr(pair, "sweep_ground_mask_", None), len(second)),
            scale=float(getattr(pair, "ego_scale_", np.nan)),
            detections=detections,
        )

    def fit_apart(self, previous, frame):
        """:meth:`fit` as a process of its own runs it: the sweeps' states and the
        warnings raised go with the fit."""
        with warnings.catch_warnings(record=True) as raised:
            warnings.simplefilter("always")
            fit = self.fit(previous, frame)
        fit.states = (previous.state, frame.state)
        fit.warnings = [(str(w.message), w.category) for w in raised]
        return fit


def _fit_parameters(estimator):
    """The keyword parameters of ``estimator.fit`` (everything, for ``**kwargs``)."""
    parameters = inspect.signature(estimator.fit).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values()):
        return _Anything()
    return set(parameters)


class _Anything:
    """Contains every name: the parameters of a ``fit(**kwargs)``."""

    def __contains__(self, name):
        return True


def _mask(values, n):
    return np.zeros(n, dtype=bool) if values is None else np.asarray(values, dtype=bool)
