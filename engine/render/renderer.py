"""The off-screen renderer: a scene's particles and soft bodies as an (H, W, 4) uint8 RGBA image.

A frame, each step one kernel (PERF-NOTES: a launch costs ~17 µs; nothing here loops in Python
over particles or pixels):
1. background (``background.py``) — only when the camera, colliders or size changed (only the
   rectangles a moved collider left and entered when nothing else did);
2. soft bodies (``mesh.py``) into the frame's own background and depth, only where they are;
3. sprites (``sprites.py``): every live particle → a sprite record, at full or reduced resolution;
4. binning (``binning.py``): a stable counting sort of sprites into 16×16 tiles;
5. the reduced buffer's tile pass, then the full-resolution tile pass that splats, composites with
   the upsampled reduced buffer, tone-maps and writes packed RGBA (``composite.py``).

Kernels are built once per scene (they compile in only the blend modes, colliders and bodies the
scene has); every image-sized array is an ndarray argument held per size in ``FrameTargets``, so
rendering at a new size, another camera or a transparent overlay compiles nothing. Frames are
byte-identical run to run and for any CPU thread count: no float is summed by two threads.
"""
from __future__ import annotations

from collections import OrderedDict

import numpy as np
import taichi as ti

from ..launch import fast
from .background import build_background_kernel
from .background import copy_background as _copy_background
from .background import downsample_depth as _downsample_depth
from .binning import build_binning_kernels, chunks_for
from .composite import build_composite_kernels
from .resolution import CO_MIN_TEXELS, LO_MIN_TEXELS, particle_scale
from .sprites import TILE, Look, SpriteRecords, build_sprite_kernel
from .targets import FrameTargets, packed_view, untouched_tiles

SCHEDULES = ("tiles", "pixels")
MAX_SIZES_KEPT = 4  # image sizes whose buffers a Renderer keeps (least recently used dropped)
RESOLUTIONS = {"auto": None, "1": 1.0, "0.5": 0.5, "0.25": 0.25}


def screen_box(cam, centre, radius: float, W: int, H: int):
    """The pixel rectangle (x0, y0, x1, y1), clamped to the W×H image, that holds every pixel whose
    ray (engine.render.background.ray_dir) meets the sphere (centre, radius) seen by ``cam`` = (o,
    f, r, u, tan_half): the projected corners of the sphere's bounding cube (a convex set in front
    of the eye projects inside its corners' hull) widened by 2 px. None when the cube reaches
    behind the eye or the radius is infinite (a plane): the caller redraws everything."""
    if not np.isfinite(radius):
        return None
    o, f, r, u = (np.asarray(a, np.float64) for a in cam[:4])
    corners = np.asarray(centre, np.float64) + radius * np.array(
        [(i, j, k) for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], np.float64)
    d = corners - o
    z = d @ f
    if (z <= 1e-3).any():
        return None
    s = 0.5 * H / (z * float(cam[4]))
    x, y = (d @ r) * s + 0.5 * W - 0.5, 0.5 * H - (d @ u) * s - 0.5  # pixel indices (centres at +0.5)
    return (max(0, int(np.floor(x.min())) - 2), max(0, int(np.floor(y.min())) - 2),
            min(W, int(np.ceil(x.max())) + 3), min(H, int(np.ceil(y.max())) + 3))


def _arch_is_cpu() -> bool:
    from taichi.lang import impl

    return impl.current_cfg().arch in (ti.x64, ti.arm64)


