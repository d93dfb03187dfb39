"""The rigid bodies' broad phase: which pairs of bounding spheres (grown by their margins)
overlap, in a fixed order (by i, then j) — a uniform grid (:func:`broad_phase`), a sorted sweep on
x where the grid would not fit (:func:`sweep_phase`), and the pairs kept between calls while no
body has moved past a skin (:class:`PairList`). The narrow phase is :mod:`.collide`."""
from __future__ import annotations

import numpy as np

DENSE_CELLS = 8  # the grid is a dense table while it has at most this many cells per body (+ 4,096)
# up to this many bodies every pair is tested at once (n(n − 1)/2 ≤ 1,128 distances): for a few
# bodies the grid's fourteen cell look-ups are NumPy calls on tiny arrays (debris' 14 bodies: the
# grid ~0.3 ms a step under cProfile, all pairs ~0.05)
ALL_PAIRS = 48
_HALF = [(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1) if (a, b, c) > (0, 0, 0)]


def broad_phase(x, bound, margin):
    """Pairs (i < j) whose bounding spheres (grown by their margins) overlap, in a fixed order (by
    i, then j): every pair tested at once up to ALL_PAIRS bodies, else a uniform grid of cells 2·max(bound + margin) wide (an overlapping pair lies in the
    same or neighbouring cells), each body against its own cell and the 13 neighbours of one half
    space, found in the bodies sorted by cell through a dense table of cells (a grid of at most
    DENSE_CELLS cells a body) or else by binary search among the occupied cells; then the exact test. The sorted
    sweep on x (:func:`sweep_phase`) takes over where the grid would not fit an int64 key (spread
    over too many cells) or a position is not finite. A lattice of 10,000 bodies made the x-sweep
    list millions of candidates (every body of a slab), 80 ms a step."""
    n = len(x)
    if n < 2:
        return np.zeros((0, 2), np.int64)
    ext = bound + margin
    cs = 2.0 * float(ext.max())
    if not (np.isfinite(x).all() and cs > 0):
        return sweep_phase(x, bound, margin)
    if n <= ALL_PAIRS:  # (row-major i < j: already the fixed order)
        i, j = np.triu_indices(n, 1)
        return _overlapping(x, ext, i, j)
    c = np.floor(x / cs)
    c = c - c.min(0) + 1.0  # ≥ 1: a neighbour's coordinate is ≥ 0
    dims = c.max(0) + 2.0
    if float(dims[0]) * float(dims[1]) * float(dims[2]) > 2.0 ** 62:
        return sweep_phase(x, bound, margin)
    c = c.astype(np.int64)
    d1, d2 = int(dims[1]), int(dims[2])
    key = (c[:, 0] * d1 + c[:, 1]) * d2 + c[:, 2]  # a neighbour's key is key + a fixed offset
    order = np.argsort(key, kind="stable")
    skey = key[order]
    cells = int(key.max()) + d1 * d2 + d2 + 2  # every neighbour's key is below this
    if cells <= DENSE_CELLS * n + 4096:  # a dense table: each cell's first sorted index and count
        count = np.bincount(key, minlength=cells)
        start = np.cumsum(count) - count

        def lookup(nk):
            return start[nk], count[nk]
    else:  # sparse: binary search among the occupied cells
        ukey, ustart, ucount = np.unique(skey, return_index=True, return_counts=True)

        def lookup(nk):
            at = np.minimum(np.searchsorted(ukey, nk), len(ukey) - 1)
            hit = ukey[at] == nk
            return ustart[at], np.where(hit, ucount[at], 0)
    firsts, seconds = [], []
    for o in [(0, 0, 0)] + _HALF:
        lo_, counts = lookup(key + (o[0] * d1 + o[1]) * d2 + o[2])
        if counts.sum() == 0:
            continue
        first, offs = _runs(counts)
        second = order[np.repeat(lo_, counts) + offs]
        if o == (0, 0, 0):  # the same cell: each pair once
            keep = first < second
            first, second = first[keep], second[keep]
        firsts.append(first)
        seconds.append(second)
    if not firsts:
        return np.zeros((0, 2), np.int64)
    return _overlapping(x, ext, np.concatenate(firsts), np.concatenate(seconds))


