"""Argoverse 2 sensor-dataset logs: real LiDAR sweeps with ground-truth scene flow.

An Argoverse 2 (AV2) sensor-dataset log is a folder::

    <log_dir>/
        sensors/lidar/<timestamp_ns>.feather   x, y, z (float16, metres, ego frame), ...
        annotations.feather                    tracked cuboids of every annotated sweep
        city_SE3_egovehicle.feather            ego-vehicle poses in the city frame
        map/<log_id>_ground_height_surface____<CITY>.npy   ground height raster (float16)
        map/<log_id>___img_Sim2_city.json      city -> raster-pixel similarity, Sim(2)

The ego-vehicle frame has x forward, y left and z up; a cuboid's pose (quaternion
``qw, qx, qy, qz`` scalar first, translation ``tx_m, ty_m, tz_m``) maps the object frame
(x along the length) into the ego frame of its sweep. The scene flow follows the official
labels, ``av2.torch.structures.flow.Flow.from_sweep_pair`` in ``argoverse/av2-api``: every
point moves with the ego motion; a point inside a cuboid at ``t`` (grown by 0.2 m in length
and width) moves with that cuboid's rigid motion from ``t`` to ``t + 1``. Sweep ``t + 1``
and ``b = a + flow`` are in the ego frame at ``t + 1``.
"""

import itertools
import json
import numbers
import os
import re
from functools import cached_property
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from sklearn.utils import Bunch

from mmreg._array.neighbors import lookup_tree
from mmreg.io._arrays import _load_npy, _load_npz
from mmreg.io._checks import _check_readable
from mmreg.io._feather import numeric_column, read_feather

__all__ = [
    "ARGOVERSE2_CATEGORIES",
    "Argoverse2Log",
    "load_argoverse2",
    "read_scene_flow",
    "write_argoverse2_log",
]

#: Category names of the official flow labels: ``"NONE"`` (index 0, no cuboid), then the 30
#: AV2 annotation categories in the order of ``av2.datasets.sensor.constants``
#: (alphabetical); index ``i`` is the official ``classes`` value ``i``.
ARGOVERSE2_CATEGORIES = (
    "NONE",
    "ANIMAL",
    "ARTICULATED_BUS",
    "BICYCLE",
    "BICYCLIST",
    "BOLLARD",
    "BOX_TRUCK",
    "BUS",
    "CONSTRUCTION_BARREL",
    "CONSTRUCTION_CONE",
    "DOG",
    "LARGE_VEHICLE",
    "MESSAGE_BOARD_TRAILER",
    "MOBILE_PEDESTRIAN_CROSSING_SIGN",
    "MOTORCYCLE",
    "MOTORCYCLIST",
    "OFFICIAL_SIGNALER",
    "PEDESTRIAN",
    "RAILED_VEHICLE",
    "REGULAR_VEHICLE",
    "SCHOOL_BUS",
    "SIGN",
    "STOP_SIGN",
    "STROLLER",
    "TRAFFIC_LIGHT_TRAILER",
    "TRUCK",
    "TRUCK_CAB",
    "VEHICULAR_TRAILER",
    "WHEELCHAIR",
    "WHEELED_DEVICE",
    "WHEELED_RIDER",
)

# The official constants (av2-api: torch/structures/flow.py, evaluation/scene_flow/constants.py,
# map/map_api.py, rust/src/data_loader.rs).
_BOX_EXPANSION = 0.2  # metres added to a cuboid's length and width at t
_DYNAMIC_THRESHOLD = 0.05  # metres of flow beyond the ego flow, per sweep pair (~0.1 s)
_GROUND_THRESHOLD = 0.3  # metres from the ground height raster
_MIN_INTERIOR_POINTS = 1  # cuboids with fewer interior LiDAR points are dropped

_LIDAR_COLUMNS = ("x", "y", "z")
_OFFSET_COLUMN = "offset_ns"  # capture time of each point after the sweep's timestamp
_POSE_COLUMNS = ("timestamp_ns", "qw", "qx", "qy", "qz", "tx_m", "ty_m", "tz_m")
_ANNOTATION_COLUMNS = (
    "timestamp_ns",
    "track_uuid",
    "category",
    "length_m",
    "width_m",
    "height_m",
    "qw",
    "qx",
    "qy",
    "qz",
    "tx_m",
    "ty_m",
    "tz_m",
    "num_interior_pts",
)
_FLOW_COLUMNS = ("flow_tx_m", "flow_ty_m", "flow_tz_m")
_SWEEP_NAME = re.compile(r"^(\d+)\.feather$")

_DESCR = """\
.. _argoverse2_dataset:

Argoverse 2 sensor dataset: LiDAR sweeps with ground-truth scene flow
---------------------------------------------------------------------

A pair of consecutive LiDAR sweeps (10 Hz, two roof-mounted 32-beam LiDARs) of one
Argoverse 2 sensor-dataset log, with the ground-truth scene flow of the first sweep
derived from the tracked 3-D cuboids exactly as the official scene-flow labels
(``av2.torch.structures.flow.Flow.from_sweep_pair``): every point moves with the
ego-vehicle motion, a point inside a cuboid at t (grown by 0.2 m in length and width)
with that cuboid's rigid motion from t to t+1. Points are in metres, ``a`` in the
ego-vehicle frame at t, ``b = a + flow`` and ``sweep2`` in the ego-vehicle frame at t+1.

:Motions: label 0 = the static world (the ego motion), k >= 1 = the k-th moving
    cuboid (most of its points dynamic: >= 0.05 m beyond the ego flow), -1 = a point
    in a cuboid that has no pose at t+1 (flow unknown).
:Ground: the map rule of the AV2 API: within 0.3 m of the ground height raster, or
    below it.
:Licence: data CC BY-NC-SA 4.0 (non-commercial research use, attribution,
    share-alike); see https://www.argoverse.org

References: B. Wilson et al., "Argoverse 2: Next Generation Datasets for
Self-Driving Perception and Forecasting", NeurIPS Datasets and Benchmarks, 2021.
"""


class _MissingPathError(FileNotFoundError, ValueError):
    """A file or folder of the log is missing (both FileNotFoundError and ValueError)."""


# --------------------------------------------------------------------------- small checks
def _check_int(value, name, *, low=None):
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer; got {value!r}.")
    value = int(value)
    if low is not None and value < low:
        raise ValueError(f"{name} must be >= {low}; got {value}.")
    return value


def _check_length(value, name):
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a number (metres); got {value!r}.")
    value = float(value)
    if not np.isfinite(value) or value < 0:
        raise ValueError(f"{name} must be a finite number >= 0 (metres); got {value}.")
    return value


