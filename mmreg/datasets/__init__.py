"""Scenes with known objects, motions and outliers, and loaders for real data sets.

One module per family of scenes; every generator returns a :class:`sklearn.utils.Bunch`
and is seeded by ``random_state``.
"""

from mmreg.datasets._flow_noise import corrupt_scene_flow
from mmreg.datasets._flying_things import PRIMITIVES, make_flying_things
from mmreg.datasets._sam import simulate_sam_masks
from mmreg.datasets._scene import SHAPES, make_scene
from mmreg.datasets._street import SURFACE_KINDS, make_street

__all__ = [
    "PRIMITIVES",
    "SHAPES",
    "SURFACE_KINDS",
    "corrupt_scene_flow",
    "make_flying_things",
    "make_scene",
    "make_street",
    "simulate_sam_masks",
]
