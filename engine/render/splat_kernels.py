"""The splat half of the frame's pass: sprites added into the accumulator arrays of the three
levels (full, reduced, coarse), per tile on the CPU or per texel on a GPU.

:mod:`engine.render.composite` builds these with its composite and tone-map kernels, per pair of
blend modes, and its docstring tells the two schedules and the levels; :mod:`engine.render.splat`
says what one sprite adds to a pixel. Here: where each level keeps its sums (the full level tile
by tile, ``tile_rows``; the reduced and coarse levels row-major), how a record covers a tile's
pixels (discs by rows of their span, 1–3 px sprites as unrolled blocks, streaks by rows of their
capsule), and the reduced level resolved in place to its layer once the coarse sums under it are
added (``with_coarse``).
"""
# (no `from __future__ import annotations`: Taichi reads kernel annotations at definition)

import taichi as ti

from ..spread import TASK, item, rounds, tasks
from .binning import vec16
from .splat import add_sprite, capsule_point, disc_weight, record_box
from .sprites import TILE
from .upsample import ND_F, ND_I1, ND_V4, co_mix, co_quad, footprint, is_empty_layer, lo_near

EMPTY_LAYER = ti.Vector([0.0, 0.0, 0.0, 1.0])  # a layer that draws nothing: RGB 0, T 1


@ti.func
def row_mask(y0, y1, py0):
    """Bits y0 − py0 … y1 − py0 set (rows y0..y1 of a tile whose first row is py0; y0 ≤ y1)."""
    return ((1 << (y1 - py0 + 1)) - 1) ^ ((1 << (y0 - py0)) - 1)
ND_PAIRS = ti.types.ndarray(dtype=vec16, ndim=1)  # the binned records, one per (tile, sprite)


