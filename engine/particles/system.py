"""The particle half of a scene: pool, emitters, forces and integrator, stepped to frame times.

Built once from a validated config (``finalize`` happens in the constructor: every field is
allocated and every kernel compiled before the first step). Fixed steps divide each interval into
equal substeps that land exactly on its end; adaptive steps are step doubling with the ODE core's
controller, clipped to land exactly on the end without a sliver step.
"""
from __future__ import annotations

import math

from ..ode.controller import StepDoublingController, clip_to_target
from ..ode.steppers import METHODS
from ..runtime import check_stop
from .emitters import Emitters
from .forces import Forces
from .integrate import NO_FAILURE, ParticleIntegrator
from .pool import ParticleState, PoolLayout


class DivergenceError(RuntimeError):
    """The simulation produced a non-finite state; the message names integrator, h and time."""


class ParticleSystem:
    def __init__(self, cfg, colliders, stats, contacts: int = 0):
        self.cfg = cfg
        sol = cfg.solver
        self.method, self.adaptive, self.stats = sol.integrator, sol.adaptive, stats
        self.layout = PoolLayout.for_emitters(cfg.emitters, 1.0 / cfg.fps)
        self.emitters = Emitters(cfg.emitters, self.layout, cfg.seed)
        self.state = ParticleState(self.layout.capacity, self.adaptive, self.emitters.uses_events)
        self.forces = Forces(cfg.forces, cfg.emitters, self.state, self.emitters.emitter_drag)
        self.colliders = colliders
        self.moving_colliders = any(s.path for s in colliders.specs)
        collide = colliders.make_func(report=True) if colliders.count else None
        self.integrator = ParticleIntegrator(self.state, self.forces.make_accel(), collide,
                                             self.method, self.adaptive,
                                             events=self.emitters.uses_events, contacts=contacts)
        self.emitters.build(self.state)
        self.h_last = sol.h
        if self.adaptive:
            self.controller = StepDoublingController(order=METHODS[self.method].order)
            self._h_try = sol.h
            self._atol = sol.atol if sol.atol is not None else sol.tolerance

    def _step_fixed(self, t, h):
        self.emitters.emit(t, h)
        if self.moving_colliders:
            self.colliders.move_to(t + h)
        self.integrator.step_fixed(t, h)
        self.emitters.emit_children()
        self.h_last = h
        self.stats.steps += 1

    def _advance_adaptive(self, t, t_target):
        sol = self.cfg.solver
        steps = 0
        while t < t_target:
            check_stop()
            if steps >= sol.max_steps_per_frame:
                raise DivergenceError(
                    f"integrator {self.method}: more than {sol.max_steps_per_frame} steps in the frame "
                    f"ending t={t_target:.4g} s (h={self._h_try:.3g} s); raise solver.tolerance or "
                    f"solver.max_steps_per_frame")
            h, lands = clip_to_target(t, self._h_try, t_target)
            self.emitters.emit(t, h)  # newborns wait (negative age) if the step is retried shorter
            if self.moving_colliders:
                self.colliders.move_to(t + h)
            err = self.integrator.attempt(t, h, self._atol, sol.tolerance)
            ok, h_new = self.controller.propose(h, err)
            steps += 1
            if not ok:
                self.stats.rejected += 1
                self._h_try = h_new
                if h_new < 1e-9:
                    raise DivergenceError(
                        f"integrator {self.method} diverged at t={t:.4g} s: step size fell to "
                        f"h={h_new:.3g} s (error estimate {err:.3g})")
                continue
            self.integrator.commit(t, h)
            self.emitters.emit_children()
            self.h_last = h
            t = t_target if lands else t + h
            self.stats.steps += 1
            self.stats.h_min = min(self.stats.h_min, h)
            self.stats.h_max = max(self.stats.h_max, h)
            self._h_try = max(h_new, self._h_try) if lands else min(h_new, sol.h * 64)

    def advance(self, t: float, dt: float) -> None:
        """Advance from t by dt seconds (any length), landing exactly on t + dt."""
        t_target = t + dt
        if self.adaptive:
            self._advance_adaptive(t, t_target)
        else:
            n = max(1, math.ceil(dt / self.cfg.solver.h - 1e-9))
            h = dt / n  # equal substeps that land exactly on the target
            for j in range(n):
                check_stop()
                self._step_fixed(t + j * h, h)
            self.stats.h_min = min(self.stats.h_min, h)
            self.stats.h_max = max(self.stats.h_max, h)
        bad = float(self.integrator.nonfinite_t[None])
        if bad < NO_FAILURE:
            raise DivergenceError(
                f"integrator {self.method} diverged: non-finite particle state at t={bad:.4g} s "
                f"with h={self.h_last:.4g} s")

    def count_alive(self) -> int:
        return int(self.integrator.count_alive())

    def dropped(self) -> int:
        return int(self.emitters.dropped_counts().sum())
