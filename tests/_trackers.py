"""A log's tracker with no pair estimator, for tests of its steps on points they build."""

import numpy as np

from mmreg.tracking._log import LogTracker


def bare_tracker(tau):
    """A :class:`LogTracker` at length scale ``tau`` that registers no pair."""
    return LogTracker(
        None,
        tau=tau,
        lookahead=0,
        max_misses=3,
        frame_rate=None,
        min_points=10,
        rng=np.random.RandomState(0),
    )
