"""Scenes with known objects, motions and outliers, and loaders for real data sets.

One module per family of scenes; every generator returns a :class:`sklearn.utils.Bunch`
and is seeded by ``random_state``.
"""

from mmreg.datasets._flow_noise import corrupt_scene_flow
from mmreg.datasets._sam import simulate_sam_masks
from mmreg.datasets._scene import SHAPES, make_scene

__all__ = ["SHAPES", "corrupt_scene_flow", "make_scene", "simulate_sam_masks"]
