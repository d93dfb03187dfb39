"""Force fields on point masses: gravity, linear drag toward the wind, attractors and vortices, for
spring nodes as for particles (issue 21, item 3).

Per unit mass (m/s²): a = g − k (v − w) with g the gravity, k the linear drag coefficient (1/s)
and w the wind (m/s): the Stokes-regime drag of :mod:`engine.particles.forces`, relative to the
air. Under it alone a point's velocity relaxes to w + g/k with time constant 1/k (NUMERICS.md,
"Linear drag": v = v∞ + (v₀ − v∞) e^(−kt), v∞ = w + g/k).

Attractors and vortices (``[[forces.attractors]]``, ``[[forces.vortices]]``; their formulas are
:func:`attractor_accel` and :func:`vortex_accel`, the particles' terms call the same functions):
a = s d̂ / (1 + (|d|/r)²) toward the point, and a tangential s · 2q/(1 + q²) around the axis
(q = ρ/r, ρ the distance from it).

Gravity and wind are the scene's Control fields (0-d: a game changes them without a compile);
the drag coefficient is a 0-d field of its own. The drag term is a compile-time switch: without
drag (k = 0 in the config) the field is gravity alone, the same arithmetic as before wind reached
the nodes, so a body in a scene without drag keeps its bytes.
"""
import numpy as np
import taichi as ti  # (no __future__ annotations: Taichi reads the funcs' annotations)

from ..launch import data_oriented


@ti.func
def attractor_accel(x, pos, strength, radius):
    """Acceleration toward ``pos`` (m/s²; negative strength pushes): s · d̂ / (1 + (|d|/r)²), the
    1e-6 m guard keeping the point at the centre finite."""
    d = pos - x
    r = d.norm() + 1e-6
    return strength * (d / r) / (1.0 + (r / radius) ** 2)


@ti.func
def vortex_accel(x, pos, axis, strength, radius):
    """Tangential acceleration around the unit ``axis`` through ``pos``: s · 2q/(1 + q²) along
    axis × ρ̂ (q = ρ/r, ρ the point's distance from the axis): zero on the axis, largest at ρ = r."""
    d = x - pos
    rho_v = d - d.dot(axis) * axis  # from the axis, perpendicular to it
    rho = rho_v.norm() + 1e-6
    q = rho / radius
    return strength * (2.0 * q / (1.0 + q * q)) * axis.cross(rho_v / rho)


@data_oriented
class PointForces:
    """``gravity``, ``wind``: 0-d vector fields (the control's; m/s², m/s); ``drag``: k (1/s),
    compiled in only when positive (``use_drag``); ``attractors``, ``vortices``: the config's
    (objects with position, strength, radius and, for vortices, axis), their count a compile-time
    constant. ``dtype``: the precision of the points."""

    def __init__(self, gravity, wind=None, drag: float = 0.0, dtype=ti.f32, attractors=(), vortices=()):
        if not drag >= 0.0:
            raise ValueError(f"drag: must be >= 0 1/s, got {drag}")
        self.gravity, self.wind, self.dtype = gravity, wind, dtype
        self.use_drag = drag > 0.0 and wind is not None
        if self.use_drag:
            self.drag = ti.field(dtype, shape=())
            self.drag[None] = drag
        self.attractor_count, self.vortex_count = len(attractors), len(vortices)
        if self.attractor_count:
            n = self.attractor_count
            self.attractor_pos = ti.Vector.field(3, dtype, shape=n)
            self.attractor_strength = ti.field(dtype, shape=n)
            self.attractor_radius = ti.field(dtype, shape=n)
            for k, a in enumerate(attractors):
                self.attractor_pos[k], self.attractor_strength[k], self.attractor_radius[k] = \
                    list(a.position), a.strength, a.radius
        if self.vortex_count:
            n = self.vortex_count
            self.vortex_pos = ti.Vector.field(3, dtype, shape=n)
            self.vortex_axis = ti.Vector.field(3, dtype, shape=n)
            self.vortex_strength = ti.field(dtype, shape=n)
            self.vortex_radius = ti.field(dtype, shape=n)
            for k, v in enumerate(vortices):
                ax = np.asarray(v.axis, np.float64)
                self.vortex_pos[k], self.vortex_axis[k] = list(v.position), (ax / np.linalg.norm(ax)).tolist()
                self.vortex_strength[k], self.vortex_radius[k] = v.strength, v.radius

    def set_drag(self, k: float) -> None:
        """A new drag coefficient (1/s) for a field compiled with drag (no compile)."""
        if not self.use_drag:
            raise ValueError("drag: this body was built without drag (give [forces] a drag > 0)")
        self.drag[None] = float(k)

    @ti.func
    def external(self, g, x, v):
        """The acceleration of a point at x moving at v, given the gravity ``g`` (read once per
        kernel: ``ti.cast(gravity[None], dtype)``): g, less k (v − w) when drag is compiled in,
        plus the attractors' and vortices' pulls."""
        a = g
        if ti.static(self.use_drag):
            a = g - self.drag[None] * (v - ti.cast(self.wind[None], self.dtype))
        for k in ti.static(range(self.attractor_count)):
            a += attractor_accel(x, self.attractor_pos[k], self.attractor_strength[k], self.attractor_radius[k])
        for k in ti.static(range(self.vortex_count)):
            a += vortex_accel(x, self.vortex_pos[k], self.vortex_axis[k], self.vortex_strength[k],
                              self.vortex_radius[k])
        return a