class PairList:
    """The broad phase's pairs kept between calls (a Verlet list: Verlet 1967; Ericson,
    "Real-Time Collision Detection" §7.4 on grown volumes): :func:`broad_phase` is run with every
    sphere grown by a skin s, and while no body has moved more than s from where it was then —
    counting a margin grown since as movement — every overlapping pair is among those listed, so a
    call only re-tests the listed pairs exactly. Bounding spheres do not turn with the body, so
    rotation never spoils the list; other bounds (bodies added or removed) rebuild it. The answer is exactly :func:`broad_phase`'s, pairs and order
    (the list is in its order and the exact test keeps it); 10,000 bodies in free flight paid the
    grid every step, 3 ms of a 5.7 ms step."""

    SKIN = 0.25  # s, as a fraction of the largest grown bound: rebuilt about every s / (v h) steps

    def __init__(self):
        self.x0 = None

    def pairs(self, x, bound, margin):
        """:func:`broad_phase` (x, bound, margin), from the list while it holds. ``x`` may be a
        strided view (the ODE state's position columns): the test reads it column by column, and
        only a rebuild copies it."""
        n = len(x)
        if n < 2:
            return np.zeros((0, 2), np.int64)
        x = np.asarray(x, np.float64)
        # (a position that is not finite fails the test: its squared move is NaN or ∞)
        if (self.x0 is None or self.x0.shape != x.T.shape or not np.array_equal(bound, self.bound0)
                or not self._holds(x, margin)):
            x = np.ascontiguousarray(x)
            if not np.isfinite(x).all():
                self.x0 = None
                return broad_phase(x, bound, margin)
            self.skin = self.SKIN * float((bound + margin).max())
            self.x0, self.margin0 = np.ascontiguousarray(x.T), np.asarray(margin, np.float64).copy()
            self.bound0 = np.array(bound, np.float64)
            self.listed = broad_phase(x, bound, margin + self.skin)
        i, j = self.listed[:, 0], self.listed[:, 1]
        if not len(i):
            return self.listed
        ext = bound + margin
        return self.listed[np.linalg.norm(x[i] - x[j], axis=1) <= ext[i] + ext[j]]

    # the moved test is kept a part in 10⁹ inside the skin: squares are compared, not lengths
    # (no square root a body), and the margin of rounding errs towards a rebuild, never towards
    # a stale list
    INSIDE = 1.0 - 1e-9

    def _holds(self, x, margin):
        """Whether every body has moved (plus its margin's growth) at most the skin since the
        list was built, body by body. The squared moves are summed a column at a time against the
        list's positions kept as (3, B) rows (10,000 free bodies, x a view of the ODE state's
        columns: a call of :meth:`pairs` 236 → 72 µs; NumPy's passes over a strided (B, 3) view
        were most of it)."""
        moved2 = None
        for c in range(3):
            d = x[:, c] - self.x0[c]
            moved2 = d * d if moved2 is None else moved2 + d * d
        room = self.skin * self.INSIDE - np.maximum(np.asarray(margin, np.float64) - self.margin0, 0.0)
        return bool(((room >= 0.0) & (moved2 <= room * room)).all())


def _overlapping(x, ext, i, j):
    """The candidate pairs (i, j) whose spheres of radius ``ext`` around ``x`` overlap, as (min,
    max) rows sorted by the first, then the second (the broad phase's fixed order)."""
    d = np.linalg.norm(x[i] - x[j], axis=1)
    keep = d <= ext[i] + ext[j]
    p = np.stack([np.minimum(i, j), np.maximum(i, j)], 1)[keep]
    if len(p) == 0:
        return p
    return p[np.lexsort((p[:, 1], p[:, 0]))]


def _runs(counts):
    """(owner, offset) for each element of runs of ``counts`` elements: the flat expansion of
    per-row candidate ranges."""
    owner = np.repeat(np.arange(len(counts)), counts)
    return owner, np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)


def sweep_phase(x, bound, margin):
    """:func:`broad_phase` by a sorted sweep on x, then a vectorised test (the same pairs in the
    same order)."""
    n = len(x)
    if n < 2:
        return np.zeros((0, 2), np.int64)
    ext = bound + margin
    lo, hi = x[:, 0] - ext, x[:, 0] + ext
    order = np.argsort(lo, kind="stable")
    lo_s, hi_s = lo[order], hi[order]
    end = np.searchsorted(lo_s, hi_s, side="right")  # candidates k in (s, end)
    counts = np.maximum(end - np.arange(n) - 1, 0)
    if counts.sum() == 0:
        return np.zeros((0, 2), np.int64)
    first, offs = _runs(counts)
    second = first + 1 + offs
    return _overlapping(x, ext, order[first], order[second])