def _check_options(drop_ground, min_interior_points, box_expansion, dynamic_threshold):
    if not isinstance(drop_ground, (bool, np.bool_)):
        raise TypeError(f"drop_ground must be True or False; got {drop_ground!r}.")
    return (
        bool(drop_ground),
        _check_int(min_interior_points, "min_interior_points", low=0),
        _check_length(box_expansion, "box_expansion"),
        _check_length(dynamic_threshold, "dynamic_threshold"),
    )


def _check_dir(path, what):
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"log_dir must be a str or path-like; got {type(path).__name__}.")
    path = Path(path)
    if not path.exists():
        raise _MissingPathError(f"{path}: no such folder ({what}).")
    if not path.is_dir():
        raise ValueError(f"{path}: is not a folder ({what}).")
    return path


def _require_file(path, what):
    if not Path(path).exists():
        raise _MissingPathError(f"{path}: no such file ({what}).")
    return _check_readable(path, what)


# --------------------------------------------------------------------------- file readers
def _read_feather(path, columns, what, optional=(), nulls_as_nan=()):
    return read_feather(_require_file(path, what), columns, what, optional, nulls_as_nan)


def _read_points(path):
    """(n, 3) float64 xyz of one LiDAR sweep (ego frame, metres), and the capture times.

    The times are ``offset_ns`` in seconds (from the sweep's timestamp), or None when the
    file has no such column.
    """
    columns = _read_feather(path, _LIDAR_COLUMNS, "LiDAR sweep", optional=(_OFFSET_COLUMN,))
    points = np.column_stack([numeric_column(columns[c], path, c) for c in _LIDAR_COLUMNS])
    times = None
    if _OFFSET_COLUMN in columns:
        times = numeric_column(columns[_OFFSET_COLUMN], path, _OFFSET_COLUMN, "i") * 1e-9
    return points.reshape(-1, 3), times


def _quaternion_matrices(q_wxyz, path):
    norms = np.linalg.norm(q_wxyz, axis=1)
    if np.any(norms < 1e-9):
        raise ValueError(f"{path}: a quaternion (qw, qx, qy, qz) is zero.")
    return Rotation.from_quat(q_wxyz[:, [1, 2, 3, 0]]).as_matrix()


def _poses(columns, path):
    """(k, 4, 4) rigid transforms from the qw..qz, tx_m..tz_m columns."""
    q = np.column_stack([numeric_column(columns[c], path, c) for c in ("qw", "qx", "qy", "qz")])
    t = np.column_stack([numeric_column(columns[c], path, c) for c in ("tx_m", "ty_m", "tz_m")])
    T = np.tile(np.eye(4), (len(q), 1, 1))
    if len(q):
        T[:, :3, :3] = _quaternion_matrices(q, path)
    T[:, :3, 3] = t
    return T


def _invert(T):
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def _apply(T, points):
    # einsum: several times faster than a BLAS matmul for (n, 3) @ (3, 3)
    return np.einsum("ij,nj->ni", T[:3, :3], points) + T[:3, 3]


# --------------------------------------------------------------------------- the log
class _Log:
    """The files of one log, read once each and only when needed."""

    def __init__(self, log_dir):
        self.log_dir = _check_dir(log_dir, "Argoverse 2 log")
        lidar_dir = self.log_dir / "sensors" / "lidar"
        if not lidar_dir.is_dir():
            raise _MissingPathError(f"{lidar_dir}: no such folder (the log's LiDAR sweeps).")
        found = {}
        for entry in os.scandir(lidar_dir):
            match = _SWEEP_NAME.match(entry.name)
            if match and entry.is_file():
                found[int(match.group(1))] = Path(entry.path)
        if not found:
            raise ValueError(f"{lidar_dir}: no LiDAR sweeps (<timestamp_ns>.feather files).")
        self.sweep_timestamps = np.array(sorted(found), dtype=np.int64)
        self.sweep_paths = found
        self.annotations_path = self.log_dir / "annotations.feather"
        self.poses_path = self.log_dir / "city_SE3_egovehicle.feather"
        self.map_dir = self.log_dir / "map"
        for path, what in (
            (self.annotations_path, "the tracked cuboids"),
            (self.poses_path, "the ego-vehicle poses"),
        ):
            _require_file(path, what)
        if not self.map_dir.is_dir():
            raise _MissingPathError(f"{self.map_dir}: no such folder (the log's map).")

    @cached_property
    def annotations(self):
        path = self.annotations_path
        cols = _read_feather(path, _ANNOTATION_COLUMNS, "the tracked cuboids")
        out = {
            "timestamp_ns": numeric_column(cols["timestamp_ns"], path, "timestamp_ns", "i"),
            "num_interior_pts": numeric_column(
                cols["num_interior_pts"], path, "num_interior_pts", "i"
            ),
            "track_uuid": np.asarray(cols["track_uuid"]).astype(str),
            "category": np.asarray(cols["category"]).astype(str),
            "size": np.column_stack(
                [numeric_column(cols[c], path, c) for c in ("length_m", "width_m", "height_m")]
            ).reshape(-1, 3),
            "pose": _poses(cols, path),
        }
        if np.any(out["size"] < 0):
            raise ValueError(f"{path}: a cuboid has a negative length, width or height.")
        out["timestamps"] = np.unique(out["timestamp_ns"])
        return out

    @cached_property
    def poses(self):
        path = self.poses_path
        cols = _read_feather(path, _POSE_COLUMNS, "the ego-vehicle poses")
        stamps = numeric_column(cols["timestamp_ns"], path, "timestamp_ns", "i")
        order = np.argsort(stamps, kind="stable")
        return stamps[order], _poses(cols, path)[order]

    @cached_property
    def ground_map(self):
        heights = sorted(self.map_dir.glob("*ground_height_surface*.npy"))
        sim2s = sorted(self.map_dir.glob("*img_Sim2_city.json"))
        for found, what in (
            (heights, "*ground_height_surface*.npy"),
            (sim2s, "*img_Sim2_city.json"),
        ):
            if len(found) != 1:
                problem = "no" if not found else f"{len(found)} files, not one"
                raise _MissingPathError(f"{self.map_dir}: {problem} {what} (the ground map).")
        raster = _load_npy(heights[0])
        if raster.ndim != 2 or raster.dtype.kind != "f" or raster.size == 0:
            raise ValueError(
                f"{heights[0]}: the ground height raster must be a non-empty 2-D float array; "
                f"got shape {raster.shape}, dtype {raster.dtype}."
            )
        try:
            record = json.loads(Path(sim2s[0]).read_text(encoding="utf-8"))
            R = np.asarray(record["R"], dtype=float).reshape(2, 2)
            t = np.asarray(record["t"], dtype=float).reshape(2)
            s = float(record["s"])
        except (ValueError, KeyError, TypeError, UnicodeDecodeError) as exc:
            raise ValueError(
                f"{sim2s[0]}: not a Sim(2) json with keys R (4 numbers), t (2) and s: {exc!r}"
            ) from exc
        if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t)) and np.isfinite(s) and s > 0):
            raise ValueError(f"{sim2s[0]}: R, t and s must be finite and s > 0.")
        return raster.astype(np.float64), R, t, s

    def successor(self, i):
        """Timestamp paired with sweep ``i``: the next sweep, else the next annotated time."""
        stamps = self.sweep_timestamps
        if i + 1 < len(stamps):
            return int(stamps[i + 1])
        later = self.annotations["timestamps"]
        later = later[later > stamps[i]]
        return int(later[0]) if len(later) else None

    def __len__(self):
        return len(self.sweep_timestamps) - (self.successor(len(self.sweep_timestamps) - 1) is None)

    def pose(self, timestamp):
        stamps, matrices = self.poses
        j = np.searchsorted(stamps, timestamp)
        if j == len(stamps) or stamps[j] != timestamp:
            raise ValueError(f"{self.poses_path}: no ego-vehicle pose at timestamp {timestamp} ns.")
        return matrices[j]

    def cuboids(self, timestamp, min_interior_points):
        ann = self.annotations
        at = ann["timestamp_ns"] == timestamp
        if not at.any():
            raise ValueError(f"{self.annotations_path}: no cuboid annotated at {timestamp} ns.")
        keep = np.flatnonzero(at & (ann["num_interior_pts"] >= min_interior_points))
        return {key: ann[key][keep] for key in ("track_uuid", "category", "size", "pose")}

    def ground(self, points_ego, city_SE3_ego, threshold=_GROUND_THRESHOLD):
        raster, R, t, s = self.ground_map
        return _ground_mask(_apply(city_SE3_ego, points_ego), raster, R, t, s, threshold)


