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

The splat's funcs and kernels live in ``splat_kernels.py``, built here with the composite's (the
reduced level resolves its texels with this module's ``layer``; the composite finds a tile's sums
with its ``tile_rows``).

Tone map: exposure, the ACES filmic fit (Narkowicz 2015), sRGB by a 20,480-entry table of 8-bit
values (``pow`` once per entry at build, not three times per pixel), found by the value's bits
(``engine.render.tonemap``), packed as one u32 RGBA per pixel (bytes R, G, B, A in memory):
``engine.render.pack``, built here with the kernels.
"""
# (no `from __future__ import annotations`: Taichi reads kernel annotations at definition)

import taichi as ti

from .. import runtime
from ..launch import fast
from ..spread import TASK, item, rounds, tasks
from .splat_kernels import EMPTY_LAYER, ND_PAIRS, build_splat
from .sprites import TILE
from .pack import build_pack
from .upsample import (ND_F, ND_I1, ND_V4, bilateral_mix, empty_rows, lo_bilateral, lo_edge, lo_near, lo_row,
                       lo_rows, lo_sample, row_place, rows_lerp, tile_edge_rows)

# (flat pixel arrays, as engine.render.upsample's)
ND_U32 = ti.types.ndarray(dtype=ti.u32, ndim=1)
ND_U64 = ti.types.ndarray(dtype=ti.u64, ndim=1)


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
    tone_rgb, finish, finish_opaque = build_pack()
    NT = tasks()  # (the per-tile loop's tasks: engine.spread)

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
    def acc_layer(accA: ti.template(), accB: ti.template(), k, shading):
        B = ti.Vector([0.0, 0.0, 0.0, 0.0])
        if ti.static(uses_alpha):
            B = accB[k]
        return layer(accA[k], B, shading)

    tile_rows, splat_pixel, splat_tiles, splat_pixels_co, splat_pixels_lo = build_splat(
        uses_add, uses_alpha, layer)

    @ti.func
    def reduced_row(lo: ti.template(), dep: ti.template(), bgc: ti.template(), out: ti.template(), la, lb,
                    k0, px0, fy, exposure, Wl, k: ti.template(), bilateral):
        """A whole tile row (TILE pixels from k0 = y·W + px0) of the reduced layer alone over the
        background, opaque RGBA (mode 0: ``finish_opaque``), from the reduced texels of rows la,
        lb (their first texels' indices): each row's TILE/k + 2 texels loaded once, interpolated
        along x at each pixel (``row_lerp``), then between the rows; all loads and table lookups
        first, then the stores (a store through an ndarray makes every later load re-read its
        array's address: none come between them). ``bilateral``: every pixel of the row takes ``upsample.lo_bilateral``'s
        weights instead (the horizon's band under smoke, where the receding floor's depth grows
        by more than 10 % a texel), the row's texel depths loaded once too: the per-pixel path
        took each pixel's quad by float floors and its eight loads again (explosion.toml at
        1280×720: 3,520 such rows, ~1 ms of the composite's 5.7). (A row function of its own for
        them, unrolled too, took the composite's cold compile 1.6 → 3.6–4.5 s; as a loop it was
        slower than the per-pixel path.)"""
        i0 = (px0 // k) - 1  # the texel left of the row's first pixel (px0 a multiple of TILE)
        ta = [lo[la + ti.min(ti.max(i0 + n, 0), Wl - 1)] for n in ti.static(range(TILE // k + 2))]
        tb = [lo[lb + ti.min(ti.max(i0 + n, 0), Wl - 1)] for n in ti.static(range(TILE // k + 2))]
        za = [dep[la + ti.min(ti.max(i0 + n, 0), Wl - 1)] for n in ti.static(range(TILE // k + 2))]
        zb = [dep[lb + ti.min(ti.max(i0 + n, 0), Wl - 1)] for n in ti.static(range(TILE // k + 2))]
        vals = ti.Vector([0] * TILE, dt=ti.u32)
        for dx in ti.static(range(TILE)):
            n, fx = ti.static(row_place(dx, k))
            a = (1.0 - fx) * ta[n] + fx * ta[n + 1]
            b = (1.0 - fx) * tb[n] + fx * tb[n + 1]
            low = (1.0 - fy) * a + fy * b
            if bilateral != 0:
                low = bilateral_mix(fx, fy, dep[k0 + dx], za[n], za[n + 1], zb[n], zb[n + 1], ta[n], ta[n + 1],
                                    tb[n], tb[n + 1])
            vals[dx] = finish_opaque(bgc[k0 + dx], low, exposure)
        for dx in ti.static(range(TILE)):
            out[k0 + dx] = vals[dx]

    @ti.func
    def reduced_rows(lo: ti.template(), accB: ti.template(), bgc: ti.template(), out: ti.template(), la, lb, y0,
                     y1, px0, py0, W, s, drawn, ab, aw, exposure, shading, Wl, k: ti.template()):
        """Pixel rows y0..y1 of a tile (TILE pixels from px0 each, tile rows from py0), all reading
        the reduced rows la, lb (their first texels' indices in ``lo``, which is ``accA``)
        bilinearly, opaque RGBA (mode 0), bit for bit what the row-at-a-time paths give them:
        the rows' lerps along x (``row_lerp``'s values: they depend on the column and the two rows
        only) taken once for them all, then per pixel its row's vertical lerp, the background
        under it and, in a row its tile's sprites drew in (bit y − py0 of ``drawn``), the full
        layer over it (``acc_layer`` at ab + y·aw + x: ``tile_rows``) — ``finish(bg, low, full,
        exposure, 0)``'s colour, its alpha 255 as ``finish_opaque``'s (without a full layer, its
        c·1 + 0 is c). A loop over the row's pixels, the lerps in a local matrix: unrolled over
        the row (16 copies), the rows without a full layer took flames.toml's composite at
        1280×720 from 3.55 to 3.19 ms; this way, every row, 3.64 → 3.07 (best of 31, one process;
        the tile's rows with sprites had taken the per-pixel loop at ~0.5 ms of it)."""
        i0 = (px0 // k) - 1  # the texel left of the rows' first pixel (px0 a multiple of TILE)
        ta = [lo[la + ti.min(ti.max(i0 + n, 0), Wl - 1)] for n in ti.static(range(TILE // k + 2))]
        tb = [lo[lb + ti.min(ti.max(i0 + n, 0), Wl - 1)] for n in ti.static(range(TILE // k + 2))]
        place = ti.static([row_place(dx, k) for dx in range(TILE)])  # (n, fx) of each column
        ha = [(1.0 - place[dx][1]) * ta[place[dx][0]] + place[dx][1] * ta[place[dx][0] + 1]
              for dx in ti.static(range(TILE))]
        hb = [(1.0 - place[dx][1]) * tb[place[dx][0]] + place[dx][1] * tb[place[dx][0] + 1]
              for dx in ti.static(range(TILE))]
        HA = ti.Matrix([[ha[dx][c] for c in ti.static(range(4))] for dx in ti.static(range(TILE))])
        HB = ti.Matrix([[hb[dx][c] for c in ti.static(range(4))] for dx in ti.static(range(TILE))])
        for y in range(y0, y1 + 1):
            v = (y + 0.5) * s - 0.5  # (fy as the composite's row loop takes it)
            fy = v - ti.cast(ti.floor(v), ti.i32)
            fh = (drawn >> (y - py0)) & 1
            for dx in range(TILE):
                low = ti.Vector([(1.0 - fy) * HA[dx, c] + fy * HB[dx, c] for c in ti.static(range(4))])
                bg = bgc[y * W + px0 + dx]
                c = ti.Vector([bg[0], bg[1], bg[2]]) * low[3] + ti.Vector([low[0], low[1], low[2]])
                if fh != 0:
                    full = acc_layer(lo, accB, ab + y * aw + px0 + dx, shading)
                    c = c * full[3] + ti.Vector([full[0], full[1], full[2]])
                r, g, b = tone_rgb(c * exposure)
                out[y * W + px0 + dx] = r | (g << 8) | (b << 16) | ti.u32(0xFF000000)

    @ti.func
    def bg_pixel(bg_packed: ti.template(), k):
        """Pixel k of the packed background (two pixels to a u64, the lower one in the low half:
        bytes in pixel order on a little-endian machine)."""
        return ti.cast((bg_packed[k >> 1] >> ti.cast(32 * (k & 1), ti.u64)) & ti.u64(0xFFFFFFFF), ti.u32)

    @ti.func
    def background_row(bg_packed: ti.template(), out: ti.template(), out64: ti.template(), copy, y, px0,
                       px1, W):
        """Pixels [px0, px1] of row y as the packed background (``copy``: see composite_tiles)."""
        if copy == 2:
            pass
        elif copy == 1 and px1 - px0 == TILE - 1:
            # two pixels an element: Taichi's CPU code pays per ndarray element, not per byte (a
            # tile-ordered copy at 1280×720, one thread: u32 3.4–3.9 ms, u64 1.0–1.1 ms in a
            # micro-benchmark; the empty frame's composite ~1 ms less)
            k0 = (y * W + px0) >> 1
            for i in range(k0, k0 + TILE // 2):
                out64[i] = bg_packed[i]
        else:
            for k in range(y * W + px0, y * W + px1 + 1):
                out[k] = bg_pixel(bg_packed, k)

    @ti.kernel
    def composite_tiles(tile_count: ND_I1, full_rows: ND_I1, accA: ND_V4, accB: ND_V4, bgc: ND_V4, dep: ND_F,
                        bg_packed: ND_U64, out: ND_U32, out64: ND_U64, copy: ti.i32, dirty: ND_I1,
                        dirty_prev: ND_I1,
                        touched_lo: ND_I1, edges: ND_I1, edge_rows: ND_I1, ex0: ti.i32, ey0: ti.i32,
                        ex1: ti.i32, ey1: ti.i32, TX: ti.i32, TY: ti.i32, W: ti.i32, H: ti.i32,
                        TXl: ti.i32, Wl: ti.i32, Hl: ti.i32, s: ti.f32, exposure: ti.f32,
                        shading: ti.f32, mode: ti.i32, k: ti.template()):
        """Full resolution, per tile: the tile's own layer over the upsampled reduced layer over
        the background, tone-mapped and packed. An untouched tile copies the packed background
        (``copy`` 0: pixel by pixel; 1: two pixels an element, through ``out64``; 2: not at all,
        the caller has filled ``out`` with it in one memcpy: ``targets.untouched_tiles``).

        ``edges`` (TX·TY,) caches per tile whether its upsample is bilateral at any pixel (−1: not
        known) and ``edge_rows`` (TX·TY·TILE,) at which (``tile_edge_rows``: a mask per pixel row,
        valid where ``edges`` is not −1), for they depend on the depths alone, which change only
        where the background was redrawn — the tiles [ex0, ex1] × [ey0, ey1] (empty when
        ex0 > ex1), given with one tile of margin, since a tile's upsample reads texels up to
        2 / s pixels past its edge — or where soft bodies drew this frame or the last (``dirty``,
        ``dirty_prev``: a tile next to such a tile too).

        ``k`` 0: this frame draws no reduced layer; its code is not compiled in, so a
        scene that never draws one (sparks, galaxy) does not build it: in sparks' warm start the
        composite's first call (its front end and the cached kernel's load) took 0.48 s, 0.06 s so
        (``Renderer.warm_levels`` compiles both for a loading screen).

        The reduced layer (scale s = 1/k, k = 2 or 4) is read from its texels in ``accA``: each
        pixel row's two reduced rows interpolated along x (``upsample.row_lerp``; in the usual
        opaque mode, a whole tile's rows that read the same two reduced rows take those lerps
        once, ``reduced_rows``, or, in a tile with bilateral pixels, a row its TILE/k + 2 texels
        of each, ``reduced_row``), then between them.
        Before, a kernel of its own wrote every needed row interpolated at every full-resolution
        column (``lo_rows``, 3.7 MB at 1280×720) for the composite to read back: explosion.toml
        at 1280×720, both kernels 6.1 → 4.6 ms, campfire 5.2 → 3.9 (one process, old and new in
        turn, best of 11). Per tile, the reduced rows that are the empty layer under it
        (``upsample.empty_rows``): a tile row under only the reduced layer whose two rows are both
        empty shows the packed background. ``full_rows`` (TX·TY,): per tile with sprites,
        the mask of the rows they may have drawn in (``splat_tiles``); a row outside it is the
        empty full layer (0, 0, 0, 1) exactly, so it is composited as a row of a tile without
        sprites is: the reduced layer alone, or, with neither and no body drawn in the tile, the
        packed background (33 % of those tiles' rows in sparks at 1280×720, 61 % in explosion)."""
        # the tiles spread over the CPU's tasks (engine.spread): in order, a fire's tiles, which
        # lie together, were one or two tasks of 512
        for sl in range(NT * TASK):
            for r in range(rounds(TX * TY, NT)):
                t = item(sl, r, NT)
                if t < TX * TY:
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
                    if ti.static(k != 0):
                        near = lo_near(px0, py0, px1, py1, touched_lo, Wl, Hl, TXl, s)
                    if n == 0 and near == 0 and dirty[t] == 0:
                        if copy != 2:
                            for y in range(py0, py1 + 1):
                                background_row(bg_packed, out, out64, copy, y, px0, px1, W)
                    else:
                        drawn = 0  # the rows of this tile its own sprites may have drawn in
                        if n > 0:
                            drawn = full_rows[t]
                        ab, aw = tile_rows(px0, py0, px1, py1, W)
                        edge, jt, empty = 0, 0, 0
                        if ti.static(k != 0):
                            if near != 0:
                                edge = edges[t]
                                if edge < 0:
                                    edge = tile_edge_rows(px0, py0, px1, py1, dep, W * H, W, Wl, Hl, s, edge_rows,
                                                          t * TILE)
                                    edges[t] = edge
                            jt = ti.max(lo_row(py0, k), 0)  # the tile's first reduced row
                            # bit j - jt: reduced row j is the empty layer under the tile
                            if near != 0 and dirty[t] == 0 and drawn != (1 << (py1 - py0 + 1)) - 1:
                                empty = empty_rows(accA, jt, ti.min(lo_row(py1, k) + 1, Hl - 1), px0, px1, W * H, Wl, k)
                        grouped = -1  # the last row drawn with the rows before it (``reduced_rows``)
                        for y in range(py0, py1 + 1):
                            if y <= grouped:
                                continue
                            full_here = (drawn >> (y - py0)) & 1
                            fy, ra, rb, mask = 0.0, 0, 0, 0
                            done = 0  # the row drawn under the reduced layer alone
                            if ti.static(k != 0):
                                # the upsample's row terms, hoisted by hand (two loads and a lerp per pixel
                                # where it is bilinear: every pixel whose bit in the row's mask is clear)
                                v = (y + 0.5) * s - 0.5
                                j0 = ti.cast(ti.floor(v), ti.i32)
                                fy = v - j0
                                ja, jb = ti.min(ti.max(j0, 0), Hl - 1), ti.min(ti.max(j0 + 1, 0), Hl - 1)
                                ra, rb = W * H + ja * Wl, W * H + jb * Wl  # (the reduced rows' first texels)
                                if edge != 0:
                                    mask = edge_rows[t * TILE + y - py0]
                                if edge == 0 and mode == 0 and px1 - px0 == TILE - 1 and near != 0:
                                    # the rows that read the same two reduced rows (k of them, fewer at
                                    # the tile's edges) drawn at once (``reduced_rows``), unless the two
                                    # rows are both empty and no sprite of the tile drew in them: then
                                    # each is the packed background, below
                                    y1 = y
                                    while y1 < py1 and lo_row(y1 + 1, k) == j0:
                                        y1 += 1
                                    if (drawn >> (y - py0)) & ((1 << (y1 - y + 1)) - 1) != 0 or not (
                                            dirty[t] == 0 and (empty >> (ja - jt)) & (empty >> (jb - jt)) & 1 != 0):
                                        reduced_rows(accA, accB, bgc, out, ra, rb, y, y1, px0, py0, W, s, drawn, ab, aw,
                                                     exposure, shading, Wl, k)
                                        grouped = y1
                                        continue
                                if full_here == 0 and near != 0:
                                    done = 1
                                    if dirty[t] == 0 and (empty >> (ja - jt)) & (empty >> (jb - jt)) & 1 != 0:
                                        # both its rows the empty layer here (``empty``: upsample.empty_rows),
                                        # and no body drew in the tile (``bgc`` is then the frame's, bodies
                                        # drawn in, not what was packed): the packed background, bit for bit
                                        # — also where the upsample is bilateral (``mask``): its four texels
                                        # are then the empty layer, whose weighted mean is itself (RGB 0·w =
                                        # 0; T: Σ w·1 / Σ w, one sum over the other). The horizon's band of
                                        # bilateral rows, where the receding floor's depth grows by more
                                        # than 10 % a texel, is mostly such rows (flames.toml at 1280×720:
                                        # three rows of tiles, 56k pixels)
                                        background_row(bg_packed, out, out64, copy, y, px0, px1, W)
                                    elif (mask == 0 or mask == (1 << TILE) - 1) and px1 - px0 == TILE - 1 and mode == 0:
                                        # the common case under smoke: bilinear (or, with a full mask,
                                        # bilateral at every pixel: the horizon's band), a whole row of the
                                        # tile, opaque RGBA (the usual mode) with the mode a constant: its
                                        # tests and swaps folded away (a branch per pixel cost the unrolled
                                        # row ~1 ms a frame at 1280×720; a second unrolled copy for the
                                        # other modes, ~0.15 s of every start: they take the loops)
                                        reduced_row(accA, dep, bgc, out, ra, rb, y * W + px0, px0, fy, exposure, Wl, k,
                                                    mask)
                                    elif mask == 0:
                                        for x in range(px0, px1 + 1):
                                            low = rows_lerp(accA, ra, rb, x, fy, Wl, k)
                                            out[y * W + x] = finish(bgc[y * W + x], low, EMPTY_LAYER, exposure, mode)
                                    else:
                                        done = 0  # (some pixels bilateral: the general loop below)
                            if done == 0:
                                if full_here == 0 and near == 0 and dirty[t] == 0:
                                    background_row(bg_packed, out, out64, copy, y, px0, px1, W)
                                else:
                                    for x in range(px0, px1 + 1):
                                        q = y * W + x
                                        full = EMPTY_LAYER
                                        if full_here != 0:
                                            full = acc_layer(accA, accB, ab + y * aw + x, shading)
                                        low = EMPTY_LAYER
                                        if ti.static(k != 0):
                                            if near != 0:
                                                if (mask >> (x - px0)) & 1 != 0:
                                                    low = lo_bilateral(x, y, dep[q], accA, dep, W * H, Wl, Hl, s)
                                                else:
                                                    low = rows_lerp(accA, ra, rb, x, fy, Wl, k)
                                        out[q] = finish(bgc[q], low, full, exposure, mode)

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
        for sl in range(NT * TASK):  # (the rows spread over the CPU's tasks: engine.spread)
            for rr in range(rounds(y1 - y0, NT)):
                y = y0 + item(sl, rr, NT)
                if y < y1:
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
