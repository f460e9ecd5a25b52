"""Whether rows ``[a | b]`` are two LiDAR sweeps stacked row by row, not correspondences.

Two sweeps of the same size (a fixed-size downsampling gives that every time) stacked
row by row pair row ``i`` of one scan with row ``i`` of the other. A scanner writes its
returns in the order of its beams and azimuths, so row ``i`` of both is about the same
ray: the ground and the walls along the road come back at about the same range, and the
rows read as "the world did not move" however far the sensor drove. The estimators'
test of pairs (:func:`mmreg._validation.check_paired`: neighbouring rows must move
alike) passes them, since neighbouring rays move alike too; the fit then finds the
static world at rest and a hundred "moving" pieces.

The test here asks the sweeps themselves where the static world went: the ego motion
between the two clouds as sets (:func:`mmreg.sweeps._ego_motion.ego_motion`, GICP from
the identity). Correspondences follow that motion on the static world (their b-points
are the second cloud, so the ICP finds their own motion), up to their noise and their
wrong rows, which differ from row to row. Rows of two scans do not, in one of two ways:

* they stay where they were: more rows are explained by "nothing moved" alone than by
  the sweeps' motion alone, and at least :data:`MAX_STILL_ONLY` of them. Ray-cast
  streets (2 m drive) and real nuScenes pairs, stacked row by row: 0.22-0.59;
  correspondences (the truth, with noise, with half the rows wrong): at most 0.05;
* their order drifts between the scans (each scan cut to a fixed size by evenly spaced
  rows: a row of one is a few azimuth steps from its row in the other), so the rows
  follow neither, but their misfit is a smooth field: the b-points lie a median of more
  than :data:`STILL_SPACINGS` point spacings from where the sweeps' motion takes the
  a-points, and nearest rows are misplaced alike (the median difference of nearest rows'
  misfits is below :data:`MAX_COHERENCE` times the median misfit). Stacked and drifting
  rows gave 0.00-0.06 (nuScenes, 2 m drive) and up to 0.17 (a still sensor);
  correspondences with noise or wrong rows 1.2 and more, and without either a misfit of
  0.03 spacings or less.

Every length is relative: a row "stays" when its b-point lies within
:data:`STILL_SPACINGS` times its a-point's distance to its nearest neighbour, and the
ICP's scale is the points' median distance from the sensor.

Only clouds that both look like LiDAR sweeps around their sensor are tested
(:func:`mmreg._array.frames.detect_frame`); a sensor that did not move leaves little to
tell (stacked scans of a still sensor are then close to right for the static world). An
ICP that failed on real correspondences would read as a smooth misfit: it aligns the
a-points with their own b-points, which only a drive beyond the reach (the points'
median distance from the sensor) would defeat.
"""

import numpy as np
from scipy.spatial import cKDTree

from mmreg._array.frames import detect_frame
from mmreg._validation import NotCorrespondencesError, invalid_rows

__all__ = ["MAX_COHERENCE", "MAX_STILL_ONLY", "STILL_SPACINGS", "check_rows_follow_motion"]
__all__ += ["stacked_sweeps"]

#: A row "stays" when its b-point lies within this many of its a-point's nearest-neighbour
#: distances of the a-point (or of where the sweeps' motion takes it).
STILL_SPACINGS = 4.0
#: The share of rows explained by "nothing moved" and not by the sweeps' own motion from
#: which the rows are two scans (when that share also exceeds the opposite one).
MAX_STILL_ONLY = 0.2
#: Rows whose misfit to the sweeps' motion exceeds STILL_SPACINGS point spacings are two
#: scans when nearest rows' misfits differ by less than this share of the misfit (a
#: smooth field, not noise: noise or wrong rows give about the square root of 2).
MAX_COHERENCE = 0.5
# Rows the shares are measured on (evenly strided); fewer rows are not judged.
_SAMPLE = 4096
_MIN_ROWS = 100
# The ego ICP's scale: this share of the points' median distance from the sensor; it
# reaches 4 scales (the median distance) from the identity.
_SCALE_PER_RANGE = 0.25
_REACH_SCALES = 4.0


