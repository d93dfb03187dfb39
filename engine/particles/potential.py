"""External potentials on particles: a Python ``ti.func`` U(x, p) (J/kg), a = −∇U by Taichi's
reverse-mode autodiff, applied as half kicks around each particle step (PHYSICS.md,
"Energy-based models"; NUMERICS.md on splitting).

Determinism (as engine.forces.user): the differentiated kernel reads only a per-particle copy
``xe[i]`` of the particle's position, so the adjoint ``xe.grad[i]`` has one writer, particle i's
own thread (Taichi turns the read into an atomic add, but with a single contributor the sum is
exact). The per-particle values ``u[i]`` are not state; the reported total is summed on the host in
f64. Nothing reaches the particle state through a float atomic, so frames are byte-identical
for any thread count.

Time integration — Strang splitting around the particle step S_h (the scene's integrator with
its own forces, collisions and ageing):

    v ← v − (h/2) ∇U(x);   (x, v) ← S_h(x, v);   v ← v − (h/2) ∇U(x)        (kick–S–kick)

The kicks are the exact flow of the potential part (x' = 0, v' = −∇U), so with a symplectic inner
step this is a composition of symplectic maps, and the symmetric composition is second order
(Hairer, Lubich & Wanner, GNI §II.5, Strang splitting). Without other forces the inner step is a
pure drift and the whole is velocity Verlet, which conserves a modified energy: no drift over
long runs. With RK4 or step doubling the potential's part is still second order: the splitting
error O(h³) per step bounds the scheme at order 2 whatever the inner method's order. The
gradient is evaluated twice per step (after the step, and again before the next one: births,
sub-emitters and a changed h sit between them), each a launch of three kernels
(copy, ∇U, kick).

A particle born s seconds into a step (age −s < 0 at the step's start) is integrated from its
birth over h − s: its kicks are (h − s)/2 each, the first at its birth position. A particle that
dies in the step takes no second kick.
"""

import numpy as np
import taichi as ti

from ..forces.user import check_reads
from ..runtime import cfg_optimized
from ..ode.steppers import is_finite

PRE, POST, REPORT = 0, 1, 2  # what gather() selects: the step's first kick, its second, the energy report
MAX_PARAMS = 16  # entries of p (a Taichi vector: compiled into registers)


def check_function(where: str, potential) -> None:
    if not getattr(potential, "_is_taichi_function", False):
        raise ValueError(f"{where}: potential: must be a @ti.func of (x, p) returning U (J/kg), got "
                         f"{type(potential).__name__} {getattr(potential, '__name__', '')}".rstrip())
    check_reads(f"{where}: potential", potential)


