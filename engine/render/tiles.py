"""Tiled, parallel and deterministic particle splatting: the same image as ``raster.py``'s serial
splat, accumulated by many threads without float atomics.

Every live particle is turned into a *sprite* once (centre, radius, depth, colour, alpha, energy,
optional streak), then binned into 16×16-pixel screen tiles by a counting sort that is stable in
slot order, and each tile is accumulated by one thread walking its particles in slot order. Each
pixel therefore receives exactly the contributions the serial splat gives it, in the same order:
the result does not depend on the number of threads, and matches the serial splat.

Passes, each one kernel (PERF-NOTES: launches cost ~17 µs, float atomics are slow and make sums
depend on thread timing):
1. ``sprites`` (parallel over slots): project, evaluate the colour/alpha/size curves, write the
   sprite and the range of tiles it covers.
2. ``count`` (parallel over CHUNKS fixed slot ranges): per chunk, how many sprites touch each tile.
   One thread owns a chunk's histogram row, so no atomics; CHUNKS is a constant, not the thread
   count, so the order below does not depend on threads.
3. ``offsets`` (parallel over tiles) and ``starts`` (serial over tiles): the exclusive prefix sum
   in (tile, chunk, slot) order — a stable counting sort by tile.
4. ``scatter`` (parallel over chunks): each chunk writes its slot indices into the tile lists.
5. ``accumulate`` (parallel over tiles): each tile's pixels, its sprites in slot order.

The pair list grows (and only the kernels that take it are re-specialised) when a frame needs
more tile–sprite pairs than it holds.
"""
# (no `from __future__ import annotations`: Taichi reads kernel annotations at definition)

from types import SimpleNamespace

import taichi as ti

TILE = 16
CHUNKS = 64
MAX_SPLAT_RADIUS = 48.0  # pixels; as raster.py
vec3 = ti.types.vector(3, ti.f32)


@ti.func
def oit_depth_weight(z):
    """McGuire & Bavoil (2013) eq. 10 depth weight (the factor of the alpha in w)."""
    return ti.max(1e-2, ti.min(3e3, 10.0 / (1e-5 + ti.pow(z / 5.0, 2.0) + ti.pow(z / 200.0, 6.0))))


def make_sprite_funcs(S, look, W: int, H: int):
    """The one definition of how a particle becomes a sprite, for the tiled and the serial splat.

    ``project(i, o, f, r, u, th)`` → (drawn, emitter, cx, cy, rad px, z, colour, alpha, energy,
    size m): sized in world units, sub-pixel sprites drawn at 0.75 px carrying their light, large
    ones clamped. ``streak_end(i, e, o, f, r, u, th)`` → pixel (tx, ty) of the streak's tail."""
    pos, vel, age, life, alive, pem, prand = (
        S.particle_pos, S.particle_vel, S.particle_age, S.particle_life, S.particle_alive,
        S.particle_emitter, S.particle_rand)
    color_at, alpha_at, size_at = look.color_at, look.alpha_at, look.size_at
    streak, size_rand = look.streak, look.size_rand

    @ti.func
    def project(i, o, f, r, u, th):
        drawn, e = 0, 0
        cx = cy = rad = z = a = energy = sz = 0.0
        col = ti.Vector([0.0, 0.0, 0.0])
        if alive[i] != 0 and age[i] >= 0.0:  # (negative age: not born yet)
            e = pem[i]
            tl = ti.min(1.0, age[i] / life[i])
            dpos = pos[i] - o
            z = dpos.dot(f)
            if z > 0.05:
                drawn = 1
                col = color_at(e, tl)
                a = alpha_at(e, tl)[0]
                sz = size_at(e, tl)[0] * (1.0 + size_rand[e] * (2.0 * prand[i] - 1.0))
                scale = 0.5 * H / (z * th)
                cx = dpos.dot(r) * scale + 0.5 * W
                cy = 0.5 * H - dpos.dot(u) * scale
                rad = 0.5 * sz * scale
                energy = 1.0
                if rad < 0.75:  # sub-pixel: draw at 0.75 px, keep the light it carries
                    energy = (rad / 0.75) ** 2
                    rad = 0.75
                if rad > MAX_SPLAT_RADIUS:
                    rad = MAX_SPLAT_RADIUS
        return drawn, e, cx, cy, rad, z, col, a, energy, sz

    @ti.func
    def streak_end(i, e, o, f, r, u, th):
        tpos = pos[i] - vel[i] * streak[e] - o
        zt = ti.max(tpos.dot(f), 0.05)
        st_scale = 0.5 * H / (zt * th)
        return tpos.dot(r) * st_scale + 0.5 * W, 0.5 * H - tpos.dot(u) * st_scale

    return project, streak_end


