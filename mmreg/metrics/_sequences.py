"""Measures over a whole LiDAR log: moving-object segmentation IoU and tracking per point.

A sequence estimate gives, for every frame, one label per point; these functions take
lists of per-frame arrays (the frames may hold different numbers of points) and add up
over the frames.
"""

from dataclasses import dataclass

import numpy as np

__all__ = ["TrackingScores", "moving_iou", "tracking_scores"]


def _as_frames(values, name):
    """A list of per-frame 1-D arrays: a sequence of arrays, a 2-D array, or one frame."""
    if isinstance(values, (list, tuple)):
        if not values:
            raise ValueError(f"{name} holds no frames.")
        if np.ndim(values[0]) >= 1:
            return [np.asarray(v) for v in values]
        return [np.asarray(values)]
    array = np.asarray(values)
    if array.ndim == 2:
        return list(array)
    return [array]


def _check_frames(values, name, lengths, kind):
    """Per-frame arrays of ``values`` checked against ``lengths`` (None: take theirs)."""
    frames = _as_frames(values, name)
    if lengths is not None and len(frames) != len(lengths):
        raise ValueError(
            f"{name} holds {len(frames)} frame(s) but the truth holds {len(lengths)}; one "
            "array per frame is needed."
        )
    checked = []
    for k, frame in enumerate(frames):
        where = f"{name}[{k}]" if len(frames) > 1 else name
        if frame.ndim != 1:
            raise ValueError(f"{where} must be 1-D (one value per point); got shape {frame.shape}.")
        if lengths is not None and len(frame) != lengths[k]:
            raise ValueError(
                f"{where} has {len(frame)} points but the truth's frame has {lengths[k]}; one "
                "value per point is needed."
            )
        checked.append(_check_mask(frame, where) if kind == "mask" else _check_ids(frame, where))
    return checked


def _check_mask(frame, where):
    if frame.dtype.kind == "b":
        return frame
    if frame.dtype.kind not in "iuf":
        raise TypeError(f"{where} must be booleans; got dtype {frame.dtype}.")
    if frame.dtype.kind == "f" and not np.all(np.isfinite(frame)):
        raise ValueError(f"{where} contains NaN or infinity.")
    if not np.all((frame == 0) | (frame == 1)):
        raise ValueError(f"{where} must be booleans (or 0/1); got other values.")
    return frame.astype(bool)


def _check_ids(frame, where):
    if frame.dtype.kind == "f":
        if not np.all(np.isfinite(frame)):
            raise ValueError(f"{where} contains NaN or infinity.")
        if not np.all(frame == np.round(frame)):
            raise TypeError(f"{where} must be integers; got non-integer values.")
    elif frame.dtype.kind not in "iu":
        raise TypeError(f"{where} must be integers; got dtype {frame.dtype}.")
    return frame.astype(np.int64)


def _check_ignore(ignore, lengths):
    if ignore is None:
        return [np.zeros(n, dtype=bool) for n in lengths]
    return _check_frames(ignore, "ignore", lengths, "mask")


def moving_iou(y_true_moving, y_pred_moving, *, ignore=None):
    """Intersection over union of the moving points (LiDAR-MOS's moving-object IoU).

    With the moving points as positives, over every point of every frame that is not
    left out,

    .. math::

        \\mathrm{IoU}_{\\mathrm{MOS}} = \\frac{TP}{TP + FP + FN},

    the measure of Chen et al., "Moving Object Segmentation in 3D LiDAR Data" (2021).
    The counts are summed over the frames before the ratio is taken, as LiDAR-MOS's
    evaluation does: a frame with many points weighs more, and it is not the mean of
    per-frame IoUs.

    Parameters
    ----------
    y_true_moving : array-like of bool, shape (n,), or a sequence of them (one per frame)
        Whether each point truly moves (e.g. :func:`mmreg.io.moving_from_labels`).
    y_pred_moving : the same shapes
        Whether it is estimated to move.
    ignore : the same shapes, optional
        Points no count includes: the ego vehicle's body, unlabelled or invalid returns.

    Returns
    -------
    iou : float
        In ``[0, 1]``; NaN when no point left in is moving in either.

    Raises
    ------
    ValueError
        If the frames differ in number or length, or a mask is not 1-D or not 0/1.
    TypeError
        If a mask is not boolean.

    Examples
    --------
    >>> from mmreg.metrics import moving_iou
    >>> moving_iou([1, 1, 0, 0], [1, 0, 1, 0])
    0.3333333333333333
    >>> frames_true = [[1, 1, 0, 0], [1, 1, 1, 1, 0, 0]]
    >>> frames_pred = [[1, 0, 0, 0], [1, 1, 1, 1, 0, 0]]
    >>> moving_iou(frames_true, frames_pred)  # (1 + 4) / (2 + 4), not (1/2 + 1) / 2
    0.8333333333333334
    >>> moving_iou(frames_true, frames_pred, ignore=[[0, 1, 0, 0], [0] * 6])
    1.0
    """
    truth = _check_frames(y_true_moving, "y_true_moving", None, "mask")
    lengths = [len(frame) for frame in truth]
    pred = _check_frames(y_pred_moving, "y_pred_moving", lengths, "mask")
    left_out = _check_ignore(ignore, lengths)
    inter = union = 0
    for t, p, out in zip(truth, pred, left_out, strict=True):
        keep = ~out
        inter += np.count_nonzero(t & p & keep)
        union += np.count_nonzero((t | p) & keep)
    return float(inter / union) if union else float("nan")


