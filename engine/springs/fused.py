"""A frame's fixed substeps of a small spring network in one kernel launch (CPU).

Per substep the network needs: pin drive, a copy of the step's start (for locating impacts), the
step itself (an XPBD step — predict, λ = 0, ``iterations`` Gauss–Seidel sweeps of every colour,
velocity update —, a splitting scheme's gather-accelerations and kick–drifts, or an explicit
Runge–Kutta tableau's stages: each a per-node linear combination, then a gather) and the finalize
(pins snapped, impacts located, contacts held). Launched one by one that is 4–16 launches a
substep, each of 1–12 offloaded tasks; on the CPU backend every launch costs tens of µs of Python
and every task a thread-pool wake-up, which for a 28 × 28 cloth or a 31-node chain is far more
than the arithmetic (cloth on `energy`: 7.2 ms a frame in 144 colour tasks of ~370 springs).

So here one launch runs the whole frame as ONE serial task: an outer loop over the substeps with
``ti.loop_config(serialize=True)``, every phase an inner loop over nodes or springs in index
order. No grid-wide sync is needed (one thread), and the results are bit-identical to the
launch-by-launch path: each per-node phase computes every node independently (a gather, no
reductions), and an XPBD colour's springs share no node, so sweeping all springs in colour order
(:func:`~engine.xpbd.constraints.sweep_serial`) is the parallel per-colour sweep exactly. No float
atomics: the result is the same for any thread count. The per-substep times (α of the pins' lerp,
t_end) are computed on the host in f64 exactly as the stepped path does and passed as one small
ndarray (no field write, no extra launch). (Against a moving collider the two paths agree to
rounding, not bit for bit: the same arithmetic compiled into two kernels contracts differently;
hair's strands parted by 7e-8 m after 37 frames. So do energy terms' forces and projections, and
an explicit method's located impacts on a sphere: in f64 ~1e-12 m at first, which a chaotic
drape, such as a cloth sliding off a ball, grows to ~1e-4 m in 20 frames. Each path alone is deterministic, and which one
runs depends on the scene, never on the thread count.)

Used only when nothing needs the host between substeps (:meth:`SpringSystem._fusable`): CPU
backend, fixed steps, no stretch limits, colliders that do not turn (moving ones are placed from a
table of their poses over the substeps, computed on the host as it would place them), no rigid
bodies' shapes, energy terms of the built-in kinds only (engine.forces.elements: their XPBD sweep
or their forces run serially here too; a user energy's autodiff kernels do not), the springs
accumulated by gather, and at most :data:`MAX_NODES` nodes (beyond that two threads per phase beat
one; the GPU keeps the launch-by-launch path, whose colour loops are parallel).
"""
import taichi as ti

from ..forces.elements import element_force, node_force
from ..launch import fast
from ..forces.elements import sweep_serial as sweep_elements
from ..ode.staged import kick_drift_node, rk_stage_node
from ..xpbd.constraints import sweep_serial
from ..xpbd.solver import predict_node
from .constraints import drive_node, finalize_node, write_moves
from .forces import gather_node

# Above this a serial frame loses to the 2-thread per-phase launches: the bench's 128 × 128 cloth
# (16,384 nodes, 97,026 springs) measured XPBD 41-46 ms fused vs 33 ms launched, symplectic Euler
# 187-233 vs 155 ms (load ~10 on 2 cores). Break-even estimate from those: a colour task's ~40 µs
# wake-up against ~20 ns a spring saved by the second thread, ~24k springs ≈ 4k nodes of cloth.
MAX_NODES = 4096


@ti.func
def add_elements(elements: ti.template(), X: ti.template(), V: ti.template(), w: ti.template(),
                 A: ti.template(), j):
    """A[j] += each energy term's w_i f_i, term by term (``ElementGroup.add_forces``, serial)."""
    for gi in ti.static(range(len(elements))):
        for e in range(elements[gi].count):
            element_force(elements[gi], X, V, e)
        for i in range(elements[gi].n_nodes):
            node_force(elements[gi], w, A, j, i)


