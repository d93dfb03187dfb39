"""What happens around every integrator step: pins, collisions, the divergence flag.

* ``pin_drive(alpha, h)`` before a step: a pinned node (inv_mass 0, so zero acceleration) gets the
  velocity that carries it from where it is to its target at the end of the step,
  lerp(pin_start, pin_target, alpha) — fixed pins get v = 0, moving pins an inferred velocity.
* stretch limits run between the two (see :mod:`.limits`).
* ``finalize(alpha, t_end, h)`` after: pinned nodes snap exactly onto their target; every other
  node's impacts are located in the step (:class:`NodeContacts`) and its resting contacts held
  (the colliders' projection), evaluated in the colliders' precision (f32) and written back only
  where something was touched; a non-finite node records the step's end time.

A node's motion inside a coupled step is not its own to re-integrate (its neighbours moved with
it), so its impacts are located on the step's own path: the quadratic through its start (x₀, v₀)
and end x₁, x(s) = x₀ + v₀s + ½as² with a = 2(x₁ − x₀ − v₀h)/h² (the node's mean acceleration over
the step), on which the ODE core's :func:`~engine.ode.events.located_step` finds the impact (a
plane's in closed form), reflects the node there and carries it ballistically to the step's end.
The springs see the bounce from the next step on.
"""
import taichi as ti

from ..ode.events import located_step
from ..ode.steppers import is_finite

NO_FAILURE = 1e30  # bad_t sentinel: no node went non-finite


@ti.func
def pin_at(model: ti.template(), i, alpha):
    return model.pin_start[i] + alpha * (model.pin_target[i] - model.pin_start[i])


@ti.func
def drive_node(model: ti.template(), state: ti.template(), alpha, h, i):
    """Pinned node i gets the velocity that carries it to its target at the step's end."""
    X, V = ti.static(state.node_pos, state.node_vel)
    if model.node_pinned[i]:
        V[i] = (pin_at(model, i, ti.cast(alpha, model.dtype)) - X[i]) / ti.cast(h, model.dtype)


@ti.kernel
def pin_drive(model: ti.template(), state: ti.template(), alpha: ti.f64, h: ti.f64):
    for i in range(model.node_count):
        drive_node(model, state, alpha, h, i)


def ballistic(dtype):
    """The exact step of y = (x, a, v, 0) ∈ R¹² under constant acceleration a (q = (x, a),
    p = (v, 0), q' = p), error 0: a node's path over its step, for event location."""

    @ti.func
    def step(y, t, h, i, atol, rtol):
        out = y
        for c in ti.static(range(3)):
            out[c] = y[c] + h * y[6 + c] + 0.5 * h * h * y[3 + c]
            out[6 + c] = y[6 + c] + h * y[3 + c]
        return out, ti.cast(0.0, dtype)

    return step


class NodeContacts:
    """A network's colliders as its nodes meet them: ``on`` (any colliders), ``colliders`` and
    ``locate``, the ODE core's event location over :func:`ballistic` paths (compile-time parts
    of :func:`finalize`)."""

    def __init__(self, colliders):
        self.on = colliders is not None and colliders.count > 0
        self.colliders = colliders
        self.dtype = colliders.dtype if self.on else ti.f32
        if self.on:
            self.locate = located_step(ballistic(self.dtype), colliders, 12, self.dtype, quadratic=True,
                                       first_apart=True)


@ti.func
def finalize_node(model: ti.template(), state: ti.template(), contacts: ti.template(), x0: ti.template(),
                  v0: ti.template(), bad_t: ti.template(), alpha, t_end, h, log: ti.template(), i):
    """:func:`finalize` of node i (alpha, t_end, h: f64)."""
    X, V = ti.static(state.node_pos, state.node_vel)
    x, v = X[i], V[i]
    if model.node_pinned[i]:
        x = pin_at(model, i, ti.cast(alpha, model.dtype))
    else:
        if ti.static(contacts.on):
            dt = contacts.dtype
            hh = ti.cast(h, dt)
            xs, vs, xa, va = ti.cast(x, dt), ti.cast(v, dt), ti.cast(x0[i], dt), ti.cast(v0[i], dt)
            acc = 2.0 * (hh * vs - (xs - xa)) / (hh * hh)
            u = vs - hh * acc
            y0 = ti.Vector([xa[0], xa[1], xa[2], acc[0], acc[1], acc[2], u[0], u[1], u[2], 0.0, 0.0, 0.0], dt=dt)
            y, _err, count, which, lag, xh, nh, speed, _dv, _stop = contacts.locate(
                y0, ti.cast(t_end - h, dt), hh, i, 1.0, 1.0, 0.0)
            if count > 0:  # an impact located on the path: the node as the events left it
                xs, vs = ti.Vector([y[0], y[1], y[2]]), ti.Vector([y[6], y[7], y[8]])
            else:  # none: contacts held on the node's own end state (not the path's velocity)
                xs, vs, hits, _killed, which, nh, speed = contacts.colliders.project(xs, vs, xa, va, hh)
                xh, lag = xs, 0.0
            if which >= 0:
                x = ti.cast(xs, model.dtype)
                v = ti.cast(vs, model.dtype)
                if ti.static(log.enabled):
                    log.record(i, which, xh, ti.cast(nh, ti.f32), ti.cast(speed, ti.f32), t_end - lag, 0)
    if not is_finite(x.sum() + v.sum()):
        ti.atomic_min(bad_t[None], t_end)
    X[i] = x
    V[i] = v


@ti.kernel
def finalize(model: ti.template(), state: ti.template(), contacts: ti.template(), x0: ti.template(),
             v0: ti.template(), bad_t: ti.template(), alpha: ti.f64, t_end: ti.f64, h: ti.f64,
             log: ti.template()):
    """Pins, located impacts and held contacts of every node after a step of h ending at t_end
    that started from (``x0``, ``v0``). ``log``: an :class:`engine.contacts.ContactBuffer`
    (recording compiled in only when it is enabled): the step's fastest impact of each node, at
    its located time and position (a held contact's at the step's end)."""
    for i in range(model.node_count):
        finalize_node(model, state, contacts, x0, v0, bad_t, alpha, t_end, h, log, i)


@ti.func
def write_moves(model: ti.template(), moves: ti.template(), n_moves):
    """Pin targets from ``moves``: (≥ n_moves, 4) f64 rows (node, x, y, z) naming distinct nodes
    (a dict's keys: SpringSystem._move_rows), so the rows may be written in any order."""
    for m in range(n_moves):
        node = ti.cast(moves[m, 0], ti.i32)
        for c in ti.static(range(3)):
            model.pin_target[node][c] = ti.cast(moves[m, 1 + c], model.dtype)


@ti.kernel
def pin_moves(model: ti.template(), moves: ti.types.ndarray(), n_moves: ti.i32):
    """The pin targets set since the last step, in one launch (not one field write per component:
    a 260-strand hair's pin path wrote 780 a frame, 8.5 ms of Python)."""
    write_moves(model, moves, n_moves)


@ti.kernel
def begin_frame(model: ti.template(), state: ti.template()):
    """Pinned nodes start the frame where they are."""
    for i in range(model.node_count):
        if model.node_pinned[i]:
            model.pin_start[i] = state.node_pos[i]
