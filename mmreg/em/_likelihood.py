"""The weighted Gaussian likelihood of eq. (7) and the classification step built on it.

The classification step needs, for every correspondence, the arg-max of
``log(pi_j phi_j(b_i | a_i))`` over the clusters the distance gate admits, ties going to
the correspondence's own cluster, then to the lowest index. A dense ``(n, K)`` table of
scores would cost ``n * K`` work and memory per EM iteration; here, exactly the same
decisions cost far less:

* the correspondences are visited in spatially compact blocks (Morton order of the
  a-points), and each sub-block scores only the clusters whose bounding ball, grown by
  ``tau``, reaches its bounding box (every cluster without a gate);
* of those, a cluster whose score is provably below every own score in the sub-block
  (:meth:`CorrespondenceBlocks.column_bounds`) can neither win nor tie, and is left out;
* the scores of a block come from one matrix product (an expansion of the squared
  residual), with a bound on their rounding; rows where the best score is not clearly
  ahead are recomputed from explicit residuals before they are decided;
* in a repeated classification, sub-blocks whose points stayed put and whose clusters
  did not change are not scored again.
"""

import contextlib

import numpy as np

from mmreg._array.threads import single_threaded_blas
from mmreg.em._gate import gated_argmax

__all__ = ["CorrespondenceBlocks", "classify"]

# Correspondences per sub-block, which chooses the clusters to score: small enough for a
# compact bounding box (few clusters in reach). Blocks, which centre the features and
# are scored a run of sub-blocks at a time, may be larger, as long as they stay compact.
_SUB_ROWS = 2048
_BLOCK_ROWS = 16384
# One more pass over a table costs about as much as scoring this many more cells.
_PASS_CELLS = 2**15
# Rows whose own score is this far below their sub-block's mean are pruned separately.
_WEAK_SCORE = 2.0
# Largest (rows x clusters) score table scored at once: 8 MiB, about the size of a cache.
_BLOCK_CELLS = 2**20
# Bits of the Morton code per axis (at most 30 bits in all).
_MORTON_BITS = 10
_EPS = np.finfo(float).eps


