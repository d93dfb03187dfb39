"""Config models for particle emitters: ``[[emitters]]`` with their bursts, sub-emitters, life
curves and ``interact`` table, and the scene-wide checks of interactions and two-way coupling.
Names follow Godot (``lifetime``, ``lifetime_randomness``, ``spread``) and Unity (``rate``, ``bursts``)."""
from __future__ import annotations

import math
from typing import Annotated, List, Literal, Optional

from pydantic import Field, model_validator

from ..particles.pm import MAX_DIRECT, MAX_MESH
from .base import (ColorStop, Fraction01, Keyframe, Name, NonNeg, Positive, ScalarStop, Strict, Vec3,
                   _check_path, _report)

MAX_STOPS = 8


def _check_curve(stops):
    if stops is None:
        return None
    if not 1 <= len(stops) <= MAX_STOPS:
        return f"needs 1 to {MAX_STOPS} stops, got {len(stops)}"
    ts = [s[0] for s in stops]
    if any(t < 0 or t > 1 for t in ts) or any(b < a for a, b in zip(ts, ts[1:])):
        return f"stop times must lie in [0, 1] and increase, got {ts}"
    return None


class Burst(Strict):
    """``count`` particles at ``time``, repeated ``cycles`` times every ``interval`` seconds."""

    time: NonNeg = 0.0
    count: Annotated[int, Field(ge=1, le=10_000_000)]
    cycles: Annotated[int, Field(ge=1, le=100_000)] = 1
    interval: Positive = 1.0


class SubEmitter(Strict):
    """Spawn ``count`` particles of emitter ``emitter`` where a particle of this one dies or hits a
    collider (with a velocity change of at least ``min_speed`` m/s)."""

    event: Literal["death", "collision"] = "death"
    emitter: Name
    count: Annotated[int, Field(ge=1, le=64)] = 1
    min_speed: NonNeg = 1.0


INTERACT_KINDS = ("granular", "fluid", "gravity", "repel")
MAX_INTERACT_RADIUS = 1.0  # m: a grid cell is 2–4 radii; larger grains belong to rigid bodies
# keys that mean something for one kind only (a key for another kind is refused, naming its kind)
_KIND_KEYS = {"friction": "granular", "cohesion": "granular", "G": "gravity", "softening": "gravity", "method": "gravity",
              "mass": "gravity", "viscosity": "fluid", "vorticity": "fluid", "surface_tension": "fluid"}


class Interact(Strict):
    """Particles of emitters of the same ``kind`` interact with each other (engine.particles.interact).

    granular: grains of ``radius`` (m) in contact at 2·radius, ``friction`` μ (position-based,
    static = kinetic), ``cohesion`` in [0, 1] (fraction of a small gap closed per iteration).
    fluid: position-based fluid at rest spacing 2·radius; ``viscosity`` (XSPH c, a fraction),
    ``vorticity`` (confinement ε, m/s), ``surface_tension`` (cohesion acceleration, m/s²).
    gravity: softened pair attraction, ``G`` (m³/(kg·s²)), ``softening`` ε (m), ``mass`` per particle
    (kg), ``method`` "direct" (every pair, up to MAX_DIRECT slots), "mesh" (particle–mesh,
    engine.particles.pm) or "auto" (direct up to AUTO_DIRECT slots, mesh beyond); ``radius`` is
    unused by gravity but kept for a uniform table. repel: pairs closer
    than 2·radius pushed softly apart. ``iterations``: Jacobi sweeps per step."""

    kind: str
    radius: float
    friction: float = 0.5
    cohesion: float = 0.0
    G: float = 1.0
    softening: float = 0.05
    mass: Annotated[float, Field(gt=0, le=1e30)] = 1.0
    viscosity: Annotated[float, Field(ge=0, le=1)] = 0.02
    vorticity: Annotated[float, Field(ge=0, le=100)] = 0.0
    surface_tension: Annotated[float, Field(ge=0, le=1e3)] = 0.0
    iterations: Annotated[int, Field(ge=1, le=20)] = 4
    method: Literal["auto", "direct", "mesh"] = "auto"  # gravity: every pair, particle–mesh, or by count

    @model_validator(mode="after")
    def _check(self):
        given = self.model_fields_set
        problems = [
            ("kind", f"{self.kind!r} is not a kind of interaction (kinds: {', '.join(INTERACT_KINDS)})"
             if self.kind not in INTERACT_KINDS else None),
            ("radius", f"must be > 0, got {self.radius:g}" if self.radius <= 0 else
             f"{self.radius:g} m is larger than the grid allows ({MAX_INTERACT_RADIUS:g} m)"
             if self.radius > MAX_INTERACT_RADIUS else None),
            ("friction", f"must be >= 0, got {self.friction:g}" if self.friction < 0 else
             "must be <= 10" if self.friction > 10 else None),
            ("cohesion", f"must lie in [0, 1], got {self.cohesion:g}"
             if not 0 <= self.cohesion <= 1 else None),
            ("G", f"must be >= 0, got {self.G:g}" if self.G < 0 else
             "must be <= 1e6" if self.G > 1e6 else None),
            ("softening", f"must be > 0, got {self.softening:g}" if not 0 < self.softening <= 1e3 else None),
        ]
        if self.kind in INTERACT_KINDS:
            for key, kind in _KIND_KEYS.items():
                if key in given and kind != self.kind:
                    problems.append((key, f"applies to kind {kind!r} only, not {self.kind!r}"))
        return _report(self, problems)


