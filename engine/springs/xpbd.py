"""XPBD: extended position-based dynamics (Macklin, Müller & Chentanez 2016) for springs.

Each spring is a distance constraint C = |x_a − x_b| − r with compliance α = 1/ks; per step of h
α̃ = α/h², and spring damping kd enters as the paper's β: γ = α̃·(h²β)/h = kd/(ks·h). Per step:

    v += h a_ext (free nodes: gravity, drag toward the wind); x_prev = x; x += h v; λ = 0
    repeat `iterations` times, colour by colour (Gauss–Seidel, race-free, deterministic):
        Δλ = (−C − α̃λ − γ ∇C·(x − x_prev)) / ((1 + γ)(w_a + w_b) + α̃)
        λ += Δλ;  x_a += w_a Δλ n;  x_b −= w_b Δλ n          (n = (x_a − x_b)/|x_a − x_b|)
    v = (x − x_prev)/h

Unconditionally stable for any h: the price is that too few iterations leave stiff springs softer
than ks (sagging), never exploding. Springs with ks = 0 are skipped.
"""
import taichi as ti

from ..forces.fields import PointForces


@ti.kernel
def _predict(model: ti.template(), state: ti.template(), fields: ti.template(), x_prev: ti.template(),
             lam: ti.template(), h: ti.f64):
    X, V, w = ti.static(state.node_pos, state.node_vel, model.node_inv_mass)
    hh = ti.cast(h, model.dtype)
    g = ti.cast(fields.gravity[None], model.dtype)
    for i in range(model.node_count):
        v = V[i]
        if w[i] > 0:
            v += hh * fields.external(g, X[i], v)  # gravity (and drag toward the wind)
        V[i] = v
        x_prev[i] = X[i]
        X[i] += hh * v
    for s in range(model.spring_count):
        lam[s] = 0


@ti.kernel
def _project_color(model: ti.template(), state: ti.template(), x_prev: ti.template(), lam: ti.template(),
                   lo: ti.i32, hi: ti.i32, h: ti.f64):
    X, w = ti.static(state.node_pos, model.node_inv_mass)
    sa, sb, rl, ks, kd = ti.static(model.spring_a, model.spring_b, model.spring_rest_length,
                                   model.spring_ks, model.spring_kd)
    hh = ti.cast(h, model.dtype)
    for q in range(lo, hi):
        s = model.color_spring[q]
        a, b = sa[s], sb[s]
        wa, wb = w[a], w[b]
        if ks[s] > 0 and wa + wb > 0:
            L = X[a] - X[b]
            ln = L.norm()
            if ln > 1e-12:
                nrm = L / ln
                alpha = 1 / (ks[s] * hh * hh)
                gamma = kd[s] / (ks[s] * hh)
                C = ln - rl[s]
                dC = nrm.dot((X[a] - x_prev[a]) - (X[b] - x_prev[b]))
                dlam = (-C - alpha * lam[s] - gamma * dC) / ((1 + gamma) * (wa + wb) + alpha)
                lam[s] += dlam
                X[a] += wa * dlam * nrm
                X[b] -= wb * dlam * nrm


@ti.kernel
def _update_velocity(model: ti.template(), state: ti.template(), x_prev: ti.template(), h: ti.f64):
    hh = ti.cast(h, model.dtype)
    for i in range(model.node_count):
        state.node_vel[i] = (state.node_pos[i] - x_prev[i]) / hh


class XPBDStepper:
    """``step(h)``: one XPBD step of the network (fixed steps only: no error estimate)."""

    method = "xpbd"
    order = 1
    fevals = 1

    def __init__(self, model, state, fields, iterations: int = 10):
        """``fields``: :class:`~engine.forces.fields.PointForces` (gravity, drag, wind; a bare 0-d
        gravity field is gravity alone)."""
        if not isinstance(fields, PointForces):
            fields = PointForces(fields, dtype=model.dtype)
        dtype, N, M = model.dtype, max(1, model.node_count), max(1, model.spring_count)
        self.model, self.state, self.fields, self.iterations = model, state, fields, int(iterations)
        self.x_prev = ti.Vector.field(3, dtype, N)
        self.lam = ti.field(dtype, M)

    def step(self, h: float) -> None:
        m, s = self.model, self.state
        if m.node_count == 0:
            return
        _predict(m, s, self.fields, self.x_prev, self.lam, h)
        for _ in range(self.iterations):
            for lo, hi in m.color_ranges:
                _project_color(m, s, self.x_prev, self.lam, lo, hi, h)
        _update_velocity(m, s, self.x_prev, h)
