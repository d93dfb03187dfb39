"""Spring and gravity accelerations over all nodes: a per-node gather (default) or an atomic scatter.

Damped Hooke spring between a and b (NUMERICS.md), L = x_a − x_b, L̇ = v_a − v_b, rest length r:
f_a = −[ks(|L| − r) + kd (L̇·L)/|L|] L/|L|, f_b = −f_a. Nodes with inv_mass 0 (pinned) get no
acceleration, not even gravity.

* gather: each node walks its CSR row and sums ±f of its incident springs in a fixed order — every
  spring is evaluated twice, but there are no atomics and the sums are bit-identical run to run.
* atomic: one pass over springs adding f·w_a to a and −f·w_b to b with float atomics; the
  summation order depends on thread timing, so the last bits may differ between runs.

Both kernels write ``A[j, i]`` (j selects an evaluation slot of the stepper) for the state held in
the fields X, V; ``fields`` is the scene's :class:`~engine.forces.fields.PointForces` (gravity,
and drag toward the wind when the scene has drag: ``fields.external``, added to free nodes only).
"""
import taichi as ti

from ..forces.fields import PointForces
from ..forces.terms import hooke_energy, hooke_force

ACCUMULATORS = ("gather", "atomic")


@ti.func
def spring_force(model: ti.template(), X: ti.template(), V: ti.template(), s):
    """The force on end a of spring s (end b receives its negative): the Hooke term's
    (engine.forces.terms.hooke_force)."""
    a, b = model.spring_a[s], model.spring_b[s]
    return hooke_force(model.dtype, X[a], X[b], V[a], V[b], model.spring_ks[s], model.spring_kd[s],
                       model.spring_rest_length[s])


@ti.kernel
def spring_energy(model: ti.template(), X: ti.template()) -> ti.f64:
    """Σ ½ ks C² over the springs (J), in f64, summed in spring order (serial: deterministic)."""
    total = ti.cast(0, ti.f64)
    ti.loop_config(serialize=True)
    for s in range(model.spring_count):
        a, b = model.spring_a[s], model.spring_b[s]
        total += hooke_energy(ti.f64, ti.cast(X[a], ti.f64), ti.cast(X[b], ti.f64),
                              ti.cast(model.spring_ks[s], ti.f64),
                              ti.cast(model.spring_rest_length[s], ti.f64))
    return total


@ti.func
def gather_node(model: ti.template(), fields: ti.template(), g, X: ti.template(), V: ti.template(), i):
    """Node i's acceleration: its CSR row's spring forces in row order, times w, plus the point-mass
    fields (gravity g, drag toward the wind, attractors, vortices: engine.forces.fields)."""
    off, adj, sign = ti.static(model.adj_offset, model.adj_spring, model.adj_sign)
    f = ti.Vector.zero(model.dtype, 3)
    for e in range(off[i], off[i + 1]):
        f += sign[e] * spring_force(model, X, V, adj[e])
    w = model.node_inv_mass[i]
    acc = w * f
    if w > 0:
        acc += fields.external(g, X[i], V[i])
    return acc


@ti.kernel
def accel_gather(model: ti.template(), fields: ti.template(), X: ti.template(), V: ti.template(),
                 A: ti.template(), j: ti.i32):
    g = ti.cast(fields.gravity[None], model.dtype)
    for i in range(model.node_count):
        A[j, i] = gather_node(model, fields, g, X, V, i)


@ti.kernel
def accel_atomic(model: ti.template(), fields: ti.template(), X: ti.template(), V: ti.template(),
                 A: ti.template(), j: ti.i32):
    g = ti.cast(fields.gravity[None], model.dtype)
    w = ti.static(model.node_inv_mass)
    for i in range(model.node_count):
        acc = ti.Vector.zero(model.dtype, 3)
        if w[i] > 0:
            acc = fields.external(g, X[i], V[i])
        A[j, i] = acc
    for s in range(model.spring_count):
        f = spring_force(model, X, V, s)
        a, b = model.spring_a[s], model.spring_b[s]
        A[j, a] += w[a] * f
        A[j, b] -= w[b] * f


def accel_launcher(model, fields, accumulate: str = "gather"):
    """``accel(X, V, A, j)`` for the staged steppers (engine.ode.staged); nothing to do for an
    empty network. ``fields``: :class:`~engine.forces.fields.PointForces` (a bare 0-d gravity
    field, as callers passed before force fields reached the nodes, is gravity alone)."""
    if not isinstance(fields, PointForces):
        fields = PointForces(fields, dtype=model.dtype)
    if accumulate not in ACCUMULATORS:
        raise ValueError(f"accumulate: unknown value {accumulate!r}; allowed: {', '.join(ACCUMULATORS)}")
    kernel = accel_gather if accumulate == "gather" else accel_atomic

    def accel(X, V, A, j):
        if model.node_count:
            kernel(model, fields, X, V, A, j)

    return accel
