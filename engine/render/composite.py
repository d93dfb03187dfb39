"""Splat, composite and tone map in one pass per tile (or per pixel): the frame's only full pass.

Two schedules give the same image (each pixel takes its tile's sprites in slot order; see
``splat.py`` for what a sprite adds):

* **per tile** (the CPU's): one thread per 16×16 tile walks the tile's sprite list once and adds
  each disc to the few pixels it covers (small discs as unrolled 2×2 / 4×4 blocks), into the tile's
  slice of the accumulator arrays — hot in cache, written by that thread only, no atomics — then
  composites and tone-maps the tile's pixels straight into the packed RGBA output. A tile that no
  sprite, reduced-buffer sprite or soft body touches copies the cached, already tone-mapped
  background: a still frame costs a copy, not a shading pass (no clears, no `exp`, no `pow`).
* **per pixel** (for GPUs, after 3D Gaussian Splatting's rasterizer, Kerbl et al. 2023): one thread
  per pixel walks its tile's list, accumulating in registers; no accumulator arrays at all.

The reduced buffer (level 1, Cantlay 2007) is splatted first by the same schedules into its own
accumulators; the full-resolution pass samples it through ``upsample.py`` (bilinear, bilateral at
the edges of nearer surfaces). Big sprites (radius ≥ 4 of its texels) go to a coarse buffer
(level 2) at half the reduced scale, splatted before it: each reduced texel adds the coarse sums
under it (``co_quad``/``co_mix``, the same bilinear-or-bilateral rule) before it resolves, so the
two levels are one layer — sums add, transmittances multiply, the OIT resolve is taken once — and
a big sprite costs a quarter of the texels (explosion.toml at 1280×720: covered pixel–sprite
pairs 1.96 M → 0.59 M, the splat 19–26 → 11–13 ms on a slow day of this 2-core machine).

Tone map: exposure, the ACES filmic fit (Narkowicz 2015), sRGB by a 16,384-entry table of 8-bit
values (``pow`` once per entry at build, not three times per pixel), packed as one u32 RGBA per
pixel (bytes R, G, B, A in memory).
"""
# (no `from __future__ import annotations`: Taichi reads kernel annotations at definition)

import numpy as np
import taichi as ti

from .. import runtime
from ..launch import fast
from .splat import add_sprite, capsule_point, disc_weight, record_box
from .sprites import TILE
from .upsample import ND_I1, ND_V4, co_mix, co_quad, lo_edge, lo_near, lo_rows, lo_sample, tile_is_edge

LUT_SIZE = 16384
LUT_MAX = 8.0
EMPTY_LAYER = ti.Vector([0.0, 0.0, 0.0, 1.0])  # a layer that draws nothing: RGB 0, T 1
vec16 = ti.types.vector(16, ti.f32)
# (flat pixel arrays, as engine.render.upsample's)
ND_F = ti.types.ndarray(dtype=ti.f32, ndim=1)
ND_U32 = ti.types.ndarray(dtype=ti.u32, ndim=1)
ND_U64 = ti.types.ndarray(dtype=ti.u64, ndim=1)
ND_PAIRS = ti.types.ndarray(dtype=vec16, ndim=1)