def check_params(where: str, params) -> np.ndarray:
    """``params`` as a 1-D float64 array of 1..MAX_PARAMS finite numbers (None: one zero)."""
    if params is None:
        return np.zeros(1)
    if isinstance(params, (str, bytes, dict)):
        raise ValueError(f"{where}: params: {params!r} is not a 1-D sequence of numbers")
    try:
        a = np.asarray(params, np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: params: {params!r} is not a 1-D sequence of numbers") from None
    if a.ndim == 0:
        raise ValueError(f"{where}: params: {params!r} is not a 1-D sequence of numbers (a scalar: "
                         f"give [{a.item()!r}])")
    if a.ndim != 1 or not 1 <= a.size <= MAX_PARAMS:
        raise ValueError(f"{where}: params: shape {a.shape} is not allowed: a 1-D sequence of 1 to "
                         f"{MAX_PARAMS} numbers")
    if not np.isfinite(a).all() or np.abs(a).max() > 3.4e38:
        raise ValueError(f"{where}: params: {a.tolist()!r} is not allowed: every entry must be a finite "
                         f"float32 number")
    return a


@ti.kernel
def _save(v: ti.template(), keep: ti.template(), n: ti.i32):
    for i in range(n):
        keep[i] = v[i]


class ParticlePotential:
    """One potential of a particle system. ``potential``: a ``ti.func`` (x: 3-vector, m; p:
    vector of P) → U (J/kg, f32); ``params``: (P,) floats; ``rows``: (R,) int, 1 where the
    emitter row is acted on; ``state``: the pool (engine.particles.pool.ParticleState);
    ``nonfinite_t``: the integrator's 0-d failure time, which a non-finite gradient also sets.

    Fields (n = max(1, capacity)): ``xe`` (n, 3) f32 copies of the positions (needs_grad), ``u``
    (n,) f32 values, ``kick_dt`` (n,) f32 the current kick's duration (0: not acted on), ``p``
    0-d vector of P, ``rows`` (R,) i32, ``bad_t`` 0-d f32 (earliest failure time, s)."""

    def __init__(self, potential, params, rows, state, nonfinite_t, name: str = "potential"):
        self.name = name
        self.cap = state.capacity
        n, P, R = max(1, self.cap), len(params), len(rows)
        self.p = ti.Vector.field(P, ti.f32, shape=())
        self.rows = ti.field(ti.i32, shape=R)
        self.xe = ti.Vector.field(3, ti.f32, n, needs_grad=True)
        self.u = ti.field(ti.f32, n, needs_grad=True)
        self.kick_dt = ti.field(ti.f32, n)
        self.bad_t = ti.field(ti.f32, shape=())
        self.p[None] = np.asarray(params, np.float32).tolist()
        self.rows.from_numpy(np.asarray(rows, np.int32))
        self.bad_t[None] = 1e30
        self.state, self.nonfinite_t = state, nonfinite_t
        self._build(potential)

    def _build(self, potential):
        g, S, cap = self, self.state, self.cap

        @ti.kernel
        def gather(h: ti.f32, phase: ti.i32):
            """Copy the positions of the particles this kick acts on and their kick durations."""
            for i in range(cap):
                d = 0.0
                if S.particle_alive[i] != 0 and g.rows[S.particle_emitter[i]] != 0:
                    a = S.particle_age[i]
                    if phase == PRE:  # before the step: a < 0 is born −a into it (integrated over h + a)
                        if a >= 0:
                            d = h
                        elif -a < h:
                            d = h + a
                    elif phase == POST:  # after it (ages advanced by h): min(age, h) of it was integrated
                        if a > 0:
                            d = ti.min(a, h)
                    elif a >= 0:  # REPORT: every born particle
                        d = 1.0
                g.kick_dt[i] = d
                g.xe[i] = S.particle_pos[i]
                g.xe.grad[i] = ti.Vector([0.0, 0.0, 0.0])
                g.u.grad[i] = 1.0

        @ti.kernel
        def values():
            """Differentiated: reads xe[i] (its adjoint has one writer) and the constant p."""
            for i in range(cap):
                if g.kick_dt[i] > 0:
                    g.u[i] = potential(g.xe[i], g.p[None])

        @ti.kernel
        def kick(t: ti.f32):
            """v −= (d/2) ∇U for the gathered particles; a non-finite gradient ends the particle
            and records t (the step's failure check then reports this potential by name)."""
            for i in range(cap):
                d = g.kick_dt[i]
                if d > 0:
                    gu = g.xe.grad[i]
                    if is_finite(gu.sum()):  # (a NaN or inf component makes the sum one)
                        S.particle_vel[i] -= (0.5 * d) * gu
                    else:
                        ti.atomic_min(g.bad_t[None], t)
                        ti.atomic_min(g.nonfinite_t[None], t)
                        S.particle_alive[i] = 0

        self._gather, self._values, self._kick = gather, values, kick

    def compile(self) -> None:
        """Compile the kick's kernels now (acting on nobody: ``rows`` zeroed for the launch), so
        a potential Taichi cannot compile is refused when added, not at a later step."""
        rows = self.rows.to_numpy()
        self.rows.fill(0)
        try:
            self._gather(0.0, PRE)
            self._values_grad()
            self._kick(0.0)
        finally:
            self.rows.from_numpy(rows)

    def _values_grad(self) -> None:
        with cfg_optimized():  # (an adjoint compiles right only with Taichi's CFG passes: engine.runtime)
            self._values.grad()

    def half_kick(self, t: float, h: float, phase: int) -> None:
        """v −= (d/2) ∇U(x), d the particle's share of the step of h (``phase`` PRE or POST); t:
        the time the kick happens (s), recorded if a gradient is not finite."""
        self._gather(h, phase)
        self._values_grad()
        self._kick(t)

    def energy(self) -> float:
        """Σ U(x_i) over the born particles it acts on (J/kg: each particle of unit mass)."""
        self._gather(0.0, REPORT)
        self._values()
        # summed on the host in slot order (f64): the same total on any thread count, and no
        # serial kernel (a diagnostic, never part of a frame)
        on = self.kick_dt.to_numpy() > 0
        return float(np.sum(self.u.to_numpy()[on].astype(np.float64)))

    def gradient(self, x) -> np.ndarray:
        """(N, 3) float64 ∇U at the (N, 3) positions ``x`` (N <= capacity), by the kick's own
        kernels: for tests against closed forms."""
        x = np.asarray(x, np.float64).reshape(-1, 3)
        if len(x) > self.cap:
            raise ValueError(f"gradient: x: {len(x)} points, at most the pool's {self.cap}")
        buf = np.zeros((max(1, self.cap), 3), np.float32)
        buf[: len(x)] = x
        self.xe.from_numpy(buf)
        self.xe.grad.fill(0)
        self.u.grad.fill(1)
        d = np.zeros(max(1, self.cap), np.float32)
        d[: len(x)] = 1
        self.kick_dt.from_numpy(d)
        self._values_grad()
        return self.xe.grad.to_numpy()[: len(x)].astype(np.float64)

    def failed_at(self):
        """The earliest time a gradient was not finite since the last call (s), or None."""
        t = float(self.bad_t[None])
        if t >= 1e30:
            return None
        self.bad_t[None] = 1e30
        return t