@ti.kernel
def run_steps(model: ti.template(), state: ti.template(), fields: ti.template(), contacts: ti.template(),
              x0: ti.template(), v0: ti.template(), bad_t: ti.template(), log: ti.template(),
              times: ti.types.ndarray(), h: ti.f64, begin: ti.i32, moves: ti.types.ndarray(),
              n_moves: ti.i32, poses: ti.types.ndarray(), n_shapes: ti.i32, xpbd: ti.template(),
              x_prev: ti.template(), lam: ti.template(), iterations: ti.i32, segments: ti.template(),
              A: ti.template(), rows: ti.template(), b: ti.template(), vs: ti.template(), yx: ti.template(),
              yv: ti.template(), elements: ti.template()) -> ti.f64:
    """``moves``: (≥ n_moves, 4) f64 rows (node, x, y, z): pin targets set since the last step
    (a pin path's per-frame move), written here instead of one field write per component.
    ``poses``: (k, ≥ n_shapes, 6) rows (position, velocity) of the moving colliders' first
    ``n_shapes`` shapes over each substep (Colliders.poses_over), written before its finalize as
    the host's ``follow`` would (0: the colliders stay).
    Returns the divergence flag (bad_t) after the run, so the driver needs no read-back launch.
    ``times``: (k, 2) f64, (α, t_end) of each of the k substeps of h to run. ``begin``: 1 at a
    frame's first substep (pinned nodes' pin_start = where they are, as ``begin_frame``).
    ``xpbd``: an XPBD step (``x_prev``, ``lam``, ``iterations``); else a Runge–Kutta tableau's
    ``rows`` and ``b`` when ``rows`` is not empty (stage buffers ``vs``, ``yx``, ``yv``), or the
    splitting scheme's ``segments`` ((slot, kick, drifts)), as FieldStepper, over its accelerations ``A``.
    ``elements``: the body's energy terms (a tuple of :class:`~engine.forces.elements.ElementGroup`),
    in the launched path's order: XPBD groups after the springs, forces after the springs' gather."""
    X, V, w = ti.static(state.node_pos, state.node_vel, model.node_inv_mass)
    n = ti.static(model.node_count)
    g = ti.cast(fields.gravity[None], model.dtype)  # fields: engine.forces.fields.PointForces
    hh = ti.cast(h, model.dtype)
    write_moves(model, moves, n_moves)
    ti.loop_config(serialize=True)
    for k in range(times.shape[0]):
        alpha, t_end = times[k, 0], times[k, 1]
        if begin and k == 0:
            for i in range(n):
                if model.node_pinned[i]:
                    model.pin_start[i] = X[i]
        for i in range(n):
            drive_node(model, state, alpha, h, i)
        if ti.static(contacts.on):
            for i in range(n):
                x0[i] = X[i]
                v0[i] = V[i]
        if ti.static(xpbd):
            for i in range(n):
                predict_node(X, V, w, x_prev, hh, fields, g, i)
            for s in range(model.spring_count):
                lam[s] = 0
            for gi in ti.static(range(len(elements))):
                for e in range(elements[gi].count):
                    elements[gi].mult[e] = 0
            for _ in range(iterations):
                sweep_serial(model, X, x_prev, w, lam, hh)
                for gi in ti.static(range(len(elements))):
                    sweep_elements(elements[gi], X, w, hh)
            for i in range(n):
                V[i] = (X[i] - x_prev[i]) / hh
        elif ti.static(len(rows)):  # explicit RK: stage j from the stages before it (FieldStepper.step)
            for i in range(n):
                A[0, i] = gather_node(model, fields, g, X, V, i)
            add_elements(elements, X, V, w, A, 0)
            for j in ti.static(range(1, len(rows))):
                for i in range(n):
                    rk_stage_node(X, V, A, vs, yx, yv, i, hh, rows[j], False)
                for i in range(n):
                    A[j, i] = gather_node(model, fields, g, yx, yv, i)
                add_elements(elements, yx, yv, w, A, j)
            for i in range(n):
                rk_stage_node(X, V, A, vs, yx, yv, i, hh, b, True)
        else:
            for seg in ti.static(range(len(segments))):
                slot, kick, drifts = ti.static(segments[seg][0], segments[seg][1], segments[seg][2])
                for i in range(n):
                    A[slot, i] = gather_node(model, fields, g, X, V, i)
                add_elements(elements, X, V, w, A, slot)
                for i in range(n):
                    kick_drift_node(X, V, A, i, hh, slot, kick, drifts)
        if ti.static(contacts.on):
            for c in range(n_shapes):
                for d in ti.static(range(3)):
                    contacts.colliders.collider_point[c][d] = poses[k, c, d]
                    contacts.colliders.collider_vel[c][d] = poses[k, c, 3 + d]
        for i in range(n):
            finalize_node(model, state, contacts, x0, v0, bad_t, alpha, t_end, h, log, i)
    return bad_t[None]


run_steps = fast(run_steps)  # (engine.launch: without Taichi's per-call Python)
