"""Frames half a second apart: the evidence of objects too slow for their pairs.

A walker at 1 m/s moves 0.1 m between 10 Hz sweeps, about one spacing of its points at
10 m, and a car's side slides along itself: a pair cannot tell such a motion from none,
though half a second shows it plainly (2 Hz keyframes' pairs see walkers). Where a log's
frames come faster, each pair's first sweep is also compared with the frame about
:data:`LONG_SPAN` before it (:func:`long_partner`), by the same claims as a pair
(:mod:`mmreg.tracking._evidence`, :mod:`mmreg.tracking._births`). A motion found there
is the motion of the last half second; the pair's motion is taken at its constant twist
(:func:`pair_motion`), and the pair itself must not refute it (:func:`refuted`): a car
that has stopped since moved in the span, and its pair shows it standing.
"""

import numpy as np

from mmreg.tracking._evidence import _Answers
from mmreg.tracking._motion import compose, inverse, predicted_motion, twist_of

__all__ = ["LONG_SPAN", "kept_frames", "long_partner", "pair_motion", "refuted"]

# Seconds between the frames compared (the 2 Hz interval, at which pairs see walkers).
LONG_SPAN = 0.5
# Frames kept for it at most (a 20 Hz log's half second): the memory it costs.
_MOST_FRAMES = 10
# Frame times agree within a millisecond (a sensor's clock jitters, and ten 10 Hz
# intervals in floating point are not exactly 1 s).
_TIME_SLACK = 1e-3


def _far_enough(frame, other):
    return frame.time - other.time >= LONG_SPAN - _TIME_SLACK


def kept_frames(recent, frame):
    """The frames to keep once ``frame`` joins ``recent`` (oldest first): back to the
    newest one at least :data:`LONG_SPAN` before ``frame``, at most ``_MOST_FRAMES``.

    Examples
    --------
    >>> from types import SimpleNamespace as F
    >>> from mmreg.tracking._long_span import kept_frames
    >>> frames = [F(index=k, time=k / 10) for k in range(9)]
    >>> [f.index for f in kept_frames(frames[:8], frames[8])]
    [3, 4, 5, 6, 7, 8]
    """
    recent = [*recent, frame][-_MOST_FRAMES:]
    far = [i for i, other in enumerate(recent) if _far_enough(frame, other)]
    return recent[far[-1] :] if far else recent


def long_partner(recent, frame):
    """The newest of ``recent`` at least :data:`LONG_SPAN` before ``frame`` and two
    frames back (one frame back is the pair itself: a 2 Hz log has no partner), or None.

    Examples
    --------
    >>> from types import SimpleNamespace as F
    >>> from mmreg.tracking._long_span import long_partner
    >>> frames = [F(index=k, time=k / 10) for k in range(9)]
    >>> long_partner(frames[:8], frames[8]).index
    3
    >>> slow = [F(index=k, time=k / 2) for k in range(3)]
    >>> long_partner(slow[:2], slow[2]) is None
    True
    """
    for other in reversed(recent):
        if _far_enough(frame, other):
            return other if frame.index - other.index >= 2 else None
    return None


def pair_motion(back, poses, centre, span, dt):
    """The motion of a pair's first sweep to its second at the constant twist of ``back``.

    ``back`` (4 x 4) carries an object's points from the pair's first sweep to the sweep
    ``span`` earlier, each in its sensor's frame; ``poses`` are the sensor's poses (world
    from sensor) at the first sweep, the second and the earlier one; ``centre``: the
    object's centre in the world at the first sweep; ``dt``: the pair's interval.
    Returns the 4 x 4 motion from the first sweep's frame to the second's.
    """
    first, second, earlier = poses
    world = compose(earlier, back, inverse(first))
    omega, velocity = twist_of(world, centre, -span)
    return compose(inverse(second), predicted_motion(omega, velocity, centre, dt), first)


def refuted(points, ego, motion, target, *, ties=False):
    """Whether the next sweep refutes ``motion`` of ``points`` against the ego motion.

    It does when more of the points lie on it (within two of its spacings, as a claim
    counts them) where ``ego`` puts them and not where ``motion`` does than the other
    way round; with ``ties``, also when as many do (no more points say it moves than say
    it stands: an object the sweeps showed stopping needs the next sweep's word to move
    again). ``target``: ``(sweep, tree, normals)`` of the next sweep.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.spatial import cKDTree
    >>> from mmreg.sweeps._icp import SurfaceNormals
    >>> from mmreg.tracking._long_span import refuted
    >>> g = np.arange(0.0, 1.0, 0.05)
    >>> box = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    >>> shift = np.eye(4)
    >>> shift[0, 3] = 0.3
    >>> standing = (box, cKDTree(box), SurfaceNormals(box, cKDTree(box), 10))
    >>> moved = box + [0.3, 0, 0]
    >>> gone = (moved, cKDTree(moved), SurfaceNormals(moved, cKDTree(moved), 10))
    >>> refuted(box, np.eye(4), shift, standing), refuted(box, np.eye(4), shift, gone)
    (True, False)

    A shift of a hundredth of the spacing: the sweep tells the two apart nowhere.

    >>> creep = np.eye(4)
    >>> creep[0, 3] = 0.0005
    >>> still = refuted(box, np.eye(4), creep, standing)
    >>> still, refuted(box, np.eye(4), creep, standing, ties=True)
    (False, True)
    """
    answers = _Answers(points, target, scale=None)
    on_ego, on_motion = answers.explained(ego), answers.explained(motion)
    against = np.count_nonzero(on_ego & ~on_motion)
    for_ = np.count_nonzero(on_motion & ~on_ego)
    return bool(against > for_ or (ties and against == for_))