def _ground_mask(points_city, raster, R, t, s, threshold):
    """The AV2 map rule: ``|z - h| <= threshold`` or ``z < h``; off the raster or NaN: False."""
    # pixel (column, row) = s (R xy + t), truncated towards zero as the API does
    pixels = ((np.einsum("ij,nj->ni", R, points_city[:, :2]) + t) * s).astype(np.int64)
    rows, cols = raster.shape
    inside = (
        (pixels[:, 0] >= 0) & (pixels[:, 0] < cols) & (pixels[:, 1] >= 0) & (pixels[:, 1] < rows)
    )
    height = np.full(len(points_city), np.nan)
    height[inside] = raster[pixels[inside, 1], pixels[inside, 0]]
    z = points_city[:, 2]
    return (np.abs(z - height) <= threshold) | (z < height)


def _points_in_cuboids(points, poses, half_sizes):
    """(point, cuboid) index pairs with the point inside (faces included) the cuboid.

    A k-d tree of the points gives the candidates within each cuboid's circumscribed
    sphere; they are then tested in the cuboid frames all at once.
    """
    if len(poses) == 0 or len(points) == 0:
        return np.empty(0, np.intp), np.empty(0, np.intp)
    tree = lookup_tree(points)
    candidates = tree.query_ball_point(poses[:, :3, 3], np.linalg.norm(half_sizes, axis=1))
    counts = np.array([len(c) for c in candidates], dtype=np.intp)
    point = np.fromiter(itertools.chain.from_iterable(candidates), np.intp, int(counts.sum()))
    cuboid = np.repeat(np.arange(len(poses)), counts)
    local = np.einsum(
        "nji,nj->ni", poses[cuboid, :3, :3], points[point] - poses[cuboid, :3, 3]
    )  # R^T (p - c)
    inside = np.all(np.abs(local) <= half_sizes[cuboid], axis=1)
    return point[inside], cuboid[inside]


def _category_indices(names):
    """Index of each name in ARGOVERSE2_CATEGORIES; unknown names appended after them."""
    table = list(ARGOVERSE2_CATEGORIES)
    extra = sorted(set(names) - set(table))
    table += extra
    lookup = {name: i for i, name in enumerate(table)}
    return np.array([lookup[n] for n in names], dtype=np.int64), tuple(table)


# --------------------------------------------------------------------------- loader
def _check_index(log, index, timestamp_ns):
    n_pairs = len(log)
    if timestamp_ns is not None:
        timestamp_ns = _check_int(timestamp_ns, "timestamp_ns")
        if index != 0:
            raise ValueError("give either index or timestamp_ns, not both.")
        where = np.flatnonzero(log.sweep_timestamps == timestamp_ns)
        if not len(where):
            raise ValueError(
                f"{log.log_dir}: no LiDAR sweep at timestamp_ns={timestamp_ns} (sweeps from "
                f"{log.sweep_timestamps[0]} to {log.sweep_timestamps[-1]})."
            )
        index = int(where[0])
    index = _check_int(index, "index")
    if not 0 <= index < n_pairs:
        allowed = f"index 0 to {n_pairs - 1}" if n_pairs else "no index is valid"
        raise ValueError(
            f"{log.log_dir}: index {index} out of range; the log has {len(log.sweep_timestamps)} "
            f"sweep(s) and {n_pairs} sweep pair(s) ({allowed}): the last sweep has no next "
            "sweep nor a later annotated timestamp."
        )
    return index