def stacked_sweeps(a, b, *, workers=1):
    """How rows ``(a_i, b_i)`` relate to the motion of the two clouds as sets.

    Parameters
    ----------
    a, b : array-like of shape (n, 3)
        The rows' a-points and b-points.
    workers : int, default=1
        Threads of the KD-tree and the ICP.

    Returns
    -------
    found : dict or None
        None when the clouds do not both look like LiDAR sweeps or no motion can be
        found between them; else ``still_only`` and ``moved_only`` (shares of the rows
        that stay where they were but do not follow the sweeps' motion, and the
        reverse), ``misfit_spacings`` (the median distance of the b-points from where the
        sweeps' motion takes the a-points, in median point spacings), ``coherence`` (the
        median difference of nearest rows' misfits over the median misfit),
        ``translation`` (the length of the sweeps' motion's translation) and ``stacked``
        (whether the rows are two scans, see :data:`MAX_STILL_ONLY` and
        :data:`MAX_COHERENCE`).

    Examples
    --------
    >>> from mmreg.datasets import make_lidar_sweeps
    >>> from mmreg.sweeps._stacked_rows import stacked_sweeps
    >>> scene = make_lidar_sweeps(n_azimuths=512, ego_speed=20.0, random_state=0)
    >>> n = min(len(scene.a), len(scene.sweep))
    >>> stacked_sweeps(scene.a[:n], scene.sweep[:n])["stacked"]  # row i with row i
    True
    >>> stacked_sweeps(scene.a, scene.a + scene.flow)["stacked"]  # where they went
    False
    """
    from mmreg.sweeps._ego_motion import ego_motion

    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    valid = ~invalid_rows(np.hstack([a, b]))
    a, b = a[valid], b[valid]
    if len(a) < _MIN_ROWS or detect_frame(a) != "lidar" or detect_frame(b) != "lidar":
        return None
    scale = _SCALE_PER_RANGE * float(np.median(np.linalg.norm(a, axis=1)))
    try:
        rotation, translation, _ = ego_motion(
            a, b, scale=scale, max_displacement=_REACH_SCALES * scale, workers=workers
        )
    except (ValueError, ImportError):  # too few points or voxels, or no small_gicp
        return None
    rows = np.unique(np.linspace(0, len(a) - 1, min(len(a), _SAMPLE)).astype(np.intp))
    spacing, nearest = cKDTree(a).query(a[rows], k=2, workers=workers)
    spacing, nearest = spacing[:, 1], nearest[:, 1]
    reach = STILL_SPACINGS * spacing
    stays = np.linalg.norm(b[rows] - a[rows], axis=1) <= reach
    misfit = b[rows] - (a[rows] @ rotation.T + translation)
    follows = np.linalg.norm(misfit, axis=1) <= reach
    still_only = float(np.mean(stays & ~follows))
    moved_only = float(np.mean(follows & ~stays))
    # How far the rows lie from the sweeps' motion, and whether nearest rows lie alike.
    size = float(np.median(np.linalg.norm(misfit, axis=1)))
    spacings = size / max(float(np.median(spacing)), np.finfo(float).tiny)
    beside = b[nearest] - (a[nearest] @ rotation.T + translation)
    coherence = float(np.median(np.linalg.norm(misfit - beside, axis=1))) / max(
        size, np.finfo(float).tiny
    )
    still = still_only > max(MAX_STILL_ONLY, moved_only)
    drifted = spacings > STILL_SPACINGS and coherence < MAX_COHERENCE
    return {
        "still_only": still_only,
        "moved_only": moved_only,
        "misfit_spacings": spacings,
        "coherence": coherence,
        "translation": float(np.linalg.norm(translation)),
        "stacked": bool(still or drifted),
    }


def check_rows_follow_motion(a, b, *, where, advice, workers=1):
    """Raise NotCorrespondencesError when rows ``(a_i, b_i)`` are two LiDAR scans stacked.

    Parameters
    ----------
    a, b : array-like of shape (n, 3)
        The rows' a-points and b-points.
    where : str
        What the rows are (a file, a job), for the message.
    advice : str
        What to do instead (how to register two sweeps), ending the message.
    workers : int, default=1

    Raises
    ------
    NotCorrespondencesError
        A ValueError naming the shares measured and ``advice``.

    Examples
    --------
    >>> from mmreg.datasets import make_lidar_sweeps
    >>> from mmreg.sweeps._stacked_rows import check_rows_follow_motion
    >>> scene = make_lidar_sweeps(n_azimuths=512, ego_speed=20.0, random_state=0)
    >>> n = min(len(scene.a), len(scene.sweep))
    >>> check_rows_follow_motion(scene.a[:n], scene.sweep[:n], where="frames", advice="...")
    Traceback (most recent call last):
    ...
    mmreg._validation.NotCorrespondencesError: frames: row i of one cloud is no match ...
    """
    found = stacked_sweeps(a, b, workers=workers)
    if found is None or not found["stacked"]:
        return
    raise NotCorrespondencesError(
        f"{where}: row i of one cloud is no match of row i of the other: they are two LiDAR "
        f"sweeps stacked row by row. The sweeps' own geometry moves the static world by "
        f"{found['translation']:.3g} (the sensor's motion), yet {found['still_only']:.0%} of "
        f"the rows stay where they were (within {STILL_SPACINGS:g} point spacings) without "
        f"following it, and the b-points lie a median of {found['misfit_spacings']:.3g} "
        f"point spacings from where it takes the a-points, nearest rows misplaced alike "
        f"(their misfits differ by {found['coherence']:.2f} of it, not as noise); rows must "
        f"pair a point with where it went. {advice}"
    )