@dataclass(frozen=True)
class TrackingScores:
    """What :func:`tracking_scores` finds: per object, per frame and in sum.

    Attributes
    ----------
    objects : ndarray of shape (n_objects,)
        The true object ids (``>= 1``), sorted.
    visible : ndarray of shape (n_frames, n_objects), dtype bool
        Whether the object has a point (not left out) in the frame.
    matches : ndarray of shape (n_frames, n_objects), dtype int64
        The track that finds the object in the frame, or 0 (not found or not visible).
    id_switches : ndarray of shape (n_objects,), dtype int64
        Per object, how often it is found by another track than the one that last found it.
    fragmentations : ndarray of shape (n_objects,), dtype int64
        Per object, how often its finding is interrupted: runs of visible frames in which
        it is not found, between frames in which it is.
    n_tracks : ndarray of shape (n_frames,), dtype int64
        Predicted tracks (ids ``>= 1``) with a point in the frame.
    false_tracks : ndarray of shape (n_frames,), dtype int64
        Of those, the tracks of which less than ``min_overlap`` of the points lie on a true
        object (false moving objects).
    min_overlap : float
    """

    objects: np.ndarray
    visible: np.ndarray
    matches: np.ndarray
    id_switches: np.ndarray
    fragmentations: np.ndarray
    n_tracks: np.ndarray
    false_tracks: np.ndarray
    min_overlap: float

    @property
    def found(self):
        """(n_frames, n_objects) bool: the object is found in the frame."""
        return self.matches != 0

    @property
    def found_share(self):
        """(n_objects,) float: the share of each object's visible frames it is found in."""
        visible = self.visible.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.found.sum(axis=0) / visible

    @property
    def unmatched_tracks(self):
        """(n_frames,) int: tracks that find no object (CLEAR-MOT's false positives).

        Besides the false tracks, these count a second track on one object (a piece split
        off it): it lies on a moving object but finds none.
        """
        return self.n_tracks - self.found.sum(axis=1)

    def summary(self):
        """The figures of the whole sequence, as a dict.

        ``objects``, ``frames``; ``found_share``: found object-frames over visible ones;
        ``mean_found_share``: the mean of the objects' shares; ``id_switches``,
        ``fragmentations``, ``false_tracks``, ``unmatched_tracks``: totals;
        ``false_tracks_per_frame``: their mean.
        """
        visible = int(self.visible.sum())
        n_frames = len(self.n_tracks)
        return {
            "objects": len(self.objects),
            "frames": n_frames,
            "found_share": float(self.found.sum() / visible) if visible else float("nan"),
            "mean_found_share": (
                float(np.mean(self.found_share)) if len(self.objects) else float("nan")
            ),
            "id_switches": int(self.id_switches.sum()),
            "fragmentations": int(self.fragmentations.sum()),
            "false_tracks": int(self.false_tracks.sum()),
            "false_tracks_per_frame": float(self.false_tracks.sum() / n_frames),
            "unmatched_tracks": int(self.unmatched_tracks.sum()),
        }

    def per_object(self):
        """A :class:`pandas.DataFrame`, one row per true object.

        Columns ``object``, ``first_frame``, ``last_frame`` (visible), ``frames_visible``,
        ``frames_found``, ``found_share``, ``id_switches``, ``fragmentations``.
        """
        import pandas as pd

        seen = self.visible.any(axis=0)
        first = np.where(seen, np.argmax(self.visible, axis=0), -1)
        last = np.where(seen, len(self.visible) - 1 - np.argmax(self.visible[::-1], axis=0), -1)
        return pd.DataFrame(
            {
                "object": self.objects,
                "first_frame": first,
                "last_frame": last,
                "frames_visible": self.visible.sum(axis=0),
                "frames_found": self.found.sum(axis=0),
                "found_share": self.found_share,
                "id_switches": self.id_switches,
                "fragmentations": self.fragmentations,
            }
        )