class Emitter(Strict):
    name: Name = ""
    effect: Optional[Name] = None  # a preset from effects/ that this emitter starts from
    shape: Literal["point", "sphere", "box", "disc", "cone"] = "point"
    position: Vec3 = [0.0, 0.0, 0.0]
    path: List[Keyframe] = []
    radius: NonNeg = 0.0  # sphere, disc and cone base
    box_size: Vec3 = [1.0, 1.0, 1.0]
    surface: bool = False  # sphere: emit from the surface instead of the volume
    direction: Vec3 = [0.0, 1.0, 0.0]
    spread: Annotated[float, Field(ge=0, le=180)] = 0.0  # half-angle of the emission cone, degrees
    speed: Annotated[List[NonNeg], Field(min_length=2, max_length=2)] = [1.0, 1.0]  # [min, max] m/s
    inherit_velocity: Annotated[float, Field(ge=-10, le=10)] = 0.0
    rate: Annotated[float, Field(ge=0, le=1e8)] = 0.0  # particles per second
    emitting: bool = True  # Godot's name: false = silent until code starts it or calls burst()
    # (such an emitter gets at least 1024 pool slots unless `capacity` says otherwise)
    bursts: List[Burst] = []
    start: NonNeg = 0.0  # emission window, seconds
    stop: Optional[NonNeg] = None
    lifetime: Annotated[float, Field(gt=0, le=1e4)] = 1.0
    lifetime_randomness: Fraction01 = 0.0  # lifetime × (1 − randomness·u), u ∈ [0, 1)
    drag: Optional[NonNeg] = None  # overrides forces.drag for this emitter's particles
    gravity_scale: Annotated[float, Field(ge=-100, le=100)] = 1.0  # 0: neutrally buoyant (smoke)
    buoyancy: Annotated[float, Field(ge=-1e3, le=1e3)] = 0.0  # upward m/s² while hot
    cooling: Positive = 1.0  # buoyancy decays as exp(−age / cooling), seconds
    turbulence: NonNeg = 1.0  # scales forces.turbulence for this emitter's particles
    sub_emitters: Annotated[List[SubEmitter], Field(max_length=4)] = []
    capacity: Optional[Annotated[int, Field(ge=1, le=50_000_000)]] = None
    # look
    blend: Literal["additive", "alpha"] = "additive"
    color: List[ColorStop] = [[0.0, 1.0, 1.0, 1.0]]  # [[t, r, g, b], ...] over life
    alpha: List[ScalarStop] = [[0.0, 1.0]]  # [[t, a], ...]
    size: List[ScalarStop] = [[0.0, 0.05]]  # [[t, diameter m], ...]
    size_randomness: Fraction01 = 0.0
    streak: NonNeg = 0.0  # draw a motion streak of streak × velocity (seconds)
    # "local": live particles are carried with the emitter's motion (a jet on a moving ship)
    space: Literal["world", "local"] = "world"
    interact: Optional[Interact] = None  # particles of emitters of one kind interact (Interact)
    # two-way coupling: its particles push the rigid bodies they hit back (README "Coupling"),
    # each with `mass` kg (ignored without two_way)
    two_way: bool = False
    mass: Annotated[float, Field(gt=0, le=1e3)] = 1e-3

    @model_validator(mode="after")
    def _check(self):
        return _report(self, [
            ("color", _check_curve(self.color)),
            ("alpha", _check_curve(self.alpha)),
            ("size", _check_curve(self.size)),
            ("speed", f"[min, max] needs min <= max, got {self.speed}"
             if self.speed[1] < self.speed[0] else None),
            ("direction", f"must not be zero, got {self.direction}"
             if math.fsum(c * c for c in self.direction) < 1e-12 else None),
            ("stop", f"{self.stop} is before start {self.start}"
             if self.stop is not None and self.stop < self.start else None),
            ("path", _check_path(self.path)),
        ])


