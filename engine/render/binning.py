"""Sprites binned into screen tiles by a counting sort that is stable in slot order.

After ``bin`` a tile's sprites lie contiguously in ``pairs[tile_start[t] : tile_start[t] +
tile_count[t]]``, in slot order, as 16-float records (streamed by the splat instead of gathered
by slot: one cache miss each): centre x, y, radius, depth | RGB, alpha | energy, tail x, y, OIT
depth weight | kind (1 disc, −1 streak), additive, 1/soft-fade distance, 1/streak length². Tiles of every level share one index space: level 0 (full
resolution) tiles are [0, T0), level-1 (reduced buffer) tiles [T0, T0 + T1), level-2 (coarse
buffer) tiles [T0 + T1, T0 + T1 + T2).

No float atomics and nothing that depends on the thread count (PERF-NOTES: atomics are slow on
the CPU and make sums depend on timing):
1. count: per CHUNK of slots (a fixed number, not the thread count), how many sprites touch
   each tile; one thread owns a chunk's histogram row.
2. offsets: per tile, the exclusive prefix over chunks and the tile's total; block totals by
   integer atomics (exact, so order-free).
3. starts: per block of tiles, the sum of the block totals before it, then a short run over the
   block's tiles — a two-level parallel scan, nothing serial (1–3 are one kernel, ``tally``).
4. ``scatter``: each chunk writes its records into the tile lists.
"""
# (no `from __future__ import annotations`: Taichi reads kernel annotations at definition)

import taichi as ti

from .. import runtime
from ..launch import fast
from ..spread import TASK, item, rounds, tasks

SCAN_BLOCK = 64  # tiles per block of the two-level scan
vec16 = ti.types.vector(16, ti.f32)


def chunks_for(arch_is_cpu: bool) -> int:
    """Slot chunks of the counting sort: a few per core on a CPU (each costs a histogram row of
    every tile to clear and scan), many for a GPU's threads. A constant per backend (never the
    thread count), so the order of records never changes."""
    return 16 if arch_is_cpu else 1024


