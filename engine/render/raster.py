"""Off-screen particle renderer in Taichi: background, splats, blend, tone map.

Passes, each one kernel:
1. ``background``: per pixel, a sky gradient, faint grids on plane colliders (or the ground) and
   faintly lit collider spheres, writing an opaque depth so particles behind a sphere are hidden.
2. ``splat``: every live particle as a round soft sprite sized in world units (a far particle is
   smaller), optionally stretched into a streak along its velocity (motion blur).
   * additive emitters (sparks, flames) add light;
   * alpha emitters (smoke, dust) use weighted blended order-independent transparency (McGuire &
     Bavoil 2013): Σ c·α·w, Σ α·w and Σ log(1 − α) are sums, so the image does not depend on the
     order particles sit in the pool, and no per-frame sort is needed (PERF-NOTES: a 1M sort costs
     0.38 s). Its cost — colour is an average, not exact "over" — is invisible in soft media.
   Float atomics from several threads would make sums depend on thread timing, so ``render``
   splats through ``tiles.TiledSplat``: particles binned into screen tiles by a stable counting
   sort, each tile accumulated by one thread in slot order — parallel, and every pixel sees the
   same contributions in the same order as the serial loop kept here as ``_splat`` (reference).
3. ``resolve``: composite (background·T + OIT colour·shade·(1 − T) + additive light, where
   shade darkens thick media with their optical depth), exposure, the ACES
   filmic fit (Narkowicz 2015), sRGB encoding to 8 bits.
"""
# (no `from __future__ import annotations`: Taichi reads kernel annotations at definition)

import numpy as np
import taichi as ti

from ..colliders import PLANE
from ..particles.curves import Curves

vec3 = ti.types.vector(3, ti.f32)


