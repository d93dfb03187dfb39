"""A particle scene: the builder that turns a validated config into fields and kernels once, and
the stepping loop that advances it frame by frame.

Model (fixed: pool layout, emitter and collider parameters), State (particle fields, emitter
clocks) and Control (this step's emitter and collider positions, gravity, wind) are kept apart;
``Scene.build`` allocates every field and compiles every kernel before the first frame, and a
feature the config does not use compiles nothing.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import runtime
from .colliders import ColliderSpec, Colliders
from .ode.controller import StepDoublingController, clip_to_target
from .ode.steppers import METHODS
from .particles.emitters import Emitters
from .particles.forces import Forces
from .particles.integrate import NO_FAILURE, ParticleIntegrator
from .particles.pool import ParticleState, PoolLayout
from .render.camera import Camera


class DivergenceError(RuntimeError):
    """The simulation produced a non-finite state; the message names integrator, h and time."""


@dataclass
class Stats:
    steps: int = 0
    rejected: int = 0
    frames: int = 0
    peak_alive: int = 0
    alive: int = 0
    h_min: float = math.inf
    h_max: float = 0.0
    history: list = field(default_factory=list, repr=False)


def collider_specs(cfg_colliders):
    out = []
    for c in cfg_colliders:
        if c.type == "plane":
            out.append(ColliderSpec("plane", point=c.point, normal=c.normal, restitution=c.restitution,
                                    friction=c.friction, kill=c.kill, name=c.name,
                                    path=[(k.time, k.position) for k in c.path], visible=c.visible))
        else:
            out.append(ColliderSpec("sphere", point=c.center, radius=c.radius, restitution=c.restitution,
                                    friction=c.friction, kill=c.kill, name=c.name,
                                    path=[(k.time, k.position) for k in c.path], visible=c.visible))
    return out


class Scene:
    """Everything one config needs, built once. ``advance_frame()`` steps to the next frame time;
    ``render()`` draws the current state."""

    def __init__(self, cfg, *, width=None, height=None, render=True):
        runtime.ensure_init()
        self.cfg = cfg
        self.t = 0.0
        self.frame = 0
        self.frame_dt = 1.0 / cfg.fps
        sol = cfg.solver
        self.method = sol.integrator
        self.adaptive = sol.adaptive
        self.stats = Stats()
        self._h_last = sol.h
        self.layout = PoolLayout.for_emitters(cfg.emitters, self.frame_dt)
        self.emitters = Emitters(cfg.emitters, self.layout, None, cfg.seed)
        self.state = ParticleState(self.layout.capacity, self.adaptive, self.emitters.uses_events)
        self.emitters.state = self.state
        self.forces = Forces(cfg.forces, cfg.emitters, self.state, self.emitters.emitter_drag)
        self.colliders = Colliders(collider_specs(cfg.colliders))
        self._moving_colliders = any(s.path for s in self.colliders.specs)
        collide = self.colliders.make_func() if self.colliders.count else None
        self.integrator = ParticleIntegrator(self.state, self.forces.make_accel(), collide,
                                             self.method, self.adaptive,
                                             events=self.emitters.uses_events)
        self.emitters.build()
        self.camera = Camera(tuple(cfg.camera.position), tuple(cfg.camera.look_at), cfg.camera.fov)
        self.renderer = None
        if render:
            from .render.raster import Renderer

            self.renderer = Renderer(self.state, cfg.emitters, self.colliders, cfg.render, width, height)
        if self.adaptive:
            self.controller = StepDoublingController(order=METHODS[self.method].order)
            self._h_try = sol.h
            self._atol = sol.atol if sol.atol is not None else sol.tolerance

    # -- stepping -----------------------------------------------------------------------------
    def _substep_fixed(self, h):
        if self._moving_colliders:
            self.colliders.move_to(self.t + h)
        self.integrator.step_fixed(self.t, h)
        self._h_last = h
        self.stats.steps += 1

    def _advance_adaptive(self, t_target):
        sol = self.cfg.solver
        steps = 0
        while self.t < t_target:
            if steps >= sol.max_steps_per_frame:
                raise DivergenceError(
                    f"integrator {self.method}: more than {sol.max_steps_per_frame} steps in the frame "
                    f"ending t={t_target:.4g} s (h={self._h_try:.3g} s); raise solver.tolerance or "
                    f"solver.max_steps_per_frame")
            h, lands = clip_to_target(self.t, self._h_try, t_target)
            self.emitters.emit(self.t, h)  # newborns wait (negative age) if the step shrinks
            if self._moving_colliders:
                self.colliders.move_to(self.t + h)
            err = self.integrator.attempt(self.t, h, self._atol, sol.tolerance)
            ok, h_new = self.controller.propose(h, err)
            steps += 1
            if not ok:
                self.stats.rejected += 1
                self._h_try = h_new
                if h_new < 1e-9:
                    raise DivergenceError(
                        f"integrator {self.method} diverged at t={self.t:.4g} s: step size fell to "
                        f"h={h_new:.3g} s (error estimate {err:.3g})")
                continue
            self.integrator.commit(self.t, h)
            self._h_last = h
            self.emitters.emit_children()
            self.t = t_target if lands else self.t + h
            self.stats.steps += 1
            self.stats.h_min = min(self.stats.h_min, h)
            self.stats.h_max = max(self.stats.h_max, h)
            self._h_try = max(h_new, self._h_try) if lands else min(h_new, sol.h * 64)

    def advance(self, dt: float):
        """Advance by dt seconds (any length), landing exactly on t + dt."""
        t_target = self.t + dt
        if self.adaptive:
            self._advance_adaptive(t_target)
        else:
            n = max(1, math.ceil(dt / self.cfg.solver.h - 1e-9))
            h = dt / n  # equal substeps that land exactly on the target
            for j in range(n):
                self.emitters.emit(self.t, h)
                self._substep_fixed(h)
                self.emitters.emit_children()
                self.t = t_target if j == n - 1 else self.t + h
            self.stats.h_min = min(self.stats.h_min, h)
            self.stats.h_max = max(self.stats.h_max, h)
        self._check_finite()

    def _check_finite(self):
        bad = float(self.integrator.nonfinite_t[None])
        if bad < NO_FAILURE:
            raise DivergenceError(
                f"integrator {self.method} diverged: non-finite particle state at t={bad:.4g} s "
                f"with h={self._h_last:.4g} s")

    def advance_frame(self):
        self.advance((self.frame + 1) * self.frame_dt - self.t)
        self.frame += 1
        self.stats.frames += 1
        alive = int(self.integrator.count_alive())
        self.stats.alive = alive
        self.stats.peak_alive = max(self.stats.peak_alive, alive)

    def render(self) -> np.ndarray:
        return self.renderer.render(self.camera)

    # -- read-back ----------------------------------------------------------------------------
    def alive_mask(self) -> np.ndarray:
        return self.state.particle_alive.to_numpy()[: self.layout.capacity].astype(bool)

    def positions(self) -> np.ndarray:
        """(N, 3) float32 positions of live particles, in pool order."""
        m = self.alive_mask()
        return self.state.particle_pos.to_numpy()[: self.layout.capacity][m]

    def velocities(self) -> np.ndarray:
        m = self.alive_mask()
        return self.state.particle_vel.to_numpy()[: self.layout.capacity][m]

    def dropped(self) -> int:
        return int(self.emitters.dropped_counts().sum())
