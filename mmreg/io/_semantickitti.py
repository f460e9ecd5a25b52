"""SemanticKITTI ``.label`` files: one label per point, and which points move.

Two layouts share the ``.label`` name, told apart by the file's size:

* SemanticKITTI (and LiDAR-MOS): one little-endian ``uint32`` per point, the lower 16
  bits the class, the upper 16 bits the instance id. For moving-object segmentation
  (LiDAR-MOS) the class is ``251`` moving, ``9`` static, ``0`` unlabelled; the full
  SemanticKITTI classes ``252`` to ``259`` are its moving cars, bicyclists, persons,
  motorcyclists, trains, buses, trucks and other vehicles.
* nuScenes logs converted to the SemanticKITTI layout: one ``uint8`` per point, the
  nuScenes lidarseg class (``0`` to ``31``; ``31`` is the ego vehicle's own body) and,
  for points that move, a value of ``32`` or more.
"""

from collections import namedtuple

import numpy as np

from mmreg.io._atomic import atomic_write
from mmreg.io._checks import _check_readable, _extension, _read_bytes

__all__ = [
    "SemanticKittiLabels",
    "moving_from_labels",
    "read_semantickitti_labels",
    "semantickitti_mos_labels",
    "write_semantickitti_labels",
]

# LiDAR-MOS classes (config/semantic-kitti-mos.yaml of LiDAR-MOS: "static" 9, "moving" 251;
# its learning map sends "unlabeled" 0 and "outlier" 1 to the ignored class, every other
# SemanticKITTI class to static and 251-259 to moving).
MOS_UNLABELLED = 0
MOS_STATIC = 9
MOS_MOVING = 251
_SEMANTICKITTI_MOVING = (251, 259)  # inclusive
_SEMANTICKITTI_IGNORED = (0, 1)  # unlabelled, outlier
# nuScenes conversions (one byte a point): the lidarseg classes 0-31, moving points 32 up.
_NUSCENES_EGO_BODY = 31
_NUSCENES_FIRST_MOVING = 32
_CONVENTIONS = ("semantickitti", "nuscenes")
_UINT16_MAX = 0xFFFF

SemanticKittiLabels = namedtuple("SemanticKittiLabels", ["semantic", "instance", "convention"])
SemanticKittiLabels.__doc__ = """The labels of one ``.label`` file.

Attributes
----------
semantic : ndarray of shape (n,), dtype int64
    The class of each point: the lower 16 bits of a SemanticKITTI ``uint32``, or the byte
    of a nuScenes conversion.
instance : ndarray of shape (n,), dtype int64, or None
    The instance id of each point (the upper 16 bits); None for a one-byte file, which has
    none.
convention : {"semantickitti", "nuscenes"}
    Which layout the file had (four bytes a point, or one); pass it to
    :func:`moving_from_labels`.
"""


def _check_ids(values, name, n=None):
    """A 1-D int64 array of integers in ``[0, 65535]`` (length ``n`` when given)."""
    array = np.asarray(values)
    if array.ndim != 1:
        raise ValueError(f"{name} must be 1-D (one per point); got shape {array.shape}.")
    if n is not None and len(array) != n:
        raise ValueError(f"{name} has length {len(array)} but semantic has {n}; one per point.")
    if array.dtype.kind == "f":
        if not np.all(np.isfinite(array)):
            raise ValueError(f"{name} contains NaN or infinity.")
        if not np.all(array == np.round(array)):
            raise TypeError(f"{name} must be integers; got non-integer values.")
    elif array.dtype.kind not in "iub":
        raise TypeError(f"{name} must be integers; got dtype {array.dtype}.")
    if len(array) and (array.min() < 0 or array.max() > _UINT16_MAX):
        raise ValueError(
            f"{name} must lie in [0, 65535] (16 bits of a SemanticKITTI label); got values "
            f"from {array.min()} to {array.max()}."
        )
    return array.astype(np.int64)