class Renderer:
    """Draws one scene. ``state``/``emitter_configs`` may be None/empty (a soft-body scene:
    no splat kernel is built); ``bodies`` are drawn as meshes and lines (engine.render.mesh)."""

    def __init__(self, state, emitter_configs, colliders, render_cfg, width=None, height=None,
                 bodies=()):
        self.W = int(width or render_cfg.width)
        self.H = int(height or render_cfg.height)
        W, H = self.W, self.H
        self.cfg = render_cfg
        self.image = ti.field(ti.u8, shape=(H, W, 3))
        self.light = ti.Vector.field(3, ti.f32, shape=(H, W))  # additive
        self.oit_rgb = ti.Vector.field(3, ti.f32, shape=(H, W))
        self.oit_w = ti.field(ti.f32, shape=(H, W))
        self.oit_logT = ti.field(ti.f32, shape=(H, W))
        self.bg = ti.Vector.field(3, ti.f32, shape=(H, W))
        self.depth = ti.field(ti.f32, shape=(H, W))
        E = len(emitter_configs)
        self.has_particles = state is not None and E > 0
        self.uses_alpha = self.has_particles and any(c.blend == "alpha" for c in emitter_configs)
        self.uses_additive = self.has_particles and any(c.blend == "additive" for c in emitter_configs)
        self._colliders = colliders
        self._bg_key = None  # (camera, collider placement) the background fields were drawn for
        self._build_background(colliders)
        if self.has_particles:
            self._build_particles(state, emitter_configs)
        self.mesh = None
        if bodies:
            from .mesh import MeshLayer

            self.mesh = MeshLayer(bodies, self)

    def _build_particles(self, state, emitter_configs):
        from .tiles import look_of, make_sprite_funcs, oit_depth_weight
        E = len(emitter_configs)
        self.color = Curves([e.color for e in emitter_configs], 3)
        self.alpha = Curves([e.alpha for e in emitter_configs], 1)
        self.size = Curves([e.size for e in emitter_configs], 1)
        self.emitter_additive = ti.field(ti.i32, shape=E)
        self.emitter_streak = ti.field(ti.f32, shape=E)
        self.emitter_size_rand = ti.field(ti.f32, shape=E)
        for e, c in enumerate(emitter_configs):
            self.emitter_additive[e] = int(c.blend == "additive")
            self.emitter_streak[e] = c.streak
            self.emitter_size_rand[e] = c.size_randomness
        W, H = self.W, self.H
        light, oit_rgb, oit_w, oit_logT, depth = (
            self.light, self.oit_rgb, self.oit_w, self.oit_logT, self.depth)
        S = state
        cap = S.capacity
        additive, streak = self.emitter_additive, self.emitter_streak
        uses_alpha, uses_add = self.uses_alpha, self.uses_additive

        @ti.func
        def deposit(cx, cy, rad, z, col, a, is_add, energy, soft):
            """A soft disc of radius rad px at (cx, cy): kernel (1 − d²/r²)². Depth-tested as a
            soft particle (Lorach 2007): it fades over ``soft`` metres in front of an opaque
            surface instead of being cut by it, so a flame on the ground has no hard edge."""
            x0 = ti.max(0, ti.cast(ti.floor(cx - rad), ti.i32))
            x1 = ti.min(W - 1, ti.cast(ti.floor(cx + rad), ti.i32))
            y0 = ti.max(0, ti.cast(ti.floor(cy - rad), ti.i32))
            y1 = ti.min(H - 1, ti.cast(ti.floor(cy + rad), ti.i32))
            inv_r2 = 1.0 / (rad * rad)
            for yy in range(y0, y1 + 1):
                for xx in range(x0, x1 + 1):
                    dx = xx + 0.5 - cx
                    dy = yy + 0.5 - cy
                    q = 1.0 - (dx * dx + dy * dy) * inv_r2
                    gap = depth[yy, xx] - z
                    if q > 0 and gap > 0:
                        w = q * q * energy * ti.min(1.0, gap / soft)
                        if ti.static(uses_add):
                            if is_add:
                                light[yy, xx] += col * (a * w)
                        if ti.static(uses_alpha):
                            if not is_add:
                                aa = ti.min(0.98, a * w)
                                wz = aa * oit_depth_weight(z)  # McGuire & Bavoil (2013) eq. 10
                                oit_rgb[yy, xx] += col * wz
                                oit_w[yy, xx] += wz
                                oit_logT[yy, xx] += ti.log(1.0 - aa)

        project, streak_end = make_sprite_funcs(S, look_of(self), W, H)

        @ti.kernel
        def splat(o: vec3, f: vec3, r: vec3, u: vec3, th: ti.f32):
            ti.loop_config(serialize=True)
            for i in range(cap):
                drawn, e, cx, cy, rad, z, col, a, energy, sz = project(i, o, f, r, u, th)
                if drawn != 0:
                    is_add = additive[e] != 0
                    soft = ti.max(0.5 * sz, 1e-3)
                    if streak[e] > 0:
                        tx, ty = streak_end(i, e, o, f, r, u, th)
                        length = ti.sqrt((tx - cx) ** 2 + (ty - cy) ** 2)
                        n = ti.min(32, ti.cast(length / ti.max(0.5 * rad, 0.5), ti.i32) + 1)
                        for s in range(n):
                            a_s = (s + 0.5) / n
                            deposit(cx + a_s * (tx - cx), cy + a_s * (ty - cy), rad, z, col,
                                    a * (1.0 - 0.6 * a_s), is_add, energy * 2.0 / n, soft)
                    else:
                        deposit(cx, cy, rad, z, col, a, is_add, energy, soft)

        self._splat = splat  # the serial reference; render() uses the tiled splat (same image)
        from .tiles import TiledSplat, targets_of

        self.tiled = TiledSplat(state, look_of(self), targets_of(self), W, H)

    def _build_background(self, colliders):
        W, H, cfg = self.W, self.H, self.cfg
        image, light, oit_rgb, oit_w, oit_logT, bg, depth = (
            self.image, self.light, self.oit_rgb, self.oit_w, self.oit_logT, self.bg, self.depth)
        uses_alpha, uses_add = self.uses_alpha, self.uses_additive
        bgc = tuple(float(c) for c in cfg.background)
        show = cfg.show_colliders and colliders is not None
        vis = [k for k, s in enumerate(colliders.specs) if s.visible] if show else []
        planes = tuple(k for k in vis if colliders.kinds[k] == PLANE)
        spheres = tuple(k for k in vis if colliders.kinds[k] != PLANE)
        ground_grid = bool(cfg.grid) and not planes
        if colliders is not None:
            cpt, cnr, crad = colliders.collider_point, colliders.collider_normal, colliders.collider_radius
        else:
            cpt = cnr = crad = None
        shading = float(cfg.density_shading)
        aspect = W / H

        @ti.func
        def ray_dir(px, py, f, r, u, th):
            x = (2.0 * (px + 0.5) / W - 1.0) * th * aspect
            y = (1.0 - 2.0 * (py + 0.5) / H) * th
            return (f + x * r + y * u).normalized()

        @ti.func
        def grid_shade(o, d, p0, n, th, f, col, zbest):
            """A faint 1 m grid on the plane (p0, n) seen along ray o + s d."""
            dn = d.dot(n)
            z = zbest
            if dn < -1e-6:
                s = (p0 - o).dot(n) / dn
                zz = s * d.dot(f)
                if s > 0 and zz < zbest:
                    q = o + s * d
                    a = ti.Vector([1.0, 0.0, 0.0]) if ti.abs(n[0]) < 0.9 else ti.Vector([0.0, 0.0, 1.0])
                    e1 = n.cross(a).normalized()
                    e2 = n.cross(e1)
                    uu, vv = (q - p0).dot(e1), (q - p0).dot(e2)
                    foot = s * 2.0 * th / H / ti.max(ti.abs(dn), 0.05)  # metres per pixel
                    du = ti.abs(uu - ti.round(uu))
                    dv = ti.abs(vv - ti.round(vv))
                    line = ti.max(ti.max(0.0, 1.0 - du / (1.2 * foot)), ti.max(0.0, 1.0 - dv / (1.2 * foot)))
                    line *= ti.min(1.0, 0.25 / foot)  # fade lines that become finer than a pixel
                    fade = ti.exp(-s / 40.0)
                    col = (ti.Vector([0.018, 0.019, 0.022]) + line * ti.Vector([0.030, 0.032, 0.036])) * fade \
                        + col * (1.0 - fade)
                    z = zz
            return col, z

        @ti.kernel
        def background(o: vec3, f: vec3, r: vec3, u: vec3, th: ti.f32):
            for py, px in bg:
                d = ray_dir(px, py, f, r, u, th)
                tsky = 0.5 + 0.5 * d[1]
                col = ti.Vector([bgc[0], bgc[1], bgc[2]]) * (0.6 + 0.8 * tsky)
                z = 1e30
                if ti.static(ground_grid):
                    col, z = grid_shade(o, d, ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 1.0, 0.0]),
                                        th, f, col, z)
                for k in ti.static(planes):
                    col, z = grid_shade(o, d, cpt[k], cnr[k], th, f, col, z)
                for k in ti.static(spheres):
                    oc = o - cpt[k]
                    b = oc.dot(d)
                    c = oc.dot(oc) - crad[k] * crad[k]
                    disc = b * b - c
                    if disc > 0:
                        s = -b - ti.sqrt(disc)
                        zz = s * d.dot(f)
                        if s > 0 and zz < z:
                            n = (o + s * d - cpt[k]).normalized()
                            ldir = ti.Vector([0.4, 0.8, 0.3]).normalized()
                            lam = ti.max(0.0, n.dot(ldir))
                            rim = ti.pow(1.0 - ti.abs(n.dot(d)), 3.0)
                            col = ti.Vector([0.02, 0.021, 0.025]) + 0.06 * lam * ti.Vector([0.8, 0.85, 1.0]) \
                                + 0.03 * rim
                            z = zz
                bg[py, px] = col
                depth[py, px] = z
                light[py, px] = ti.Vector([0.0, 0.0, 0.0])
                oit_rgb[py, px] = ti.Vector([0.0, 0.0, 0.0])
                oit_w[py, px] = 0.0
                oit_logT[py, px] = 0.0

        @ti.kernel
        def clear():
            """Reset the accumulators only: the background and its depth are still valid."""
            for py, px in bg:
                light[py, px] = ti.Vector([0.0, 0.0, 0.0])
                oit_rgb[py, px] = ti.Vector([0.0, 0.0, 0.0])
                oit_w[py, px] = 0.0
                oit_logT[py, px] = 0.0

        @ti.func
        def aces(x):
            return ti.math.clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)

        @ti.func
        def srgb(c):
            return ti.select(c <= 0.0031308, 12.92 * c, 1.055 * ti.pow(c, 1.0 / 2.4) - 0.055)

        @ti.kernel
        def resolve(exposure: ti.f32):
            for py, px in bg:
                c = bg[py, px]
                if ti.static(uses_alpha):
                    tau = -oit_logT[py, px]  # optical depth through the medium at this pixel
                    T = ti.exp(-tau)
                    wsum = oit_w[py, px]
                    if wsum > 1e-8:
                        # thick smoke is darker inside: light reaching the core is attenuated
                        # (a one-parameter stand-in for self-shadowing, order independent)
                        shade = 0.25 + 0.75 * ti.exp(-shading * tau)
                        c = c * T + (oit_rgb[py, px] / wsum) * shade * (1.0 - T)
                if ti.static(uses_add):
                    c += light[py, px]
                out = srgb(aces(c * exposure))
                for ch in ti.static(range(3)):
                    image[py, px, ch] = ti.cast(ti.min(255.0, out[ch] * 255.0 + 0.5), ti.u8)

        self._background, self._resolve, self._clear = background, resolve, clear

    def _background_key(self, args):
        """What the background depends on, or None when it must be redrawn every frame (meshes
        draw into it)."""
        if self.mesh is not None:
            return None
        c = self._colliders
        placed = b"" if c is None else (c.collider_point.to_numpy().tobytes()
                                        + c.collider_normal.to_numpy().tobytes()
                                        + c.collider_radius.to_numpy().tobytes())
        return (tuple(tuple(float(x) for x in a) for a in args[:4]), float(args[4]), placed)

    def render(self, camera, exposure=None, serial=False) -> np.ndarray:
        """Render the pool as seen by ``camera``; returns an (H, W, 3) uint8 sRGB image.
        Particles are splatted by the tiled parallel path (engine.render.tiles); ``serial`` uses
        the one-thread reference splat instead (the same image up to float rounding)."""
        p, f, r, u = camera.basis()
        th = camera.tan_half
        args = (p.tolist(), f.tolist(), r.tolist(), u.tolist(), th)
        key = self._background_key(args)
        if key is not None and key == self._bg_key:
            self._clear()  # same camera, colliders where they were: the background is unchanged
        else:
            self._background(*args)
        self._bg_key = key
        if self.mesh is not None:
            self.mesh.update()
            self.mesh.draw(args)
        if self.has_particles:
            if serial:
                self._splat(*args)
            else:
                self.tiled.splat(*args)
        self._resolve(self.cfg.exposure if exposure is None else exposure)
        return self.image.to_numpy()