def _load_pair(log, index, drop_ground, min_interior_points, box_expansion, dynamic_threshold):
    t0 = int(log.sweep_timestamps[index])
    t1 = log.successor(index)
    a, times = _read_points(log.sweep_paths[t0])
    sweep2, sweep2_times = None, None
    if t1 in log.sweep_paths:
        sweep2, sweep2_times = _read_points(log.sweep_paths[t1])
    city_SE3_ego0, city_SE3_ego1 = log.pose(t0), log.pose(t1)
    ego_motion = _invert(city_SE3_ego1) @ city_SE3_ego0  # ego(t) -> ego(t+1)
    ego_flow = _apply(ego_motion, a) - a

    # cuboids at t and t+1 (the official filter on num_interior_pts), matched by track
    c0, c1 = log.cuboids(t0, min_interior_points), log.cuboids(t1, min_interior_points)
    n_cuboids = len(c0["track_uuid"])
    next_row = {uuid: j for j, uuid in enumerate(c1["track_uuid"])}  # the last one wins
    match = np.array([next_row.get(u, -1) for u in c0["track_uuid"]], dtype=np.intp)
    has_next = match >= 0
    motions = np.full((n_cuboids, 4, 4), np.nan)
    if has_next.any():
        inverse0 = np.linalg.inv(c0["pose"][has_next])
        motions[has_next] = c1["pose"][match[has_next]] @ inverse0  # c1_SE3_c0

    # points in the grown cuboids at t; a later cuboid overwrites an earlier one
    grown = c0["size"] + [box_expansion, box_expansion, 0.0]
    point, cuboid = _points_in_cuboids(a, c0["pose"], grown / 2.0)
    instance = np.zeros(len(a), dtype=np.int64)
    np.maximum.at(instance, point, cuboid + 1)

    flow = ego_flow.copy()
    inside = instance > 0
    valid = ~inside.copy()
    valid[inside] = has_next[instance[inside] - 1]
    moved = np.flatnonzero(inside & valid)
    if len(moved):
        T = motions[instance[moved] - 1]
        flow[moved] = np.einsum("nij,nj->ni", T[:, :3, :3], a[moved]) + T[:, :3, 3] - a[moved]
    dynamic = np.linalg.norm(flow - ego_flow, axis=1) >= dynamic_threshold

    # a cuboid moves when most of its points are dynamic; moving cuboids are labels 1..M
    n_points = np.bincount(instance, minlength=n_cuboids + 1)[1:]
    n_dynamic = np.bincount(instance[dynamic], minlength=n_cuboids + 1)[1:]
    moving = has_next & (2 * n_dynamic > n_points)
    moving_cuboids = np.flatnonzero(moving)
    label_of_cuboid = np.zeros(n_cuboids + 1, dtype=np.int64)
    label_of_cuboid[1:][~has_next] = -1
    label_of_cuboid[moving_cuboids + 1] = np.arange(1, len(moving_cuboids) + 1)
    labels = label_of_cuboid[instance]

    category_of_cuboid, category_names = _category_indices(list(c0["category"]))
    category = np.concatenate([[0], category_of_cuboid])[instance]
    ground = log.ground(a, city_SE3_ego0)
    sweep2_ground = None if sweep2 is None else log.ground(sweep2, city_SE3_ego1)

    motion_instance = np.concatenate([[-1], moving_cuboids])  # cuboid of each label
    if drop_ground:
        keep = ~ground
        a, flow, ego_flow = a[keep], flow[keep], ego_flow[keep]
        labels, instance, category = labels[keep], instance[keep], category[keep]
        dynamic, valid, ground = dynamic[keep], valid[keep], ground[keep]
        times = None if times is None else times[keep]
        if sweep2 is not None:
            keep2 = ~sweep2_ground
            if sweep2_times is not None:
                sweep2_times = sweep2_times[keep2]
            sweep2, sweep2_ground = sweep2[keep2], sweep2_ground[keep2]
        # moving cuboids whose points were all ground: renumber the labels compactly
        present = np.zeros(len(motion_instance), bool)
        present[0] = True
        present[labels[labels > 0]] = True
        if not present.all():
            new = np.cumsum(present) - 1
            labels = np.where(labels > 0, new[np.maximum(labels, 0)], labels)
            motion_instance = motion_instance[present]

    transforms = np.concatenate([ego_motion[None], motions[motion_instance[1:]]])
    b = a + flow
    return Bunch(
        a=a,
        b=b,
        flow=flow,
        X=np.hstack([a, b]),
        ego_flow=ego_flow,
        sweep2=sweep2,
        sweep2_ground=sweep2_ground,
        times=times,
        sweep2_times=sweep2_times,
        ground=ground,
        labels=labels,
        rotations=transforms[:, :3, :3].copy(),
        translations=transforms[:, :3, 3].copy(),
        instance=instance,
        category=category,
        category_names=category_names,
        dynamic=dynamic,
        valid=valid,
        motion_instance=motion_instance,
        instance_uuid=c0["track_uuid"],
        instance_category=np.asarray(category_names)[category_of_cuboid],
        instance_moving=moving,
        instance_has_next=has_next,
        instance_rotations=motions[:, :3, :3].copy(),
        instance_translations=motions[:, :3, 3].copy(),
        ego_motion=ego_motion,
        city_SE3_ego=np.stack([city_SE3_ego0, city_SE3_ego1]),
        timestamps=np.array([t0, t1], dtype=np.int64),
        dt=(t1 - t0) * 1e-9,
        index=index,
        log_dir=str(log.log_dir),
        DESCR=_DESCR,
    )


