"""Wrong correspondences: b-points moved off their true position, labelled as outliers."""

import numbers

import numpy as np
from sklearn.utils import check_random_state


def add_wrong_correspondences(X, labels, fraction=0.1, *, distance=(0.5, 1.5), random_state=None):
    """Move the b-points of a random ``fraction`` of the correspondences; label them -1.

    The wrong matches of a feature matcher or a scene-flow network: each chosen b-point is
    moved by a distance drawn uniformly from ``distance`` in a uniformly random direction
    (Table I, Exp. 4 of ``paper/``: 10 % moved by 0.5-1.5 m).

    Parameters
    ----------
    X : array-like of shape (n, 2d)
        Correspondences ``[a, b]``.
    labels : array-like of shape (n,)
        Ground truth; the moved correspondences become -1.
    fraction : float in [0, 1], default=0.1
        Share of the correspondences to move (rounded to the nearest count).
    distance : (float, float), default=(0.5, 1.5)
        Range of the distance each moved b-point travels, in the units of ``X``.
    random_state : int, RandomState instance, numpy Generator or None, default=None

    Returns
    -------
    X_wrong : ndarray of shape (n, 2d)
        A copy of ``X`` with the chosen b-points moved.
    labels_wrong : ndarray of shape (n,)
        A copy of ``labels`` with the moved correspondences labelled -1.

    Examples
    --------
    >>> from mmreg.datasets import add_wrong_correspondences, make_scene
    >>> scene = make_scene(n_objects=2, n_points=1000, random_state=0)
    >>> X, y = add_wrong_correspondences(scene.X, scene.labels, 0.1, random_state=0)
    >>> int((y == -1).sum()), float(abs(X - scene.X).max()) <= 1.5
    (100, True)
    """
    X = np.array(X, dtype=float)
    labels = np.array(labels)
    if X.ndim != 2 or X.shape[1] % 2 or X.shape[1] == 0:
        raise ValueError(f"X must have shape (n, 2d), got {X.shape}.")
    if labels.shape != (len(X),):
        raise ValueError(f"labels must have shape ({len(X)},), got {labels.shape}.")
    if not isinstance(fraction, numbers.Real) or not 0 <= fraction <= 1:
        raise ValueError(f"fraction must be a number in [0, 1], got {fraction!r}.")
    low, high = distance
    if not 0 <= low <= high:
        raise ValueError(f"distance must be (low, high) with 0 <= low <= high, got {distance!r}.")
    count = int(round(fraction * len(X)))
    if count == 0:
        return X, labels
    rng = random_state
    if not isinstance(rng, np.random.Generator):
        rng = check_random_state(random_state)
    d = X.shape[1] // 2
    wrong = rng.choice(len(X), count, replace=False)
    direction = rng.normal(size=(count, d))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    X[wrong, d:] += direction * rng.uniform(low, high, (count, 1))
    labels[wrong] = -1
    return X, labels
