"""Soft bodies in a scene: config → topology → :class:`~engine.springs.SpringSystem`, each a system
of the scene (:mod:`engine.system`)."""
from __future__ import annotations

import math

import numpy as np

from .collider_view import ColliderView
from .colliders import Colliders
from .forces.terms import lame
from .paths import Path, sample_path
from .springs import SpringSystem, Topology, chain, cloth, hair, jelly, line_roots, scalp_roots, solid
from .springs.topology import STRUCTURAL, hinges
from .system import SystemBase


def _term(b, kind):
    return next((t for t in (b.energies or []) if t.type == kind), None)


def build_topology(b):
    """The node network a config Body describes: its springs (none when ``energies`` lists no
    ``spring``; a ``spring`` term's stiffness replaces ``stiffness``), triangles and tetrahedra."""
    if b.type == "solid":
        return solid(*b.resolution, size=b.size, origin=b.position, density=b.density,
                     pinned=b.pins if isinstance(b.pins, list) else [])
    top = _spring_topology(b)
    if b.energies is not None and _term(b, "spring") is None:
        top = Topology(top.positions, top.masses, np.zeros((0, 2), np.int32), np.zeros(0), np.zeros(0),
                       np.zeros(0), np.zeros(0, np.int8), top.pinned, top.triangles, top.tets)
    return top


def element_specs(b, top) -> list:
    """The energy terms of a config Body besides its springs, as ElementGroup arguments
    (engine.forces.elements): the solid's material, then ``energies`` in order."""
    out = []
    if b.type == "solid":
        m = b.material
        out.append(dict(kind="elastic", nodes=top.tets, material=(m.model, *lame(m.young, m.poisson)),
                        damping=b.damping, name=m.model))
    nodes = {"bending": lambda: hinges(top.triangles), "area": lambda: top.triangles, "volume": lambda: top.tets}
    for t in b.energies or []:
        if t.type != "spring":
            out.append(dict(kind=t.type, nodes=nodes[t.type](), stiffness=t.stiffness, name=t.type))
    return out


def _spring_topology(b):
    spring = _term(b, "spring")
    kw = dict(mass=b.mass, ks=b.stiffness if spring is None else spring.stiffness, kd=b.damping)
    if b.type == "chain":
        bend = {} if b.bend_stiffness is None else dict(bend_ks=b.bend_stiffness, bend_kd=b.damping)
        return chain(b.segments + 1, start=b.position, length=b.length, direction=b.direction,
                     pin_start=b.pins != "none", **kw, **bend)
    if b.type == "hair":
        if b.roots == "scalp":
            roots, normals = scalp_roots(b.position, b.radius, b.strands, math.radians(b.cap_angle))
        else:
            roots, normals = line_roots(b.position, b.line_end, b.strands), b.direction
        bend = 0.1 * b.stiffness if b.bend_stiffness is None else b.bend_stiffness
        return hair(roots, normals, length=b.length, segments=b.segments, bend_ks=bend,
                    bend_kd=b.damping, **kw)
    if b.type == "cloth":
        pin = b.pins if isinstance(b.pins, list) else {"start": "none"}.get(b.pins, b.pins)
        return cloth(b.resolution[0], b.resolution[1], size=b.size, origin=b.position, plane=b.plane,
                     bend_ks=b.bend_stiffness, pin=pin, **kw)
    pinned = b.pins if isinstance(b.pins, list) else []
    return jelly(*b.resolution, size=b.size, origin=b.position, pinned=pinned, **kw)


