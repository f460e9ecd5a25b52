"""The paper's baselines (Section V-A), with the interface of MultiModelRegistration."""

from mmreg.baselines._naive import NaiveRegistration
from mmreg.baselines._sequential_ransac import SequentialRANSAC, sequential_ransac
from mmreg.baselines._t_linkage import TLinkage, t_linkage

__all__ = [
    "NaiveRegistration",
    "SequentialRANSAC",
    "TLinkage",
    "sequential_ransac",
    "t_linkage",
]
