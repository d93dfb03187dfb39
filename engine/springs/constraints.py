"""What happens around every integrator step: pins, collisions, the divergence flag.

* ``pin_drive(alpha, h)`` before a step: a pinned node (inv_mass 0, so zero acceleration) gets the
  velocity that carries it from where it is to its target at the end of the step,
  lerp(pin_start, pin_target, alpha) — fixed pins get v = 0, moving pins an inferred velocity.
* stretch limits run between the two (see :mod:`.limits`).
* ``finalize(alpha, t_end)`` after: pinned nodes snap exactly onto their target; every other node
  goes through the Colliders' ``collide(x, v)`` (evaluated in f32, the colliders' precision, and
  written back only where it touched something); a non-finite node records the step's end time.
"""
import taichi as ti

from ..ode.steppers import is_finite

NO_FAILURE = 1e30  # bad_t sentinel: no node went non-finite


@ti.func
def pin_at(model: ti.template(), i, alpha):
    return model.pin_start[i] + alpha * (model.pin_target[i] - model.pin_start[i])


@ti.kernel
def pin_drive(model: ti.template(), state: ti.template(), alpha: ti.f64, h: ti.f64):
    X, V = ti.static(state.node_pos, state.node_vel)
    for i in range(model.node_count):
        if model.node_pinned[i]:
            V[i] = (pin_at(model, i, ti.cast(alpha, model.dtype)) - X[i]) / ti.cast(h, model.dtype)


@ti.func
def no_collision(x, v):
    """``collide`` for a network without colliders (the compiler drops the dead branch); the
    colliders' reporting signature (x, v, killed, hits, which, normal, speed)."""
    return x, v, 0, 0, -1, ti.Vector([0.0, 0.0, 0.0]), 0.0


@ti.kernel
def finalize(model: ti.template(), state: ti.template(), collide: ti.template(), bad_t: ti.template(),
             alpha: ti.f64, t_end: ti.f64, contacts: ti.template()):
    """``contacts``: an :class:`engine.contacts.ContactBuffer` (recording compiled in only when
    it is enabled; the unused report outputs of ``collide`` are then dead code)."""
    X, V = ti.static(state.node_pos, state.node_vel)
    for i in range(model.node_count):
        x, v = X[i], V[i]
        if model.node_pinned[i]:
            x = pin_at(model, i, ti.cast(alpha, model.dtype))
        else:
            xc, vc, killed, hits, which, nrm, spd = collide(ti.cast(x, ti.f32), ti.cast(v, ti.f32))
            if hits > 0:
                x = ti.cast(xc, model.dtype)
                v = ti.cast(vc, model.dtype)
                if ti.static(contacts.enabled):
                    contacts.record(i, which, xc, nrm, spd, t_end)
        if not is_finite(x.sum() + v.sum()):
            ti.atomic_min(bad_t[None], t_end)
        X[i] = x
        V[i] = v


@ti.kernel
def begin_frame(model: ti.template(), state: ti.template()):
    """Pinned nodes start the frame where they are."""
    for i in range(model.node_count):
        if model.node_pinned[i]:
            model.pin_start[i] = state.node_pos[i]
