"""Explicit integrators for coupled spring networks, stage by stage.

Forces couple nodes, so an RK stage needs every node's stage state before any derivative: the
tableau (engine.ode.tableau.TABLEAUS) is driven from Python, one generic routine for all of them:

    A_0 = a(x, v);  for j ≥ 1:  X_j = x + h Σ_m a_jm V_m,  V_j = v + h Σ_m a_jm A_m,  A_j = a(X_j, V_j)
    x⁺ = x + h Σ_j b_j V_j,  v⁺ = v + h Σ_j b_j A_j        (V_0 = v)

The coefficients live in small fields filled from the exact fractions (rounded once to the dtype).
Symplectic Euler (v⁺ = v + h a(x, v); x⁺ = x + h v⁺) and velocity Verlet (kick–drift–kick, the
closing kick uses a(x⁺, v½): order 2 for position-only forces, order 1 with spring damping) are
their own small kernels. Pins are handled outside (see :mod:`.constraints`): a pinned node has
a = 0 and a velocity set so that x + h v lands on its target.
"""
import numpy as np
import taichi as ti

from ..ode.steppers import METHODS
from ..ode.tableau import TABLEAUS
from .model import SpringModel, SpringState

MAX_STAGES = max(t.stages for t in TABLEAUS.values())


class ExplicitStepper:
    """``step(h)`` advances ``state`` by h with ``method`` (any name of engine.ode.steppers.METHODS),
    evaluating accelerations with the given accel kernel (gather or atomic)."""

    def __init__(self, model: SpringModel, state: SpringState, accel, method: str):
        n, dtype, N = model.node_count, model.dtype, max(1, model.node_count)
        self.model, self.state, self.accel = model, state, accel
        S = MAX_STAGES
        self.A = ti.Vector.field(3, dtype, (S, N))  # stage accelerations
        self.Vs = ti.Vector.field(3, dtype, (S, N))  # stage velocities (slot 0 unused: V_0 = v)
        self.Yx = ti.Vector.field(3, dtype, N)
        self.Yv = ti.Vector.field(3, dtype, N)
        self.tab_a = ti.field(dtype, (S, S))
        self.tab_b = ti.field(dtype, S)
        X, V, A, Vs, Yx, Yv, ta, tb = state.node_pos, state.node_vel, self.A, self.Vs, self.Yx, self.Yv, self.tab_a, self.tab_b

        @ti.kernel
        def stage(j: ti.i32, h: dtype):
            for i in range(n):
                dx = V[i] * ta[j, 0]
                dv = A[0, i] * ta[j, 0]
                for m in range(1, j):
                    dx += Vs[m, i] * ta[j, m]
                    dv += A[m, i] * ta[j, m]
                Yx[i] = X[i] + h * dx
                vj = V[i] + h * dv
                Yv[i] = vj
                Vs[j, i] = vj

        @ti.kernel
        def combine(s: ti.i32, h: dtype):
            for i in range(n):
                dx = V[i] * tb[0]
                dv = A[0, i] * tb[0]
                for j in range(1, s):
                    dx += Vs[j, i] * tb[j]
                    dv += A[j, i] * tb[j]
                X[i] += h * dx
                V[i] += h * dv

        @ti.kernel
        def symplectic_update(h: dtype):
            for i in range(n):
                v = V[i] + h * A[0, i]
                V[i] = v
                X[i] += h * v

        @ti.kernel
        def kick_drift(h: dtype):
            for i in range(n):
                v = V[i] + (h / 2) * A[0, i]
                V[i] = v
                X[i] += h * v

        @ti.kernel
        def kick(h: dtype):
            for i in range(n):
                V[i] += (h / 2) * A[0, i]

        self._k = dict(stage=stage, combine=combine, symplectic_update=symplectic_update,
                       kick_drift=kick_drift, kick=kick)
        self.set_method(method)

    def set_method(self, method: str) -> None:
        if method not in METHODS:
            raise ValueError(f"integrator: unknown value {method!r}; allowed: {', '.join(METHODS)}, xpbd")
        self.method = method
        self.order = METHODS[method].order
        if method in TABLEAUS:
            tab = TABLEAUS[method]
            npd = np.float64 if self.model.dtype == ti.f64 else np.float32
            a = np.zeros((MAX_STAGES, MAX_STAGES), npd)
            b = np.zeros(MAX_STAGES, npd)
            for j, row in enumerate(tab.a):
                a[j, : len(row)] = [float(q) for q in row]
            b[: tab.stages] = [float(q) for q in tab.b]
            self.tab_a.from_numpy(a)
            self.tab_b.from_numpy(b)
            self.stages = tab.stages

    def step(self, h: float) -> None:
        X, V, k = self.state.node_pos, self.state.node_vel, self._k
        self.accel(X, V, self.A, 0)
        if self.method == "symplectic_euler":
            k["symplectic_update"](h)
        elif self.method == "verlet":
            k["kick_drift"](h)
            self.accel(X, V, self.A, 0)
            k["kick"](h)
        else:
            for j in range(1, self.stages):
                k["stage"](j, h)
                self.accel(self.Yx, self.Yv, self.A, j)
            k["combine"](self.stages, h)

    @property
    def fevals(self) -> int:
        return METHODS[self.method].fevals
