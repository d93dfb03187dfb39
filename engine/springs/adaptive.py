"""Step doubling for spring networks: state snapshots and the error norm as small kernels.

One attempt (driven by the system with engine.ode.controller.StepDoublingController): save y0;
y1 = one step of h; restore y0; y2 = two steps of h/2; err = max over nodes and components of
|y2 − y1|/(2^p − 1) / (atol + rtol·max(|y0|, |y2|)), positions and velocities alike. The max is
reduced with ti.atomic_max into a 0-d field: max is order-independent, so the result is
deterministic. A non-finite node makes err = +inf (a rejection).
"""
import taichi as ti

from ..ode.steppers import is_finite
from .model import SpringModel, SpringState


class DoublingBuffers:
    def __init__(self, model: SpringModel, state: SpringState):
        n, dtype, N = model.node_count, model.dtype, max(1, model.node_count)
        self.x0 = ti.Vector.field(3, dtype, N)
        self.v0 = ti.Vector.field(3, dtype, N)
        self.x1 = ti.Vector.field(3, dtype, N)
        self.v1 = ti.Vector.field(3, dtype, N)
        self.err = err = ti.field(dtype, ())
        self.state = state

        @ti.kernel
        def copy(xs: ti.template(), vs: ti.template(), xd: ti.template(), vd: ti.template()):
            for i in range(n):
                xd[i] = xs[i]
                vd[i] = vs[i]

        @ti.kernel
        def error_norm(x0: ti.template(), v0: ti.template(), x1: ti.template(), v1: ti.template(),
                       x2: ti.template(), v2: ti.template(), denom: dtype, atol: dtype, rtol: dtype) -> dtype:
            err[None] = 0
            for i in range(n):
                ex = ti.abs(x2[i] - x1[i]) / denom / (atol + rtol * ti.max(ti.abs(x0[i]), ti.abs(x2[i])))
                ev = ti.abs(v2[i] - v1[i]) / denom / (atol + rtol * ti.max(ti.abs(v0[i]), ti.abs(v2[i])))
                e = ti.max(ex.max(), ev.max())
                if not is_finite(ex.sum() + ev.sum()):
                    e = ti.math.inf
                ti.atomic_max(err[None], e)
            return err[None]

        self._copy, self._err = copy, error_norm

    def save(self):
        s = self.state
        self._copy(s.node_pos, s.node_vel, self.x0, self.v0)

    def restore(self):
        s = self.state
        self._copy(self.x0, self.v0, s.node_pos, s.node_vel)

    def keep_single(self):
        s = self.state
        self._copy(s.node_pos, s.node_vel, self.x1, self.v1)

    def error(self, order: int, atol: float, rtol: float) -> float:
        s = self.state
        return float(self._err(self.x0, self.v0, self.x1, self.v1, s.node_pos, s.node_vel,
                               2 ** order - 1, atol, rtol))