def build_splat(uses_add: bool, uses_alpha: bool, layer):
    """The splat funcs and kernels for scenes with these blend modes (``uses_add``: some sprite is
    additive; ``uses_alpha``: some is alpha-blended: the other's code is not compiled).
    ``layer(A, B, shading)``: the composite's resolve of a pixel's sums (A, B) to a premultiplied
    layer (RGB, T), which the reduced level's texels take in place.

    Returns ``(tile_rows, splat_pixel, splat_tiles, splat_pixels_co, splat_pixels_lo)``: the
    funcs ``tile_rows`` (where the full level keeps a tile's sums) and ``splat_pixel`` (one pixel's
    sums in registers) serve the composite too; the three kernels splat the levels, per tile
    (``splat_tiles``) or per texel (the coarse level, then the reduced)."""
    NT = tasks()  # (the per-tile loop's tasks: engine.spread)

    @ti.func
    def deposit(px0, py0, px1, py1, rec, accA: ti.template(), accB: ti.template(),
                dep: ti.template(), base, W, ab, aw, want_rows):
        """A record onto the pixels of [px0, px1] × [py0, py1] it covers (depths at
        base + y·W + x, accumulators at ab + y·aw + x: ``tile_rows``); returns a mask of the tile's
        rows it may have drawn in (bit y − py0: each row whose span of the disc or capsule reaches
        into the tile; for a 1–3 px sprite, its box's rows). ``want_rows`` false (the reduced and
        coarse levels: only the full level's mask is kept, for the composite): a disc's rows are
        not asked for their span — a square root a row, for nothing (the splat of explosion.toml
        at 1280×720, coarse level 0.97 → 0.92 ms, reduced 1.15 → 1.09; flames 0.89 → 0.77 and
        1.40 → 1.35; best of 21–25 in one process, the same sums)."""
        rows = 0
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
                rows |= ti.select(x0 <= x1, 1 << (yy - py0), 0)  # (a row its span reaches)
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
                    rows = row_mask(y0, y1, py0)
                    block(2, x0, y0, x1, y1, cx, cy, inv_r2, rec, col, a, is_add, energy, accA, accB,
                          dep, base, W, ab, aw)
                else:  # one inlined pixel in a loop keeps the kernel (and its build) small: a 4×4
                    # unrolled block as well cost 5.6 s more to compile cold, for 1M-particle frames
                    for yy in range(y0, y1 + 1):
                        # the row's span inside the circle marks the row drawn; its pixels are the
                        # box's [x0, x1] (weight 0 outside the circle, which adds nothing: + 0, × 1):
                        # one trip count for every row of the record, which the branch predictor
                        # learns, where a span's own (a box wastes 1 − π/4 of its pixels) missed
                        # at every row's end — flames.toml's splat at 1280×720 3.23 → 3.08 ms,
                        # explosion 2.83 → 2.67 (best of 21, one process; the same sums)
                        if want_rows:
                            dy = yy + 0.5 - cy
                            half = ti.sqrt(ti.max(0.0, rad * rad - dy * dy))
                            xs0 = ti.max(x0, ti.cast(ti.floor(cx - half), ti.i32))
                            xs1 = ti.min(x1, ti.cast(ti.floor(cx + half), ti.i32))
                            rows |= ti.select(xs0 <= xs1, 1 << (yy - py0), 0)
                        for xx in range(x0, x1 + 1):
                            pixel(xx, yy, True, cx, cy, inv_r2, rec, col, a, is_add, energy, accA,
                                  accB, dep, base, W, ab, aw)
        return rows

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
                   dep: ti.template(), base, W, ab, aw, want_rows):
        """Clear a tile's accumulators and add its sprites, in slot order (per-tile schedule);
        returns the mask of the rows they may have drawn in (``deposit``; ``want_rows``: its)."""
        for y in range(py0, py1 + 1):
            for x in range(ab + y * aw + px0, ab + y * aw + px1 + 1):
                accA[x] = EMPTY_LAYER
                if ti.static(uses_alpha):
                    accB[x] = ti.Vector([0.0, 0.0, 0.0, 0.0])
        rows = 0
        for j in range(tile_start[t], tile_start[t] + tile_count[t]):
            rows |= deposit(px0, py0, px1, py1, pairs[j], accA, accB, dep, base, W, ab, aw, want_rows)
        return rows

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

    @ti.func
    def co_drawn(px0, py0, px1, py1, accA: ti.template(), accB: ti.template(), LC, Wc, Hc):
        """Whether any coarse texel that ``with_coarse`` reads for the reduced texels
        [px0, px1] × [py0, py1] holds a sprite's sums (not the empty sums (0, 0, 0, 1), (0, 0, 0, 0)
        exactly). Where none does, the coarse level adds nothing there: the tile is not near it
        (``lo_near`` says only that a coarse tile under it was drawn: about a third of those in
        explosion, campfire and debris at 1280×720 draw nothing under it), so it is neither mixed
        in nor, where no sprite of its own is drawn, the tile counted as drawn."""
        lx0, lx1, ly0, ly1 = footprint(px0, py0, px1, py1, 0.5, Wc, Hc)
        drawn = 0
        for ly in range(ly0, ly1 + 1):
            for k in range(LC + ly * Wc + lx0, LC + ly * Wc + lx1 + 1):
                if not is_empty_layer(accA[k]):
                    drawn = 1
                if ti.static(uses_alpha):
                    if (accB[k] != 0.0).any():
                        drawn = 1
        return drawn

    @ti.kernel
    def splat_tiles(pairs: ND_PAIRS, tile_count: ND_I1, tile_start: ND_I1, accA: ND_V4, accB: ND_V4,
                    dep: ND_F, touched_lo: ND_I1, touched_co: ND_I1, full_rows: ND_I1, t_lo: ti.i32,
                    t_hi: ti.i32,
                    T0: ti.i32, TX: ti.i32, W: ti.i32, H: ti.i32, T1: ti.i32, TXl: ti.i32, Wl: ti.i32,
                    Hl: ti.i32, TXc: ti.i32, Wc: ti.i32, Hc: ti.i32, shading: ti.f32, levels: ti.template()):
        """Per tile (the CPU's schedule), the tiles [t_lo, t_hi) of the index space (full level,
        then reduced, then coarse): clear and splat the tile's sprites into the accumulators (and
        keep a full-level tile's mask of the rows they may have drawn in, ``full_rows``, for the
        composite). The
        renderer launches the coarse tiles first, then the others: a reduced-level tile then
        adds the coarse level's sums under it (``with_coarse``) and resolves each texel to its
        layer (RGB, T) in place. A reduced or coarse tile emptied since the last frame is reset
        (to the empty layer, or the empty sums), so the upsamples may read any texel without
        asking whether its tile was drawn. ``levels`` False: the full level's tiles alone (t_hi ≤
        T0), for a frame with no sprite at the other two while every tile of theirs is already
        clear (``Renderer._splat``): their code is not compiled in, so a scene that never draws
        them (sparks, galaxy) does not build it, at any start."""
        LO, LC = W * H, W * H + Wl * Hl
        # the tiles spread over the CPU's tasks (engine.spread): in order, the coarse level's
        # few dozen were one task and the reduced level's one or two, each a thread's alone
        for s in range(NT * TASK):
            for r in range(rounds(t_hi - t_lo, NT)):
                t = t_lo + item(s, r, NT)
                if t < t_hi:
                    lvl, tt, tx_n, Wk, Hk, base = 0, t, TX, W, H, 0
                    if ti.static(levels):
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
                        rows = splat_tile(t, px0, py0, px1, py1, pairs, tile_count, tile_start, accA, accB, dep,
                                          base, Wk, ab, aw, lvl == 0)
                        if lvl == 0:
                            full_rows[t] = rows
                    if ti.static(levels):
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
                            if near != 0:
                                near = co_drawn(px0, py0, px1, py1, accA, accB, LC, Wc, Hc)
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
            x0, y0 = tx * TILE, ty * TILE
            x1, y1 = ti.min(Wl - 1, x0 + TILE - 1), ti.min(Hl - 1, y0 + TILE - 1)
            near = lo_near(x0, y0, x1, y1, touched_co, Wc, Hc, TXc, 0.5)
            if near != 0:
                near = co_drawn(x0, y0, x1, y1, accA, accB, LC, Wc, Hc)
            # bit 0: drawn (as the tile schedule has it); bit 1: the coarse level mixed in, read
            # by the texels below (the tile's test, as the tile schedule makes it)
            touched_lo[t] = ti.select(tile_count[T0 + t] > 0 or near != 0, 1, 0) | (near << 1)
        for py, px in ti.ndrange(Hl, Wl):
            k = LO + py * Wl + px
            tx, ty = px // TILE, py // TILE
            A, B = splat_pixel(T0 + ty * TXl + tx, px, py, pairs, tile_count, tile_start, dep[k])
            if touched_lo[ty * TXl + tx] & 2 != 0:
                A, B = with_coarse(A, B, px, py, dep[k], accA, accB, dep, LC, Wc, Hc)
            accA[k] = layer(A, B, shading)

    return tile_rows, splat_pixel, splat_tiles, splat_pixels_co, splat_pixels_lo