class TiledSplat:
    """Splats a particle pool into the renderer's accumulation fields (``light``, ``oit_rgb``,
    ``oit_w``, ``oit_logT``), depth-tested against ``depth``; same blending as the serial splat.

    ``look`` holds the per-emitter look as the Renderer has it: ``color_at``, ``alpha_at``,
    ``size_at`` (curve ``ti.func``s), ``additive``, ``streak``, ``size_rand`` fields and the
    ``uses_alpha``/``uses_additive`` flags.
    """

    def __init__(self, state, look, targets, width: int, height: int, pairs_per_particle: float = 1.5,
                 min_pairs: int = 1 << 16):
        self.W, self.H = int(width), int(height)
        self.cap = state.capacity
        n = max(1, self.cap)
        self.tiles_x = (self.W + TILE - 1) // TILE
        self.tiles_y = (self.H + TILE - 1) // TILE
        self.tiles = self.tiles_x * self.tiles_y
        self.chunk = (n + CHUNKS - 1) // CHUNKS
        self.spr_geom = ti.Vector.field(4, ti.f32, shape=n)  # cx, cy, rad, z
        self.spr_look = ti.Vector.field(4, ti.f32, shape=n)  # r, g, b, alpha
        self.spr_tail = ti.Vector.field(4, ti.f32, shape=n)  # energy, tail x, tail y, OIT depth weight
        self.spr_soft = ti.field(ti.f32, shape=n)  # soft-particle fade distance (m)
        self.spr_info = ti.Vector.field(2, ti.i32, shape=n)  # sub-deposits (0: not drawn), additive
        self.spr_tiles = ti.Vector.field(4, ti.i32, shape=n)  # tile x0, y0, x1, y1 (inclusive)
        self.hist = ti.field(ti.i32, shape=(CHUNKS, self.tiles))
        self.tile_count = ti.field(ti.i32, shape=self.tiles)
        self.tile_start = ti.field(ti.i32, shape=self.tiles)
        self.pairs = None
        self._alloc_pairs(max(int(min_pairs), int(pairs_per_particle * n)))
        self.last_pairs = 0
        self._build(state, look, targets)

    def _alloc_pairs(self, size: int):
        # One 64-byte sprite record per (tile, sprite) pair, in tile order: the accumulate pass
        # then streams through memory instead of gathering records by slot (a cache miss each).
        self.pairs = ti.Vector.field(16, ti.f32, shape=size)
        self.pair_capacity = size

    def _build(self, S, look, targets):
        W, H, cap = self.W, self.H, self.cap
        TX, T, chunk = self.tiles_x, self.tiles, self.chunk
        additive, streak = look.additive, look.streak
        uses_alpha, uses_add = look.uses_alpha, look.uses_additive
        light, oit_rgb, oit_w, oit_logT, depth = targets
        geom, slook, tail, info, tiles, softf = (self.spr_geom, self.spr_look, self.spr_tail,
                                                 self.spr_info, self.spr_tiles, self.spr_soft)
        hist, tcount, tstart = self.hist, self.tile_count, self.tile_start

        project, streak_end = make_sprite_funcs(S, look, W, H)

        @ti.kernel
        def sprites(o: vec3, f: vec3, r: vec3, u: vec3, th: ti.f32):
            for i in range(cap):
                nsub = 0
                drawn, e, cx, cy, rad, z, col, a, energy, sz = project(i, o, f, r, u, th)
                if drawn != 0:
                    tx, ty = cx, cy
                    nsub = 1
                    if streak[e] > 0:
                        tx, ty = streak_end(i, e, o, f, r, u, th)
                        length = ti.sqrt((tx - cx) ** 2 + (ty - cy) ** 2)
                        nsub = -(ti.min(32, ti.cast(length / ti.max(0.5 * rad, 0.5), ti.i32) + 1))
                    # pixel bounds as the serial deposit computes them (padded by 1/64 px for
                    # rounding along a streak), clamped in float before the integer cast
                    lox = ti.max(-1.0, ti.min(W + 1.0, ti.min(cx, tx) - rad - 0.015625))
                    hix = ti.max(-1.0, ti.min(W + 1.0, ti.max(cx, tx) + rad + 0.015625))
                    loy = ti.max(-1.0, ti.min(H + 1.0, ti.min(cy, ty) - rad - 0.015625))
                    hiy = ti.max(-1.0, ti.min(H + 1.0, ti.max(cy, ty) + rad + 0.015625))
                    x0 = ti.max(0, ti.cast(ti.floor(lox), ti.i32))
                    x1 = ti.min(W - 1, ti.cast(ti.floor(hix), ti.i32))
                    y0 = ti.max(0, ti.cast(ti.floor(loy), ti.i32))
                    y1 = ti.min(H - 1, ti.cast(ti.floor(hiy), ti.i32))
                    if x0 <= x1 and y0 <= y1:
                        geom[i] = ti.Vector([cx, cy, rad, z])
                        slook[i] = ti.Vector([col[0], col[1], col[2], a])
                        wz = 0.0
                        if ti.static(uses_alpha):
                            wz = oit_depth_weight(z)
                        tail[i] = ti.Vector([energy, tx, ty, wz])
                        tiles[i] = ti.Vector([x0 // TILE, y0 // TILE, x1 // TILE, y1 // TILE])
                        info[i] = ti.Vector([0, ti.cast(additive[e] != 0, ti.i32)])
                        softf[i] = ti.max(0.5 * sz, 1e-3)
                    else:
                        nsub = 0
                info[i][0] = nsub  # > 0: one disc; < 0: a streak of −nsub discs

        @ti.kernel
        def count():
            ti.loop_config(block_dim=1)  # one chunk per task: the default grain is all 64 at once
            for c in range(CHUNKS):
                for t in range(T):
                    hist[c, t] = 0
                for i in range(c * chunk, ti.min(cap, (c + 1) * chunk)):
                    if info[i][0] != 0:
                        b = tiles[i]
                        for ty in range(b[1], b[3] + 1):
                            for tx in range(b[0], b[2] + 1):
                                hist[c, ty * TX + tx] += 1

        @ti.kernel
        def offsets():
            ti.loop_config(block_dim=16)
            for t in range(T):
                run = 0
                for c in range(CHUNKS):
                    v = hist[c, t]
                    hist[c, t] = run
                    run += v
                tcount[t] = run

        @ti.kernel
        def starts() -> ti.i32:
            run = 0
            ti.loop_config(serialize=True)
            for t in range(T):
                tstart[t] = run
                run += tcount[t]
            return run

        @ti.kernel
        def scatter(pairs: ti.template()):
            ti.loop_config(block_dim=1)
            for c in range(CHUNKS):
                for i in range(c * chunk, ti.min(cap, (c + 1) * chunk)):
                    if info[i][0] != 0:
                        b = tiles[i]
                        for ty in range(b[1], b[3] + 1):
                            for tx in range(b[0], b[2] + 1):
                                t = ty * TX + tx
                                g, lk, tl, nf = geom[i], slook[i], tail[i], info[i]
                                pairs[tstart[t] + hist[c, t]] = ti.Vector([
                                    g[0], g[1], g[2], g[3], lk[0], lk[1], lk[2], lk[3],
                                    tl[0], tl[1], tl[2], tl[3], ti.cast(nf[0], ti.f32),
                                    ti.cast(nf[1], ti.f32), softf[i], 0.0])
                                hist[c, t] += 1

        @ti.func
        def pixel(xx, yy, inside, cx, cy, inv_r2, z, col, a, is_add, energy, wzf, soft):
            """One pixel of a soft disc, (1 − d²/r²)², depth-tested as a soft particle (fading over
            ``soft`` metres in front of an opaque surface, as raster.py). Branch-free: a pixel outside
            the disc (or ``inside`` false: a padding lane, its index clamped onto a real pixel)
            adds exactly zero. Plain load + store, not ``+=``: one thread owns the tile, and a
            ``+=`` on a field in a parallel loop compiles to a float atomic."""
            dx = xx + 0.5 - cx
            dy = yy + 0.5 - cy
            q = 1.0 - (dx * dx + dy * dy) * inv_r2
            gap = depth[yy, xx] - z
            w = ti.select(inside and q > 0 and gap > 0, q * q * energy * ti.min(1.0, gap / soft), 0.0)
            if ti.static(uses_add):
                if is_add:
                    light[yy, xx] = light[yy, xx] + col * (a * w)
            if ti.static(uses_alpha):
                if not is_add:
                    aa = ti.min(0.98, a * w)
                    wz = aa * wzf
                    oit_rgb[yy, xx] = oit_rgb[yy, xx] + col * wz
                    oit_w[yy, xx] = oit_w[yy, xx] + wz
                    oit_logT[yy, xx] = oit_logT[yy, xx] + ti.log(1.0 - aa)

        @ti.func
        def block(B: ti.template(), bx, by, x1, y1, cx, cy, inv_r2, z, col, a, is_add, energy, wzf,
                  soft):
            """A B×B pixel block from (bx, by), unrolled at compile time, clipped to (x1, y1)."""
            for dy in ti.static(range(B)):
                for dx in ti.static(range(B)):
                    inside = bx + dx <= x1 and by + dy <= y1
                    pixel(ti.min(bx + dx, x1), ti.min(by + dy, y1), inside, cx, cy, inv_r2, z, col,
                          a, is_add, energy, wzf, soft)

        @ti.func
        def deposit(px0, py0, px1, py1, cx, cy, rad, z, col, a, is_add, energy, wzf, soft):
            """The serial splat's soft disc limited to one tile's pixels [px0, px1] × [py0, py1].
            Taichi's dynamic inner loops cost more than the pixel work of the 1–3 px sprites of a
            dense pool, so a disc that fits a 2×2 or 4×4 block runs no loop at all (the
            blocks are unrolled at compile time). Each pixel
            gets one contribution per disc, so the order of pixels within a disc is immaterial."""
            x0 = ti.max(px0, ti.cast(ti.floor(cx - rad), ti.i32))
            x1 = ti.min(px1, ti.cast(ti.floor(cx + rad), ti.i32))
            y0 = ti.max(py0, ti.cast(ti.floor(cy - rad), ti.i32))
            y1 = ti.min(py1, ti.cast(ti.floor(cy + rad), ti.i32))
            if x0 <= x1 and y0 <= y1:
                inv_r2 = 1.0 / (rad * rad)
                span = ti.max(x1 - x0, y1 - y0)
                if span < 2:
                    block(2, x0, y0, x1, y1, cx, cy, inv_r2, z, col, a, is_add, energy, wzf, soft)
                elif span < 4:
                    block(4, x0, y0, x1, y1, cx, cy, inv_r2, z, col, a, is_add, energy, wzf, soft)
                else:  # large discs are few; one inlined pixel keeps the kernel (and its build) small
                    for yy in range(y0, y1 + 1):
                        for xx in range(x0, x1 + 1):
                            pixel(xx, yy, True, cx, cy, inv_r2, z, col, a, is_add, energy, wzf, soft)

        @ti.kernel
        def accumulate(pairs: ti.template()):
            ti.loop_config(block_dim=1)
            for t in range(T):
                tx, ty = t % TX, t // TX
                px0, py0 = tx * TILE, ty * TILE
                px1, py1 = ti.min(W - 1, px0 + TILE - 1), ti.min(H - 1, py0 + TILE - 1)
                for j in range(tstart[t], tstart[t] + tcount[t]):
                    rec = pairs[j]
                    g = ti.Vector([rec[0], rec[1], rec[2], rec[3]])
                    lk = ti.Vector([rec[4], rec[5], rec[6], rec[7]])
                    tl = ti.Vector([rec[8], rec[9], rec[10], rec[11]])
                    nsub = ti.cast(rec[12], ti.i32)
                    is_add = rec[13] != 0.0
                    soft = rec[14]
                    col = ti.Vector([lk[0], lk[1], lk[2]])
                    n = ti.abs(nsub)
                    for s in range(n):  # a streak: n discs along it, fading; else one disc
                        cx, cy, a, energy = g[0], g[1], lk[3], tl[0]
                        if nsub < 0:
                            a_s = (s + 0.5) / n
                            cx = g[0] + a_s * (tl[1] - g[0])
                            cy = g[1] + a_s * (tl[2] - g[1])
                            a = lk[3] * (1.0 - 0.6 * a_s)
                            energy = tl[0] * 2.0 / n
                        deposit(px0, py0, px1, py1, cx, cy, g[2], g[3], col, a, is_add, energy, tl[3],
                                soft)

        self._sprites, self._count, self._offsets, self._starts = sprites, count, offsets, starts
        self._scatter, self._accumulate = scatter, accumulate

    def splat(self, o, f, r, u, th):
        """Add every live particle to the accumulation fields (cleared by the caller)."""
        self._sprites(o, f, r, u, th)
        self._count()
        self._offsets()
        total = int(self._starts())
        if total > self.pair_capacity:  # grow; the kernels taking the pair list re-specialise
            self._alloc_pairs(int(total * 1.25) + 1024)
        self.last_pairs = total
        self._scatter(self.pairs)
        self._accumulate(self.pairs)


def look_of(renderer):
    """The per-emitter look a :class:`~engine.render.raster.Renderer` holds, as TiledSplat wants it."""
    return SimpleNamespace(
        color_at=renderer.color.make_func(), alpha_at=renderer.alpha.make_func(),
        size_at=renderer.size.make_func(), additive=renderer.emitter_additive,
        streak=renderer.emitter_streak, size_rand=renderer.emitter_size_rand,
        uses_alpha=renderer.uses_alpha, uses_additive=renderer.uses_additive)


def targets_of(renderer):
    """The renderer's accumulation fields and background depth, in TiledSplat's order."""
    return (renderer.light, renderer.oit_rgb, renderer.oit_w, renderer.oit_logT, renderer.depth)


def render_tiled(renderer, tiled, camera, exposure=None):
    """Background, tiled splat, resolve: the renderer's image (H, W, 3) uint8 via the tiled path."""
    p, f, r, u = camera.basis()
    args = (p.tolist(), f.tolist(), r.tolist(), u.tolist(), camera.tan_half)
    renderer._background(*args)
    tiled.splat(*args)
    renderer._resolve(renderer.cfg.exposure if exposure is None else exposure)
    return renderer.image.to_numpy()