def load_argoverse2(
    log_dir,
    index=0,
    *,
    timestamp_ns=None,
    drop_ground=False,
    min_interior_points=_MIN_INTERIOR_POINTS,
    box_expansion=_BOX_EXPANSION,
    dynamic_threshold=_DYNAMIC_THRESHOLD,
):
    """Load a pair of Argoverse 2 LiDAR sweeps with the ground-truth scene flow.

    Reads one log of the Argoverse 2 sensor dataset in its own layout
    (``sensors/lidar/<timestamp_ns>.feather``, ``annotations.feather``,
    ``city_SE3_egovehicle.feather``, ``map/*ground_height_surface*.npy`` and
    ``map/*img_Sim2_city.json``) and derives the scene flow of sweep ``index`` from the
    tracked cuboids as the official scene-flow labels do.

    Parameters
    ----------
    log_dir : str or path-like
        The log's folder (``.../sensor/<split>/<log_id>``).
    index : int, default=0
        Which sweep pair: sweep ``index`` (in timestamp order) and the next sweep. The last
        sweep of a log is paired with the next annotated timestamp when the annotations go
        further than the sweeps (then ``sweep2`` is None), otherwise it has no pair.
    timestamp_ns : int, default=None
        Select the first sweep by its timestamp (the file name) instead of ``index``.
    drop_ground : bool, default=False
        Remove the ground points (``ground``) from ``a`` and from ``sweep2``, with every
        per-point array.
    min_interior_points : int, default=1
        Cuboids annotated with fewer LiDAR points (``num_interior_pts``) at t or at t+1 are
        dropped, as the official data loader does. 0 keeps every cuboid.
    box_expansion : float, default=0.2
        Metres added to each cuboid's length and width at t before testing which points
        it holds (the official labels' margin; the boxes are a little tight).
    dynamic_threshold : float, default=0.05
        A point is dynamic when its flow differs from the ego-motion flow by at least this
        many metres over the pair (the official ``SCENE_FLOW_DYNAMIC_THRESHOLD``).

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        Dictionary-like object with the following attributes (n points of sweep t,
        M moving cuboids, K cuboids at t; metres).

        a : ndarray of shape (n, 3)
            Sweep t in the ego-vehicle frame at t.
        flow : ndarray of shape (n, 3)
            Ground-truth scene flow; ``b = a + flow``.
        b : ndarray of shape (n, 3)
            Where each point of ``a`` is at t+1, in the ego-vehicle frame at t+1.
        X : ndarray of shape (n, 6)
            ``np.hstack([a, b])``, the correspondences for the estimators.
        ego_flow : ndarray of shape (n, 3)
            The flow each point would have if it were static (ego motion only).
        sweep2 : ndarray of shape (m, 3) or None
            The real sweep t+1 in the ego-vehicle frame at t+1 (no correspondence), None
            when the log has no sweep at t+1.
        sweep2_ground : ndarray of shape (m,) of bool or None
            Ground points of ``sweep2``.
        times : ndarray of shape (n,) or None
            Capture time of each point of ``a`` in seconds after the sweep's timestamp
            (the sweep file's ``offset_ns``, 0-0.106 s: the two LiDARs turn for 0.1 s);
            None when the file has no ``offset_ns`` column. The sweeps are compensated
            for the ego motion, not for the objects': a moving object appears where it was
            when each point was captured (``SweepRegistration.fit(..., times=)``
            deskews it). The ground-truth ``flow`` does not depend on it.
        sweep2_times : ndarray of shape (m,) or None
            The same for ``sweep2``, after its own timestamp.
        ground : ndarray of shape (n,) of bool
            The AV2 map rule: ``|z_city - h| <= 0.3`` or ``z_city < h`` with ``h`` the
            ground height raster's value at the point; points off the raster or on a NaN
            cell are not ground.
        labels : ndarray of shape (n,) of int
            0 = the static world (moves with the ego motion; static cuboids included),
            k >= 1 = the k-th moving cuboid, -1 = unknown (in a cuboid without a pose at
            t+1).
        rotations : ndarray of shape (M + 1, 3, 3)
            Rotation of each label: label 0 the ego motion ego(t) -> ego(t+1), label k the
            motion of its cuboid from ego(t) coordinates to ego(t+1) coordinates.
        translations : ndarray of shape (M + 1, 3)
            Translation of each label.
        instance : ndarray of shape (n,) of int
            0 = in no cuboid, k = in the k-th cuboid at t (1-based; the last one in the
            file when cuboids overlap).
        category : ndarray of shape (n,) of int
            Category of each point as an index into ``category_names`` (0 = ``"NONE"``),
            the official ``classes``.
        category_names : tuple of str
            :data:`ARGOVERSE2_CATEGORIES`, then any other category of the log.
        dynamic : ndarray of shape (n,) of bool
            ``|flow - ego_flow| >= dynamic_threshold``.
        valid : ndarray of shape (n,) of bool
            False for the points of a cuboid without a pose at t+1 (their flow is the ego
            flow, as in the official labels, but unknown).
        motion_instance : ndarray of shape (M + 1,) of int
            The cuboid (0-based row of the ``instance_*`` arrays) of each label; -1 for 0.
        instance_uuid, instance_category : ndarray of shape (K,) of str
            Track id and category of each cuboid at t.
        instance_moving, instance_has_next : ndarray of shape (K,) of bool
            Whether each cuboid moves (most of its points dynamic) and has a pose at t+1.
        instance_rotations, instance_translations : ndarray of shape (K, 3, 3), (K, 3)
            Motion of each cuboid from t to t+1 (NaN without a pose at t+1).
        ego_motion : ndarray of shape (4, 4)
            ``inv(city_SE3_ego[1]) @ city_SE3_ego[0]``, the ego motion ego(t) -> ego(t+1).
        city_SE3_ego : ndarray of shape (2, 4, 4)
            Ego-vehicle poses in the city frame at t and t+1.
        timestamps : ndarray of shape (2,) of int64
            t and t+1 in nanoseconds; ``dt`` their difference in seconds.
        index, log_dir : int, str
            The pair loaded.
        DESCR : str
            Description of the data set.

    Raises
    ------
    FileNotFoundError
        If the folder or one of its files is missing (also a ValueError).
    ValueError
        If a file is truncated, corrupt or lacks a column, the log has no sweep, ``index``
        is out of range, or a pose or the annotations at t or t+1 are missing.
    TypeError
        If an option has the wrong type.

    See Also
    --------
    Argoverse2Log : The sweep pairs of a log as a sequence.
    read_scene_flow : Read a scene-flow estimate to compare with ``flow``.
    write_argoverse2_log : Write a small log in this layout.

    Notes
    -----
    The rule of ``av2.torch.structures.flow.Flow.from_sweep_pair`` (av2-api 0.3):

    - every point gets the ego-motion flow ``inv(city_SE3_ego1) city_SE3_ego0 p - p``;
    - cuboids with ``num_interior_pts < min_interior_points`` at t or at t+1 are dropped,
      as the official Rust data loader does (so a cuboid annotated with no point at t+1
      counts as having no pose there);
    - a point inside a cuboid at t, grown by ``box_expansion`` in length and width, gets
      that cuboid's rigid motion ``c1_SE3_c0 = ego1_SE3_obj(t+1) inv(ego0_SE3_obj(t))``
      (the ego motion included); a later cuboid of the file overwrites an earlier one;
      a cuboid without a pose at t+1 leaves its points with the ego flow, invalid;
    - ``dynamic``: ``|flow - ego_flow| >= 0.05`` m. The official code compares this
      displacement over the pair (nominally 0.1 s, i.e. 0.5 m/s) without dividing by the
      actual time between the sweeps.

    The poses of t and t+1 are looked up at exactly those timestamps, as the official
    loader does. Ground pixels are found by truncating ``s (R xy + t)`` to integers, as
    ``RasterMapLayer.get_raster_values_at_coords``. The LiDAR coordinates are float16 in
    the files (steps of 1.6 cm at 16-32 m); they are returned as float64 and the flow is
    computed in float64, so it matches the official float32 labels to about 1 mm.

    A cuboid moves (has a label k >= 1) when more than half of its points are dynamic;
    static cuboids (parked cars) follow label 0 to within their annotation jitter (a few
    centimetres), moving ones follow ``rotations[k]``, ``translations[k]`` exactly. Labels
    are renumbered after ``drop_ground`` when a moving cuboid loses all its points.

    Cost: reading the sweep and the log's tables, one k-d tree of the sweep for the
    cuboid test; about 0.1 s for 100 000 points and 100 cuboids.

    References
    ----------
    B. Wilson et al., "Argoverse 2: Next Generation Datasets for Self-Driving Perception
    and Forecasting", NeurIPS Datasets and Benchmarks, 2021.
    The official labels: ``av2/torch/structures/flow.py`` in
    https://github.com/argoverse/av2-api; the task:
    https://argoverse.github.io/user-guide/tasks/3d_scene_flow.html

    Examples
    --------
    A car drives 1.5 m forward while the ego vehicle drives 1 m:

    >>> import tempfile
    >>> import numpy as np
    >>> from mmreg.datasets import load_argoverse2, write_argoverse2_log
    >>> rng = np.random.default_rng(0)
    >>> road = np.c_[rng.uniform(-20, 20, (300, 2)), np.zeros(300)]
    >>> car = rng.uniform([-2, -0.8, 0.3], [2, 0.8, 1.5], (100, 3)) + [8, 3, 0]
    >>> def pose(x, y=0.0, z=0.0):
    ...     T = np.eye(4)
    ...     T[:3, 3] = x, y, z
    ...     return T
    >>> t0, t1 = 315966265259836000, 315966265359836000
    >>> cuboids = [dict(timestamp_ns=t, track_uuid="car-1", category="REGULAR_VEHICLE",
    ...                 size=(4.4, 1.8, 1.5), pose=pose(x, 3, 0.9))
    ...            for t, x in ((t0, 8.0), (t1, 8.5))]
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     log = write_argoverse2_log(
    ...         folder, sweeps={t0: np.vstack([road, car]), t1: np.vstack([road, car])},
    ...         city_SE3_ego={t0: pose(0.0), t1: pose(1.0)}, cuboids=cuboids)
    ...     scene = load_argoverse2(log, 0)
    >>> scene.X.shape, np.bincount(scene.labels).tolist(), int(scene.ground.sum())
    ((400, 6), [300, 100], 300)
    >>> scene.flow[scene.labels == 0].mean(axis=0).round(6).tolist()
    [-1.0, 0.0, 0.0]
    >>> scene.flow[scene.labels == 1].mean(axis=0).round(6).tolist()
    [0.5, 0.0, 0.0]
    >>> scene.category_names[scene.category[-1]], scene.sweep2.shape
    ('REGULAR_VEHICLE', (400, 3))
    """
    options = _check_options(drop_ground, min_interior_points, box_expansion, dynamic_threshold)
    log = log_dir if isinstance(log_dir, _Log) else _Log(log_dir)
    index = _check_index(log, index, timestamp_ns)
    return _load_pair(log, index, *options)


