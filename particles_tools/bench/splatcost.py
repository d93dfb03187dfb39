"""The splat's cost per covered pixel–sprite pair, against a plain memory-bound loop over the same pairs.

A *covered pair* is a pixel of a tile (any level) and a sprite of that tile's list whose disc (or
capsule, for a streak) contains the pixel's centre: the work the splat cannot avoid. The reference
is the cheapest loop that touches the same memory in the same order: per tile (one thread each, as
the splat), for each covered pair in slot order, a load and a store of that pixel's vec4
accumulator from a precomputed list of pixel indices (no weights, no branches), its tiles spread
over the CPU's tasks as the splat's are (engine.spread). Both are timed on the renderer's own
arrays in one process, alternating, best of N.
"""
# (no `from __future__ import annotations`: Taichi reads kernel annotations at definition)

import time

import numpy as np

TILE = 16
_REF = None


def _ref_kernel():
    global _REF
    if _REF is None:
        import taichi as ti

        vec4 = ti.types.vector(4, ti.f32)

        from engine.spread import TASK, item, rounds, tasks

        NT = tasks()

        @ti.kernel
        def ref(idx: ti.types.ndarray(dtype=ti.i32, ndim=1), start: ti.types.ndarray(dtype=ti.i32, ndim=1),
                acc: ti.types.ndarray(dtype=vec4, ndim=1), T: ti.i32):
            for s in range(NT * TASK):  # (the tiles spread over the CPU's tasks, as the splat's)
                for r in range(rounds(T, NT)):
                    t = item(s, r, NT)
                    if t < T:
                        for j in range(start[t], start[t + 1]):
                            k = idx[j]
                            acc[k] = acc[k] + ti.Vector([1e-3, 1e-3, 1e-3, 0.0])

        _REF = ref
    return _REF


def covered_pairs(t, total: int):
    """(pixel indices of every covered pair in tile order, per-tile starts (T + 1,)) of the
    targets ``t`` (engine.render.targets.FrameTargets) after a frame's binning of ``total`` pairs."""
    rec = t.pairs.to_numpy()[:total].astype(np.float32)
    counts = t.tile_count.to_numpy()[: t.T]
    tile = np.repeat(np.arange(t.T), counts)
    lvl = (tile >= t.T0).astype(np.int64) + (tile >= t.T0 + t.T1)  # full, reduced, coarse
    tt = tile - np.choose(lvl, [0, t.T0, t.T0 + t.T1])
    txn = np.choose(lvl, [t.TX, t.TXl, t.TXc])
    Wc = np.choose(lvl, [t.W, t.Wl, t.Wc])
    Hc = np.choose(lvl, [t.H, t.Hl, t.Hc])
    base = np.choose(lvl, [0, t.LO, t.LC])
    px0 = (tt % txn) * TILE
    py0 = (tt // txn) * TILE
    idx_all, per_pair = [], np.zeros(total, np.int64)
    step = 4096
    off = np.arange(TILE * TILE)
    ox, oy = off % TILE, off // TILE
    for a in range(0, total, step):
        b = min(total, a + step)
        r = rec[a:b]
        px = px0[a:b, None] + ox[None, :]
        py = py0[a:b, None] + oy[None, :]
        ok = (px < Wc[a:b, None]) & (py < Hc[a:b, None])
        fx = px + np.float32(0.5) - r[:, 0:1]
        fy = py + np.float32(0.5) - r[:, 1:2]
        streak = r[:, 12:13] < 0
        dx, dy = r[:, 9:10] - r[:, 0:1], r[:, 10:11] - r[:, 1:2]
        s = np.clip((fx * dx + fy * dy) * r[:, 15:16], 0.0, 1.0)
        fx = np.where(streak, fx - s * dx, fx)
        fy = np.where(streak, fy - s * dy, fy)
        ok &= fx * fx + fy * fy < r[:, 2:3] * r[:, 2:3]
        k = base[a:b, None] + py * Wc[a:b, None] + px
        per_pair[a:b] = ok.sum(1)
        idx_all.append(k[ok].astype(np.int32))  # row-major per pair: pairs stay in tile order
    idx = np.concatenate(idx_all) if idx_all else np.zeros(0, np.int32)
    per_tile = np.bincount(tile, weights=per_pair, minlength=t.T).astype(np.int64)
    start = np.zeros(t.T + 1, np.int32)
    start[1:] = np.cumsum(per_tile)
    return idx, start


def measure(renderer, t, dep, rounds: int = 7):
    """(covered pairs, splat ms, reference ms) for the frame last binned into ``t``."""
    import taichi as ti

    R = renderer
    idx_np, start_np = covered_pairs(t, R.last_pairs)
    n = len(idx_np)
    idx = ti.ndarray(ti.i32, shape=max(1, n))
    if n:
        idx.from_numpy(idx_np)
    start = ti.ndarray(ti.i32, shape=len(start_np))
    start.from_numpy(start_np)
    ref = _ref_kernel()
    scratch = ti.ndarray(ti.types.vector(4, ti.f32), shape=t.accA.shape[0])

    def splat():  # (as the frame launched it: the full level alone, or the coarse level first)
        R.splat_frame(t, dep, R.last_reduced_pairs)

    def plain():
        ref(idx, start, scratch, t.T)

    best = {splat: 1e9, plain: 1e9}
    for fn in (splat, plain):
        fn()
    for _ in range(rounds):
        for fn in (splat, plain):
            ti.sync()
            t0 = time.perf_counter()
            fn()
            ti.sync()
            best[fn] = min(best[fn], time.perf_counter() - t0)
    return n, best[splat] * 1e3, best[plain] * 1e3
