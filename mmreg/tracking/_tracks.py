"""Tracks of moving objects in the world frame: predict, associate, update, confirm, end.

A track (:class:`Track`) holds the object's last seen points in the world frame, the time
they were seen and a constant twist (:mod:`mmreg.tracking._motion`) fitted to its last
measured motion. One step of a log, as in AB3DMOT (Weng et al., IROS 2020): every track
is predicted to the frame's time; the frame's detections (point sets with a measured
motion) are associated with the tracks by how many of their points lie where a track's
points are predicted; matched tracks are updated, detections nobody claims become
tentative tracks, and tracks that miss too many frames end. A tentative track is
confirmed when its motion holds into a second pair: a detection there follows its
prediction. A motion seen in one pair only (a ghost) dies tentative.
"""

from dataclasses import dataclass

import numpy as np

from mmreg._array.geometry import rows_in_box
from mmreg._array.neighbors import lookup_tree
from mmreg.tracking._motion import predicted_motion, transform, twist_of

__all__ = ["Track", "consistent_motion", "overlap_matrix"]


@dataclass
class Track:
    """One object followed from frame to frame (world frame, the log's time unit)."""

    key: int
    points: np.ndarray  # last seen points, world frame
    time: float  # when they were seen
    frame: int  # the frame they were seen in
    omega: np.ndarray  # rotation vector per unit time
    velocity: np.ndarray  # the centre's velocity
    hits: int = 1
    misses: int = 0
    identity: int = 0  # the public id, given when confirmed
    first_frame: int = -1  # the earliest frame it has points in (-1: its first frame)
    # The confirmed track that missed, in the pair this one was born in, the cluster it was
    # born on over its prediction (-1: none): confirmed, this one goes on with its id.
    heir_of: int = -1
    # Found over the long span (frames half a second apart), where its pairs show nothing:
    # it is followed there too.
    slow: bool = False
    # Over the long span, the pair last refuted its motion (it had stopped since): a claim
    # there needs the pair's evidence that it moves again, not only none against it.
    stopped: bool = False

    def __post_init__(self):
        if self.first_frame < 0:
            self.first_frame = self.frame

    @property
    def centre(self):
        return self.points.mean(axis=0)

    @property
    def confirmed(self):
        return self.identity > 0

    def motion(self, dt):
        """The predicted 4 x 4 world motion of its points over ``dt``."""
        return predicted_motion(self.omega, self.velocity, self.centre, dt)

    def predicted_points(self, time):
        """Its points where the twist puts them at ``time``."""
        return transform(self.motion(time - self.time), self.points)

    def update(self, points, time, frame, motion, dt):
        """A detection: ``points`` (world) seen at ``time``, moving by ``motion`` over ``dt``."""
        self.points, self.time, self.frame = points, time, frame
        self.omega, self.velocity = twist_of(motion, points.mean(axis=0), dt)
        self.hits += 1
        self.misses = 0

    def coast(self, time, frame):
        """No detection at ``frame``: its points move on by the twist."""
        self.points = self.predicted_points(time)
        self.time, self.frame = time, frame
        self.misses += 1


def overlap_matrix(detections, predictions, radii):
    """Share of each detection's points within ``radii[j]`` of track ``j``'s predicted points.

    ``detections`` and ``predictions`` are lists of (n_i, 3) arrays in one frame.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.tracking._tracks import overlap_matrix
    >>> d = [np.zeros((4, 3)), np.ones((2, 3)) * 10]
    >>> p = [np.zeros((1, 3)) + 0.1]
    >>> overlap_matrix(d, p, [0.5]).tolist()
    [[1.0], [0.0]]
    """
    table = np.zeros((len(detections), len(predictions)))
    for j, (where, radius) in enumerate(zip(predictions, radii, strict=True)):
        if not len(where):
            continue
        tree = lookup_tree(where)  # distances alone are read
        low, high = where.min(axis=0) - radius, where.max(axis=0) + radius
        for i, points in enumerate(detections):
            inside = rows_in_box(points, low, high)
            if not len(inside):
                continue
            distance, _ = tree.query(points[inside], distance_upper_bound=radius)
            table[i, j] = np.count_nonzero(np.isfinite(distance)) / len(points)
    return table


def consistent_motion(track, velocity, dt, tolerance):
    """Whether a measured ``velocity`` follows the track's within the noise.

    The displacements over ``dt`` may differ by half the track's displacement plus
    ``tolerance`` (a length): a car brakes or turns, a ghost's motion points anywhere.
    """
    predicted = track.velocity * dt
    return bool(
        np.linalg.norm(velocity * dt - predicted) <= 0.5 * np.linalg.norm(predicted) + tolerance
    )
