"""How a particle becomes a sprite: the one definition both splat schedules use.

A sprite is a soft disc (or a streak: a capsule back along the velocity, motion blur) sized in
world units, so a far particle is smaller. ``build_sprite_kernel`` turns every live slot into a record once per frame:

* ``spr_geom``  (cap,) vec4 f32: centre x, y (px of its level's image), radius (px), view depth z (m)
* ``spr_look``  (cap,) vec4 f32: linear RGB, alpha
* ``spr_tail``  (cap,) vec4 f32: energy (sub-pixel light kept), streak tail x, y (px), OIT depth weight
* ``spr_info``  (cap,) vec4 i32: kind (0 not drawn, 1 a disc, −1 a streak: a capsule from the
  centre to the tail),
  additive (0/1), level (0 full resolution, 1 the reduced off-screen buffer, 2 the coarse one),
  unused
* ``spr_soft``  (cap,) f32: 1 / the soft-particle fade distance (1/m); the fade distance is half
  the sprite's world size
* ``spr_tiles`` (cap,) vec4 i32: the tile rectangle it covers, x0, y0, x1, y1 inclusive, in its
  level's tile grid

Levels (Cantlay, *GPU Gems 3* ch. 23, "High-Speed, Off-Screen Particles"): large soft sprites
fill pixels, so a sprite whose full-resolution radius is at least ``lo_min_rad`` pixels is drawn
into a buffer at ``lo_scale`` of the resolution (½ or ¼) and composited with a depth-aware
upsample; small sprites (sparks and their thin streaks) stay at full resolution. One of at least
``co_min_rad`` pixels goes to a coarse buffer at half that scale (a big smoke puff covers ~16
times the texels of its smallest neighbours at the reduced level; at the coarse one a quarter of
them: engine.render.composite merges the coarse level into the reduced one).
"""
# (no `from __future__ import annotations`: Taichi reads kernel annotations at definition)

import taichi as ti

import numpy as np

TILE = 16  # pixels per tile side (3DGS uses 16×16 tiles)
MAX_RADIUS_FRACTION = 0.15  # a sprite's radius is clamped to this fraction of the image height
vec3 = ti.types.vector(3, ti.f32)


@ti.func
def oit_depth_weight(z):
    """McGuire & Bavoil (2013) eq. 10: w(z) = clamp(10 / (1e-5 + (z/5)² + (z/200)⁶), 1e-2, 3e3)."""
    a = z / 5.0
    b = z / 200.0
    b2 = b * b
    return ti.max(1e-2, ti.min(3e3, 10.0 / (1e-5 + a * a + b2 * b2 * b2)))


LOOK_SAMPLES = 256  # samples of each emitter's ramps over life (error at a kink ≤ slope / 512)


class Look:
    """Per-emitter look, shape (E,): the colour, alpha and size ramps over normalised life baked
    into ``look_table`` (E, LOOK_SAMPLES + 1) vec8 f32 = (R, G, B, alpha, size m, 0, 0, 0), read
    with one linear interpolation per sprite (evaluating up to 8 stops of three ramps per particle
    per frame cost more than the projection); ``emitter_additive`` (i32), ``emitter_streak`` (f32,
    s of motion blur), ``emitter_size_rand``."""

    def __init__(self, emitter_configs, rows: int = 0):
        """``rows``: emitter rows (spare ones for emitters added later: :meth:`update`)."""
        self.rows = R = max(len(emitter_configs), int(rows))
        self.look_table = ti.Vector.field(8, ti.f32, shape=(R, LOOK_SAMPLES + 1))
        self.emitter_additive = ti.field(ti.i32, shape=R)
        self.emitter_streak = ti.field(ti.f32, shape=R)
        self.emitter_size_rand = ti.field(ti.f32, shape=R)
        self.update(emitter_configs)
        self.uses_alpha = any(c.blend == "alpha" for c in emitter_configs)
        self.uses_additive = any(c.blend == "additive" for c in emitter_configs)

    def covers(self, emitter_configs) -> bool:
        """Whether the compiled blend modes and rows serve these emitters."""
        return len(emitter_configs) <= self.rows and all(
            self.uses_alpha if c.blend == "alpha" else self.uses_additive for c in emitter_configs)

    def update(self, emitter_configs) -> None:
        """Bake every emitter's ramps and write the fields (rows past the emitters are zero)."""
        R = self.rows
        t = np.linspace(0.0, 1.0, LOOK_SAMPLES + 1)
        table = np.zeros((R, LOOK_SAMPLES + 1, 8), np.float32)
        for e, c in enumerate(emitter_configs):
            for col, (ramp, comp) in enumerate([(c.color, 1), (c.color, 2), (c.color, 3), (c.alpha, 1),
                                                (c.size, 1)]):
                stops = np.asarray(ramp, np.float64)
                table[e, :, col] = np.interp(t, stops[:, 0], stops[:, comp])  # flat outside
        cs = emitter_configs
        params = np.zeros((R, 3), np.float32)  # additive (0/1), streak, size randomness
        for e, c in enumerate(cs):
            params[e] = (float(c.blend == "additive"), c.streak, c.size_randomness)
        # one launch for the four fields (four ``from_numpy`` were four kernels to load at each
        # start, ~13 ms each; the same values: additive is 0 or 1, the others f32 already)
        _write_look(self.look_table, self.emitter_additive, self.emitter_streak, self.emitter_size_rand,
                    table, params)

    def make_func(self):
        """``look_at(e, t)`` → vec8 (R, G, B, alpha, size) of emitter e at normalised life t."""
        table = self.look_table

        @ti.func
        def look_at(e, t):
            x = ti.min(ti.max(t, 0.0), 1.0) * LOOK_SAMPLES
            k = ti.min(ti.cast(x, ti.i32), LOOK_SAMPLES - 1)
            f = x - k
            return table[e, k] + f * (table[e, k + 1] - table[e, k])

        return look_at