class Renderer:
    """Draws one scene. ``state``/``emitter_configs`` may be None/empty (a soft-body scene: no
    sprite kernels are built); ``bodies`` are drawn as meshes and lines."""

    def __init__(self, state, emitter_configs, colliders, render_cfg, bodies=(), schedule=None, rows: int = 0):
        self.cfg = render_cfg
        self.shading = float(render_cfg.density_shading)
        self.colliders = colliders
        self.cpu = _arch_is_cpu()
        self.schedule = schedule or ("tiles" if self.cpu else "pixels")
        if self.schedule not in SCHEDULES:
            raise ValueError(f"schedule: unknown value {self.schedule!r}; allowed: {', '.join(SCHEDULES)}")
        self.chunks = chunks_for(self.cpu)
        self.has_particles = state is not None and len(emitter_configs) > 0
        # (each per-frame kernel launched without Taichi's per-argument Python: engine.launch)
        self._background = fast(build_background_kernel(render_cfg, colliders))
        uses_add = uses_alpha = False
        if self.has_particles:
            self.look = Look(emitter_configs, rows)  # (rows: spare emitter rows, engine.api add_emitter)
            uses_add, uses_alpha = self.look.uses_additive, self.look.uses_alpha
            self.records = SpriteRecords(state.capacity)
            self._sprites = fast(build_sprite_kernel(state, self.look, self.records))
            self._tally, self._scatter = build_binning_kernels(
                self.records, state.capacity, self.chunks)
            self.capacity = state.capacity
        self.uses_alpha = uses_alpha
        self._k = build_composite_kernels(uses_add, uses_alpha)
        self._copy_background, self._downsample_depth = fast(_copy_background), fast(_downsample_depth)
        self.mesh = None
        if bodies:
            from .mesh import MeshLayer

            self.mesh = MeshLayer(bodies)
        self._all_levels = False  # (warm_up: a frame takes the reduced and coarse levels' kernels)
        self._targets = OrderedDict()  # (W, H, layer scale) -> FrameTargets, most recent last
        self.last_pairs = self.last_reduced_pairs = 0  # (tile-sprite pairs; those of levels 1 and 2)

    # -- per-size arrays ------------------------------------------------------------------------
    def targets(self, width: int, height: int) -> FrameTargets:
        W, H = int(width), int(height)
        scale = particle_scale(getattr(self.cfg, "particle_resolution", "auto"), H)
        key = (W, H, scale if self.has_particles else 1.0)
        t = self._targets.get(key)
        if t is None:
            cap = self.capacity if self.has_particles else 1
            t = FrameTargets(W, H, key[2], self.chunks, alpha=self.uses_alpha, mesh=self.mesh is not None,
                             pairs=max(1 << 14, int(1.5 * cap)), host=self.cpu, rows=self.schedule == "pixels")
            self._targets[key] = t
            # keep the buffers of the last few sizes only (a window being resized would otherwise
            # hold one set per size it passed through); a size dropped here costs an allocation,
            # never a compile, when it comes back
            while len(self._targets) > MAX_SIZES_KEPT:
                self._targets.popitem(last=False)
        else:
            self._targets.move_to_end(key)
        return t

    def _background_rect(self, t: FrameTargets, cam, show):
        """The pixel rectangle (x0, y0, x1, y1) of the kept background to redraw, or None.

        The whole image when the camera, the size or ``show`` changed; when only some shown
        colliders moved, the screen rectangle around where each moved one was and is now (its
        bounding sphere's box projected, 2 px of margin; the whole image for a plane or a shape
        reaching behind the camera); nothing when none did. Hidden colliders move nothing."""
        view = (tuple(tuple(float(x) for x in a) for a in cam[:4]), float(cam[4]), bool(show))
        shapes = self.colliders.shown_bounds() if (self.colliders is not None and show) else []
        old, t.bg_shapes = t.bg_shapes, shapes
        if t.bg_key != view or old is None or len(old) != len(shapes):
            t.bg_key = view
            return 0, 0, t.W, t.H
        rect = None
        for (was, c0, r0), (now, c1, r1) in zip(old, shapes):
            if was != now:
                for c, r in ((c0, r0), (c1, r1)):
                    b = screen_box(cam, c, r, t.W, t.H)
                    if b is None:
                        return 0, 0, t.W, t.H
                    rect = b if rect is None else (min(rect[0], b[0]), min(rect[1], b[1]),
                                                   max(rect[2], b[2]), max(rect[3], b[3]))
        if rect is not None and (rect[0] >= rect[2] or rect[1] >= rect[3]):
            return None  # moved off screen
        return rect

    # -- a frame ------------------------------------------------------------------------------
    def render(self, camera, width=None, height=None, *, out=None, exposure=None, show_colliders=None,
               transparent=False, bgra=False, blend=1.0) -> np.ndarray:
        """The scene seen by ``camera`` as an (H, W, 4) uint8 RGBA image (``out`` if given: a
        C-contiguous uint8 array of that shape, written in place; else a new array). Opaque
        unless ``transparent``: then premultiplied, alpha 0 where only background would show.
        ``bgra``: bytes in B, G, R, A order (what X11, SDL and Taichi's fast GUI blit directly).
        ``blend``: where between the last two game steps particles are drawn (a pool built with
        ``interpolate``; engine.render.sprites)."""
        W = int(width or self.cfg.width)
        H = int(height or self.cfg.height)
        image = out if out is not None else np.empty((H, W, 4), np.uint8)
        packed = packed_view(image, W, H)
        t = self.targets(W, H)
        p, f, r, u = camera.basis()
        cam = (p.tolist(), f.tolist(), r.tolist(), u.tolist(), float(camera.tan_half))
        show = self.cfg.show_colliders if show_colliders is None else bool(show_colliders)
        exposure = float(self.cfg.exposure if exposure is None else exposure)
        mode = int(bool(transparent)) | (2 if bgra else 0)
        rect = self._background_rect(t, cam, show)
        if rect is not None:
            self._background(t.bgc, t.depth, *cam, W, H, int(show), *rect)
            if t.mesh:
                self._copy_background(t.fbg, t.fdep, t.bgc, t.depth, W, *rect)
        if (exposure, mode) != t.packed_key:
            self._k["pack_background"](t.bgc, t.bg_packed, W, H, 0, 0, W, H, exposure, mode)
            t.packed_key = (exposure, mode)
        elif rect is not None:
            self._k["pack_background"](t.bgc, t.bg_packed, W, H, *rect, exposure, mode)
        bgc, dep = t.bgc, t.depth
        if self.mesh is not None:
            self.mesh.update()
            self.mesh.draw(t, cam)
            bgc, dep = t.fbg, t.fdep
        if t.has_lo:  # the reduced depths where the full one changed: the redrawn rectangle, the bodies' tiles
            prev = t.dirty_prev if self.mesh is not None else t.dirty
            for k, at, Wk, Hk in ((round(1 / t.scale), t.LO, t.Wl, t.Hl), (round(2 / t.scale), t.LC, t.Wc, t.Hc)):
                if rect is not None:
                    lo = (rect[0] // k, rect[1] // k, min(Wk, -(-rect[2] // k)), min(Hk, -(-rect[3] // k)))
                    self._downsample_depth(dep, W, H, at, Wk, k, *lo, t.dirty, prev, t.TX, 0)
                if self.mesh is not None:
                    self._downsample_depth(dep, W, H, at, Wk, k, 0, 0, Wk, Hk, t.dirty, prev, t.TX, 1)
        has_lo = self._splat(t, cam, dep, blend) if self.has_particles else 0
        common = (t.TX, t.TY, W, H, t.TXl, t.Wl, t.Hl, t.scale)
        tone = (exposure, self.shading, mode)
        if has_lo and self.schedule == "pixels":
            self._k["lo_rows"](t.accA, t.lo_rows, W, H, t.Wl, t.Hl, t.scale, t.touched_lo, t.TXl, t.TYl,
                               int(TILE * t.scale) + 3)
        if self.schedule == "tiles":
            # the tiles whose cached edge flag the redrawn background makes stale (one of margin)
            ex0, ey0, ex1, ey1 = 1, 1, 0, 0
            if rect is not None:
                ex0, ey0 = rect[0] // TILE - 1, rect[1] // TILE - 1
                ex1, ey1 = (rect[2] - 1) // TILE + 1, (rect[3] - 1) // TILE + 1
            self._k["composite_tiles"](t.tile_count, t.full_rows, t.accA, t.accB, bgc, dep, t.bg_packed,
                                       packed, *untouched_tiles(t, image, packed), t.dirty, t.dirty_prev if t.mesh else t.dirty,
                                       t.touched_lo, t.edges, t.edge_rows, ex0, ey0, ex1, ey1, *common, *tone,
                                       round(1 / t.scale) if has_lo else 0)  # (k 0: no reduced layer this frame)
        else:
            self._k["composite_pixels"](t.pairs, t.tile_count, t.tile_start, t.accA, t.lo_rows, bgc,
                                        dep, t.bg_packed, packed, t.dirty, t.touched_lo, *common, has_lo, *tone)
        return image

    def warm_levels(self, camera, width: int, height: int) -> None:
        """Where this size has a reduced layer, a render through the reduced and coarse levels'
        kernels (the same picture), so that they are compiled even if the scene draws nothing
        there yet: a frame with nothing at those levels takes smaller kernels (``_splat``)."""
        if self.has_particles and self.targets(width, height).has_lo:
            self._all_levels = True
            try:
                self.render(camera, width, height)
            finally:
                self._all_levels = False

    def splat_tiles(self, t: FrameTargets, dep, t_lo: int, t_hi: int, levels: bool = True) -> None:
        """The per-tile splat of the tiles [t_lo, t_hi) (engine.render.splat_kernels.splat_tiles;
        ``levels`` False: full-level tiles only, t_hi ≤ T0)."""
        if t_hi > t_lo:
            self._k["splat_tiles"](t.pairs, t.tile_count, t.tile_start, t.accA, t.accB, dep, t.touched_lo,
                                   t.touched_co, t.full_rows, t_lo, t_hi, t.T0, t.TX, t.W, t.H, t.T1, t.TXl, t.Wl, t.Hl,
                                   t.TXc, t.Wc, t.Hc, self.shading, bool(levels))

    def splat_frame(self, t: FrameTargets, dep, reduced: int) -> None:
        """The per-tile splat of a frame binned into ``t`` with ``reduced`` pairs at the reduced
        and coarse levels, launched as the frame takes it (the bench times it so)."""
        if reduced == 0 and t.lo_clear and not self._all_levels:
            # nothing at the reduced and coarse levels, now or at the last splat: their tiles
            # are all clear already, so only the full level's are splatted, by a kernel
            # without the other levels' code (sparks and galaxy never build it; one parallel
            # loop less a frame)
            self.splat_tiles(t, dep, 0, t.T0, levels=False)
        else:
            self.splat_tiles(t, dep, t.T0 + t.T1, t.T)  # the coarse level first: the reduced one reads it
            self.splat_tiles(t, dep, 0, t.T0 + t.T1)

    def _splat(self, t: FrameTargets, cam, dep, blend: float = 1.0) -> int:
        """Sprites, binning, and the splat (per tile: both levels; per pixel: the reduced level,
        the full one is splatted in the composite); returns whether the reduced level is used."""
        W, H = t.W, t.H
        # a reduced sprite's radius is at least LO_MIN_TEXELS texels, a coarse one's CO_MIN_TEXELS
        lo_min = LO_MIN_TEXELS / t.scale if t.has_lo else 1e30
        co_min = CO_MIN_TEXELS / (0.5 * t.scale) if t.has_lo else 1e30
        self._sprites(*cam, W, H, t.scale, lo_min, co_min, float(blend))
        counts = self._tally(t.hist, t.tile_count, t.tile_start, t.block_sum, t.T, t.T0, t.T1, t.TX,
                             t.TXl, t.TXc, t.NB)
        total, reduced = int(counts[0]), int(counts[1])
        if total > t.pair_capacity:  # an ndarray: growing it recompiles nothing
            t.grow_pairs(int(total * 1.25) + 1024)
        self.last_pairs, self.last_reduced_pairs = total, reduced
        if total == 0 and t.lo_clear and not self._all_levels:
            # nothing to draw, and no reduced or coarse tile was drawn at these targets' last
            # splat (each ``touched_lo`` and ``touched_co`` is 0): every tile count is 0, so no
            # accumulator is read — no scatter, splat or reduced rows (an empty frame's fixed cost)
            return 0
        self._scatter(t.pairs, t.hist, t.tile_start, t.T0, t.T1, t.TX, t.TXl, t.TXc)
        if self.schedule == "tiles":
            self.splat_frame(t, dep, reduced)
        elif t.has_lo:
            self._k["splat_pixels_co"](t.pairs, t.tile_count, t.tile_start, t.accA, t.accB, dep, t.touched_co,
                                       t.T0 + t.T1, t.LC, t.T2, t.TXc, t.Wc, t.Hc)
            self._k["splat_pixels_lo"](t.pairs, t.tile_count, t.tile_start, t.accA, t.accB, dep, t.touched_lo,
                                       t.touched_co, t.T0, W, H, t.T1, t.TXl, t.Wl, t.Hl, t.TXc, t.Wc, t.Hc,
                                       self.shading)
        # (every splat sets each touched_lo and touched_co to whether its tile was drawn: with no
        # pair at those levels, all of them to 0)
        t.lo_clear = reduced == 0
        # no sprite in the reduced or coarse level this frame (sparks, galaxy: small sprites only):
        # every reduced tile was just splatted empty, so the composite need not read that layer and
        # its rows need not be interpolated (the empty layer over the background is the background)
        return int(t.has_lo and (reduced > 0 or self._all_levels))
