"""Forces on particles as small ``ti.func`` terms, summed under ``ti.static``.

The set of terms is fixed when the scene is finalised: a term the scene does not use is not
compiled at all. Each term maps (x, v, age, t, i) → acceleration (m/s²), with the particle's age at the
stage time (it is part of the integrated state); what a game may change at run time (gravity,
wind) is read from the scene's Control (engine.control: 0-d fields, so changing them recompiles
nothing).
"""
from __future__ import annotations


import numpy as np
import taichi as ti

from ..fieldio import ColumnWriter
from ..forces.fields import attractor_accel, vortex_accel
from .noise import curl_noise


class Forces:
    """Fields: ``force_drag`` (1/s, the scene's linear drag; an emitter's own ``drag`` overrides
    it for its particles) and the per-emitter parameters of the terms in use. Gravity (m/s²,
    scaled per emitter by ``gravity_scale``) and wind (m/s) are the control's."""

    def __init__(self, cfg, emitter_configs, state, emitter_drag, control, rows: int = 0, writes=None):
        """``rows``: per-emitter parameter rows (at least one per emitter; spare rows for
        emitters added later by :meth:`set_emitters`). ``writes``: the
        :class:`~engine.fieldio.WriterGroup` whose kernel writes them (the emitters')."""
        self.rows = R = max(len(emitter_configs), int(rows))
        self.control = control
        self.force_drag = ti.field(ti.f32, shape=())
        self.force_drag[None] = cfg.drag
        self.__dict__.update(self.features(cfg, emitter_configs))
        self.attractor_count, self.vortex_count = len(cfg.attractors), len(cfg.vortices)
        self._state, self._emitter_drag = state, emitter_drag
        self.turbulence = cfg.turbulence
        # per-emitter parameters; those of the optional terms allocated only when the term is used
        self._params = {"emitter_gravity_scale": ti.field(ti.f32, shape=R)}
        if self.use_buoyancy:
            self._params["emitter_buoyancy"] = ti.field(ti.f32, shape=R)
            self._params["emitter_inv_cooling"] = ti.field(ti.f32, shape=R)
        if self.use_turbulence:
            self._params["emitter_turbulence"] = ti.field(ti.f32, shape=R)
        self.__dict__.update(self._params)
        self._writer = ColumnWriter(list(self._params.values()), group=writes)
        self.set_emitters(emitter_configs)
        if self.attractor_count:
            n = self.attractor_count
            self.attractor_pos = ti.Vector.field(3, ti.f32, shape=n)
            self.attractor_strength = ti.field(ti.f32, shape=n)
            self.attractor_radius = ti.field(ti.f32, shape=n)
            for k, a in enumerate(cfg.attractors):
                self.attractor_pos[k], self.attractor_strength[k], self.attractor_radius[k] = \
                    a.position, a.strength, a.radius
        if self.vortex_count:
            n = self.vortex_count
            self.vortex_pos = ti.Vector.field(3, ti.f32, shape=n)
            self.vortex_axis = ti.Vector.field(3, ti.f32, shape=n)
            self.vortex_strength = ti.field(ti.f32, shape=n)
            self.vortex_radius = ti.field(ti.f32, shape=n)
            for k, v in enumerate(cfg.vortices):
                ax = np.asarray(v.axis, np.float64)
                self.vortex_pos[k], self.vortex_axis[k] = v.position, (ax / np.linalg.norm(ax)).tolist()
                self.vortex_strength[k], self.vortex_radius[k] = v.strength, v.radius

    @staticmethod
    def features(cfg, emitter_configs) -> dict:
        """The compile-time switches these emitters need (a term is compiled in only when used)."""
        es = emitter_configs
        tb = cfg.turbulence
        return dict(
            use_gravity=any(g != 0.0 for g in cfg.gravity) and any(e.gravity_scale != 0 for e in es),
            use_drag=cfg.drag > 0 or any((e.drag or 0.0) > 0 for e in es),
            # Only when some emitter sets its own drag (or gravity scale) does the kernel gather a
            # per-emitter value by the particle's emitter id; otherwise the scene's value is used.
            per_emitter_drag=any(e.drag is not None for e in es),
            per_emitter_gravity=any(e.gravity_scale != 1.0 for e in es),
            use_buoyancy=any(e.buoyancy != 0 for e in es),
            use_turbulence=tb.strength > 0 and any(e.turbulence > 0 for e in es))

    def covers(self, cfg, emitter_configs) -> bool:
        """Whether the compiled terms serve these emitters (every switch they need is on)."""
        need = self.features(cfg, emitter_configs)
        return len(emitter_configs) <= self.rows and all(getattr(self, k) or not v for k, v in need.items())

    def set_emitters(self, emitter_configs) -> None:
        """Write the per-emitter parameters (rows past the emitters are zero); no compile."""
        cols = {"emitter_gravity_scale": [e.gravity_scale for e in emitter_configs],
                "emitter_buoyancy": [e.buoyancy for e in emitter_configs],
                "emitter_inv_cooling": [1.0 / e.cooling for e in emitter_configs],
                "emitter_turbulence": [e.turbulence for e in emitter_configs]}
        arrays = []
        for name in self._params:
            a = np.zeros(self.rows, np.float32)
            a[: len(emitter_configs)] = cols[name]
            arrays.append(a)
        self._writer.write(*arrays)  # (one launch for all: engine.fieldio)

    @property
    def names(self):
        """The terms compiled into this scene's acceleration, in order."""
        return [n for n, used in (("gravity", self.use_gravity), ("drag", self.use_drag),
                                  ("buoyancy", self.use_buoyancy), ("turbulence", self.use_turbulence),
                                  ("attractors", self.attractor_count > 0),
                                  ("vortices", self.vortex_count > 0)) if used]

    def make_accel(self):
        """``accel(x, v, age, t, i)``: the sum of the scene's terms for particle slot i."""
        g, wind, kdrag = self.control.gravity, self.control.wind, self.force_drag
        pem, edrag = self._state.particle_emitter, self._emitter_drag
        per_emitter, per_emitter_g = self.per_emitter_drag, self.per_emitter_gravity

        gscale = self.emitter_gravity_scale

        @ti.func
        def gravity(x, v, age, t, i):
            a = g[None]
            if ti.static(per_emitter_g):
                a = a * gscale[pem[i]]
            return a

        @ti.func
        def drag(x, v, age, t, i):
            k = kdrag[None]
            if ti.static(per_emitter):
                ke = edrag[pem[i]]
                if ke >= 0.0:
                    k = ke
            return -k * (v - wind[None])  # linear drag relative to the air (Stokes regime)

        available = {"gravity": gravity, "drag": drag}
        if self.use_buoyancy:
            bu, inv_cool = self.emitter_buoyancy, self.emitter_inv_cooling

            @ti.func
            def buoyancy(x, v, age, t, i):
                # hot gas rises; its temperature excess decays as exp(−age/cooling) (Newton cooling)
                e = pem[i]
                return ti.Vector([0.0, bu[e] * ti.exp(-age * inv_cool[e]), 0.0])

            available["buoyancy"] = buoyancy
        if self.use_turbulence:
            tb, et = self.turbulence, self.emitter_turbulence
            strength, freq, scroll, octaves = tb.strength, tb.frequency, tb.scroll, tb.octaves

            @ti.func
            def turbulence(x, v, age, t, i):
                p = x * freq - ti.Vector([0.0, scroll * freq * t, 0.0])
                return (strength * et[pem[i]]) * curl_noise(p, octaves)

            available["turbulence"] = turbulence
        if self.attractor_count:
            apos, astr, arad, na = (self.attractor_pos, self.attractor_strength, self.attractor_radius,
                                    self.attractor_count)

            @ti.func
            def attractors(x, v, age, t, i):
                a = ti.Vector([0.0, 0.0, 0.0])
                for k in ti.static(range(na)):
                    a += attractor_accel(x, apos[k], astr[k], arad[k])  # (engine.forces.fields: nodes' too)
                return a

            available["attractors"] = attractors
        if self.vortex_count:
            vpos, vax, vstr, vrad, nv = (self.vortex_pos, self.vortex_axis, self.vortex_strength,
                                         self.vortex_radius, self.vortex_count)

            @ti.func
            def vortices(x, v, age, t, i):
                a = ti.Vector([0.0, 0.0, 0.0])
                for k in ti.static(range(nv)):
                    a += vortex_accel(x, vpos[k], vax[k], vstr[k], vrad[k])
                return a

            available["vortices"] = vortices
        terms = tuple(available[n] for n in self.names)

        @ti.func
        def accel(x, v, age, t, i):
            a = ti.Vector([0.0, 0.0, 0.0])
            for k in ti.static(range(len(terms))):
                a += terms[k](x, v, age, t, i)
            return a

        return accel
