"""mmreg: multi-model 3D registration by Classification-EM (Jin et al., ICRA 2024).

Subpackages: :mod:`mmreg.estimators` (the EM), :mod:`mmreg.init` (initial clusterings),
:mod:`mmreg.baselines` (Naive, Sequential RANSAC, T-Linkage), :mod:`mmreg.metrics` (the
paper's measures and scorers), :mod:`mmreg.theory` (Definitions 1-2 as checks) and
:mod:`mmreg.datasets` (synthetic scenes).
"""

from mmreg.baselines import NaiveRegistration, SequentialRANSAC, TLinkage
from mmreg.estimators import MultiModelRegistration

__version__ = "0.1.0"

__all__ = [
    "MultiModelRegistration",
    "NaiveRegistration",
    "SequentialRANSAC",
    "TLinkage",
    "__version__",
]
