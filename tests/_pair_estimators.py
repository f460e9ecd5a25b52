"""Pair estimators for the tests of a log whose pairs run in another process: importable
there (a test module's own classes would import the test module with them)."""

import os
import warnings

from sklearn.base import BaseEstimator

from mmreg import SweepRegistration


class Pairs(BaseEstimator):
    """SweepRegistration that says something of every pair: ``warns`` a warning naming the
    pair's sizes, ``fails`` a ValueError on the pair whose first sweep has that many
    points, ``dies`` an exit of its process there (code 3)."""

    def __init__(self, warns=False, fails=None, dies=None, random_state=None):
        self.warns = warns
        self.fails = fails
        self.dies = dies
        self.random_state = random_state

    def fit(self, points, *, sweep, **kwargs):
        if len(points) == self.fails:
            raise ValueError(f"a pair of {len(points)} points refused")
        if len(points) == self.dies:
            os._exit(3)
        if self.warns:
            warnings.warn(
                f"pair of {len(points)} and {len(sweep)} points", UserWarning, stacklevel=2
            )
        est = SweepRegistration(random_state=self.random_state).fit(points, sweep=sweep, **kwargs)
        for name, value in vars(est).items():
            if name.endswith("_") and not name.startswith("_"):
                setattr(self, name, value)
        return self

    def sweep_state(self, points):
        return SweepRegistration().sweep_state(points)


class HereOnly(Pairs):
    """:class:`Pairs` that cannot be rebuilt in another process (as a class of a user's
    session may not be)."""

    def __reduce__(self):
        return (_rebuild_in, (os.getpid(), self.get_params()))


def _rebuild_in(pid, params):
    if os.getpid() != pid:
        raise ImportError("this pair estimator is not importable here")
    return HereOnly(**params)