def write_semantickitti_labels(path, semantic, instance=None):
    """Write a SemanticKITTI ``.label`` file, atomically: one ``uint32`` per point.

    Each point's value is ``instance << 16 | semantic`` (little-endian), the layout the
    SemanticKITTI and LiDAR-MOS tools read.

    Parameters
    ----------
    path : str or path-like
        A ``.label`` file.
    semantic : array-like of shape (n,)
        The class of each point, integers in ``[0, 65535]`` (e.g. from
        :func:`semantickitti_mos_labels`).
    instance : array-like of shape (n,), optional
        The instance id of each point, integers in ``[0, 65535]``; None writes 0.

    Raises
    ------
    ValueError
        If the extension is not ``.label``, the arrays are not 1-D, differ in length or
        hold values outside ``[0, 65535]``.
    TypeError
        If they are not integers.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.io import write_semantickitti_labels
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = Path(folder) / "000000.label"
    ...     write_semantickitti_labels(path, [251, 9, 0], instance=[3, 0, 0])
    ...     raw = np.fromfile(path, dtype="<u4")
    >>> raw.tolist(), (raw & 0xFFFF).tolist(), (raw >> 16).tolist()
    ([196859, 9, 0], [251, 9, 0], [3, 0, 0])
    """
    _extension(path, (".label",), "SemanticKITTI labels")
    semantic = _check_ids(semantic, "semantic")
    if instance is None:
        instance = np.zeros_like(semantic)
    else:
        instance = _check_ids(instance, "instance", len(semantic))
    raw = (instance.astype("<u4") << 16) | semantic.astype("<u4")
    with atomic_write(path) as handle:
        handle.write(raw.astype("<u4").tobytes())


def read_semantickitti_labels(path, n_points=None):
    """Read a ``.label`` file: SemanticKITTI's ``uint32`` per point, or a ``uint8`` per point.

    The layout follows from the file's size: ``4 n`` bytes hold ``n`` SemanticKITTI labels
    (class in the lower 16 bits, instance id in the upper 16), ``n`` bytes hold the labels
    of a nuScenes log converted to the SemanticKITTI layout. Give ``n_points`` (the
    points of the frame's scan) to tell the two apart; without it the file is read as
    SemanticKITTI's ``uint32``.

    Parameters
    ----------
    path : str or path-like
        A ``.label`` file.
    n_points : int, optional
        The number of points of the scan the file labels.

    Returns
    -------
    labels : SemanticKittiLabels
        ``(semantic, instance, convention)``: ``semantic`` (n,) int64, ``instance`` (n,)
        int64 or None for a one-byte file, ``convention`` ``"semantickitti"`` or
        ``"nuscenes"``.

    Raises
    ------
    FileNotFoundError
        If the file is missing.
    ValueError
        If the extension is not ``.label``, or the size is neither ``4 n_points`` nor
        ``n_points`` bytes (without ``n_points``: not a multiple of 4).

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.io import read_semantickitti_labels, write_semantickitti_labels
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_semantickitti_labels(Path(folder) / "a.label", [251, 9], instance=[3, 0])
    ...     np.array([24, 31, 35], dtype=np.uint8).tofile(Path(folder) / "b.label")
    ...     kitti = read_semantickitti_labels(Path(folder) / "a.label", n_points=2)
    ...     nuscenes = read_semantickitti_labels(Path(folder) / "b.label", n_points=3)
    >>> kitti.semantic.tolist(), kitti.instance.tolist(), kitti.convention
    ([251, 9], [3, 0], 'semantickitti')
    >>> nuscenes.semantic.tolist(), nuscenes.instance, nuscenes.convention
    ([24, 31, 35], None, 'nuscenes')
    """
    path = _check_readable(path, "SemanticKITTI labels")
    _extension(path, (".label",), "SemanticKITTI labels")
    if n_points is not None:
        if isinstance(n_points, (bool, np.bool_)) or not isinstance(n_points, (int, np.integer)):
            raise TypeError(f"n_points must be an integer; got {n_points!r}.")
        if n_points < 0:
            raise ValueError(f"n_points must be >= 0; got {n_points}.")
    data = _read_bytes(path)
    size = len(data)
    if n_points is None:
        if size % 4:
            raise ValueError(
                f"{path}: holds {size} bytes, not a multiple of 4, so not one uint32 per "
                "point (SemanticKITTI); if it holds one byte per point (a nuScenes "
                "conversion), give n_points."
            )
        one_byte = False
    elif size == 4 * n_points:
        one_byte = False
    elif size == n_points:
        one_byte = True
    else:
        raise ValueError(
            f"{path}: holds {size} bytes, which fits neither 4 bytes a point (SemanticKITTI "
            f"uint32, {4 * n_points} bytes) nor 1 byte a point (a nuScenes conversion, "
            f"{n_points} bytes) for the scan's {n_points} points."
        )
    if one_byte:
        semantic = np.frombuffer(data, dtype=np.uint8).astype(np.int64)
        return SemanticKittiLabels(semantic, None, "nuscenes")
    raw = np.frombuffer(data, dtype="<u4")
    semantic = (raw & _UINT16_MAX).astype(np.int64)
    instance = (raw >> 16).astype(np.int64)
    return SemanticKittiLabels(semantic, instance, "semantickitti")