class Argoverse2Log:
    """The sweep pairs of an Argoverse 2 log as a sequence (KISS-ICP's dataset style).

    ``log[i]`` is ``load_argoverse2(log_dir, i, **loader_options)``; the log's tables and
    map are read once and shared by every item.

    Parameters
    ----------
    log_dir : str or path-like
        The log's folder.
    **loader_options
        Keyword options of :func:`load_argoverse2` (``drop_ground``,
        ``min_interior_points``, ``box_expansion``, ``dynamic_threshold``).

    Attributes
    ----------
    log_dir : pathlib.Path
    timestamps : ndarray of int64
        Timestamps of the LiDAR sweeps (nanoseconds), in order.
    loader_options : dict

    Notes
    -----
    ``len(log)`` counts the pairs that can be formed: each sweep with the next one, and the
    last sweep with the next annotated timestamp if the annotations go further (as in the
    truncated logs of the AV2 API's tests); a full log of N sweeps has N - 1 pairs.

    References
    ----------
    I. Vizzo et al., "KISS-ICP: In Defense of Point-to-Point ICP", RA-L 2023 (the
    ``__len__``/``__getitem__`` dataset interface).

    Examples
    --------
    >>> import tempfile
    >>> import numpy as np
    >>> from mmreg.datasets import Argoverse2Log, write_argoverse2_log
    >>> points = np.random.default_rng(0).uniform(-10, 10, (50, 3))
    >>> poses = {t: np.eye(4) for t in (100, 200, 300)}
    >>> cone = [dict(timestamp_ns=t, track_uuid="cone", category="CONSTRUCTION_CONE",
    ...              size=(0.4, 0.4, 0.7), pose=np.eye(4)) for t in poses]
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     _ = write_argoverse2_log(folder, {t: points for t in poses}, poses, cone)
    ...     log = Argoverse2Log(folder, drop_ground=True)
    ...     pairs = [pair.timestamps.tolist() for pair in log]
    >>> len(log), pairs
    (2, [[100, 200], [200, 300]])
    """

    def __init__(self, log_dir, **loader_options):
        unknown = set(loader_options) - {
            "drop_ground",
            "min_interior_points",
            "box_expansion",
            "dynamic_threshold",
        }
        if unknown:
            raise TypeError(f"unknown loader option(s): {', '.join(sorted(unknown))}.")
        defaults = dict(
            drop_ground=False,
            min_interior_points=_MIN_INTERIOR_POINTS,
            box_expansion=_BOX_EXPANSION,
            dynamic_threshold=_DYNAMIC_THRESHOLD,
        )
        _check_options(**{**defaults, **loader_options})
        self._log = _Log(log_dir)
        self.log_dir = self._log.log_dir
        self.timestamps = self._log.sweep_timestamps.copy()
        self.loader_options = dict(loader_options)

    def __len__(self):
        return len(self._log)

    def __getitem__(self, i):
        n = len(self)
        i = _check_int(i, "index")
        if not -n <= i < n:
            raise IndexError(f"{self.log_dir}: pair {i} out of range; the log has {n} pair(s).")
        return load_argoverse2(self._log, i % n, **self.loader_options)

    def __iter__(self):
        for i in range(len(self)):
            yield self[i]

    def __repr__(self):
        return f"Argoverse2Log({str(self.log_dir)!r}, pairs={len(self)})"


