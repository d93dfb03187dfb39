"""XPBD: extended position-based dynamics (Macklin, Müller & Chentanez 2016), one loop for every
constraint group of a system.

Per step of h over a set of point masses (positions X, velocities V, inverse masses w):

    v += h g (free nodes); x_prev = x; x += h v; λ = 0 for every group
    repeat `iterations` times, group by group, colour by colour (Gauss–Seidel, race-free):
        each constraint C with gradients ∇ᵢC and compliance α (α̃ = α/h², γ = damping):
        Δλ = (−C − α̃λ − γ Σ ∇ᵢC·(xᵢ − x_prevᵢ)) / ((1 + γ) Σ wᵢ|∇ᵢC|² + α̃)
        λ += Δλ;  xᵢ += wᵢ Δλ ∇ᵢC
    v = (x − x_prev)/h

A *constraint group* (springs: :class:`~engine.xpbd.constraints.SpringConstraints`; energy terms:
:class:`~engine.forces.elements.ElementGroup`) gives ``clear()`` (λ = 0) and
``project(X, x_prev, w, h)`` — one launch that sweeps all its colours in order (each colour a
top-level loop of the kernel: Taichi runs a kernel's top-level loops one after the other, so the
sweep is the same Gauss–Seidel order as one launch per colour, at one launch's cost).
On the CPU backend a spring-only network of up to 4096 nodes skips this loop: its whole frame,
every substep and colour, is one serial launch (engine.springs.fused, the same bytes; the
per-node and per-spring bodies — :func:`predict_node`, ``project_spring`` — are shared).
Unconditionally stable for any h: too few iterations leave stiff constraints softer (sagging),
never exploding. Joints, rigid contacts and particle constraints join as further groups.
"""
import taichi as ti


@ti.func
def predict_node(X: ti.template(), V: ti.template(), w: ti.template(), x_prev: ti.template(), hh,
                 fields: ti.template(), g, i):
    """v += h a_ext (free node i: gravity g and the point-mass fields); x_prev = x; x += h v."""
    v = V[i]
    if w[i] > 0:
        v += hh * fields.external(g, X[i], v)
    V[i] = v
    x_prev[i] = X[i]
    X[i] += hh * v


@ti.kernel
def _predict(n: ti.i32, X: ti.template(), V: ti.template(), w: ti.template(), fields: ti.template(),
             x_prev: ti.template(), h: ti.f64):
    hh = ti.cast(h, X.dtype)
    g = ti.cast(fields.gravity[None], X.dtype)
    for i in range(n):
        predict_node(X, V, w, x_prev, hh, fields, g, i)


@ti.kernel
def _update_velocity(n: ti.i32, X: ti.template(), V: ti.template(), x_prev: ti.template(), h: ti.f64):
    hh = ti.cast(h, X.dtype)
    for i in range(n):
        V[i] = (X[i] - x_prev[i]) / hh


class XPBDSolver:
    """``step(h)``: one XPBD step of the nodes (fixed steps only: no error estimate).

    ``X``, ``V``: (N,) 3-vector fields (m, m/s); ``w``: (N,) inverse masses (1/kg, 0 pinned);
    ``gravity``: :class:`~engine.forces.fields.PointForces` (gravity and the fields acting on every
    free node; a bare 0-d gravity field is gravity alone); ``groups``: constraint groups, projected in this order."""

    method = "xpbd"
    order = 1
    fevals = 1

    def __init__(self, n: int, X, V, w, gravity, groups, iterations: int = 10):
        from ..forces.fields import PointForces

        if not isinstance(gravity, PointForces):
            gravity = PointForces(gravity, dtype=X.dtype)
        self.n, self.X, self.V, self.w, self.gravity = n, X, V, w, gravity
        self.groups, self.iterations = [g for g in groups if g.count], int(iterations)
        self.x_prev = ti.Vector.field(3, X.dtype, max(1, n))

    def launches_per_step(self) -> int:
        """Kernel launches of one step: predict, clears, the sweeps, the velocity update."""
        return 2 + len(self.groups) * (1 + self.iterations)

    def step(self, h: float) -> None:
        if self.n == 0:
            return
        _predict(self.n, self.X, self.V, self.w, self.gravity, self.x_prev, h)
        for g in self.groups:
            g.clear()
        for _ in range(self.iterations):
            for g in self.groups:
                g.project(self.X, self.x_prev, self.w, h)
        _update_velocity(self.n, self.X, self.V, self.x_prev, h)
