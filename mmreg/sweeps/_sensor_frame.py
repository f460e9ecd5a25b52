"""Whether raw points look like a LiDAR sweep in its sensor's frame: z up, the sensor at
the origin.

Every raw stage reads a sweep in its sensor's frame: the ground lies below the sensor
along z (Patchwork++, the ego vehicle's body, the road users' level motions), and the
sensor sees from the origin (what it could see, the range image, the faces turned away
from it). Points in a map's frame, or from a sensor mounted with another axis up, are
valid numbers that give a wrong answer without a word: a generated log moved to UTM
coordinates found no moving point (0 of 13k), a pair took 13 times as long; the same
log with y up found 37 moving objects a frame, where 5 move. :func:`sensor_frame_problems`
tells both from what the points show alone:

* the sensor outside the sweep: a spinning sensor sits inside what it sees, and one that
  looks one way (a solid-state LiDAR, a camera) at its edge; the origin farther from the
  bulk of the points (their 5-95 % box) than that box is long is not their sensor's;
* another axis up: a LiDAR sweep spreads along the ground far more than it rises
  (:func:`mmreg.sweeps._ground.is_z_up_sweep`); one whose x or y spans under a quarter of
  the other two axes' widest span, where z does not, lies flat across them, with that
  axis vertical.
"""

import numpy as np

from mmreg._warnings import warn
from mmreg.sweeps._ground import flat_across

__all__ = ["SensorFrameWarning", "sensor_frame_problems", "warn_if_not_sensor_frame"]

# The bulk of a sweep: this percentile range of each coordinate (a few far or stray
# returns do not widen it).
_BULK = (5.0, 95.0)
# Points enough to place the bulk; a larger sweep is read at evenly spread rows.
_SAMPLE = 5000


class SensorFrameWarning(UserWarning):
    """Raw points that do not look like a LiDAR sweep in its sensor's frame (z up, the
    sensor at the origin): every raw stage reads them so."""


def sensor_frame_problems(points):
    """How raw ``points`` (valid returns, ``(n, 3)``) miss their sensor's frame.

    Returns
    -------
    problems : list of tuple
        ``("away", gap, extent)`` where the origin lies ``gap`` from the bulk of the
        points (their 5-95 % box), more than the box's diagonal ``extent``;
        ``("up", axis)`` where they lie flat across the other two axes, ``axis``
        (``"x"`` or ``"y"``) vertical. Empty where they look like a sweep in its
        sensor's frame, or are too few (under 10) to tell.

    Examples
    --------
    A street around a sensor 1.8 m above it, in its own frame, 4,000 km off (a map's
    coordinates) and with y up:

    >>> import numpy as np
    >>> from mmreg.sweeps._sensor_frame import sensor_frame_problems
    >>> rng = np.random.default_rng(0)
    >>> street = rng.uniform([-50, -50, -1.8], [50, 50, 4], (2000, 3))
    >>> sensor_frame_problems(street)
    []
    >>> [p[0] for p in sensor_frame_problems(street + [5e5, 4e6, 0])]
    ['away']
    >>> sensor_frame_problems(street[:, [0, 2, 1]])
    [('up', 'y')]
    """
    points = np.asarray(points, dtype=float)
    if len(points) < 10:
        return []
    if len(points) > _SAMPLE:
        points = points[np.linspace(0, len(points) - 1, _SAMPLE).astype(np.intp)]
    low, high = np.percentile(points, _BULK, axis=0)
    problems = []
    gap = float(np.linalg.norm(np.fmax(low, 0.0) + np.fmax(-high, 0.0)))
    extent = float(np.linalg.norm(high - low))
    # Coincident points (extent 0) are another problem (a DegenerateInputWarning).
    if 0 < extent < gap:
        problems.append(("away", gap, extent))
    spread = high - low
    flat = [axis for axis in (0, 1) if flat_across(spread, axis) and not flat_across(spread, 2)]
    if flat:
        problems.append(("up", "xy"[min(flat, key=lambda axis: spread[axis])]))
    return problems


def warn_if_not_sensor_frame(points, of, problems=("away", "up")):
    """A :class:`SensorFrameWarning` for each way raw ``points`` miss their sensor's
    frame (:func:`sensor_frame_problems`, of the kinds in ``problems``), which ``of``
    names ("the first sweep"); the kinds found (a set)."""
    found = [p for p in sensor_frame_problems(points) if p[0] in problems]
    for problem in found:
        if problem[0] == "away":
            _, gap, extent = problem
            text = (
                f"the origin lies {gap:.3g} from {of}, farther than it extends "
                f"({extent:.3g}): the points are not in their sensor's frame (a map's or "
                "a world frame?). Raw sweeps are read as the sensor gives them, the "
                "sensor at the origin: subtract its position, or give the points as the "
                "sensor wrote them (and a log's poses as poses=)."
            )
        else:
            axis = problem[1]
            text = (
                f"{of} lies flat across the axes other than {axis}: a LiDAR sweep with "
                f"{axis} vertical. The ground, the ego vehicle's body and the road users' "
                "level motions are found with z up: rotate the points so that z points "
                "up."
            )
        warn(text, SensorFrameWarning)
    return {problem[0] for problem in found}
