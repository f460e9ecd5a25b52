"""Registration estimators: the paper's Classification-EM and what they all share."""

from mmreg.estimators._base import BaseRegistration, DegenerateInputWarning
from mmreg.estimators._em import EMResult, multi_model_em
from mmreg.estimators._multi_model_registration import MultiModelRegistration

__all__ = [
    "BaseRegistration",
    "DegenerateInputWarning",
    "EMResult",
    "MultiModelRegistration",
    "multi_model_em",
]
