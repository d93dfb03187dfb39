"""A scene: particles, soft bodies and colliders built once from a validated config, stepped frame
by frame, rendered off-screen.

Model (fixed: pool layout, emitter, body and collider parameters), State (particle and node
fields, emitter clocks) and Control (this frame's inputs: emitter and collider positions, rates,
bursts, pins, gravity, wind — :class:`~engine.control.Control`, what the game API writes) are kept
apart. A part the config does not use is not built: a soft-body scene has no particle pool or
splat kernel; a spark scene has no spring kernels. A failure raises the ODE core's
:class:`~engine.ode.driver.SimulationDiverged` (integrator, h and time in its message).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import runtime
from ..colliders import ColliderSpec, Colliders
from ..control import Control
from ..fieldio import WriterGroup
from ..ode.driver import DriverStats, SimulationDiverged
from ..particles.system import ParticleSystem
from ..paths import Path
from ..render.camera import Camera
from .coupler import Coupler

DivergenceError = SimulationDiverged  # the name the command line catches (exit 3): the same class
__all__ = ["Scene", "SimulationDiverged", "DivergenceError", "Stats", "collider_specs"]


@dataclass
class Stats(DriverStats):
    """The particle driver's counts (steps, rejected, h range) and per-frame figures: ``alive``
    (live particles after the last frame) and its peak."""

    frames: int = 0
    peak_alive: int = 0
    alive: int = 0


def collider_specs(cfg_colliders):
    out = []
    for c in cfg_colliders:
        common = dict(restitution=c.restitution, friction=c.friction, kill=c.kill, name=c.name,
                      path=Path((k.time, k.position) for k in c.path), visible=c.visible,
                      angular_velocity=tuple(c.angular_velocity), rotates=c.rotates)
        if c.type == "plane":
            out.append(ColliderSpec("plane", point=c.point, normal=c.normal, **common))
        elif c.type == "sphere":
            out.append(ColliderSpec("sphere", point=c.center, radius=c.radius, **common))
        elif c.type == "box":
            out.append(ColliderSpec("box", point=c.center, half_extents=tuple(c.half_extents),
                                    orientation=tuple(c.orientation), **common))
        else:
            out.append(ColliderSpec("capsule", point=c.center, radius=c.radius, half_length=c.half_length,
                                    orientation=tuple(c.orientation), **common))
    return out


def rigid_shape_specs(cfg):
    """The rigid bodies' shapes in the one shape table (after the config's colliders), named after
    the body, ``owner`` "rigid", not drawn (the body is); RigidSystem.publish moves each to its
    body's pose at every coupling step, so particles and spring nodes meet it where it is. Spheres
    first, as located events (their contact is the same at any orientation; ω × r friction from a
    spinning ball is left out); then boxes and capsules, turning with their bodies (v + ω × r at
    the contact) as the table's projected shapes: one run-time loop over them, not a located
    event each (ten spinning crates unrolled into the particles' step compiled for over three
    minutes; engine.colliders). None in a scene with no particles and no soft bodies to meet
    them: a rigid-only scene pays nothing for the table (10,000 free bodies posted their poses
    into it at 65 ms a step)."""
    if not (cfg.emitters or cfg.bodies):
        return []
    spheres = [ColliderSpec("sphere", point=b.position, radius=b.radius, restitution=b.restitution,
                            friction=b.friction, name=b.name, visible=False, owner="rigid", owner_index=i)
               for i, b in enumerate(cfg.rigid_bodies) if b.shape == "sphere"]
    solids = [ColliderSpec(b.shape, point=b.position, radius=b.radius or 0.0,
                           half_extents=tuple(b.half_extents or (0.0, 0.0, 0.0)), half_length=b.half_length or 0.0,
                           orientation=tuple(b.orientation), rotates=True, restitution=b.restitution,
                           friction=b.friction, name=b.name, visible=False, owner="rigid", owner_index=i)
              for i, b in enumerate(cfg.rigid_bodies) if b.shape in ("box", "capsule")]
    return spheres + solids


class Scene:
    """Everything one config needs, built once. ``advance_frame()`` steps to the next frame time;
    ``render()`` draws the current state."""

    def __init__(self, cfg, *, width=None, height=None, render=True, contacts: int = 0, previous=None,
                 interpolate: bool = False, spare=(0, 0)):
        """``contacts``: keep up to this many particle–collider contact records between drains
        (0: the contact code is not compiled), and as many node contacts for each body whose
        config asks for them. ``interpolate``: keep the particles' positions before each game
        step (:meth:`save_positions`) so ``render(alpha=)`` can draw between the last two steps.
        ``spare``: (emitter rows, pool slots) beyond the config's, for :meth:`add_emitters`.
        ``previous``: the scene this one replaces (a rebuild
        between frames): its time, statistics, inputs and live particles carry over by name, and
        its soft bodies whose config did not change are kept without recompiling them."""
        runtime.ensure_init("Scene")
        self.cfg = self._built = cfg
        self.t = 0.0
        self.frame = 0
        self.frame_dt = 1.0 / cfg.fps
        self.stats = Stats()
        specs = collider_specs(cfg.colliders)
        every = specs + rigid_shape_specs(cfg)  # the scene's shapes, then the rigid bodies' own
        same_colliders = (previous is not None and previous.cfg.colliders == cfg.colliders
                          and rigid_shape_specs(previous.cfg) == rigid_shape_specs(cfg))
        # the one shape table: particles read it, soft bodies through their thickness (a kept
        # body's kernels were compiled against the previous scene's table, so an unchanged
        # table is kept with them); rigid bodies publish their poses into it (RigidSystem.publish)
        # the shapes' fixed numbers and the particles' parameters: one kernel writes both, in one
        # launch as the block ends (engine.fieldio; nothing inside reads them first)
        writes = WriterGroup()
        with writes.held():
            self.colliders = previous.colliders if same_colliders else Colliders(every, writes=writes)
            if previous is None:
                self.control = Control.for_scene(cfg, every)
            else:
                self.control = previous.control.rebuilt(cfg, every)
                self.t, self.frame, self.stats = previous.t, previous.frame, previous.stats
            self.particles = (ParticleSystem(cfg, self.colliders, self.control, self.stats, contacts, interpolate,
                                             spare, writes) if cfg.emitters else None)
        if previous is not None and previous.particles is not None and self.particles is not None:
            self.particles.carry_from(previous.particles)
        self.bodies = []
        if cfg.bodies:
            from ..bodies import SoftBody

            f0, f1 = (previous.cfg.forces if previous is not None else None), cfg.forces
            same_drag = f0 is not None and (f0.drag, f0.attractors, f0.vortices) == (f1.drag, f1.attractors,
                                                                                 f1.vortices)  # compiled in
            keep = {b.cfg.name: b for b in (previous.bodies if same_colliders and same_drag else []) if b.cfg.name}
            for k, b in enumerate(cfg.bodies):
                old = keep.get(b.name) if b.name else None
                if old is not None and old.cfg == b and old.index == k:  # kept, compiled kernels and all
                    old.use_control(self.control)
                    self.bodies.append(old)
                else:
                    self.bodies.append(SoftBody(b, self.colliders, self.control, cfg.solver.integrator, k, contacts,
                                               cfg.forces))
        self.rigid = None
        if cfg.rigid_bodies:
            from ..rigid import RigidSystem

            self.rigid = RigidSystem(cfg, specs, self.control,
                                     shape_index={s.owner_index: k for k, s in enumerate(every) if s.owner == "rigid"})
            if previous is not None and previous.rigid is not None:
                self.rigid.carry_from(previous.rigid)
        self.coupler = Coupler(([self.particles] if self.particles is not None else []) + self.bodies
                               + ([self.rigid] if self.rigid is not None else []))
        self.camera = Camera(tuple(cfg.camera.position), tuple(cfg.camera.look_at), cfg.camera.fov)
        self.renderer = None
        if render:
            from ..render.renderer import Renderer

            p = self.particles
            meshes = self.bodies + ([self.rigid] if self.rigid is not None else [])
            self.renderer = Renderer(p.state if p else None, cfg.emitters, self.colliders, cfg.render,
                                     bodies=meshes, rows=p.emitters.count if p else 0)
        self.width = int(width or cfg.render.width)
        self.height = int(height or cfg.render.height)

    # -- stepping -----------------------------------------------------------------------------
    def advance(self, dt: float) -> None:
        """Advance everything by dt seconds (any length), landing exactly on t + dt."""
        t1 = self.t + dt
        self.coupler.advance(self.t, t1)
        self.t = t1

    def why_not_add(self, cfg):
        """Why the emitters ``cfg`` appends to this scene's config cannot be added in place
        (:meth:`add_emitters`), or None."""
        if self.particles is None:
            return "the scene was built without particles"
        look = self.renderer.look if self.renderer is not None else None
        if look is not None and not look.covers(cfg.emitters):
            return "it needs a blend mode the scene did not compile"
        return self.particles.why_not_add(cfg)

    def add_emitters(self, cfg) -> None:
        """Add the emitters ``cfg`` appends, in place: spare rows and slots, no compile."""
        n = len(self.cfg.emitters)
        self.control.emitters.extend(Control.inputs_for(cfg, ())[0][n:])
        self.particles.add_emitters(cfg)
        if self.renderer is not None:
            self.renderer.look.update(cfg.emitters)
        self.cfg = cfg

    def reset(self) -> None:
        """Back to the state the build left (t = 0, the config's inputs, empty pools, bodies at
        rest, emitters added since removed), keeping every field, compiled kernel and render
        target: a level restart costs launches, not compiles. The same config then gives the
        same bytes as a fresh build."""
        if self.cfg is not self._built:
            self.cfg = self._built
            if self.renderer is not None and self.particles is not None:
                self.renderer.look.update(self._built.emitters)
        self.t, self.frame = 0.0, 0
        self.coupler.clear()  # (impulses published for the next coupling step are dropped)
        self.stats.__dict__.update(Stats().__dict__)  # (the drivers hold this object)
        self.control.restart(self.cfg, self.colliders.specs)
        self.colliders.reset()
        if self.particles is not None:
            self.particles.reset()
        for body in self.bodies:
            body.reset()
        if self.rigid is not None:
            self.rigid.reset()

    def warm_up(self, sizes=()) -> None:
        """Compile what a game calls: a step with a burst from every emitter and every collider
        moving, the read-backs and contact drains, a render at each (W, H) of ``sizes``; then
        :meth:`reset` (a loading screen pays the compile cost, not the first frames)."""
        ctl = self.control
        for e in range(len(ctl.emitters)):
            ctl.burst(e, 1)
        for k in range(len(ctl.colliders)):
            ctl.move_collider(k, 0.0, self.frame_dt, ctl.collider_positions(0.0)[k])
        self.save_positions()
        self.advance(self.frame_dt)
        self.live_particles()
        self.live_count()
        if self.particles is not None:
            self.particles.warm_steps(self.t, self.cfg.solver.h)
            self.particles.contacts()
            self.particles.emitters.carry_local(0.0, 0.0, compile_only=True)
        for body in self.bodies:
            body.positions()
            body.contacts()
        for w, h in sizes:
            self.render(w, h)  # (refused where the scene was built with render=False)
            self.renderer.warm_levels(self.camera, w, h)
        self.reset()

    def save_positions(self) -> None:
        if self.particles is not None:
            self.particles.save_positions()

    def advance_frame(self) -> None:
        """Step to the next frame time; the live count is read back once per frame."""
        self.advance((self.frame + 1) * self.frame_dt - self.t)
        self.frame += 1
        self.stats.frames += 1
        alive = self.live_count()
        self.stats.alive = alive
        self.stats.peak_alive = max(self.stats.peak_alive, alive)

    def live_count(self) -> int:
        """Live particle slots now (one read-back, cached until the next advance)."""
        return self.particles.count_alive() if self.particles is not None else 0

    def render(self, width=None, height=None, camera=None, show_colliders=None, *, out=None,
               transparent=False, bgra=False, alpha=None) -> np.ndarray:
        """(H, W, 4) uint8 RGBA image of the current state (into ``out`` if given); any size and
        camera, compiled once (engine.render.renderer). ``alpha``: draw particles that far from
        their positions before the last step to their positions now (built with ``interpolate``)."""
        if self.renderer is None:
            raise RuntimeError("render: this scene was built with render=False")
        return self.renderer.render(camera or self.camera, width or self.width, height or self.height,
                                    out=out, show_colliders=show_colliders, transparent=transparent,
                                    bgra=bgra, blend=1.0 if alpha is None else float(alpha))

    # -- read-back ----------------------------------------------------------------------------
    @property
    def systems(self) -> list:
        """The scene's systems in coupling order (engine.system)."""
        return list(self.coupler.systems)

    def emitter_capacity(self, e: int) -> int:
        """Slots of emitter ``e``'s ring in the pool (the most one burst can emit)."""
        return self.particles.ring_size(e) if self.particles is not None else 0

    def energy(self) -> dict:
        """{system name: its named energy terms (J)} for every system that reports any."""
        return {s.name: e for s in self.coupler.systems if (e := s.energy())}

    def system_stats(self) -> dict:
        """{system name: its own step counts}: the particle pool's (``stats``) and each soft
        body's driver statistics."""
        return {s.name: s.stats for s in self.coupler.systems}

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

    def live_particles(self) -> dict:
        """Copies of the live (born) particles' ``position`` (N, 3), ``velocity`` (N, 3), ``age``,
        ``life`` (N,) and ``emitter`` (N,) index, in pool order."""
        if self.particles is None:
            z = np.zeros((0, 3), np.float32)
            return dict(position=z, velocity=z, age=np.zeros(0, np.float32), life=np.zeros(0, np.float32),
                        emitter=np.zeros(0, np.int32))
        S, cap = self.particles.state, self.capacity
        age = S.particle_age.to_numpy()[:cap]
        m = (S.particle_alive.to_numpy()[:cap] != 0) & (age >= 0)
        return dict(position=S.particle_pos.to_numpy()[:cap][m], velocity=S.particle_vel.to_numpy()[:cap][m],
                    age=age[m], life=S.particle_life.to_numpy()[:cap][m],
                    emitter=S.particle_emitter.to_numpy()[:cap][m])

    def dropped(self) -> int:
        return self.particles.dropped() if self.particles else 0

