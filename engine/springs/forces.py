"""Spring and gravity accelerations over all nodes: a per-node gather (default) or an atomic scatter.

Damped Hooke spring between a and b (NUMERICS.md), L = x_a − x_b, L̇ = v_a − v_b, rest length r:
f_a = −[ks(|L| − r) + kd (L̇·L)/|L|] L/|L|, f_b = −f_a. Nodes with inv_mass 0 (pinned) get no
acceleration, not even gravity.

* gather: each node walks its CSR row and sums ±f of its incident springs in a fixed order — every
  spring is evaluated twice, but there are no atomics and the sums are bit-identical run to run.
* atomic: one pass over springs adding f·w_a to a and −f·w_b to b with float atomics; the
  summation order depends on thread timing, so the last bits may differ between runs.

Both kernels write ``A[j, i]`` (j selects a stage slot) for states held in the template fields X, V.
"""
import taichi as ti

from .model import SpringModel

ACCUMULATORS = ("gather", "atomic")


def make_spring_force(model: SpringModel):
    """``spring_force(X, V, s)``: the force on end a of spring s (end b receives its negative)."""
    sa, sb, rl = model.spring_a, model.spring_b, model.spring_rest_length
    ks, kd, dtype = model.spring_ks, model.spring_kd, model.dtype

    @ti.func
    def spring_force(X, V, s):
        a, b = sa[s], sb[s]
        L = X[a] - X[b]
        ln = L.norm()
        f = ti.Vector.zero(dtype, 3)
        if ln > 1e-12:
            n = L / ln
            f = -(ks[s] * (ln - rl[s]) + kd[s] * (V[a] - V[b]).dot(n)) * n
        return f

    return spring_force


def make_accel_kernels(model: SpringModel):
    """Returns {"gather": kernel, "atomic": kernel}, each ``(X, V, A, j)`` writing A[j, i]."""
    n, m, dtype = model.node_count, model.spring_count, model.dtype
    spring_force = make_spring_force(model)
    off, adj, sign = model.adj_offset, model.adj_spring, model.adj_sign
    inv_mass, grav, sa, sb = model.node_inv_mass, model.gravity, model.spring_a, model.spring_b

    @ti.kernel
    def accel_gather(X: ti.template(), V: ti.template(), A: ti.template(), j: ti.i32):
        g = grav[None]
        for i in range(n):
            f = ti.Vector.zero(dtype, 3)
            for e in range(off[i], off[i + 1]):
                f += sign[e] * spring_force(X, V, adj[e])
            w = inv_mass[i]
            acc = w * f
            if w > 0:
                acc += g
            A[j, i] = acc

    @ti.kernel
    def accel_atomic(X: ti.template(), V: ti.template(), A: ti.template(), j: ti.i32):
        g = grav[None]
        for i in range(n):
            acc = ti.Vector.zero(dtype, 3)
            if inv_mass[i] > 0:
                acc = g
            A[j, i] = acc
        for s in range(m):
            f = spring_force(X, V, s)
            a, b = sa[s], sb[s]
            A[j, a] += inv_mass[a] * f
            A[j, b] -= inv_mass[b] * f

    return {"gather": accel_gather, "atomic": accel_atomic}