def semantickitti_mos_labels(labels, moving):
    """LiDAR-MOS labels of a frame from a sequence estimate's track labels and moving mask.

    ============================  =================  ==================
    point                         class (lower 16)   instance (upper 16)
    ============================  =================  ==================
    ``labels < 0`` (outlier)      0 (unlabelled)     0
    ``moving``                    251 (moving)       the track id ``t``
    otherwise                     9 (static)         the track id, or 0
    ============================  =================  ==================

    ``labels`` is 0 for the static world and ``t >= 1`` for track ``t``, so the instance
    id is the track id wherever ``labels >= 1`` (a tracked object at rest keeps its id),
    else 0.

    Parameters
    ----------
    labels : array-like of int, shape (n,)
        ``-1`` outliers, ego body and invalid returns; ``0`` the static world; ``t >= 1``
        a track, the same object in every frame. Track ids must be at most 65535.
    moving : array-like of bool, shape (n,)
        Whether each point moves.

    Returns
    -------
    semantic : ndarray of shape (n,), dtype int64
        251, 9 or 0.
    instance : ndarray of shape (n,), dtype int64
        The track id, or 0. Pass both to :func:`write_semantickitti_labels`.

    Raises
    ------
    ValueError
        If the arrays are not 1-D or differ in length, or a track id exceeds 65535.
    TypeError
        If ``labels`` are not integers or ``moving`` not booleans.

    Examples
    --------
    >>> from mmreg.io import semantickitti_mos_labels
    >>> semantic, instance = semantickitti_mos_labels([0, 2, 2, 5, -1], [0, 1, 1, 0, 1])
    >>> semantic.tolist(), instance.tolist()
    ([9, 251, 251, 9, 0], [0, 2, 2, 5, 0])
    """
    labels = np.asarray(labels)
    if labels.ndim != 1:
        raise ValueError(f"labels must be 1-D (one per point); got shape {labels.shape}.")
    if labels.dtype.kind not in "iu":
        raise TypeError(f"labels must be integers; got dtype {labels.dtype}.")
    moving = _check_moving(moving, len(labels))
    labels = labels.astype(np.int64)
    if len(labels) and labels.max() > _UINT16_MAX:
        raise ValueError(
            f"labels holds track {labels.max()}; a SemanticKITTI instance id has 16 bits "
            "(at most 65535)."
        )
    valid = labels >= 0
    semantic = np.where(valid, np.where(moving, MOS_MOVING, MOS_STATIC), MOS_UNLABELLED)
    instance = np.where(labels >= 1, labels, 0)
    return semantic.astype(np.int64), instance