def build_binning_kernels(rec, capacity: int, chunks: int):
    """Kernels over the sprite records ``rec`` (engine.render.sprites.SpriteRecords) of a pool of
    ``capacity`` slots. Image-size arrays are ndarray arguments: a new size compiles nothing."""
    cap = max(1, capacity)
    chunk = (cap + chunks - 1) // chunks
    info, tiles = rec.spr_info, rec.spr_tiles
    geom, slook, tail, softf = rec.spr_geom, rec.spr_look, rec.spr_tail, rec.spr_soft
    # the two loops over the scan's blocks (T/64 of them: 74 at 1280×720) on the launching thread
    # on the CPU: each was a hand-off to the thread pool for a few dozen adds (engine.runtime.one_thread)
    blocks_serial = runtime._arch_in_use() == "cpu"
    NT = tasks()

    @ti.func
    def tile_base(level, T0, T1, TX0, TX1, TX2):
        base, tx_n = 0, TX0
        if level == 1:
            base, tx_n = T0, TX1
        elif level == 2:
            base, tx_n = T0 + T1, TX2
        return base, tx_n

    @ti.kernel
    def tally(hist: ti.types.ndarray(dtype=ti.i32, ndim=2),
              tile_count: ti.types.ndarray(dtype=ti.i32, ndim=1),
              tile_start: ti.types.ndarray(dtype=ti.i32, ndim=1),
              block_sum: ti.types.ndarray(dtype=ti.i32, ndim=1), T: ti.i32, T0: ti.i32, T1: ti.i32,
              TX0: ti.i32, TX1: ti.i32, TX2: ti.i32, NB: ti.i32) -> ti.types.vector(2, ti.i32):
        """Steps 1–3 in one launch (a kernel's top-level loops run one after another, each a
        parallel pass: a launch costs ~0.1 ms here, more than a step's work); returns the number
        of tile–sprite pairs and how many of them are in the reduced and coarse levels' tiles."""
        # 1. count (the chunks spread over the CPU's tasks: engine.spread; in order, all 16 were
        # one task of 512, a thread's alone)
        for s in range(NT * TASK):
            for r in range(rounds(chunks, NT)):
                c = item(s, r, NT)
                if c < chunks:
                    for t in range(T):
                        hist[c, t] = 0
                    for i in range(c * chunk, ti.min(cap, (c + 1) * chunk)):
                        if info[i][0] != 0:
                            b = tiles[i]
                            base, tx_n = tile_base(info[i][2], T0, T1, TX0, TX1, TX2)
                            for ty in range(b[1], b[3] + 1):
                                for tx in range(b[0], b[2] + 1):
                                    t = base + ty * tx_n + tx
                                    hist[c, t] = hist[c, t] + 1  # (not +=: that compiles to an atomic)
        # 2. offsets
        ti.loop_config(serialize=ti.static(blocks_serial))
        for b in range(NB):
            block_sum[b] = 0
        for t in range(T):
            run = 0
            for c in range(chunks):
                v = hist[c, t]
                hist[c, t] = run
                run += v
            tile_count[t] = run
            ti.atomic_add(block_sum[t // SCAN_BLOCK], run)  # integer: exact in any order
        # 3. starts
        for b in range(NB):
            run = 0
            for k in range(b):  # NB is T/64 (a few dozen): the quadratic sum is cheaper than a pass
                run += block_sum[k]
            for t in range(b * SCAN_BLOCK, ti.min(T, (b + 1) * SCAN_BLOCK)):
                tile_start[t] = run
                run += tile_count[t]
        total = 0
        ti.loop_config(serialize=ti.static(blocks_serial))
        for b in range(NB):
            total += block_sum[b]
        reduced = 0  # (the levels' tiles are consecutive: 0, then 1 and 2 from T0 on)
        if T0 < T:
            reduced = total - tile_start[T0]
        return ti.Vector([total, reduced])

    @ti.kernel
    def scatter(pairs: ti.types.ndarray(dtype=vec16, ndim=1),
                hist: ti.types.ndarray(dtype=ti.i32, ndim=2),
                tile_start: ti.types.ndarray(dtype=ti.i32, ndim=1), T0: ti.i32, T1: ti.i32,
                TX0: ti.i32, TX1: ti.i32, TX2: ti.i32):
        for s in range(NT * TASK):  # (the chunks spread over the CPU's tasks, as in tally)
            for r in range(rounds(chunks, NT)):
                c = item(s, r, NT)
                if c < chunks:
                    for i in range(c * chunk, ti.min(cap, (c + 1) * chunk)):
                        nf = info[i]
                        if nf[0] != 0:
                            b = tiles[i]
                            base, tx_n = tile_base(nf[2], T0, T1, TX0, TX1, TX2)
                            g, lk, tl = geom[i], slook[i], tail[i]
                            # a streak's 1/L² (for projecting pixels on it); 0 for a disc
                            d2 = (tl[1] - g[0]) ** 2 + (tl[2] - g[1]) ** 2
                            inv_l2 = ti.select(nf[0] < 0 and d2 > 1e-6, 1.0 / ti.max(d2, 1e-6), 0.0)
                            rec16 = ti.Vector([g[0], g[1], g[2], g[3], lk[0], lk[1], lk[2], lk[3],
                                               tl[0], tl[1], tl[2], tl[3], ti.cast(nf[0], ti.f32),
                                               ti.cast(nf[1], ti.f32), softf[i], inv_l2])
                            for ty in range(b[1], b[3] + 1):
                                for tx in range(b[0], b[2] + 1):
                                    t = base + ty * tx_n + tx
                                    k = hist[c, t]
                                    pairs[tile_start[t] + k] = rec16
                                    hist[c, t] = k + 1

    return fast(tally), fast(scatter)  # (engine.launch: without the per-argument Python)
