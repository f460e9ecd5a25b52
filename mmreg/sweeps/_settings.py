"""The settings every stage of a pair's registration reads: lengths, steps, threads."""

from typing import NamedTuple

__all__ = ["PairSettings"]

# ICP has converged when no step moves a cluster by more than this share of max_distance.
_TOL = 1e-4


class PairSettings(NamedTuple):
    """What the stages of :func:`mmreg.sweeps._pair.register_pair` read.

    Lengths are in the points' units (``SweepRegistration`` derives its ``"auto"`` ones
    from ``tau``).
    """

    tau: float  # the estimator's length scale (5 stands for metres)
    max_distance: float  # an ICP matches a point within this distance
    island_radius: float  # side of the islands' voxels
    min_island_size: int  # smaller islands take the ego motion
    max_displacement: float  # the reach of the islands' motions (grown by the ego step)
    auto_reach: bool  # whether max_displacement is a guess ("auto") or a bound
    widen: bool  # whether islands nothing within a guessed reach explains search farther
    max_icp_iter: int  # Gauss-Newton steps of every ICP
    max_points: int | None  # points per cluster of an ICP
    max_rounds: int  # rounds of estimator and ICP
    ground: str  # "auto", "keep" or "drop"
    workers: int  # threads of the k-d tree queries
    interval: float | None = None  # seconds between the sweeps, when known

    @property
    def tol(self):
        """An ICP's convergence test: a step shorter than this."""
        return _TOL * self.max_distance