def _check_moving(moving, n):
    moving = np.asarray(moving)
    if moving.shape != (n,):
        raise ValueError(
            f"moving must have shape ({n},), one per point like labels; got {moving.shape}."
        )
    if moving.dtype.kind == "b":
        return moving
    if moving.dtype.kind not in "iu" or (n and not np.all((moving == 0) | (moving == 1))):
        raise TypeError(f"moving must be booleans (or 0/1); got dtype {moving.dtype}.")
    return moving.astype(bool)


def moving_from_labels(semantic, convention):
    """The true moving mask of a frame, and the points to leave out of scores.

    ``"semantickitti"`` (LiDAR-MOS's mapping of the SemanticKITTI classes)
        moving: class 251 (LiDAR-MOS's "moving") to 259 (SemanticKITTI's moving car,
        bicyclist, person, motorcyclist, on-rails, bus, truck, other vehicle: 252-259);
        left out: 0 (unlabelled) and 1 (outlier); static: every other class. A raw
        ``uint32`` value is read by its lower 16 bits.
    ``"nuscenes"`` (one byte a point)
        moving: 32 and above; left out: 31, the ego vehicle's own body; static: the rest.

    Parameters
    ----------
    semantic : array-like of int, shape (n,)
        The class of each point, e.g. :func:`read_semantickitti_labels`'s ``semantic``.
    convention : {"semantickitti", "nuscenes"}
        Which layout the labels come from (``read_semantickitti_labels(...).convention``).

    Returns
    -------
    moving : ndarray of shape (n,), dtype bool
    ignore : ndarray of shape (n,), dtype bool
        The points no score should count (pass it as ``ignore`` to
        :func:`mmreg.metrics.moving_iou`); never moving.

    Raises
    ------
    ValueError
        If ``convention`` is unknown, ``semantic`` is not 1-D, or it holds a value its
        layout cannot (negative, or above 255 for ``"nuscenes"``).
    TypeError
        If ``semantic`` is not integers.

    Examples
    --------
    >>> from mmreg.io import moving_from_labels
    >>> moving, ignore = moving_from_labels([9, 251, 254, 40, 0, 1], "semantickitti")
    >>> moving.astype(int).tolist(), ignore.astype(int).tolist()
    ([0, 1, 1, 0, 0, 0], [0, 0, 0, 0, 1, 1])
    >>> moving, ignore = moving_from_labels([24, 31, 32, 39], "nuscenes")
    >>> moving.astype(int).tolist(), ignore.astype(int).tolist()
    ([0, 0, 1, 1], [0, 1, 0, 0])
    """
    if convention not in _CONVENTIONS:
        raise ValueError(
            f"convention must be one of {', '.join(map(repr, _CONVENTIONS))}; got {convention!r}."
        )
    semantic = np.asarray(semantic)
    if semantic.ndim != 1:
        raise ValueError(f"semantic must be 1-D (one per point); got shape {semantic.shape}.")
    if semantic.dtype.kind not in "iu":
        raise TypeError(f"semantic must be integers; got dtype {semantic.dtype}.")
    semantic = semantic.astype(np.int64)
    top = 0xFFFFFFFF if convention == "semantickitti" else 0xFF
    if len(semantic) and (semantic.min() < 0 or semantic.max() > top):
        raise ValueError(
            f"semantic holds values from {semantic.min()} to {semantic.max()}; "
            f"{convention!r} labels lie in [0, {top}]."
        )
    if convention == "semantickitti":
        semantic = semantic & _UINT16_MAX
        low, high = _SEMANTICKITTI_MOVING
        moving = (semantic >= low) & (semantic <= high)
        ignore = np.isin(semantic, _SEMANTICKITTI_IGNORED)
    else:
        moving = semantic >= _NUSCENES_FIRST_MOVING
        ignore = semantic == _NUSCENES_EGO_BODY
    return moving, ignore
