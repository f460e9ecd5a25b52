"""Registration estimators: the robust default, the paper's Algorithm 1, and what they share."""

from mmreg.em._paper import EMResult, multi_model_em
from mmreg.em._robust import RobustEMResult, robust_multi_model_em
from mmreg.estimators._base import BaseRegistration, DegenerateInputWarning
from mmreg.estimators._multi_model_registration import MultiModelRegistration, ScaleWarning
from mmreg.estimators._sequence import SequenceRegistration
from mmreg.estimators._two_sweeps import SweepRegistration
from mmreg.sweeps._sensor_frame import SensorFrameWarning

__all__ = [
    "BaseRegistration",
    "DegenerateInputWarning",
    "EMResult",
    "MultiModelRegistration",
    "RobustEMResult",
    "ScaleWarning",
    "SensorFrameWarning",
    "SequenceRegistration",
    "SweepRegistration",
    "multi_model_em",
    "robust_multi_model_em",
]
