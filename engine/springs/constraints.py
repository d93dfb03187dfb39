"""What happens around every integrator step: pins, collisions, the divergence flag.

* ``pin_drive(alpha, h)`` before a step: a pinned node (inv_mass 0, so zero acceleration) gets the
  velocity that carries it from where it is to its target at the end of the step,
  lerp(pin_start, pin_target, alpha) — fixed pins get v = 0, moving pins an inferred velocity.
* stretch limits run between the two (see :mod:`.limits`).
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
    pinned, ps, pt = model.node_pinned, model.pin_start, model.pin_target
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
    def begin_frame():
        for i in range(n):
            if pinned[i]:
                ps[i] = X[i]

    return dict(pin_drive=pin_drive, finalize=finalize, begin_frame=begin_frame, bad=bad)
