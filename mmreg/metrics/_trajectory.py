"""How far an estimated trajectory of sensor poses is from the true one, pair by pair."""

import numpy as np

__all__ = ["relative_pose_errors"]


def _check_poses(poses, name):
    poses = np.asarray(poses, dtype=float)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise ValueError(f"{name} must have shape (n_frames, 4, 4); got {poses.shape}.")
    if not np.all(np.isfinite(poses)):
        raise ValueError(f"{name} contains NaN or infinity.")
    return poses


def relative_pose_errors(poses, true_poses):
    """The error of every consecutive frame pair's motion (the relative pose error, RPE).

    For frames ``k`` and ``k + 1`` the estimated motion ``inv(P_{k+1}) P_k`` is compared
    with the true one ``inv(Q_{k+1}) Q_k``: the error is ``inv(true) @ estimated``, whose
    translation's length and rotation's angle are returned. Both trajectories may start
    anywhere (the first pose the identity, a city frame): only motions between frames
    are compared, so the frame each trajectory is written in drops out.

    Parameters
    ----------
    poses : array-like of shape (n_frames, 4, 4)
        The estimated sensor poses (``x_world = P @ x_sensor``).
    true_poses : array-like of shape (n_frames, 4, 4)
        The true ones.

    Returns
    -------
    translation : ndarray of shape (n_frames - 1,)
        In the poses' units (metres).
    rotation_deg : ndarray of shape (n_frames - 1,)
        Degrees.

    Raises
    ------
    ValueError
        If the shapes differ or are not (n_frames, 4, 4), there are fewer than 2 frames,
        or a value is NaN or infinite.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.metrics import relative_pose_errors
    >>> truth = np.tile(np.eye(4), (3, 1, 1))
    >>> truth[:, 0, 3] = [0.0, 1.0, 2.0]  # 1 m a frame along x
    >>> estimate = truth.copy()
    >>> estimate[2, 0, 3] = 2.1  # the second step 10 cm too long
    >>> translation, rotation = relative_pose_errors(estimate, truth)
    >>> np.round(translation, 6).tolist(), rotation.tolist()
    ([0.0, 0.1], [0.0, 0.0])
    """
    poses = _check_poses(poses, "poses")
    true_poses = _check_poses(true_poses, "true_poses")
    if poses.shape != true_poses.shape:
        raise ValueError(
            f"poses has {len(poses)} frames but true_poses {len(true_poses)}; one pose per "
            "frame in each."
        )
    if len(poses) < 2:
        raise ValueError("relative pose errors need at least 2 frames.")
    estimated = np.linalg.inv(poses[1:]) @ poses[:-1]
    true = np.linalg.inv(true_poses[1:]) @ true_poses[:-1]
    error = np.linalg.inv(true) @ estimated
    cosine = (np.trace(error[:, :3, :3], axis1=1, axis2=2) - 1.0) / 2.0
    rotation = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
    return np.linalg.norm(error[:, :3, 3], axis=1), rotation