@ti.kernel
def _write_look(table: ti.template(), additive: ti.template(), streak: ti.template(), size_rand: ti.template(),
                rows: ti.types.ndarray(ndim=3), params: ti.types.ndarray(ndim=2)):
    """``Look``'s fields from its baked ramps ``rows`` (E, LOOK_SAMPLES + 1, 8) and per-emitter
    ``params`` (E, 3): additive, streak, size randomness."""
    for e, k in ti.ndrange(rows.shape[0], rows.shape[1]):
        for c in ti.static(range(8)):
            table[e, k][c] = rows[e, k, c]
    for e in range(params.shape[0]):
        additive[e] = ti.cast(params[e, 0], ti.i32)
        streak[e] = params[e, 1]
        size_rand[e] = params[e, 2]


class SpriteRecords:
    """The per-slot sprite records (see the module docstring), allocated once per pool."""

    def __init__(self, capacity: int):
        n = max(1, capacity)
        self.spr_geom = ti.Vector.field(4, ti.f32, shape=n)
        self.spr_look = ti.Vector.field(4, ti.f32, shape=n)
        self.spr_tail = ti.Vector.field(4, ti.f32, shape=n)
        self.spr_info = ti.Vector.field(4, ti.i32, shape=n)
        self.spr_tiles = ti.Vector.field(4, ti.i32, shape=n)
        self.spr_soft = ti.field(ti.f32, shape=n)


