"""What happens around every integrator step: pins, stretch limits, collisions, divergence flag.

* ``pin_drive(alpha, h)`` before a step: a pinned node (inv_mass 0, so zero acceleration) gets the
  velocity that carries it from where it is to its target at the end of the step,
  lerp(pin_start, pin_target, alpha) — fixed pins get v = 0, moving pins an inferred velocity.
* ``limit_color(lo, hi, max_stretch)``: distance limits for inextensible hair and chains. Each
  structural spring longer than (1 + max_stretch)·rest is shortened to that length, the correction
  split by inverse masses, and the separating part of the relative velocity along it removed (an
  inelastic impulse: energy never grows). Run colour by colour (no two springs of a colour share a
  node), a few sweeps: a deterministic Gauss–Seidel projection.
* ``finalize(alpha, k)`` after: pinned nodes snap exactly onto their target; every other node goes
  through the Colliders' ``collide(x, v)`` (evaluated in f32, the colliders' precision, and written
  back only where it touched something); a non-finite node records substep index k in ``bad``.
"""
import taichi as ti

from ..ode.steppers import is_finite
from .model import SpringModel, SpringState

NO_FAILURE = 2 ** 30


def make_constraint_kernels(model: SpringModel, state: SpringState, colliders=None):
    n, dtype = model.node_count, model.dtype
    X, V = state.node_pos, state.node_vel
    pinned, ps, pt, w = model.node_pinned, model.pin_start, model.pin_target, model.node_inv_mass
    sa, sb, rl, lim, order = (model.spring_a, model.spring_b, model.spring_rest_length,
                              model.spring_limit, model.color_spring)
    has_colliders = colliders is not None and colliders.count > 0
    collide = colliders.make_func() if has_colliders else None
    bad = ti.field(ti.i32, ())
    bad[None] = NO_FAILURE

    @ti.func
    def pin_at(i, alpha):
        return ps[i] + alpha * (pt[i] - ps[i])

    @ti.kernel
    def pin_drive(alpha: dtype, h: dtype):
        for i in range(n):
            if pinned[i]:
                V[i] = (pin_at(i, alpha) - X[i]) / h

    @ti.kernel
    def finalize(alpha: dtype, k: ti.i32):
        for i in range(n):
            x, v = X[i], V[i]
            if pinned[i]:
                x = pin_at(i, alpha)
            else:
                if ti.static(has_colliders):
                    xc, vc, killed, hits = collide(ti.cast(x, ti.f32), ti.cast(v, ti.f32))
                    if hits > 0:
                        x = ti.cast(xc, dtype)
                        v = ti.cast(vc, dtype)
            if not is_finite(x.sum() + v.sum()):
                ti.atomic_min(bad[None], k)
            X[i] = x
            V[i] = v

    @ti.kernel
    def limit_color(lo: ti.i32, hi: ti.i32, max_stretch: dtype):
        for q in range(lo, hi):
            s = order[q]
            if lim[s]:
                a, b = sa[s], sb[s]
                L = X[a] - X[b]
                ln = L.norm()
                cap = (1 + max_stretch) * rl[s]
                wa, wb = w[a], w[b]
                if ln > cap and wa + wb > 0:
                    nrm = L / ln
                    corr = (ln - cap) / (wa + wb) * nrm
                    X[a] -= wa * corr
                    X[b] += wb * corr
                    rel = (V[a] - V[b]).dot(nrm)
                    if rel > 0:
                        imp = rel / (wa + wb) * nrm
                        V[a] -= wa * imp
                        V[b] += wb * imp

    @ti.kernel
    def begin_frame():
        for i in range(n):
            if pinned[i]:
                ps[i] = X[i]

    return dict(pin_drive=pin_drive, finalize=finalize, limit_color=limit_color,
                begin_frame=begin_frame, bad=bad)