def _first_positions(values, mask):
    """Sorted unique ``values[mask]``, the index of each one's first point, and counts."""
    ids, first, counts = np.unique(values[mask], return_index=True, return_counts=True)
    return ids, np.flatnonzero(mask)[first], counts


def _first_of_groups(sorted_keys):
    """Positions of the first entry of each run of equal ``sorted_keys``."""
    return np.flatnonzero(np.r_[len(sorted_keys) > 0, sorted_keys[1:] != sorted_keys[:-1]])


def _match_frame(truth, tracks, last_track, min_overlap):
    """One frame's matching: (object ids, their tracks or 0, track sizes, on-object counts).

    ``last_track`` maps an object id to the track that last found it (for ties).
    """
    on_object = truth >= 1
    on_track = tracks >= 1
    objects, object_first, object_size = _first_positions(truth, on_object)
    track_ids, track_first, track_size = _first_positions(tracks, on_track)
    both = on_object & on_track
    rows = np.searchsorted(objects, truth[both])
    cols = np.searchsorted(track_ids, tracks[both])
    cells, shared = np.unique(rows * len(track_ids) + cols, return_counts=True)
    rows, cols = cells // max(len(track_ids), 1), cells % max(len(track_ids), 1)
    matched = np.zeros(len(objects), dtype=np.int64)
    if len(cells):
        # Each object's best track: most shared points; on a tie the track that found it
        # last (CLEAR-MOT keeps a correspondence), then the smaller track, then the track
        # whose first point comes first (never the ids, so renaming changes nothing).
        previous = np.array([last_track.get(int(o), 0) for o in objects[rows]])
        not_previous = track_ids[cols] != previous
        order = np.lexsort((track_first[cols], track_size[cols], not_previous, -shared, rows))
        best = order[_first_of_groups(rows[order])]
        best = best[shared[best] >= min_overlap * object_size[rows[best]]]
        # One object per track (CLEAR-MOT's one-to-one matching): the object sharing the
        # most points with it, then the smaller object, then the one whose first point
        # comes first.
        order = np.lexsort(
            (object_first[rows[best]], object_size[rows[best]], -shared[best], cols[best])
        )
        best = best[order][_first_of_groups(cols[best][order])]
        matched[rows[best]] = track_ids[cols[best]]
    on_objects = np.bincount(cols, weights=shared, minlength=len(track_ids))
    false = np.count_nonzero(on_objects < min_overlap * track_size)
    return objects, matched, len(track_ids), false


