"""Forces on particles as small ``ti.func`` terms, summed under ``ti.static``.

The set of terms is fixed when the scene is finalised: a term the scene does not use is not
compiled at all. Each term maps (x, v, t, i) → acceleration (m/s²); parameters a game may change
at run time (gravity, wind) live in 0-d fields, so changing them recompiles nothing.
"""
from __future__ import annotations

import taichi as ti


class Forces:
    """Fields: ``force_gravity`` (vec3, m/s²), ``force_wind`` (vec3, m/s), ``force_drag`` (1/s,
    the scene's linear drag; an emitter's own ``drag`` overrides it for its particles)."""

    def __init__(self, cfg, emitter_configs, state, emitter_drag):
        self.force_gravity = ti.Vector.field(3, ti.f32, shape=())
        self.force_wind = ti.Vector.field(3, ti.f32, shape=())
        self.force_drag = ti.field(ti.f32, shape=())
        self.force_gravity[None] = cfg.gravity
        self.force_wind[None] = cfg.wind
        self.force_drag[None] = cfg.drag
        self.use_gravity = any(g != 0.0 for g in cfg.gravity)
        self.use_drag = cfg.drag > 0 or any((e.drag or 0.0) > 0 for e in emitter_configs)
        # Only when some emitter sets its own drag does the kernel read each particle's emitter id
        # (4 more bytes per particle and a gather); otherwise every particle uses the scene's k.
        self.per_emitter_drag = any(e.drag is not None for e in emitter_configs)
        self._state, self._emitter_drag = state, emitter_drag
        self.extra_terms = []  # (name, ti.func) added by later features (buoyancy, noise, ...)

    @property
    def names(self):
        return ([n for n, used in (("gravity", self.use_gravity), ("drag", self.use_drag)) if used]
                + [n for n, _ in self.extra_terms])

    def make_accel(self):
        """``accel(x, v, t, i)``: the sum of the scene's terms for particle slot i."""
        g, wind, kdrag = self.force_gravity, self.force_wind, self.force_drag
        pem, edrag = self._state.particle_emitter, self._emitter_drag
        per_emitter = self.per_emitter_drag

        @ti.func
        def gravity(x, v, t, i):
            return g[None]

        @ti.func
        def drag(x, v, t, i):
            k = kdrag[None]
            if ti.static(per_emitter):
                ke = edrag[pem[i]]
                if ke >= 0.0:
                    k = ke
            return -k * (v - wind[None])  # linear drag relative to the air (Stokes regime)

        terms = []
        if self.use_gravity:
            terms.append(gravity)
        if self.use_drag:
            terms.append(drag)
        terms += [f for _, f in self.extra_terms]
        terms = tuple(terms)

        @ti.func
        def accel(x, v, t, i):
            a = ti.Vector([0.0, 0.0, 0.0])
            for k in ti.static(range(len(terms))):
                a += terms[k](x, v, t, i)
            return a

        return accel