class SoftBody(SystemBase):
    """One soft body of a scene: its spring system, the scene's shape table seen through its
    thickness (a :class:`~engine.collider_view.ColliderView`: an offset, not a copy) and what the
    renderer draws."""

    def __init__(self, cfg, colliders, control, default_integrator, index: int = 0, contacts: int = 0,
                 forces=None):
        """``colliders``: the scene's shape table (:class:`~engine.colliders.Colliders`; a list of
        :class:`~engine.colliders.ColliderSpec` builds one of its own). ``contacts``: node–shape
        records kept between drains when the body's config asks (``contacts = true``).
        ``forces``: the scene's ``[forces]`` config (drag and wind reach the nodes; None: gravity
        only)."""
        self.cfg, self.index = cfg, index
        self.name = cfg.name or f"soft_bodies[{index}]"
        self._pin_path = Path((k.time, k.position) for k in cfg.pin_path or ())  # sampled each step
        self.topology = build_topology(cfg)
        n = self.topology.node_count
        bad = [p for p in (cfg.pins if isinstance(cfg.pins, list) else []) if p >= n]
        if bad:
            raise ValueError(f"pins: node {bad[0]} does not exist (the body has {n} nodes)")
        # nodes keep `thickness` from every surface: flat triangles between nodes resting on a
        # sphere would otherwise cut into it (a chord lies inside the circle)
        if colliders is not None and not isinstance(colliders, Colliders):
            colliders = Colliders(list(colliders)) if len(colliders) else None
        self.colliders = ColliderView(colliders, cfg.thickness) if colliders is not None and colliders.count else None
        integrator = cfg.integrator or default_integrator
        self.system = SpringSystem(self.topology, colliders=self.colliders, control=control,
                                   integrator=integrator, substeps=cfg.substeps,
                                   xpbd_iterations=cfg.iterations, max_stretch=cfg.max_stretch,
                                   name=f"bodies[{index}] ({cfg.type})",
                                   contacts=contacts if cfg.contacts else 0,
                                   drag=forces.drag if forces is not None else 0.0,
                                   attractors=forces.attractors if forces is not None else (),
                                   vortices=forces.vortices if forces is not None else (),
                                   self_collision=cfg.thickness if cfg.self_collision else 0.0,
                                   elements=element_specs(cfg, self.topology))
        self.control = control
        self.pinned = np.array(self.topology.pinned, np.int64)
        self.pin_home = self.topology.positions[self.pinned].copy() if len(self.pinned) else None
        self.released = False
        self.triangles = self.topology.triangles if cfg.type in ("cloth", "jelly", "solid") else np.zeros((0, 3), np.int32)
        self.lines = (self.system.lines((STRUCTURAL,)) if cfg.type in ("chain", "hair")
                      else np.zeros((0, 2), np.int32))

    kind = "soft_body"

    def advance(self, t0: float, t1: float) -> None:
        """Step from t0 to exactly t1 (the System protocol)."""
        self.step(t0, t1 - t0)

    @property
    def stats(self):
        """This body's own step counts (:class:`~engine.ode.driver.DriverStats`)."""
        return self.system.driver.stats

    def drawables(self) -> dict:
        # ``position_field``: the nodes' own field, which the renderer's mesh pass reads in its
        # launch (engine.render.mesh) instead of a to_numpy and a from_numpy a frame
        return dict(kind="mesh", positions=self.positions, triangles=self.triangles, lines=self.lines,
                    color=self.cfg.color, position_field=self.system.state.node_pos)

    def energy(self) -> dict:
        return self.system.energy()

    @property
    def node_count(self) -> int:
        return self.topology.node_count

    def add_energy(self, energy, nodes, params=None, name: str = "user") -> None:
        """Attach a user energy (engine.forces.user.UserEnergy) over (E, k) ``nodes``."""
        from .forces.user import UserEnergy

        self.system.add_elements(UserEnergy(energy, nodes, self.node_count, params, dtype=self.system.dtype,
                                            name=name))

    def contacts(self, names=(), shapes=()):
        """Node contacts since the last call (:class:`~engine.contacts.Contacts`; each row names
        this body and the shape); ``names``, ``shapes``: the shape table's (default: this body's
        table's)."""
        if not names and not shapes and self.colliders is not None:
            names, shapes = self.colliders.names, self.colliders.parties
        return self.system.contact_log.drain(names, (self.name,), shapes)

    def step(self, t0: float, dt: float) -> None:
        """Advance from t0 by dt: pins follow their path, let go at ``release_at``, then take the
        control's pin requests (pin, move, release from code)."""
        c = self.cfg
        if c.release_at is not None and not self.released and t0 + dt > c.release_at:
            for node in self.pinned:
                self.system.release(int(node))
            self.released = True
        if c.pin_path and not self.released and len(self.pinned):
            offset = sample_path(self._pin_path, t0 + dt, (0, 0, 0)) \
                - np.asarray(c.pin_path[0].position, np.float64)
            self.system.set_pin_targets(self.pinned, self.pin_home + offset)
        self.system.apply(self.control.take_pins(self.index))
        self.system.step(dt)

    def reset(self) -> None:
        """Back to the rest state at t = 0, pins as configured (a reused scene)."""
        self.system.reset()
        self.released = False

    def use_control(self, control) -> None:
        """Take inputs from ``control`` (the scene's rebuilt one, sharing the gravity field)."""
        self.control = self.system.control = control

    def positions(self) -> np.ndarray:
        return self.system.positions()


Body = SoftBody  # the name before soft bodies had their own (kept for callers)
