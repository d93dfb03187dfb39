"""Spring distance constraints for the XPBD loop (:mod:`engine.xpbd.solver`).

Each spring is the Hooke term's constraint C = |x_a − x_b| − r (engine.forces.terms.
hooke_constraint) with compliance α = 1/ks; per step of h α̃ = α/h², and the spring's damping kd
enters as the paper's β: γ = α̃·(h²β)/h = kd/(ks·h). |∇C|² = 1 on both ends, so the denominator is
(1 + γ)(w_a + w_b) + α̃. Springs with ks = 0 are skipped.
"""
import taichi as ti

from ..forces.terms import hooke_constraint
from ..geometry.colouring import serial_sweep


@ti.kernel
def _clear(model: ti.template(), lam: ti.template()):
    for s in range(model.spring_count):
        lam[s] = 0


@ti.func
def project_spring(model: ti.template(), X: ti.template(), x_prev: ti.template(), w: ti.template(),
                   lam: ti.template(), hh, s):
    """One XPBD projection of spring s (step hh in model.dtype): λ_s and both ends updated."""
    sa, sb, rl, ks, kd = ti.static(model.spring_a, model.spring_b, model.spring_rest_length,
                                   model.spring_ks, model.spring_kd)
    a, b = sa[s], sb[s]
    wa, wb = w[a], w[b]
    if ks[s] > 0 and wa + wb > 0:
        C, nrm, ok = hooke_constraint(model.dtype, X[a], X[b], rl[s])
        if ok:
            alpha = 1 / (ks[s] * hh * hh)
            gamma = kd[s] / (ks[s] * hh)
            dC = nrm.dot((X[a] - x_prev[a]) - (X[b] - x_prev[b]))
            dlam = (-C - alpha * lam[s] - gamma * dC) / ((1 + gamma) * (wa + wb) + alpha)
            lam[s] += dlam
            X[a] += wa * dlam * nrm
            X[b] -= wb * dlam * nrm


@ti.func
def sweep_serial(model: ti.template(), X: ti.template(), x_prev: ti.template(), w: ti.template(),
                 lam: ti.template(), hh):
    """One Gauss–Seidel sweep of every colour, in colour order, on the calling thread (call from
    inside a serial loop). No two springs of a colour share a node, so the order inside a colour
    does not change a bit: this is the parallel per-colour sweep's result exactly."""
    for q in range(model.spring_count):
        project_spring(model, X, x_prev, w, lam, hh, model.color_spring[q])


@ti.kernel
def _project(model: ti.template(), X: ti.template(), x_prev: ti.template(), w: ti.template(),
             lam: ti.template(), h: ti.f64):
    hh = ti.cast(h, model.dtype)
    if ti.static(serial_sweep(model.spring_count)):  # every colour in order on this thread
        ti.loop_config(serialize=True)
        for q in range(model.spring_count):
            project_spring(model, X, x_prev, w, lam, hh, model.color_spring[q])
    else:
        for c in ti.static(range(len(model.color_ranges))):  # one top-level loop per colour, in order
            lo, hi = ti.static(model.color_ranges[c])
            for q in range(lo, hi):
                project_spring(model, X, x_prev, w, lam, hh, model.color_spring[q])


class SpringConstraints:
    """The springs of a :class:`~engine.springs.model.SpringModel` as an XPBD constraint group."""

    def __init__(self, model):
        self.model, self.count = model, model.spring_count
        self.lam = ti.field(model.dtype, max(1, model.spring_count))

    def clear(self) -> None:
        _clear(self.model, self.lam)

    def project(self, X, x_prev, w, h: float) -> None:
        _project(self.model, X, x_prev, w, self.lam, h)