# --------------------------------------------------------------------------- flow files
def read_scene_flow(path, n=None, *, return_valid=False):
    """Read a scene-flow estimate (or labels) of one sweep.

    Parameters
    ----------
    path : str or path-like
        ``.feather``: AV2 style, columns ``flow_tx_m``, ``flow_ty_m``, ``flow_tz_m`` and
        optionally ``is_valid`` (other columns, e.g. ``is_dynamic``, ignored);
        ``.npy``: an (n, 3) array; ``.npz``: a ``flow`` array (n, 3) and optionally
        ``is_valid``.
    n : int, default=None
        The number of points the flow must have (that of the sweep), if given.
    return_valid : bool, default=False
        Also return the ``is_valid`` flags (all True when the file has none).

    Returns
    -------
    flow : ndarray of shape (n, 3)
        Flow in metres, float64.
    valid : ndarray of shape (n,) of bool
        Only if ``return_valid``.

    Raises
    ------
    FileNotFoundError
        If the file is missing.
    ValueError
        If the extension is unknown, the file is truncated or corrupt, a column or the
        ``flow`` key is missing, the array is not (n, 3), holds NaN or infinity, or has
        a number of rows other than ``n``.

    Notes
    -----
    Every row must be finite, the invalid ones included. The AV2 submission files store
    the flow as float16; it is returned as float64.

    References
    ----------
    The AV2 scene-flow file format: ``av2/evaluation/scene_flow`` in
    https://github.com/argoverse/av2-api.

    Examples
    --------
    >>> import tempfile, os
    >>> import numpy as np
    >>> from mmreg.datasets import read_scene_flow
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = os.path.join(folder, "flow.npy")
    ...     np.save(path, np.zeros((4, 3), np.float32))
    ...     read_scene_flow(path, n=4).shape
    (4, 3)
    """
    if n is not None:
        n = _check_int(n, "n", low=0)
    if not isinstance(return_valid, (bool, np.bool_)):
        raise TypeError(f"return_valid must be True or False; got {return_valid!r}.")
    path = _check_readable(path, "scene flow")
    suffix = path.suffix.lower()
    valid = None
    if suffix == ".feather":
        table = _read_feather(path, _FLOW_COLUMNS, "scene flow", optional=("is_valid",))
        flow = np.column_stack(
            [numeric_column(table[c], path, c, finite=False) for c in _FLOW_COLUMNS]
        )
        valid = table.get("is_valid")
    elif suffix == ".npy":
        flow = _load_npy(path)
    elif suffix == ".npz":
        archive = _load_npz(path)
        if "flow" not in archive:
            raise ValueError(
                f"{path}: no 'flow' array in the archive; it holds "
                f"{', '.join(sorted(archive)) or 'nothing'}."
            )
        flow = archive["flow"]
        valid = archive.get("is_valid")
    else:
        raise ValueError(
            f"{path}: unknown extension {suffix or '(none)'!r} for a scene flow; expected "
            ".feather, .npy or .npz."
        )
    flow = np.asarray(flow)
    if flow.dtype.kind not in "iuf":
        raise ValueError(f"{path}: the flow must be numeric; got dtype {flow.dtype}.")
    if flow.ndim != 2 or flow.shape[1] != 3:
        raise ValueError(f"{path}: the flow must have shape (n, 3); got {flow.shape}.")
    flow = flow.astype(np.float64)
    if n is not None and len(flow) != n:
        raise ValueError(f"{path}: the flow has {len(flow)} rows but the sweep has {n} points.")
    finite = np.all(np.isfinite(flow), axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        raise ValueError(
            f"{path}: the flow holds NaN or infinity ({len(bad)} rows, the first is row {bad[0]})."
        )
    if valid is None:
        valid = np.ones(len(flow), dtype=bool)
    valid = np.asarray(valid)
    if valid.shape != (len(flow),) or valid.dtype.kind not in "biu":
        raise ValueError(
            f"{path}: is_valid must hold {len(flow)} booleans; got shape {valid.shape}, "
            f"dtype {valid.dtype}."
        )
    return (flow, valid.astype(bool)) if return_valid else flow


# --------------------------------------------------------------------------- writer
def _quaternion_wxyz(rotations):
    return Rotation.from_matrix(rotations).as_quat()[:, [3, 0, 1, 2]]


def _check_pose(T, what):
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"{what} must be a finite 4x4 matrix; got shape {T.shape}.")
    R = T[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ValueError(f"{what}: the top-left 3x3 block must be a rotation.")
    return T


def write_argoverse2_log(
    log_dir,
    sweeps,
    city_SE3_ego,
    cuboids=(),
    *,
    offsets_ns=None,
    ground_height=0.0,
    ground_origin=None,
    ground_resolution=0.3,
    log_id=None,
    city_name="PIT",
):
    """Write a minimal Argoverse 2 sensor-dataset log, in the real file formats.

    For tests and examples: the files written are those :func:`load_argoverse2` reads,
    with the AV2 columns and dtypes (LiDAR coordinates as float16, as the real sweeps).

    Parameters
    ----------
    log_dir : str or path-like
        Folder to write into (created if needed).
    sweeps : dict of {int: array-like of shape (n, 3)}
        LiDAR sweeps by timestamp (nanoseconds), in the ego-vehicle frame, metres.
    city_SE3_ego : dict of {int: array-like of shape (4, 4)}
        Ego-vehicle pose in the city frame at each timestamp; every sweep and every
        annotated timestamp needs one.
    cuboids : iterable of dict, default=()
        Tracked cuboids, one dict per cuboid and timestamp, with keys ``timestamp_ns``,
        ``track_uuid``, ``category`` (e.g. ``"REGULAR_VEHICLE"``), ``size`` (length, width,
        height), ``pose`` (4x4, object frame to the ego frame at ``timestamp_ns``) and
        optionally ``num_interior_pts`` (default: the number of points of the sweep at
        that timestamp inside the cuboid, or 1 without a sweep).
    offsets_ns : dict of {int: array-like of shape (n,)}, default=None
        Capture time of every point of a sweep in nanoseconds after its timestamp (the
        ``offset_ns`` column), by timestamp; sweeps not given (and all, for None) get 0.
    ground_height : float or array-like of shape (H, W), default=0.0
        Ground height (city z) of each raster cell, row = y, column = x. A number writes a
        flat raster covering every sweep point with 10 m to spare.
    ground_origin : tuple of 2 floats, default=None
        City (x, y) of the raster's corner (cell (0, 0)); required for an array.
    ground_resolution : float, default=0.3
        Cell size in metres (AV2: 0.3).
    log_id : str, default=None
        Prefix of the map files; the folder's name by default.
    city_name : str, default="PIT"
        Suffix of the ground height file.

    Returns
    -------
    log_dir : pathlib.Path
        The folder written.

    Notes
    -----
    The raster is stored as float16 (as AV2's), so its values are rounded; the similarity
    written maps city (x, y) to pixels as ``(xy - origin) / resolution``.

    References
    ----------
    The layout of the sensor dataset: https://argoverse.github.io/user-guide/datasets/sensor.html

    Examples
    --------
    >>> import tempfile
    >>> import numpy as np
    >>> from mmreg.datasets import write_argoverse2_log
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     log = write_argoverse2_log(
    ...         folder, {100: np.zeros((3, 3))}, {100: np.eye(4)}, log_id="log")
    ...     for path in sorted(log.rglob("*.*")):
    ...         print(path.relative_to(log).as_posix())
    annotations.feather
    city_SE3_egovehicle.feather
    map/log___img_Sim2_city.json
    map/log_ground_height_surface____PIT.npy
    sensors/lidar/100.feather
    """
    import pyarrow as pa
    import pyarrow.feather as feather

    if not isinstance(log_dir, (str, os.PathLike)):
        raise TypeError(f"log_dir must be a str or path-like; got {type(log_dir).__name__}.")
    log_dir = Path(log_dir)
    if not isinstance(sweeps, dict) or not sweeps:
        raise ValueError("sweeps must be a non-empty dict {timestamp_ns: (n, 3) points}.")
    if not isinstance(city_SE3_ego, dict):
        raise TypeError("city_SE3_ego must be a dict {timestamp_ns: 4x4 pose}.")
    clouds = {}
    for t, points in sweeps.items():
        t = _check_int(t, "a sweep timestamp", low=0)
        points = np.asarray(points, dtype=float)
        if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
            raise ValueError(f"sweep {t}: points must be finite, of shape (n, 3).")
        clouds[t] = points
    offsets = {}
    for t, values in (offsets_ns or {}).items():
        t = _check_int(t, "an offsets_ns timestamp", low=0)
        if t not in clouds:
            raise ValueError(f"offsets_ns[{t}]: there is no sweep at that timestamp.")
        values = np.asarray(values)
        if values.shape != (len(clouds[t]),) or values.dtype.kind not in "iu":
            raise ValueError(
                f"offsets_ns[{t}] must be {len(clouds[t])} integers (nanoseconds), one per "
                f"point; got shape {values.shape}, dtype {values.dtype}."
            )
        if values.size and (
            values.min() < np.iinfo(np.int32).min or values.max() > np.iinfo(np.int32).max
        ):
            raise ValueError(f"offsets_ns[{t}] does not fit the column's int32.")
        offsets[t] = values.astype(np.int32)
    poses = {
        _check_int(t, "a pose timestamp", low=0): _check_pose(T, f"city_SE3_ego[{t}]")
        for t, T in city_SE3_ego.items()
    }
    rows = []
    for k, cuboid in enumerate(cuboids):
        missing = {"timestamp_ns", "track_uuid", "category", "size", "pose"} - set(cuboid)
        if missing:
            raise ValueError(f"cuboids[{k}] lacks key(s) {', '.join(sorted(missing))}.")
        t = _check_int(cuboid["timestamp_ns"], f"cuboids[{k}]['timestamp_ns']", low=0)
        size = np.asarray(cuboid["size"], dtype=float)
        if size.shape != (3,) or not np.all(np.isfinite(size)) or np.any(size < 0):
            raise ValueError(f"cuboids[{k}]['size'] must be 3 finite lengths >= 0.")
        pose = _check_pose(cuboid["pose"], f"cuboids[{k}]['pose']")
        count = cuboid.get("num_interior_pts")
        if count is None:
            if t in clouds:
                local = (clouds[t] - pose[:3, 3]) @ pose[:3, :3]
                count = int(np.all(np.abs(local) <= size / 2, axis=1).sum())
            else:
                count = 1
        rows.append((t, str(cuboid["track_uuid"]), str(cuboid["category"]), size, pose, count))
    missing = sorted(({r[0] for r in rows} | set(clouds)) - set(poses))
    if missing:
        raise ValueError(f"city_SE3_ego has no pose at timestamp(s) {missing}.")

    lidar_dir = log_dir / "sensors" / "lidar"
    lidar_dir.mkdir(parents=True, exist_ok=True)
    (log_dir / "map").mkdir(exist_ok=True)
    for t, points in clouds.items():
        n = len(points)
        table = pa.table(
            {
                "x": points[:, 0].astype(np.float16),
                "y": points[:, 1].astype(np.float16),
                "z": points[:, 2].astype(np.float16),
                "intensity": np.zeros(n, np.uint8),
                "laser_number": np.zeros(n, np.uint8),
                "offset_ns": offsets.get(t, np.zeros(n, np.int32)),
            }
        )
        feather.write_feather(table, lidar_dir / f"{t}.feather")

    stamps = sorted(poses)
    matrices = np.array([poses[t] for t in stamps]).reshape(-1, 4, 4)
    q = _quaternion_wxyz(matrices[:, :3, :3]) if stamps else np.zeros((0, 4))
    feather.write_feather(
        pa.table(
            {
                "timestamp_ns": np.array(stamps, np.int64),
                **{c: q[:, i] for i, c in enumerate(("qw", "qx", "qy", "qz"))},
                **{c: matrices[:, i, 3] for i, c in enumerate(("tx_m", "ty_m", "tz_m"))},
            }
        ),
        log_dir / "city_SE3_egovehicle.feather",
    )

    cuboid_poses = np.array([r[4] for r in rows]).reshape(-1, 4, 4)
    q = _quaternion_wxyz(cuboid_poses[:, :3, :3]) if rows else np.zeros((0, 4))
    sizes = np.array([r[3] for r in rows]).reshape(-1, 3)
    feather.write_feather(
        pa.table(
            {
                "timestamp_ns": pa.array([r[0] for r in rows], pa.int64()),
                "track_uuid": pa.array([r[1] for r in rows], pa.string()),
                "category": pa.array([r[2] for r in rows], pa.string()),
                "length_m": sizes[:, 0],
                "width_m": sizes[:, 1],
                "height_m": sizes[:, 2],
                **{c: q[:, i] for i, c in enumerate(("qw", "qx", "qy", "qz"))},
                **{c: cuboid_poses[:, i, 3] for i, c in enumerate(("tx_m", "ty_m", "tz_m"))},
                "num_interior_pts": pa.array([r[5] for r in rows], pa.int64()),
            }
        ),
        log_dir / "annotations.feather",
    )

    resolution = _check_length(ground_resolution, "ground_resolution")
    if resolution <= 0:
        raise ValueError("ground_resolution must be > 0.")
    if np.ndim(ground_height) == 0:
        level = float(ground_height)
        city = np.vstack([_apply(poses[t], clouds[t]) for t in clouds])
        low, high = city[:, :2].min(axis=0) - 10.0, city[:, :2].max(axis=0) + 10.0
        origin = low if ground_origin is None else np.asarray(ground_origin, dtype=float)
        shape = np.ceil((high - origin) / resolution).astype(int)[::-1]
        raster = np.full(np.maximum(shape, 1), level)
    else:
        raster = np.asarray(ground_height, dtype=float)
        if raster.ndim != 2 or raster.size == 0:
            raise ValueError(f"ground_height must be a number or a 2-D array; got {raster.shape}.")
        if ground_origin is None:
            raise ValueError("ground_origin (the city x, y of cell (0, 0)) is needed for an array.")
        origin = np.asarray(ground_origin, dtype=float)
    if origin.shape != (2,) or not np.all(np.isfinite(origin)):
        raise ValueError(f"ground_origin must be 2 finite numbers; got {ground_origin!r}.")
    log_id = log_dir.resolve().name if log_id is None else str(log_id)
    np.save(
        log_dir / "map" / f"{log_id}_ground_height_surface____{city_name}.npy",
        raster.astype(np.float16),
    )
    sim2 = {"R": [1.0, 0.0, 0.0, 1.0], "t": (-origin).tolist(), "s": 1.0 / resolution}
    (log_dir / "map" / f"{log_id}___img_Sim2_city.json").write_text(json.dumps(sim2))
    return log_dir