def _check_interact(emitters, slots):
    """Emitters of one kind share one interact table; gravity stays under MAX_MESH slots (the
    pair sum up to MAX_DIRECT, particle–mesh beyond); the grid and its fields fit the memory budget (estimated before allocation)."""
    from ..geometry.sizing import MAX_GRID_BYTES, interact_bytes

    problems, first = [], {}
    for i, em in enumerate(emitters):
        it = em.interact
        if it is None:
            continue
        key = ("emitters", i, "interact")
        j = first.setdefault(it.kind, i)
        if j != i and emitters[j].interact != it:
            problems.append((key, f"emitters of kind {it.kind!r} share one table; emitters[{j}]'s differs"))
    grav = sum(n for em, n in zip(emitters, slots) if em.interact is not None and em.interact.kind == "gravity")
    if grav and emitters[first["gravity"]].interact.method == "direct" and grav > MAX_DIRECT:
        problems.append((("emitters", first["gravity"], "interact", "method"), f"'direct' over {grav:,} gravity "
                         f"slots; the pair sum takes at most {MAX_DIRECT:,} (use 'mesh' or 'auto', lower rate or "
                         f"lifetime, or set capacity)"))
    elif grav > MAX_MESH:
        problems.append((("emitters", first["gravity"], "interact"), f"gravity over {grav:,} slots; the "
                         f"particle-mesh path takes at most {MAX_MESH:,} (lower rate or lifetime, or set capacity)"))
    if first:
        need = interact_bytes(sum(slots), "fluid" in first)
        if need > MAX_GRID_BYTES:
            problems.append((("emitters", min(first.values()), "interact"),
                             f"the grid over {sum(slots):,} slots needs {need / 2**30:.1f} GiB; at most "
                             f"{MAX_GRID_BYTES / 2**30:.0f} GiB (lower rate or lifetime, or set capacity)"))
    return problems


def _check_two_way(scene):
    """A two_way emitter needs rigid bodies to push, fixed steps (a step-doubling attempt may be
    retried: its pushes would count twice) and no interact (the constraint solve's own
    projections are not recorded)."""
    problems = []
    for i, em in enumerate(scene.emitters):
        if not em.two_way:
            continue
        key = ("emitters", i, "two_way")
        if not scene.rigid_bodies:
            problems.append((key, "true needs rigid_bodies to push (the scene has none)"))
        elif scene.solver.adaptive:
            problems.append((key, "true needs fixed steps: set solver.adaptive = false"))
        elif em.interact is not None:
            problems.append((key, "true is not available with interact (drop one of them)"))
    return problems