def morton_order(points, bits=_MORTON_BITS):
    """Permutation that visits points along a Z-order (Morton) curve.

    Consecutive points in this order are close in space, so any run of them has a small
    bounding box. Points in the same cell keep their input order.

    Parameters
    ----------
    points : ndarray of shape (d, n)
        One coordinate per row.
    bits : int, default=10
        Cells per axis ``2**bits`` (fewer if ``d * bits`` would exceed 30).
    """
    # At most 30 bits of code: enough for locality, and code * n fits in 64 bits.
    points = points[:30]
    d, n = points.shape
    if n == 0:
        return np.zeros(0, dtype=np.intp)
    bits = max(1, min(bits, 30 // d))
    low = points.min(axis=1)
    extent = float(np.max(points.max(axis=1) - low))
    scale = (2**bits - 1) / extent if extent > 0 else 0.0
    # spread[v] puts bit i of v at bit i * d: interleaving is then a sum of shifted
    # table look-ups, one per axis.
    values = np.arange(2**bits, dtype=np.int64)
    spread = np.zeros(2**bits, dtype=np.int64)
    for bit in range(bits):
        spread |= ((values >> bit) & 1) << (bit * d)
    code = np.arange(n, dtype=np.int64)
    for axis in range(d):
        cells = ((points[axis] - low[axis]) * scale).astype(np.intp)
        code += (spread[cells] << axis) * n
    # Unique keys (code, index) make any sorting algorithm give the same order.
    return np.argsort(code, kind="quicksort")


class CorrespondenceBlocks:
    """Correspondences in spatially compact blocks, with the features of their residuals.

    ``||b - R a - t||^2 = ||b||^2 + ||a||^2 + ||t||^2 - 2 b^T R a - 2 b.t + 2 a.(R^T t)``
    makes the squared residuals of rows of a block under ``k`` motions one product of an
    ``(m, d^2 + 2d + 2)`` feature matrix with a ``(d^2 + 2d + 2, k)`` motion matrix. The
    features depend only on the points, so an EM run builds them once. Each block is
    centred on its own mean first, since the expansion loses about ``eps * ||x||^2`` of
    absolute precision and a block is small; :meth:`scores` also returns a bound on that
    loss, and :meth:`accurate_scores` recomputes rows from explicit residuals where the
    bound leaves a decision open.

    Blocks are cut into sub-blocks, which decide which clusters are worth scoring: those
    in reach of the gate (a bounding box per sub-block) and not provably worse than the
    points' own clusters (:meth:`column_bounds`).

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
        Corresponding points.
    block_rows : int, default=None
        Correspondences per block (16384 if None), rounded down to a multiple of
        ``sub_rows``.
    sub_rows : int, default=None
        Correspondences per sub-block (2048 if None).

    Attributes
    ----------
    order : ndarray of shape (n,)
        The correspondences in block order: block ``i`` holds ``order[starts[i]:stops[i]]``.
    a, b : ndarray of shape (n, d)
        The points in block order.
    """

    def __init__(self, a, b, block_rows=None, sub_rows=None):
        # Coordinates as rows: every per-point operation below runs over contiguous rows.
        a_rows = np.ascontiguousarray(np.asarray(a, dtype=float).T)
        b_rows = np.ascontiguousarray(np.asarray(b, dtype=float).T)
        d, n = a_rows.shape
        self.n, self.d = n, d
        self.order = morton_order(a_rows)
        a_rows = np.take(a_rows, self.order, axis=1)
        b_rows = np.take(b_rows, self.order, axis=1)
        self.a, self.b = a_rows.T, b_rows.T
        self._a_rows, self._b_rows = a_rows, b_rows
        # Bound on the size of any point, centroid or difference of two points.
        self.size = d * (np.max(np.abs(a_rows), initial=0) + np.max(np.abs(b_rows), initial=0))
        sub_rows = _SUB_ROWS if sub_rows is None else sub_rows
        block_rows = _BLOCK_ROWS if block_rows is None else block_rows
        self.sub_rows = sub_rows
        self.subs_per_block = max(1, block_rows // sub_rows)
        block_rows = self.subs_per_block * sub_rows
        self.starts = np.arange(0, n, block_rows)
        self.stops = np.minimum(self.starts + block_rows, n)
        self.sub_starts = np.arange(0, n, sub_rows)
        self.sub_stops = np.minimum(self.sub_starts + sub_rows, n)
        sub = self._stats(a_rows, b_rows, self.sub_starts, self.sub_stops)
        self.sub_low, self.sub_high, self.sub_mean_a, self.sub_mean_b, self.sub_extent, _ = sub
        _, _, self.mean_a, self.mean_b, self.extent, centred = self._stats(
            a_rows, b_rows, self.starts, self.stops
        )
        ca, cb, norm_a, norm_b = centred
        # Features as rows too; a block's (m, f) feature matrix is a transposed view.
        self._features = np.empty((d * d + 2 * d + 2, n))
        for p in range(d):
            for q in range(d):
                np.multiply(cb[p], ca[q], out=self._features[p * d + q])
        self._features[d * d : d * d + d] = cb
        self._features[d * d + d : d * d + 2 * d] = ca
        np.add(norm_a, norm_b, out=self._features[-2])
        self._features[-1] = 1.0

    @staticmethod
    def _stats(a_rows, b_rows, starts, stops):
        """Bounding box, means and extent of runs of rows; the centred rows too."""
        sizes = stops - starts
        low = np.minimum.reduceat(a_rows, starts, axis=1).T
        high = np.maximum.reduceat(a_rows, starts, axis=1).T
        mean_a = (np.add.reduceat(a_rows, starts, axis=1) / sizes).T
        mean_b = (np.add.reduceat(b_rows, starts, axis=1) / sizes).T
        ca = a_rows - np.repeat(mean_a.T, sizes, axis=1)
        cb = b_rows - np.repeat(mean_b.T, sizes, axis=1)
        norm_a, norm_b = np.einsum("ij,ij->j", ca, ca), np.einsum("ij,ij->j", cb, cb)
        # Largest ||a - mean_a|| + ||b - mean_b||: bounds every centred residual.
        extent = np.maximum.reduceat(np.sqrt(norm_a) + np.sqrt(norm_b), starts)
        # Rounding in the centring, so that the extent stays an upper bound.
        extent *= 1 + 16 * _EPS
        return low, high, mean_a, mean_b, extent, (ca, cb, norm_a, norm_b)

    def subs_of(self, block):
        """The sub-blocks of a block, as a range."""
        first = block * self.subs_per_block
        return range(first, min(first + self.subs_per_block, len(self.sub_starts)))

    def motion_table(self, block, rotations, translations, scale, log_prior):
        """The motion matrix of ``k`` motions for the rows of a block, for :meth:`scores`.

        Parameters
        ----------
        block : int
        rotations, translations, scale, log_prior : ndarray
            The ``k`` motions to score and their score parameters (``scale < 0``).

        Returns
        -------
        coefs : ndarray of shape (d^2 + 2d + 2, k)
        tolerance : ndarray of shape (k,)
            Bound on the rounding error of each column of the scores.
        """
        d = self.d
        k = len(rotations)
        mean_a, mean_b = self.mean_a[block], self.mean_b[block]
        # Residuals are unchanged when a and b are shifted and t becomes
        # t + R mean_a - mean_b.
        shifted = translations + rotations @ mean_a - mean_b
        shift_sq = np.einsum("kj,kj->k", shifted, shifted)
        # The scale and the log prior are folded into the motion matrix: one product
        # gives log_prior + scale * r^2.
        coefs = np.empty((d * d + 2 * d + 2, k))
        coefs[: d * d] = rotations.reshape(k, d * d).T
        coefs[d * d : d * d + d] = shifted.T
        coefs[: d * d + d] *= -2.0 * scale
        coefs[d * d + d : d * d + 2 * d] = np.einsum("kji,kj->ik", rotations, shifted)
        coefs[d * d + d : d * d + 2 * d] *= 2.0 * scale
        coefs[-2] = scale
        coefs[-1] = scale * shift_sq + log_prior
        # Every term of the expansion is at most (|a| + |b| + |t|)^2 in size, and the
        # shifted translation carries the rounding of the uncentred coordinates.
        size = self.extent[block] + np.sqrt(shift_sq)
        uncentred = (
            np.sqrt(np.einsum("kj,kj->k", translations, translations))
            + np.sqrt(mean_a @ mean_a)
            + np.sqrt(mean_b @ mean_b)
        )
        with np.errstate(invalid="ignore", over="ignore"):
            tolerance = _EPS * (
                -scale * (64 * size * (size + uncentred) + 8 * size**2) + 8 * np.abs(log_prior)
            )
        tolerance[~np.isfinite(tolerance)] = np.inf
        return coefs, tolerance

    def scores(self, rows, coefs, log_prior):
        """Scores ``log_prior + scale * ||b - R a - t||^2`` of some rows of one block.

        ``coefs`` comes from :meth:`motion_table` for that block (and ``log_prior`` holds
        the same motions' log priors); returns an ``(m, k)`` table.
        """
        out = self._features[:, rows].T @ coefs
        # scale < 0 and r^2 >= 0, so no score exceeds its log prior: clip what rounding
        # pushed past it.
        np.minimum(out, log_prior, out=out)
        return out

    def accurate_scores(self, rows, rotations, translations, scale, log_prior):
        """The same scores from explicit residual vectors, for rows (sorted indices)."""
        moved = np.einsum("kij,mj->mki", rotations, self.a[rows]) + translations
        residual = self.b[rows][:, None, :] - moved
        return log_prior + scale * np.einsum("mki,mki->mk", residual, residual)

    def own_score_floor(self, own, rotations, translations, scale, log_prior, squared=None):
        """Lower bound on each correspondence's exact score in its own cluster.

        ``own`` holds the cluster of each sorted correspondence (-1: none, bound -inf);
        ``squared``, if given, their squared residuals under their own motion. The score
        comes from the explicit residual, less a bound on its rounding error.
        """
        d = self.d
        floor = np.full(self.n, -np.inf)
        has_own = np.flatnonzero(own >= 0)
        if len(has_own) == 0:
            return floor
        lab = own[has_own]
        if squared is None:
            a_rows = np.take(self._a_rows, has_own, axis=1)
            b_rows = np.take(self._b_rows, has_own, axis=1)
            per_point = np.take(rotations.reshape(len(rotations), d * d).T, lab, axis=1)
            shift = np.take(translations.T, lab, axis=1)
            sq = np.zeros(len(lab))
            for p in range(d):
                residual = b_rows[p] - shift[p]
                for q in range(d):
                    residual -= per_point[p * d + q] * a_rows[q]
                sq += residual**2
        else:
            sq = squared[has_own]
        # Each residual component is off by a few eps times the size of the coordinates,
        # centroids and translations involved, all at most `size`.
        size = self.size + np.max(np.abs(translations))
        sc, lp = scale[lab], log_prior[lab]
        score = lp + sc * sq
        error = _EPS * (-32 * sc * size * (np.sqrt(sq) + size) + 8 * np.abs(score))
        floor[has_own] = score - error
        return floor

    def column_bounds(self, subs, rotations, translations, scale, log_prior):
        """Upper bound on the exact score of every row of some sub-blocks, ``(len(subs), k)``.

        A row's residual is ``c - t'`` with ``t' = t + R mean_a - mean_b`` and
        ``|c| <= |a - mean_a| + |b - mean_b| <= extent``, so it is at least
        ``|t'| - extent`` long: a motion that maps a sub-block's centre far from where it
        went scores low on every row of the sub-block.
        """
        mean_a, mean_b = self.sub_mean_a[subs], self.sub_mean_b[subs]
        shifted = translations[None] + np.einsum("kij,sj->ski", rotations, mean_a)
        shifted -= mean_b[:, None]
        uncentred = (
            np.sqrt(np.einsum("kj,kj->k", translations, translations))[None]
            + (
                np.sqrt(np.einsum("sj,sj->s", mean_a, mean_a))
                + np.sqrt(np.einsum("sj,sj->s", mean_b, mean_b))
            )[:, None]
        )
        extent = self.sub_extent[subs][:, None]
        gap = np.sqrt(np.einsum("skj,skj->sk", shifted, shifted)) - extent
        gap -= 16 * _EPS * (uncentred + extent)
        np.maximum(gap, 0.0, out=gap)
        bound = log_prior + scale * gap**2
        return bound + 8 * _EPS * (np.abs(log_prior) + np.abs(bound))


def classify(
    a,
    b,
    rotations,
    translations,
    sigmas,
    weights,
    gate,
    own=None,
    *,
    blocks=None,
    own_squared_residuals=None,
    settled=None,
    changed=None,
    limit_blas=True,
):
    """Classification step: each correspondence to its most likely admitted cluster.

    Parameters
    ----------
    a, b : ndarray of shape (n, d)
    rotations, translations, sigmas, weights : ndarray
        The ``K`` clusters' motions, noise scales and weights ``pi_j``.
    gate : ClusterGate
    own : ndarray of shape (n,), default=None
        Current cluster of each correspondence (-1: none), which wins ties.
    blocks : CorrespondenceBlocks, default=None
        ``a`` and ``b`` already in blocks, to reuse across calls.
    own_squared_residuals : ndarray of shape (n,), default=None
        ``||b - R a - t||^2`` of each correspondence under its own cluster's motion, if
        already known (the M-step computes them).
    settled, changed : ndarray of shape (n,) and (K,), default=None
        For a classification that repeats an earlier one: which correspondences stayed in
        their cluster the last time, and which clusters have changed since (in members,
        hence in motion, weight, noise scale and gate). Rows that stayed, next to none
        but unchanged clusters, face the very comparisons that kept them in place, so
        they stay again without being scored.
    limit_blas : bool, default=True
        Run BLAS on one thread meanwhile (see :func:`single_threaded_blas`); a caller
        that classifies repeatedly sets the limit once itself.

    Returns
    -------
    labels : ndarray of shape (n,)
        ``-1`` where the gate admits no cluster.
    """
    n, d = np.shape(a)
    k = len(rotations)
    labels = np.full(n, -1, dtype=np.intp)
    if k == 0 or n == 0:
        return labels
    if blocks is None:
        blocks = CorrespondenceBlocks(a, b)
    sigmas = np.asarray(sigmas, dtype=float)
    with np.errstate(divide="ignore"):
        log_prior = np.log(weights) - d * np.log(sigmas)
    scale = -0.5 / sigmas**2
    sorted_own = floor = None
    if own is not None:
        sorted_own = own[blocks.order]
        if settled is not None:
            settled = settled[blocks.order] & (sorted_own >= 0)
        if own_squared_residuals is not None:
            own_squared_residuals = own_squared_residuals[blocks.order]
        floor = blocks.own_score_floor(
            sorted_own, rotations, translations, scale, log_prior, own_squared_residuals
        )
    sorted_labels = np.full(n, -1, dtype=np.intp)
    with single_threaded_blas() if limit_blas else contextlib.nullcontext():
        _classify_blocks(
            blocks,
            (rotations, translations, scale, log_prior),
            gate,
            sorted_own,
            floor,
            sorted_labels,
            None if own is None or changed is None else (settled, changed),
        )
    labels[blocks.order] = sorted_labels
    return labels


def _classify_blocks(blocks, parameters, gate, sorted_own, floor, sorted_labels, repeat=None):
    """The loop of :func:`classify` over blocks, on the sorted correspondences.

    In each sub-block, a row is scored against the clusters in reach of the gate, less,
    for a row with an own cluster, every cluster that provably scores below the worst
    own score of the sub-block (:meth:`CorrespondenceBlocks.column_bounds`): such a
    cluster can neither beat nor tie any row's own cluster. Consecutive sub-blocks of a
    block that keep similar clusters are scored together. ``repeat`` is ``(settled,
    changed)`` of :func:`classify` (sorted), to skip the sub-blocks that cannot change.
    """
    for block, (start, stop) in enumerate(zip(blocks.starts, blocks.stops, strict=True)):
        subs = blocks.subs_of(block)
        reach = gate.reach_boxes(blocks.sub_low[subs], blocks.sub_high[subs])
        offsets = blocks.sub_starts[subs] - start
        work = []
        if sorted_own is None:
            every = np.arange(stop - start)
            work += [(rows, cols, None) for rows, cols in _runs(reach, offsets, start, every)]
        else:
            own = sorted_own[start:stop]
            orphan = own < 0
            owned = np.flatnonzero(~orphan)
            if len(owned) and repeat is not None:
                # Sub-blocks whose rows all stayed last time, and see no changed cluster
                # (not even their own), keep their labels.
                settled, changed = repeat
                calm = np.logical_and.reduceat(settled[start:stop], offsets)
                calm &= ~(reach & changed).any(axis=1)
                calm &= ~np.logical_or.reduceat(changed[np.maximum(own, 0)] & ~orphan, offsets)
                if calm.any():
                    still = calm[owned // blocks.sub_rows]
                    sorted_labels[start + owned[still]] = own[owned[still]]
                    owned = owned[~still]
            if len(owned):
                tiers = _tiers(blocks, subs, parameters, reach, own, owned, floor[start:stop])
                if repeat is not None:
                    # The same test on the clusters left after pruning.
                    calm = np.logical_and.reduceat(settled[start:stop], offsets)
                    seen = np.logical_or.reduce([keep for _, keep in tiers])
                    calm &= ~(seen & changed).any(axis=1)
                    if calm.any():
                        still = calm[owned // blocks.sub_rows]
                        sorted_labels[start + owned[still]] = own[owned[still]]
                        tiers = [
                            (rows[~calm[rows // blocks.sub_rows]], keep) for rows, keep in tiers
                        ]
                        for _, keep in tiers:
                            keep[calm] = False
                for rows, keep in tiers:
                    for run, columns in _runs(keep, offsets, start, rows):
                        if len(columns) == 1:
                            # Every row's own cluster, and nothing else can beat it.
                            sorted_labels[run] = columns[0]
                        else:
                            work.append((run, columns, sorted_own))
            if orphan.any():
                rows = np.flatnonzero(orphan)
                columns = np.flatnonzero(reach[np.unique(rows // blocks.sub_rows)].any(axis=0))
                work.append((start + rows, columns, None))
        work = [item for item in work if len(item[0]) and len(item[1])]
        if not work:
            continue
        # The motion matrix of every cluster the block scores, built once.
        needed = np.unique(np.concatenate([columns for _, columns, _ in work]))
        motions = tuple(x[needed] for x in parameters)
        coefs, tolerance = blocks.motion_table(block, *motions)
        for rows, columns, own in work:
            where = np.searchsorted(needed, columns)
            _classify_rows(
                blocks,
                rows,
                columns,
                (coefs[:, where], tolerance[where], tuple(x[where] for x in motions)),
                gate,
                own,
                sorted_labels,
            )


def _tiers(blocks, subs, parameters, reach, own, owned, floor):
    """The clusters to score for the rows of a block that have an own cluster.

    A cluster whose bound (:meth:`CorrespondenceBlocks.column_bounds`) is below every own
    score of a sub-block's rows cannot beat or tie any of them. A few rows with poor own
    scores (noise in the tail) would keep nearly every cluster in play for all rows, so
    the rows well below their sub-block's mean own score form a second tier, pruned
    with their own worst score.

    Returns ``(rows, keep)`` pairs: sorted rows (relative to the block) and the boolean
    (sub-block, cluster) table of the clusters to score for them.
    """
    n_subs = len(subs)
    sub_of = owned // blocks.sub_rows
    scores = floor[owned]
    count = np.bincount(sub_of, minlength=n_subs)
    mean = np.bincount(sub_of, weights=scores, minlength=n_subs) / np.maximum(count, 1)
    weak = scores < mean[sub_of] - _WEAK_SCORE
    bounds = blocks.column_bounds(subs, *parameters)

    # Rows are sorted, so each sub-block's rows are a run of `owned`.
    nonempty = np.flatnonzero(count)
    firsts = np.searchsorted(owned, nonempty * blocks.sub_rows)

    def tier(members):
        worst = np.full(n_subs, np.inf)
        worst[nonempty] = np.minimum.reduceat(np.where(members, scores, np.inf), firsts)
        keep = reach & (bounds >= worst[:, None])
        # A point's own cluster is always in reach and always scored; make sure rounding
        # cannot drop it.
        keep[sub_of[members], own[owned[members]]] = True
        return owned[members], keep

    if not weak.any() or weak.all():
        return [tier(np.ones(len(owned), dtype=bool))]
    tiers = [tier(~weak), tier(weak)]
    # One tier for all rows keeps a cluster if either tier does.
    single = (owned, tiers[0][1] | tiers[1][1])

    def cells(rows, keep):
        return np.bincount(rows // blocks.sub_rows, minlength=n_subs) @ keep.sum(axis=1)

    # Two tiers cost an extra pass per sub-block with weak rows; worth it when they
    # score far fewer cells.
    extra = _PASS_CELLS * len(np.unique(sub_of[weak]))
    if sum(cells(*t) for t in tiers) + extra < cells(*single):
        return tiers
    return [single]


def _runs(keep, offsets, start, rows):
    """Sub-blocks to score together: (sorted rows, clusters) pairs.

    ``keep`` is the boolean (sub-block, cluster) table of a block, ``offsets`` the first
    row of each sub-block and ``rows`` the rows to share out (relative to ``start``).
    Consecutive sub-blocks are scored together, against the union of their clusters,
    when the extra scores cost less than a separate pass would.
    """
    bounds = np.searchsorted(rows, offsets)
    sizes = np.diff(np.append(bounds, len(rows)))

    def cost(n_rows, n_columns):
        # A single cluster needs no table: its rows' own cluster is the only choice.
        return 0 if n_columns <= 1 else n_rows * n_columns + _PASS_CELLS

    group = [0]
    union = keep[0].copy()
    n_rows, current = sizes[0], cost(sizes[0], np.count_nonzero(keep[0]))
    for sub in range(1, len(keep)):
        merged = union | keep[sub]
        merged_cost = cost(n_rows + sizes[sub], np.count_nonzero(merged))
        if merged_cost <= current + cost(sizes[sub], np.count_nonzero(keep[sub])):
            group.append(sub)
            union, n_rows, current = merged, n_rows + sizes[sub], merged_cost
            continue
        yield _run(rows, bounds, sizes, group, union, start)
        group, union = [sub], keep[sub].copy()
        n_rows, current = sizes[sub], cost(sizes[sub], np.count_nonzero(keep[sub]))
    yield _run(rows, bounds, sizes, group, union, start)


def _run(rows, bounds, sizes, group, union, start):
    lo, hi = bounds[group[0]], bounds[group[-1]] + sizes[group[-1]]
    return start + rows[lo:hi], np.flatnonzero(union)


def _classify_rows(blocks, rows, columns, motions, gate, sorted_own, sorted_labels):
    """Score some rows of one block against some clusters and pick each row's cluster.

    ``motions`` holds the clusters' motion matrix and tolerances from
    :meth:`CorrespondenceBlocks.motion_table` and their parameters.
    """
    coefs, tolerance, parameters = motions
    log_prior = parameters[3]
    step = max(1, _BLOCK_CELLS // len(columns))
    for lo in range(0, len(rows), step):
        part = rows[lo : lo + step]
        contiguous = part[-1] - part[0] == len(part) - 1
        index = slice(part[0], part[-1] + 1) if contiguous else part
        sorted_labels[index] = gated_argmax(
            blocks.scores(index, coefs, log_prior),
            blocks.a[index],
            gate,
            None if sorted_own is None else sorted_own[index],
            columns=columns,
            tolerance=tolerance,
            refine=lambda local, part=part: blocks.accurate_scores(part[local], *parameters),
        )
