"""Theorem 1 of Jin et al. (ICRA 2024) as executable checks.

Theorem 1: if the correspondences satisfy Definition 1 (ground truth) and the initial
clusters are ``(tau, alpha, m0)``-good (Definition 2), Algorithm 1 returns a partition
that contains every ground-truth object. :func:`satisfies_ground_truth` and
:func:`is_good_clustering` check the two hypotheses on data and report which condition
fails and why; :func:`is_tau_connected` and :func:`tau_components` are the connectivity
notion both rest on.
"""

from mmreg._array.connectivity import tau_components
from mmreg.theory._definitions import (
    is_good_clustering,
    is_tau_connected,
    satisfies_ground_truth,
)
from mmreg.theory._reports import Condition, GoodClusteringReport, GroundTruthReport

__all__ = [
    "Condition",
    "GoodClusteringReport",
    "GroundTruthReport",
    "is_good_clustering",
    "is_tau_connected",
    "satisfies_ground_truth",
    "tau_components",
]
