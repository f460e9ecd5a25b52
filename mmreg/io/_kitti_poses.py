"""KITTI text tables: poses (12 numbers a line, a 3 x 4 matrix row-major) and frame times."""

import numpy as np

from mmreg._validation import ROTATION_TOLERANCE, are_rotations
from mmreg.io._arrays import _load_text_table
from mmreg.io._atomic import atomic_write
from mmreg.io._checks import _as_numeric, _check_readable

__all__ = ["read_kitti_poses", "write_kitti_poses"]


def _kitti_matrices(path, n_values, what):
    """(m, n_values) finite float rows of a KITTI text file (poses.txt, times.txt)."""
    table = _load_text_table(_check_readable(path, what))
    if table.ndim != 2 or table.shape[1] != n_values:
        raise ValueError(
            f"{path}: {what} must hold {n_values} number(s) a line; got shape {table.shape}."
        )
    if not np.all(np.isfinite(table)):
        bad = np.flatnonzero(~np.all(np.isfinite(table), axis=1))
        raise ValueError(
            f"{path}: {what} holds NaN or infinity ({len(bad)} lines, the first is line "
            f"{bad[0] + 1} of the data)."
        )
    return table


def _not_rigid(rotations):
    """Indices of the rotations that are not rotations (R^T R != I or det R != 1)."""
    return np.flatnonzero(~are_rotations(rotations))


def read_kitti_poses(path):
    """Read a KITTI pose file: one 3 x 4 matrix ``[R | t]`` a line, 12 numbers row-major.

    Line ``k`` is frame ``k``'s pose in a fixed world frame, ``x_world = R x_frame + t``
    (KITTI odometry's ``poses/NN.txt``, SemanticKITTI's ``poses.txt``).

    Parameters
    ----------
    path : str or path-like
        The text file (space, tab or comma separated).

    Returns
    -------
    poses : ndarray of shape (n_frames, 4, 4)
        Homogeneous matrices, bottom row ``0 0 0 1``.

    Raises
    ------
    FileNotFoundError
        If the file is missing.
    ValueError
        If it is empty, a line does not hold 12 numbers, a number is NaN or infinite, or a
        rotation is not one (``R^T R = I`` and ``det R = 1`` within 1e-4); the message
        names the line.
    TypeError
        If a line holds text.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.io import read_kitti_poses, write_kitti_poses
    >>> poses = np.tile(np.eye(4), (2, 1, 1))
    >>> poses[1, :3, 3] = [1.5, 0.0, 0.1]
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_kitti_poses(Path(folder) / "poses.txt", poses)
    ...     print((Path(folder) / "poses.txt").read_text().splitlines()[1])
    ...     back = read_kitti_poses(Path(folder) / "poses.txt")
    1.0 0.0 0.0 1.5 0.0 1.0 0.0 0.0 0.0 0.0 1.0 0.1
    >>> back.shape, bool(np.array_equal(back, poses))
    ((2, 4, 4), True)
    """
    table = _kitti_matrices(path, 12, "poses (a 3 x 4 matrix row-major)")
    poses = np.tile(np.eye(4), (len(table), 1, 1))
    poses[:, :3] = table.reshape(-1, 3, 4)
    bad = _not_rigid(poses[:, :3, :3])
    if len(bad):
        raise ValueError(
            f"{path}: the rotation of {len(bad)} pose(s) is not a rotation (R^T R = I and "
            f"det R = 1 within {ROTATION_TOLERANCE:g}), the first on line {bad[0] + 1} of the "
            "data."
        )
    return poses


def write_kitti_poses(path, poses):
    """Write poses as a KITTI pose file, atomically: 12 numbers a line, ``[R | t]`` row-major.

    Numbers are written in Python's shortest round-trip form, so :func:`read_kitti_poses`
    gives back exactly the poses written. Whether the first pose is the identity (KITTI's
    custom) is the caller's choice.

    Parameters
    ----------
    path : str or path-like
        The text file (``poses.txt``).
    poses : array-like of shape (n_frames, 4, 4) or (n_frames, 3, 4)
        Rigid motions; a 4 x 4 matrix's bottom row must be ``0 0 0 1``.

    Raises
    ------
    ValueError
        If the shape is wrong, there are no poses, a value is NaN or infinite, a bottom
        row is not ``0 0 0 1``, or a rotation is not one (within 1e-4).

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.io import write_kitti_poses
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_kitti_poses(Path(folder) / "poses.txt", np.eye(4)[None])
    ...     print((Path(folder) / "poses.txt").read_text(), end="")
    1.0 0.0 0.0 0.0 0.0 1.0 0.0 0.0 0.0 0.0 1.0 0.0
    """
    poses = _as_numeric(poses, "poses", "poses")
    if poses.ndim != 3 or poses.shape[1:] not in ((4, 4), (3, 4)):
        raise ValueError(
            f"poses must have shape (n_frames, 4, 4) or (n_frames, 3, 4); got {poses.shape}."
        )
    if not len(poses):
        raise ValueError("poses is empty; a pose file needs at least one pose.")
    finite = np.all(np.isfinite(poses), axis=(1, 2))
    if not finite.all():
        raise ValueError(f"poses hold NaN or infinity (the first in pose {np.argmin(finite)}).")
    if poses.shape[1] == 4:
        wrong = np.flatnonzero(np.any(poses[:, 3] != [0.0, 0.0, 0.0, 1.0], axis=1))
        if len(wrong):
            raise ValueError(
                f"poses must be homogeneous, bottom row 0 0 0 1; pose {wrong[0]} has "
                f"{poses[wrong[0], 3].tolist()}."
            )
    bad = _not_rigid(poses[:, :3, :3])
    if len(bad):
        raise ValueError(
            f"poses[{bad[0]}]'s rotation is not a rotation (R^T R = I and det R = 1 within "
            f"{ROTATION_TOLERANCE:g}); {len(bad)} pose(s) are not rigid."
        )
    rows = poses[:, :3].reshape(len(poses), 12).tolist()
    with atomic_write(path, "w") as handle:
        handle.write("".join(" ".join(map(repr, row)) + "\n" for row in rows))
