"""A scene: particles, soft bodies and colliders built once from a validated config, stepped frame
by frame, rendered off-screen.

Model (fixed: pool layout, emitter, body and collider parameters), State (particle and node
fields, emitter clocks) and Control (this step's emitter and collider positions, gravity, wind)
are kept apart. A part the config does not use is not built: a soft-body scene has no particle
pool or splat kernel; a spark scene has no spring kernels.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import runtime
from .colliders import ColliderSpec, Colliders
from .particles.system import DivergenceError, ParticleSystem
from .render.camera import Camera

__all__ = ["Scene", "DivergenceError", "Stats", "collider_specs"]


@dataclass
class Stats:
    steps: int = 0
    rejected: int = 0
    frames: int = 0
    peak_alive: int = 0
    alive: int = 0
    h_min: float = math.inf
    h_max: float = 0.0


def collider_specs(cfg_colliders):
    out = []
    for c in cfg_colliders:
        common = dict(restitution=c.restitution, friction=c.friction, kill=c.kill, name=c.name,
                      path=[(k.time, k.position) for k in c.path], visible=c.visible)
        if c.type == "plane":
            out.append(ColliderSpec("plane", point=c.point, normal=c.normal, **common))
        else:
            out.append(ColliderSpec("sphere", point=c.center, radius=c.radius, **common))
    return out


class Scene:
    """Everything one config needs, built once. ``advance_frame()`` steps to the next frame time;
    ``render()`` draws the current state."""

    def __init__(self, cfg, *, width=None, height=None, render=True, contacts: int = 0, bodies=None):
        """``contacts``: record up to this many particle–collider contacts per step batch (0: the
        contact code is not compiled). ``bodies``: already-built Body objects to reuse by index
        (a rebuilt scene keeps its soft bodies without recompiling them)."""
        runtime.ensure_init()
        self.cfg = cfg
        self.t = 0.0
        self.frame = 0
        self.frame_dt = 1.0 / cfg.fps
        self.stats = Stats()
        specs = collider_specs(cfg.colliders)
        self.colliders = Colliders(specs)
        self.particles = (ParticleSystem(cfg, self.colliders, self.stats, contacts)
                          if cfg.emitters else None)
        self.bodies = []
        if cfg.bodies:
            from .bodies import Body

            reuse = list(bodies or [])
            for k, b in enumerate(cfg.bodies):
                self.bodies.append(reuse[k] if k < len(reuse) and reuse[k] is not None
                                   else Body(b, specs, cfg.forces.gravity, cfg.solver.integrator))
        self.camera = Camera(tuple(cfg.camera.position), tuple(cfg.camera.look_at), cfg.camera.fov)
        self.renderer = None
        if render:
            from .render.renderer import Renderer

            p = self.particles
            self.renderer = Renderer(p.state if p else None, cfg.emitters, self.colliders, cfg.render,
                                     bodies=self.bodies)
        self.width = int(width or cfg.render.width)
        self.height = int(height or cfg.render.height)

    # -- stepping -----------------------------------------------------------------------------
    def advance(self, dt: float) -> None:
        """Advance everything by dt seconds (any length), landing exactly on t + dt."""
        if self.particles is not None:
            self.particles.advance(self.t, dt)
        for k, body in enumerate(self.bodies):
            try:
                body.step(self.t, dt)
            except Exception as e:
                from .springs import SimulationDiverged, StiffnessError

                if isinstance(e, (SimulationDiverged, StiffnessError)):
                    raise DivergenceError(f"bodies[{k}] ({body.cfg.type}): {e}") from None
                raise
        self.t += dt

    def advance_frame(self) -> None:
        self.advance((self.frame + 1) * self.frame_dt - self.t)
        self.frame += 1
        self.stats.frames += 1
        if self.particles is not None:
            alive = self.particles.count_alive()
            self.stats.alive = alive
            self.stats.peak_alive = max(self.stats.peak_alive, alive)

    def render(self, width=None, height=None, camera=None, show_colliders=None, *, out=None,
               transparent=False, bgra=False) -> np.ndarray:
        """(H, W, 4) uint8 RGBA image of the current state (into ``out`` if given); any size and
        camera, compiled once (engine.render.renderer)."""
        if self.renderer is None:
            raise RuntimeError("render: this scene was built with render=False")
        return self.renderer.render(camera or self.camera, width or self.width, height or self.height,
                                    out=out, show_colliders=show_colliders, transparent=transparent,
                                    bgra=bgra)

    # -- read-back ----------------------------------------------------------------------------
    @property
    def capacity(self) -> int:
        return self.particles.layout.capacity if self.particles else 0

    def alive_mask(self) -> np.ndarray:
        if self.particles is None:
            return np.zeros(0, bool)
        S = self.particles.state
        return (S.particle_alive.to_numpy()[: self.capacity] != 0) & (S.particle_age.to_numpy()[: self.capacity] >= 0)

    def positions(self) -> np.ndarray:
        """(N, 3) float32 positions of live particles, in pool order."""
        if self.particles is None:
            return np.zeros((0, 3), np.float32)
        return self.particles.state.particle_pos.to_numpy()[: self.capacity][self.alive_mask()]

    def velocities(self) -> np.ndarray:
        if self.particles is None:
            return np.zeros((0, 3), np.float32)
        return self.particles.state.particle_vel.to_numpy()[: self.capacity][self.alive_mask()]

    def dropped(self) -> int:
        return self.particles.dropped() if self.particles else 0