def build_sprite_kernel(state, look: Look, rec: SpriteRecords):
    """``sprites(o, f, r, u, th, W, H, lo_scale, lo_min_rad, co_min_rad, blend)``: every slot of the
    pool → its sprite record. (o, f, r, u) is the camera's position and basis, th the tangent of
    half the vertical field of view, W×H the image; sprites of full-resolution radius ≥
    ``lo_min_rad`` px go to the level-1 buffer of ``lo_scale``·W × ``lo_scale``·H (``lo_scale`` 1:
    everything at level 0), those of radius ≥ ``co_min_rad`` px to the level-2 buffer at half
    that scale. A pool that keeps ``particle_prev_pos`` (``interpolate``) is drawn at
    prev + blend·(pos − prev) (Fiedler, "Fix Your Timestep!": the fixed-step clock's alpha), a
    particle without a previous position (NaN: born since) where it is; otherwise blend is unused."""
    S = state
    cap = S.capacity
    pos, vel, age, life, alive, pem, prand = (
        S.particle_pos, S.particle_vel, S.particle_age, S.particle_life, S.particle_alive,
        S.particle_emitter, S.particle_rand)
    look_at = look.make_func()
    additive, streak, size_rand = look.emitter_additive, look.emitter_streak, look.emitter_size_rand
    uses_alpha = look.uses_alpha
    interp = getattr(S, "interpolate", False)
    prev = S.particle_prev_pos if interp else pos
    geom, slook, tail, info, tiles, soft = (rec.spr_geom, rec.spr_look, rec.spr_tail, rec.spr_info,
                                            rec.spr_tiles, rec.spr_soft)

    @ti.kernel
    def sprites(o: vec3, f: vec3, r: vec3, u: vec3, th: ti.f32, W: ti.i32, H: ti.i32,
                lo_scale: ti.f32, lo_min_rad: ti.f32, co_min_rad: ti.f32, blend: ti.f32):
        for i in range(cap):
            nsub = 0
            if alive[i] != 0 and age[i] >= 0.0:  # (negative age: born later in this step)
                e = pem[i]
                tl = ti.min(1.0, age[i] / life[i])
                x = pos[i]
                if ti.static(interp):
                    q = prev[i]
                    # not NaN: it was alive before the last step; at blend 1 (no alpha, or alpha
                    # 1) it is drawn exactly where it is: q + 1·(x − q) can round off x
                    if q[0] == q[0] and blend < 1.0:
                        x = q + blend * (x - q)
                dpos = x - o
                z = dpos.dot(f)
                if z > 0.05:
                    lk = look_at(e, tl)
                    sz = lk[4] * (1.0 + size_rand[e] * (2.0 * prand[i] - 1.0))
                    scale = 0.5 * H / (z * th)  # pixels per metre at depth z
                    rad = 0.5 * sz * scale
                    is_streak = streak[e] > 0
                    level = 0
                    s = 1.0
                    if lo_scale < 1.0 and rad >= lo_min_rad:  # (big flame streaks too)
                        level, s = 1, lo_scale
                        if rad >= co_min_rad:
                            level, s = 2, 0.5 * lo_scale
                    Wl, Hl = W, H
                    if level != 0:
                        Wl = ti.max(1, ti.cast(ti.ceil(W * s), ti.i32))
                        Hl = ti.max(1, ti.cast(ti.ceil(H * s), ti.i32))
                    cx = (dpos.dot(r) * scale + 0.5 * W) * s
                    cy = (0.5 * H - dpos.dot(u) * scale) * s
                    rad = ti.min(rad, MAX_RADIUS_FRACTION * H) * s
                    energy = 1.0
                    if rad < 0.75:  # sub-pixel: draw at 0.75 px, keep the light it carries
                        energy = (rad / 0.75) ** 2
                        rad = 0.75
                    tx, ty = cx, cy
                    nsub = 1
                    if is_streak:
                        tpos = x - vel[i] * streak[e] - o
                        st_scale = 0.5 * H / (ti.max(tpos.dot(f), 0.05) * th)
                        tx = (tpos.dot(r) * st_scale + 0.5 * W) * s
                        ty = (0.5 * H - tpos.dot(u) * st_scale) * s
                        length = ti.sqrt((tx - cx) ** 2 + (ty - cy) ** 2)
                        nsub = -1
                        # a capsule carrying twice a disc's light (as the streak of discs it
                        # replaced did): ∫ disc = πr²/3, ∫ capsule = 16rL/15 + πr²/3 for the
                        # profile (1 − d²/r²)²
                        disc = 3.14159265 * rad * rad / 3.0
                        energy *= 2.0 * disc / (16.0 * rad * length / 15.0 + disc)
                    # pixel bounds (padded by 1/64 px for rounding along a streak), clamped in
                    # float before the integer cast
                    lox = ti.max(-1.0, ti.min(Wl + 1.0, ti.min(cx, tx) - rad - 0.015625))
                    hix = ti.max(-1.0, ti.min(Wl + 1.0, ti.max(cx, tx) + rad + 0.015625))
                    loy = ti.max(-1.0, ti.min(Hl + 1.0, ti.min(cy, ty) - rad - 0.015625))
                    hiy = ti.max(-1.0, ti.min(Hl + 1.0, ti.max(cy, ty) + rad + 0.015625))
                    x0 = ti.max(0, ti.cast(ti.floor(lox), ti.i32))
                    x1 = ti.min(Wl - 1, ti.cast(ti.floor(hix), ti.i32))
                    y0 = ti.max(0, ti.cast(ti.floor(loy), ti.i32))
                    y1 = ti.min(Hl - 1, ti.cast(ti.floor(hiy), ti.i32))
                    if x0 <= x1 and y0 <= y1:
                        col = ti.Vector([lk[0], lk[1], lk[2]])
                        a = lk[3]
                        wz = 0.0
                        if ti.static(uses_alpha):
                            wz = oit_depth_weight(z)
                        geom[i] = ti.Vector([cx, cy, rad, z])
                        slook[i] = ti.Vector([col[0], col[1], col[2], a])
                        tail[i] = ti.Vector([energy, tx, ty, wz])
                        info[i] = ti.Vector([0, additive[e], level, 0])
                        soft[i] = 1.0 / ti.max(0.5 * sz, 1e-3)
                        tiles[i] = ti.Vector([x0 // TILE, y0 // TILE, x1 // TILE, y1 // TILE])
                    else:
                        nsub = 0
            info[i][0] = nsub

    return sprites