def tracking_scores(true_ids, track_ids, *, ignore=None, min_overlap=0.5):
    """How well tracks follow the true objects over a sequence, point by point.

    In every frame each true object is matched to the predicted track that holds the
    most of its points; the object is *found* in that frame when that track holds at
    least ``min_overlap`` of the object's points. A track finds at most one object per
    frame (the one sharing the most points with it), as in CLEAR-MOT's one-to-one
    matching (Bernardin and Stiefelhagen, 2008); ties go to the track that found the
    object last, then to the smaller track. Then, as CLEAR-MOT and py-motmetrics count
    them:

    * an *ID switch* is a frame in which an object is found by a track other than the
      track that last found it (in any earlier frame), so an object handed from track
      ``a`` to ``b`` counts once, and once more if it goes back to ``a``;
    * a *fragmentation* is an interruption: a run of frames in which the object is
      visible but not found, between two frames in which it is found;
    * a *false track* of a frame (a false moving object) is a predicted track of which
      less than ``min_overlap`` of the points lie on true objects.

    Renaming the tracks consistently over all frames changes none of the counts.

    Parameters
    ----------
    true_ids : sequence of array-like of int, one (n_k,) array per frame
        The true object of each point: the same id ``>= 1`` for the same object in every
        frame; ``0`` or negative for none. To score the moving objects only, give 0 to the
        points that do not move (``np.where(moving, instance, 0)``).
    track_ids : sequence of array-like of int, like ``true_ids``
        The predicted track of each point, ``>= 1``; ``0`` or negative for none (the
        static world, outliers). To score moving tracks only, give 0 to the points
        estimated not to move (``np.where(moving, labels, 0)``).
    ignore : sequence of array-like of bool, like ``true_ids``, optional
        Points left out of everything (the ego body, invalid returns).
    min_overlap : float in (0, 1], default=0.5
        The share of an object's points its track must hold, and the share of a track's
        points that must lie on true objects.

    Returns
    -------
    scores : TrackingScores
        ``objects``, ``visible``, ``matches``, ``id_switches``, ``fragmentations`` (per
        object), ``n_tracks``, ``false_tracks`` (per frame), ``found_share`` and
        ``unmatched_tracks``; ``summary()`` gives the totals, ``per_object()`` a table.

    Raises
    ------
    ValueError
        If the sequences differ in number of frames or a frame in length, an array is
        not 1-D, or ``min_overlap`` is outside ``(0, 1]``.
    TypeError
        If the ids are not integers or ``ignore`` not booleans.

    Examples
    --------
    Object 7 is held by track 1, then by track 2 (a switch), then missed while visible,
    then found again by track 2 (a fragmentation, no switch); track 3 lies on the
    static world in the last frame:

    >>> from mmreg.metrics import tracking_scores
    >>> truth = [[7, 7, 0], [7, 7, 0], [7, 7, 0], [7, 7, 0, 0]]
    >>> tracks = [[1, 1, 0], [2, 2, 0], [0, 0, 2], [2, 2, 3, 3]]
    >>> scores = tracking_scores(truth, tracks)
    >>> scores.matches[:, 0].tolist(), scores.found_share.tolist()
    ([1, 2, 0, 2], [0.75])
    >>> s = scores.summary()
    >>> s["id_switches"], s["fragmentations"], scores.false_tracks.tolist()
    (1, 1, [0, 0, 1, 1])
    """
    if not isinstance(min_overlap, (int, float, np.integer, np.floating)) or isinstance(
        min_overlap, bool
    ):
        raise TypeError(f"min_overlap must be a number; got {min_overlap!r}.")
    if not 0 < min_overlap <= 1:
        raise ValueError(f"min_overlap must lie in (0, 1]; got {min_overlap}.")
    truth = _check_frames(true_ids, "true_ids", None, "ids")
    lengths = [len(frame) for frame in truth]
    tracks = _check_frames(track_ids, "track_ids", lengths, "ids")
    left_out = _check_ignore(ignore, lengths)
    truth = [np.where(out, 0, t) for t, out in zip(truth, left_out, strict=True)]
    tracks = [np.where(out, 0, p) for p, out in zip(tracks, left_out, strict=True)]

    objects = np.unique(np.concatenate([t[t >= 1] for t in truth] or [np.zeros(0, int)]))
    n_frames, n_objects = len(truth), len(objects)
    visible = np.zeros((n_frames, n_objects), dtype=bool)
    matches = np.zeros((n_frames, n_objects), dtype=np.int64)
    id_switches = np.zeros(n_objects, dtype=np.int64)
    n_tracks = np.zeros(n_frames, dtype=np.int64)
    false_tracks = np.zeros(n_frames, dtype=np.int64)
    last_track = {}
    for k, (t, p) in enumerate(zip(truth, tracks, strict=True)):
        present, matched, n_tracks[k], false_tracks[k] = _match_frame(t, p, last_track, min_overlap)
        columns = np.searchsorted(objects, present)
        visible[k, columns] = True
        matches[k, columns] = matched
        for column, obj, track in zip(columns, present, matched, strict=True):
            if not track:
                continue
            previous = last_track.get(int(obj), 0)
            if previous and previous != track:
                id_switches[column] += 1
            last_track[int(obj)] = int(track)

    fragmentations = np.zeros(n_objects, dtype=np.int64)
    for column in range(n_objects):
        found = matches[visible[:, column], column] != 0
        starts = np.count_nonzero(found & ~np.r_[False, found[:-1]])
        fragmentations[column] = max(starts - 1, 0)
    return TrackingScores(
        objects=objects,
        visible=visible,
        matches=matches,
        id_switches=id_switches,
        fragmentations=fragmentations,
        n_tracks=n_tracks,
        false_tracks=false_tracks,
        min_overlap=float(min_overlap),
    )
