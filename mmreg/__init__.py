"""mmreg: multi-model 3D registration by Classification-EM (Jin et al., ICRA 2024)."""

from mmreg.estimators import MultiModelRegistration

__version__ = "0.1.0"

__all__ = ["MultiModelRegistration", "__version__"]
