"""mmreg: multi-model 3D registration by Classification-EM (Jin et al., ICRA 2024).

Subpackages: :mod:`mmreg.estimators` (the EM), :mod:`mmreg.init` (initial clusterings),
:mod:`mmreg.baselines` (Naive, Sequential RANSAC, T-Linkage), :mod:`mmreg.metrics` (the
paper's measures and scorers), :mod:`mmreg.theory` (Definitions 1-2 as checks) and
:mod:`mmreg.datasets` (synthetic scenes).

The estimators are imported on first use (PEP 562), so that ``mmreg --help`` does not pay
for scikit-learn, SciPy and pandas.
"""

import importlib

__version__ = "0.1.0"

_LAZY = {
    "MultiModelRegistration": "mmreg.estimators",
    "NaiveRegistration": "mmreg.baselines",
    "SequentialRANSAC": "mmreg.baselines",
    "SequenceRegistration": "mmreg.estimators",
    "SweepRegistration": "mmreg.estimators",
    "TLinkage": "mmreg.baselines",
}

__all__ = [*_LAZY, "__version__"]


def __getattr__(name):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'mmreg' has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