def tonemap_table(n: int = LUT_SIZE, x_max: float = LUT_MAX) -> np.ndarray:
    """8-bit sRGB (IEC 61966-2-1) of the ACES filmic fit (Narkowicz 2015) of n linear values,
    spaced evenly in sqrt(x / x_max) (fine steps near black, where sRGB is steep). ACES reaches 1
    at x ≈ 7.24, so x_max = 8 loses nothing."""
    x = x_max * np.linspace(0.0, 1.0, n) ** 2
    a = np.clip((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)
    s = np.where(a <= 0.0031308, 12.92 * a, 1.055 * np.power(a, 1.0 / 2.4) - 0.055)
    return np.minimum(255, np.floor(s * 255.0 + 0.5)).astype(np.int32)


_BUILT = {}  # (uses_add, uses_alpha) -> (Taichi program, the kernels built in it)


def build_composite_kernels(uses_add: bool, uses_alpha: bool):
    """The splat, composite and tone-map kernels for scenes with these blend modes: built once
    per Taichi program and shared by every renderer (their arrays are ndarray arguments and the
    tone-map table the only field, so a rebuilt or second scene compiles none of them again:
    composite_tiles alone was ~4–5 s of a cold build; ``engine.runtime.reset`` forgets them)."""
    from taichi.lang import impl

    key, prog = (bool(uses_add), bool(uses_alpha)), impl.get_runtime().prog
    if key not in _BUILT or _BUILT[key][0] is not prog:  # (a host may reset Taichi itself)
        _BUILT[key] = (prog, _build(*key))
    return _BUILT[key][1]


runtime.on_reset(_BUILT.clear)


def _build(uses_add: bool, uses_alpha: bool):
    lut = ti.field(ti.i32, shape=LUT_SIZE)
    lut.from_numpy(tonemap_table())

    @ti.func
    def pack(c, alpha, bgra):
        """Linear RGB (exposure applied) → ACES → sRGB 8 bits by table, with alpha, as one u32:
        bytes R, G, B, A in memory (``bgra`` 0) or B, G, R, A (windowing systems' order)."""
        v = ti.sqrt(ti.math.clamp(c, 0.0, LUT_MAX) * (1.0 / LUT_MAX)) * (LUT_SIZE - 1) + 0.5
        r = ti.cast(lut[ti.cast(v[0], ti.i32)], ti.u32)
        g = ti.cast(lut[ti.cast(v[1], ti.i32)], ti.u32)
        b = ti.cast(lut[ti.cast(v[2], ti.i32)], ti.u32)
        a = ti.cast(ti.min(255.0, alpha * 255.0 + 0.5), ti.u32)
        if bgra != 0:
            r, b = b, r
        return r | (g << 8) | (b << 16) | (a << 24)

    @ti.func
    def layer(A, B, shading):
        """A pixel's splat accumulators → a premultiplied layer (RGB, T): additive light plus the
        OIT colour (McGuire & Bavoil 2013, eq. 6) times (1 − T); thick smoke is darker inside
        (light reaching the core is attenuated: shade = 0.25 + 0.75·T^k, a one-parameter,
        order-independent stand-in for self-shadowing)."""
        T = A[3]
        c = ti.Vector([A[0], A[1], A[2]])
        if ti.static(uses_alpha):
            if B[3] > 1e-8:
                shade = 0.25 + 0.75 * ti.pow(ti.max(T, 1e-30), shading)
                c += ti.Vector([B[0], B[1], B[2]]) * (shade * (1.0 - T) / B[3])
        return ti.Vector([c[0], c[1], c[2], T])

    @ti.func
    def finish(bg, lo, full, exposure, mode):
        """bg (RGB, coverage), then the reduced layer over it, then the full-resolution layer:
        c = (bg·T_lo + rgb_lo)·T + rgb. Coverage is 1 for soft bodies; the background itself has 0
        and is left out of a transparent render (``mode`` bit 0; premultiplied, alpha =
        1 − (1 − cover)·T_lo·T). ``mode`` bit 1: BGRA byte order."""
        c = ti.Vector([bg[0], bg[1], bg[2]])
        cover = 1.0
        if mode & 1:
            c = c * bg[3]
            cover = bg[3]
        c = c * lo[3] + ti.Vector([lo[0], lo[1], lo[2]])
        c = c * full[3] + ti.Vector([full[0], full[1], full[2]])
        return pack(c * exposure, 1.0 - (1.0 - cover) * lo[3] * full[3], mode & 2)

    @ti.func
    def deposit(px0, py0, px1, py1, rec, accA: ti.template(), accB: ti.template(),
                dep: ti.template(), base, W, ab, aw):
        """A record onto the pixels of [px0, px1] × [py0, py1] it covers (depths at
        base + y·W + x, accumulators at ab + y·aw + x: ``tile_rows``)."""
        cx, cy, rad = rec[0], rec[1], rec[2]
        inv_r2 = 1.0 / (rad * rad)
        col = ti.Vector([rec[4], rec[5], rec[6]])
        is_add = rec[13] != 0.0
        if rec[12] < 0:  # a streak: each row's span of the capsule, one weight per pixel
            tx, ty = rec[9], rec[10]
            y0 = ti.max(py0, ti.cast(ti.floor(ti.min(cy, ty) - rad), ti.i32))
            y1 = ti.min(py1, ti.cast(ti.floor(ti.max(cy, ty) + rad), ti.i32))
            for yy in range(y0, y1 + 1):
                # the part of the segment within rad of this row, widened by rad
                lo_t, hi_t = 0.0, 1.0
                if ti.abs(ty - cy) > 1e-6:
                    ta = (yy + 0.5 - rad - cy) / (ty - cy)
                    tb = (yy + 0.5 + rad - cy) / (ty - cy)
                    lo_t = ti.max(0.0, ti.min(ta, tb))
                    hi_t = ti.min(1.0, ti.max(ta, tb))
                xa, xb = cx + lo_t * (tx - cx), cx + hi_t * (tx - cx)
                x0 = ti.max(px0, ti.cast(ti.floor(ti.min(xa, xb) - rad), ti.i32))
                x1 = ti.min(px1, ti.cast(ti.floor(ti.max(xa, xb) + rad), ti.i32))
                for xx in range(x0, x1 + 1):
                    qx, qy, fade = capsule_point(xx, yy, rec)
                    pixel(xx, yy, True, qx, qy, inv_r2, rec, col, rec[7] * fade, is_add, rec[8],
                          accA, accB, dep, base, W, ab, aw)
        else:
            x0 = ti.max(px0, ti.cast(ti.floor(cx - rad), ti.i32))
            x1 = ti.min(px1, ti.cast(ti.floor(cx + rad), ti.i32))
            y0 = ti.max(py0, ti.cast(ti.floor(cy - rad), ti.i32))
            y1 = ti.min(py1, ti.cast(ti.floor(cy + rad), ti.i32))
            if x0 <= x1 and y0 <= y1:
                a, energy = rec[7], rec[8]
                span = ti.max(x1 - x0, y1 - y0)
                if span < 2:
                    block(2, x0, y0, x1, y1, cx, cy, inv_r2, rec, col, a, is_add, energy, accA, accB,
                          dep, base, W, ab, aw)
                else:  # one inlined pixel in a loop keeps the kernel (and its build) small: a 4×4
                    # unrolled block as well cost 5.6 s more to compile cold, for 1M-particle frames
                    for yy in range(y0, y1 + 1):
                        # only the row's span inside the circle (a box wastes 1 − π/4 of its pixels)
                        dy = yy + 0.5 - cy
                        half = ti.sqrt(ti.max(0.0, rad * rad - dy * dy))
                        for xx in range(ti.max(x0, ti.cast(ti.floor(cx - half), ti.i32)),
                                        ti.min(x1, ti.cast(ti.floor(cx + half), ti.i32)) + 1):
                            pixel(xx, yy, True, cx, cy, inv_r2, rec, col, a, is_add, energy, accA,
                                  accB, dep, base, W, ab, aw)

    @ti.func
    def block(Bn: ti.template(), bx, by, x1, y1, cx, cy, inv_r2, rec, col, a, is_add, energy,
              accA: ti.template(), accB: ti.template(), dep: ti.template(), base, W, ab, aw):
        """A Bn×Bn pixel block from (bx, by), unrolled at compile time (Taichi's dynamic inner
        loops cost more than the pixel work of a 1–3 px sprite); lanes past (x1, y1) add zero."""
        for dy in ti.static(range(Bn)):
            for dx in ti.static(range(Bn)):
                inside = bx + dx <= x1 and by + dy <= y1
                pixel(ti.min(bx + dx, x1), ti.min(by + dy, y1), inside, cx, cy, inv_r2, rec, col, a,
                      is_add, energy, accA, accB, dep, base, W, ab, aw)

    @ti.func
    def pixel(xx, yy, inside, cx, cy, inv_r2, rec, col, a, is_add, energy, accA: ti.template(),
              accB: ti.template(), dep: ti.template(), base, W, ab, aw):
        """One pixel of a sprite: additive light touches only accA's RGB, an alpha sprite accA's T
        and accB (plain load + store, not +=: one thread owns the tile, and += on an array in a
        parallel loop compiles to an atomic)."""
        w = ti.select(inside, disc_weight(xx, yy, cx, cy, inv_r2, rec[3], dep[base + yy * W + xx], energy,
                                          rec[14]), 0.0)
        k = ab + yy * aw + xx
        if is_add:
            if ti.static(uses_add):
                accA[k] = accA[k] + ti.Vector([col[0], col[1], col[2], 0.0]) * (a * w)
        else:
            if ti.static(uses_alpha):
                A, B = add_sprite(accA[k], accB[k], w, col, a, False, rec[11], False, True)
                accA[k] = A
                accB[k] = B

    @ti.func
    def tile_rows(px0, py0, px1, py1, W):
        """Where the full level's accumulators keep tile [px0, px1] × [py0, py1]: (ab, aw), pixel
        (x, y) at ab + y·aw + x. Tile-major: each tile's pixels are one contiguous run, row after
        row (aw = the tile's width), the tiles in row-major order (a row of tiles, all of height
        h, starts at py0·W; a tile at px0·h in it), so the W·H slots are a permutation of the
        row-major ones. The per-tile splat clears and fills one run of ≤ 8 KB a tile instead of
        16 row pieces 20 KB apart, a cache miss each (explosion.toml at 1280×720, 1,628 tiles
        drawn: the full level's splat 9.4–9.9 → 5.6–5.8 ms, old and new in turn). Only the
        accumulators: walking the composite's other arrays a whole image row at a time instead
        (one thread a row of tiles) made it slower, not faster — its cost is arithmetic."""
        tw, th = px1 - px0 + 1, py1 - py0 + 1
        return py0 * W + px0 * th - py0 * tw - px0, tw

    @ti.func
    def splat_tile(t, px0, py0, px1, py1, pairs: ti.template(), tile_count: ti.template(),
                   tile_start: ti.template(), accA: ti.template(), accB: ti.template(),
                   dep: ti.template(), base, W, ab, aw):
        """Clear a tile's accumulators and add its sprites, in slot order (per-tile schedule)."""
        for y in range(py0, py1 + 1):
            for x in range(ab + y * aw + px0, ab + y * aw + px1 + 1):
                accA[x] = EMPTY_LAYER
                if ti.static(uses_alpha):
                    accB[x] = ti.Vector([0.0, 0.0, 0.0, 0.0])
        for j in range(tile_start[t], tile_start[t] + tile_count[t]):
            deposit(px0, py0, px1, py1, pairs[j], accA, accB, dep, base, W, ab, aw)

    @ti.func
    def splat_pixel(t, px, py, pairs: ti.template(), tile_count: ti.template(),
                    tile_start: ti.template(), z_here):
        """(A, B) of one pixel from its tile's list, in registers (per-pixel schedule)."""
        A = EMPTY_LAYER
        B = ti.Vector([0.0, 0.0, 0.0, 0.0])
        for j in range(tile_start[t], tile_start[t] + tile_count[t]):
            rec = pairs[j]
            x0, y0, x1, y1 = record_box(rec)
            if px + 1.0 >= x0 and px <= x1 and py + 1.0 >= y0 and py <= y1:
                col = ti.Vector([rec[4], rec[5], rec[6]])
                inv_r2 = 1.0 / (rec[2] * rec[2])
                cx, cy, a = rec[0], rec[1], rec[7]
                if rec[12] < 0:
                    qx, qy, fade = capsule_point(px, py, rec)
                    cx, cy, a = qx, qy, a * fade
                w = disc_weight(px, py, cx, cy, inv_r2, rec[3], z_here, rec[8], rec[14])
                A, B = add_sprite(A, B, w, col, a, rec[13] != 0.0, rec[11], uses_add, uses_alpha)
        return A, B

    @ti.func
    def acc_layer(accA: ti.template(), accB: ti.template(), k, shading):
        B = ti.Vector([0.0, 0.0, 0.0, 0.0])
        if ti.static(uses_alpha):
            B = accB[k]
        return layer(accA[k], B, shading)

    @ti.func
    def with_coarse(A, B, x, y, z, accA: ti.template(), accB: ti.template(), dep: ti.template(), LC,
                    Wc, Hc):
        """A reduced texel's sums (A, B) with the coarse level's under it added (``co_quad``):
        light and OIT sums add, transmittances multiply — one layer, as if every sprite had been
        drawn at the reduced level (not the coarse layer composited behind it: a big near puff
        is not put behind small far ones)."""
        k, w = co_quad(x, y, z, dep, LC, Wc, Hc)
        A2 = co_mix(accA, k, w)
        A = ti.Vector([A[0] + A2[0], A[1] + A2[1], A[2] + A2[2], A[3] * A2[3]])
        if ti.static(uses_alpha):
            B = B + co_mix(accB, k, w)
        return A, B

    @ti.kernel
    def splat_tiles(pairs: ND_PAIRS, tile_count: ND_I1, tile_start: ND_I1, accA: ND_V4, accB: ND_V4,
                    dep: ND_F, touched_lo: ND_I1, touched_co: ND_I1, t_lo: ti.i32, t_hi: ti.i32,
                    T0: ti.i32, TX: ti.i32, W: ti.i32, H: ti.i32, T1: ti.i32, TXl: ti.i32, Wl: ti.i32,
                    Hl: ti.i32, TXc: ti.i32, Wc: ti.i32, Hc: ti.i32, shading: ti.f32):
        """Per tile (the CPU's schedule), the tiles [t_lo, t_hi) of the index space (full level,
        then reduced, then coarse): clear and splat the tile's sprites into the accumulators. The
        renderer launches the coarse tiles first, then the others: a reduced-level tile then
        adds the coarse level's sums under it (``with_coarse``) and resolves each texel to its
        layer (RGB, T) in place. A reduced or coarse tile emptied since the last frame is reset
        (to the empty layer, or the empty sums), so the upsamples may read any texel without
        asking whether its tile was drawn."""
        ti.loop_config(block_dim=1)
        LO, LC = W * H, W * H + Wl * Hl
        for t in range(t_lo, t_hi):
            lvl, tt, tx_n, Wk, Hk, base = 0, t, TX, W, H, 0
            if t >= T0 + T1:
                lvl, tt, tx_n, Wk, Hk, base = 2, t - T0 - T1, TXc, Wc, Hc, LC
            elif t >= T0:
                lvl, tt, tx_n, Wk, Hk, base = 1, t - T0, TXl, Wl, Hl, LO
            n = tile_count[t]
            px0, py0 = (tt % tx_n) * TILE, (tt // tx_n) * TILE
            px1, py1 = ti.min(Wk - 1, px0 + TILE - 1), ti.min(Hk - 1, py0 + TILE - 1)
            if n > 0:
                ab, aw = base, Wk  # the reduced and coarse levels' accumulators: row-major
                if lvl == 0:
                    ab, aw = tile_rows(px0, py0, px1, py1, W)
                splat_tile(t, px0, py0, px1, py1, pairs, tile_count, tile_start, accA, accB, dep, base, Wk,
                           ab, aw)
            if lvl == 2:
                if n == 0 and touched_co[tt] != 0:
                    for y in range(py0, py1 + 1):
                        for k in range(base + y * Wk + px0, base + y * Wk + px1 + 1):
                            accA[k] = EMPTY_LAYER
                            if ti.static(uses_alpha):
                                accB[k] = ti.Vector([0.0, 0.0, 0.0, 0.0])
                touched_co[tt] = ti.select(n > 0, 1, 0)
            elif lvl == 1:
                near = lo_near(px0, py0, px1, py1, touched_co, Wc, Hc, TXc, 0.5)
                if n > 0 or near != 0 or touched_lo[tt] != 0:
                    for y in range(py0, py1 + 1):
                        for x in range(px0, px1 + 1):
                            k = base + y * Wk + x
                            v = EMPTY_LAYER
                            if n > 0 or near != 0:
                                A, B = EMPTY_LAYER, ti.Vector([0.0, 0.0, 0.0, 0.0])
                                if n > 0:
                                    A = accA[k]
                                    if ti.static(uses_alpha):
                                        B = accB[k]
                                if near != 0:
                                    A, B = with_coarse(A, B, x, y, dep[k], accA, accB, dep, LC, Wc, Hc)
                                v = layer(A, B, shading)
                            accA[k] = v
                touched_lo[tt] = ti.select(n > 0 or near != 0, 1, 0)

    @ti.kernel
    def splat_pixels_co(pairs: ND_PAIRS, tile_count: ND_I1, tile_start: ND_I1, accA: ND_V4,
                        accB: ND_V4, dep: ND_F, touched_co: ND_I1, T01: ti.i32, LC: ti.i32,
                        T2: ti.i32, TXc: ti.i32, Wc: ti.i32, Hc: ti.i32):
        """The coarse level per texel (the GPU's schedule): its sums, as ``splat_tiles`` leaves
        them (T01 = T0 + T1: its first tile)."""
        for t in range(T2):
            touched_co[t] = ti.select(tile_count[T01 + t] > 0, 1, 0)
        for py, px in ti.ndrange(Hc, Wc):
            k = LC + py * Wc + px
            A, B = splat_pixel(T01 + (py // TILE) * TXc + px // TILE, px, py, pairs, tile_count,
                               tile_start, dep[k])
            accA[k] = A
            if ti.static(uses_alpha):
                accB[k] = B

    @ti.kernel
    def splat_pixels_lo(pairs: ND_PAIRS, tile_count: ND_I1, tile_start: ND_I1, accA: ND_V4,
                        accB: ND_V4, dep: ND_F, touched_lo: ND_I1, touched_co: ND_I1, T0: ti.i32,
                        W: ti.i32, H: ti.i32, T1: ti.i32, TXl: ti.i32, Wl: ti.i32, Hl: ti.i32,
                        TXc: ti.i32, Wc: ti.i32, Hc: ti.i32, shading: ti.f32):
        """The reduced level per texel (the GPU's schedule, after ``splat_pixels_co``; the same
        layer as ``splat_tiles``)."""
        LO, LC = W * H, W * H + Wl * Hl
        for t in range(T1):
            tx, ty = t % TXl, t // TXl
            near = lo_near(tx * TILE, ty * TILE, ti.min(Wl - 1, tx * TILE + TILE - 1),
                           ti.min(Hl - 1, ty * TILE + TILE - 1), touched_co, Wc, Hc, TXc, 0.5)
            touched_lo[t] = ti.select(tile_count[T0 + t] > 0 or near != 0, 1, 0)
        for py, px in ti.ndrange(Hl, Wl):
            k = LO + py * Wl + px
            tx, ty = px // TILE, py // TILE
            A, B = splat_pixel(T0 + ty * TXl + tx, px, py, pairs, tile_count, tile_start, dep[k])
            # (the tile's test, as the tile schedule makes it: the same sums added where it does)
            if lo_near(tx * TILE, ty * TILE, ti.min(Wl - 1, tx * TILE + TILE - 1),
                       ti.min(Hl - 1, ty * TILE + TILE - 1), touched_co, Wc, Hc, TXc, 0.5) != 0:
                A, B = with_coarse(A, B, px, py, dep[k], accA, accB, dep, LC, Wc, Hc)
            accA[k] = layer(A, B, shading)

    @ti.func
    def reduced_row(rows: ti.template(), bgc: ti.template(), out: ti.template(), ra, rb, k0, px0, fy,
                    exposure, mode):
        """A whole tile row (TILE pixels from k0 = y·W + px0) of the reduced layer alone over the
        background: all loads and table lookups first, then the stores (a store through an
        ndarray makes every later load re-read its array's address: none come between them)."""
        vals = ti.Vector([0] * TILE, dt=ti.u32)
        for dx in ti.static(range(TILE)):
            low = (1.0 - fy) * rows[ra + px0 + dx] + fy * rows[rb + px0 + dx]
            vals[dx] = finish(bgc[k0 + dx], low, EMPTY_LAYER, exposure, mode)
        for dx in ti.static(range(TILE)):
            out[k0 + dx] = vals[dx]

    @ti.func
    def bg_pixel(bg_packed: ti.template(), k):
        """Pixel k of the packed background (two pixels to a u64, the lower one in the low half:
        bytes in pixel order on a little-endian machine)."""
        return ti.cast((bg_packed[k >> 1] >> ti.cast(32 * (k & 1), ti.u64)) & ti.u64(0xFFFFFFFF), ti.u32)

    @ti.kernel
    def composite_tiles(tile_count: ND_I1, accA: ND_V4, accB: ND_V4, rows: ND_V4, bgc: ND_V4, dep: ND_F,
                        bg_packed: ND_U64, out: ND_U32, out64: ND_U64, wide: ti.i32, dirty: ND_I1,
                        dirty_prev: ND_I1,
                        touched_lo: ND_I1, edges: ND_I1, ex0: ti.i32, ey0: ti.i32, ex1: ti.i32,
                        ey1: ti.i32, TX: ti.i32, TY: ti.i32, W: ti.i32, H: ti.i32, TXl: ti.i32,
                        Wl: ti.i32, Hl: ti.i32, s: ti.f32, has_lo: ti.i32, exposure: ti.f32,
                        shading: ti.f32, mode: ti.i32):
        """Full resolution, per tile: the tile's own layer over the upsampled reduced layer over
        the background, tone-mapped and packed. An untouched tile copies the packed background.

        ``edges`` (TX·TY,) caches ``tile_is_edge`` per tile (−1: not known), for it depends on the
        depths alone, which change only where the background was redrawn — the tiles
        [ex0, ex1] × [ey0, ey1] (empty when ex0 > ex1), given with one tile of margin, since a
        tile's upsample reads texels up to 2 / s pixels past its edge — or where soft bodies
        drew this frame or the last (``dirty``, ``dirty_prev``: a tile next to such a tile too)."""
        ti.loop_config(block_dim=1)
        for t in range(TX * TY):
            tx, ty = t % TX, t // TX
            px0, py0 = tx * TILE, ty * TILE
            px1, py1 = ti.min(W - 1, px0 + TILE - 1), ti.min(H - 1, py0 + TILE - 1)
            n = tile_count[t]
            stale = ex0 <= tx and tx <= ex1 and ey0 <= ty and ty <= ey1
            for j in range(ti.max(0, ty - 1), ti.min(TY - 1, ty + 1) + 1):
                for i in range(ti.max(0, tx - 1), ti.min(TX - 1, tx + 1) + 1):
                    stale |= dirty[j * TX + i] != 0 or dirty_prev[j * TX + i] != 0
            if stale:
                edges[t] = -1
            near = 0
            if has_lo != 0:
                near = lo_near(px0, py0, px1, py1, touched_lo, Wl, Hl, TXl, s)
            if n == 0 and near == 0 and dirty[t] == 0:
                if wide != 0 and px1 - px0 == TILE - 1:
                    # two pixels an element: Taichi's CPU code pays per ndarray element, not per
                    # byte (a tile-ordered copy at 1280×720, one thread: u32 3.4–3.9 ms, u64
                    # 1.0–1.1 ms in a micro-benchmark; the empty frame's composite ~1 ms less)
                    for y in range(py0, py1 + 1):
                        k0 = (y * W + px0) >> 1
                        for i in range(k0, k0 + TILE // 2):
                            out64[i] = bg_packed[i]
                else:
                    for y in range(py0, py1 + 1):
                        for k in range(y * W + px0, y * W + px1 + 1):
                            out[k] = bg_pixel(bg_packed, k)
            else:
                edge = 0
                if near != 0:
                    edge = edges[t]
                    if edge < 0:
                        edge = tile_is_edge(px0, py0, px1, py1, dep, W * H, W, Wl, Hl, s)
                        edges[t] = edge
                if n == 0 and edge == 0 and near != 0:
                    # the common case under smoke: the reduced layer alone, bilinear; the row
                    # terms hoisted by hand (two loads and a lerp per pixel)
                    for y in range(py0, py1 + 1):
                        v = (y + 0.5) * s - 0.5
                        j0 = ti.cast(ti.floor(v), ti.i32)
                        fy = v - j0
                        ra = ti.min(ti.max(j0, 0), Hl - 1) * W
                        rb = ti.min(ti.max(j0 + 1, 0), Hl - 1) * W
                        if px1 - px0 == TILE - 1 and mode == 0:
                            # a whole row of the tile, opaque RGBA (the usual mode) with the mode a
                            # constant: its tests and swaps folded away (a branch per pixel cost
                            # the unrolled row ~1 ms a frame at 1280×720; a second unrolled copy
                            # for the other modes, ~0.15 s of every start: they take the loop)
                            reduced_row(rows, bgc, out, ra, rb, y * W + px0, px0, fy, exposure, 0)
                        else:
                            for x in range(px0, px1 + 1):
                                low = (1.0 - fy) * rows[ra + x] + fy * rows[rb + x]
                                out[y * W + x] = finish(bgc[y * W + x], low, EMPTY_LAYER, exposure,
                                                        mode)
                else:
                    ab, aw = tile_rows(px0, py0, px1, py1, W)
                    for y in range(py0, py1 + 1):
                        for x in range(px0, px1 + 1):
                            k = y * W + x
                            full = EMPTY_LAYER
                            if n > 0:
                                full = acc_layer(accA, accB, ab + y * aw + x, shading)
                            low = EMPTY_LAYER
                            if near != 0:
                                low = lo_sample(x, y, dep[k], accA, rows, dep, W * H, W, Wl, Hl, s,
                                                edge)
                            out[k] = finish(bgc[k], low, full, exposure, mode)

    @ti.kernel
    def composite_pixels(pairs: ND_PAIRS, tile_count: ND_I1, tile_start: ND_I1, accA: ND_V4,
                         rows: ND_V4, bgc: ND_V4, dep: ND_F, bg_packed: ND_U64, out: ND_U32, dirty: ND_I1,
                         touched_lo: ND_I1, TX: ti.i32, TY: ti.i32, W: ti.i32, H: ti.i32, TXl: ti.i32,
                         Wl: ti.i32, Hl: ti.i32, s: ti.f32, has_lo: ti.i32, exposure: ti.f32,
                         shading: ti.f32, mode: ti.i32):
        """Full resolution per pixel (the GPU's schedule, after 3DGS): splat in registers, then
        the same composite as ``composite_tiles``."""
        for py, px in ti.ndrange(H, W):
            tx, ty = px // TILE, py // TILE
            t = ty * TX + tx
            k = py * W + px
            near = 0
            if has_lo != 0:
                near = lo_near(tx * TILE, ty * TILE, ti.min(W - 1, tx * TILE + TILE - 1),
                               ti.min(H - 1, ty * TILE + TILE - 1), touched_lo, Wl, Hl, TXl, s)
            if tile_count[t] == 0 and near == 0 and dirty[t] == 0:
                out[k] = bg_pixel(bg_packed, k)
            else:
                full = EMPTY_LAYER
                if tile_count[t] > 0:
                    A, B = splat_pixel(t, px, py, pairs, tile_count, tile_start, dep[k])
                    full = layer(A, B, shading)
                low = EMPTY_LAYER
                if near != 0:
                    edge = lo_edge(tx * TILE, ty * TILE, ti.min(W - 1, tx * TILE + TILE - 1),
                                   ti.min(H - 1, ty * TILE + TILE - 1), dep, W * H, Wl, Hl, s)
                    low = lo_sample(px, py, dep[k], accA, rows, dep, W * H, W, Wl, Hl, s, edge)
                out[k] = finish(bgc[k], low, full, exposure, mode)

    @ti.kernel
    def pack_background(bgc: ND_V4, bg_packed: ND_U64, W: ti.i32, H: ti.i32, x0: ti.i32, y0: ti.i32,
                        x1: ti.i32, y1: ti.i32, exposure: ti.f32, mode: ti.i32):
        """The background alone, tone-mapped and packed: what an untouched tile copies (in the
        pixel rectangle [x0, x1) × [y0, y1), two pixels to a u64: a pair the rectangle's edge cuts
        is packed whole, its other pixel again from its unchanged ``bgc``)."""
        for y in range(y0, y1):
            for i in range((y * W + x0) >> 1, ((y * W + x1 - 1) >> 1) + 1):
                lo = ti.cast(finish(bgc[2 * i], EMPTY_LAYER, EMPTY_LAYER, exposure, mode), ti.u64)
                hi = ti.u64(0)
                if 2 * i + 1 < W * H:
                    hi = ti.cast(finish(bgc[2 * i + 1], EMPTY_LAYER, EMPTY_LAYER, exposure, mode), ti.u64)
                bg_packed[i] = lo | (hi << 32)

    # (launched without Taichi's per-argument Python: engine.launch)
    return {name: fast(k) for name, k in dict(
        splat_tiles=splat_tiles, splat_pixels_co=splat_pixels_co, splat_pixels_lo=splat_pixels_lo, lo_rows=lo_rows,
        composite_tiles=composite_tiles, composite_pixels=composite_pixels,
        pack_background=pack_background).items()}
