"""Scenes with known objects, motions and outliers, and loaders for real data sets.

One module per family of scenes; every generator returns a :class:`sklearn.utils.Bunch`
and is seeded by ``random_state``.
"""

from mmreg.datasets._argoverse2 import (
    ARGOVERSE2_CATEGORIES,
    Argoverse2Log,
    load_argoverse2,
    read_scene_flow,
    write_argoverse2_log,
)
from mmreg.datasets._flow_noise import corrupt_scene_flow
from mmreg.datasets._flying_things import PRIMITIVES, make_flying_things
from mmreg.datasets._flying_things_data import load_flying_things
from mmreg.datasets._kitti import load_kitti_scene_flow
from mmreg.datasets._lidar import make_lidar_sweeps
from mmreg.datasets._lidar_sequence import lidar_sequence_pair, make_lidar_sequence
from mmreg.datasets._meshes import MESH_NAMES, load_mesh_points
from mmreg.datasets._pfm import read_pfm, write_pfm
from mmreg.datasets._sam import simulate_sam_masks
from mmreg.datasets._scene import SHAPES, make_scene
from mmreg.datasets._sequences import (
    Argoverse2Sweeps,
    BagSequence,
    Frame,
    FrameFolder,
    KittiSequence,
    open_sequence,
)
from mmreg.datasets._street import SURFACE_KINDS, make_street
from mmreg.datasets._wrong_matches import add_wrong_correspondences
from mmreg.io import read_correspondences as load_correspondences

__all__ = [
    "ARGOVERSE2_CATEGORIES",
    "Argoverse2Log",
    "Argoverse2Sweeps",
    "BagSequence",
    "Frame",
    "FrameFolder",
    "KittiSequence",
    "MESH_NAMES",
    "PRIMITIVES",
    "SHAPES",
    "SURFACE_KINDS",
    "add_wrong_correspondences",
    "corrupt_scene_flow",
    "lidar_sequence_pair",
    "load_argoverse2",
    "load_correspondences",
    "load_flying_things",
    "load_kitti_scene_flow",
    "load_mesh_points",
    "make_flying_things",
    "make_lidar_sequence",
    "make_lidar_sweeps",
    "make_scene",
    "make_street",
    "open_sequence",
    "read_pfm",
    "read_scene_flow",
    "simulate_sam_masks",
    "write_argoverse2_log",
    "write_pfm",
]
