"""The scene config: strict models for what a TOML effect config may say.

Every model forbids unknown keys (the error names the key and the nearest valid one), is strict
about types (a string is not a number), and rejects NaN and Inf. Names follow established engines
where they have one: Godot's ``lifetime``, ``lifetime_randomness``, ``spread``, ``one_shot``;
Unity's rate over time (``rate``) and ``bursts``.

Units: metres, seconds, degrees for angles; colours are linear RGB (values above 1 glow).
"""
from __future__ import annotations

import math
import re
from typing import Annotated, List, Literal, Optional, Union

from pydantic import Field, field_validator, model_validator

from ..ode.methods import INTEGRATORS
from .base import (ColorStop, Finite, Fraction01, Keyframe, Name, NonNeg, Positive, ScalarStop, Strict, Vec3,  # noqa: F401
                   _check_path, _report)
from ..particles.capacity import MAX_POOL, pool_sizes
from ..particles.pm import MAX_DIRECT, MAX_MESH
from .rigid import Joint, Rigid, RigidBody, check_scene as _check_rigid

BODY_INTEGRATORS = (*INTEGRATORS, "xpbd")  # soft bodies may also take XPBD (engine.xpbd)


MAX_STOPS = 8
MAX_FRAMES = 1_000_000  # frames in one run, whether given as `frames` or as duration × fps


def _check_curve(stops):
    if stops is None:
        return None
    if not 1 <= len(stops) <= MAX_STOPS:
        return f"needs 1 to {MAX_STOPS} stops, got {len(stops)}"
    ts = [s[0] for s in stops]
    if any(t < 0 or t > 1 for t in ts) or any(b < a for a, b in zip(ts, ts[1:])):
        return f"stop times must lie in [0, 1] and increase, got {ts}"
    return None


_CONTROL = re.compile(r"[\x00-\x1f\x7f]")


def _check_name(name: str) -> str:
    """A config name becomes a folder and file name: one plain path component."""
    if name and (_CONTROL.search(name) or "/" in name or "\\" in name or ":" in name
                 or name.startswith(".") or len(name) > 100):
        raise ValueError(f"{name!r} must be a plain file name: no '/', '\\', ':' or control "
                         f"characters, not starting with '.', at most 100 characters")
    return name


def _check_output(out: Optional[str]) -> Optional[str]:
    """``output`` is a folder inside the output root (renders/): relative, no '..', no drive."""
    if out is None:
        return out
    parts = out.split("/")
    why = None
    if not out.strip():
        why = "must not be empty"
    elif _CONTROL.search(out) or "\\" in out or ":" in out:
        why = "must not hold '\\', ':' (a drive letter) or control characters"
    elif out.startswith("/") or out.startswith("~"):
        why = "must be relative to the output folder renders/ (use --out for other places)"
    elif any(p in ("", ".", "..") for p in parts):
        why = "must not hold '..', '.' or empty parts: it stays inside renders/"
    elif len(out) > 200:
        why = "must be at most 200 characters"
    if why:
        raise ValueError(f"{out!r} {why}")
    return out


def _repeated_names(names) -> Optional[str]:
    """The API moves, rates and removes things by name: two with one name would leave one of
    them out of reach. Unnamed ("") items may repeat."""
    dup = sorted({n for n in names if n and names.count(n) > 1})
    return f"names must be unique, repeated: {', '.join(repr(n) for n in dup)}" if dup else None


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


class _ColliderBase(Strict):
    name: Name = ""
    restitution: Fraction01 = 0.5
    friction: NonNeg = 0.0
    kill: bool = False  # particles that touch it die
    path: List[Keyframe] = []
    visible: bool = True
    # rad/s about the shape's centre (a plane's point), world axes: the surface drags what it hits
    angular_velocity: Annotated[List[Annotated[float, Field(ge=-1e4, le=1e4)]],
                                Field(min_length=3, max_length=3)] = [0.0, 0.0, 0.0]
    rotates: bool = False  # compile the spinning code while angular_velocity is zero (spun from code)


Quaternion = Annotated[List[Finite], Field(min_length=4, max_length=4)]  # [w, x, y, z], normalised
Extent = Annotated[float, Field(gt=0, le=1e5)]


def _check_quaternion(q):
    return f"must not be zero, got {q}" if math.fsum(c * c for c in q) < 1e-12 else None


class PlaneCollider(_ColliderBase):
    type: Literal["plane"]
    point: Vec3 = [0.0, 0.0, 0.0]
    normal: Vec3 = [0.0, 1.0, 0.0]

    @model_validator(mode="after")
    def _check(self):
        return _report(self, [
            ("normal", f"must not be zero, got {self.normal}"
             if math.fsum(c * c for c in self.normal) < 1e-12 else None),
            ("path", _check_path(self.path)),
        ])


class SphereCollider(_ColliderBase):
    type: Literal["sphere"]
    center: Vec3 = [0.0, 0.0, 0.0]
    radius: Annotated[float, Field(gt=0, le=1e5)] = 1.0

    @model_validator(mode="after")
    def _check(self):
        return _report(self, [("path", _check_path(self.path))])


class BoxCollider(_ColliderBase):
    type: Literal["box"]
    center: Vec3 = [0.0, 0.0, 0.0]
    half_extents: Annotated[List[Extent], Field(min_length=3, max_length=3)] = [0.5, 0.5, 0.5]
    orientation: Quaternion = [1.0, 0.0, 0.0, 0.0]

    @model_validator(mode="after")
    def _check(self):
        return _report(self, [("orientation", _check_quaternion(self.orientation)),
                              ("path", _check_path(self.path))])


class CapsuleCollider(_ColliderBase):
    """The points within ``radius`` of a segment of length 2·``half_length`` through ``center``
    along the body y axis (turned by ``orientation``)."""

    type: Literal["capsule"]
    center: Vec3 = [0.0, 0.0, 0.0]
    radius: Extent = 0.25
    half_length: Annotated[float, Field(ge=0, le=1e5)] = 0.5
    orientation: Quaternion = [1.0, 0.0, 0.0, 0.0]

    @model_validator(mode="after")
    def _check(self):
        return _report(self, [("orientation", _check_quaternion(self.orientation)),
                              ("path", _check_path(self.path))])


Collider = Annotated[Union[PlaneCollider, SphereCollider, BoxCollider, CapsuleCollider],
                     Field(discriminator="type")]


class Turbulence(Strict):
    """Curl-noise turbulence (Bridson et al. 2007): a divergence-free acceleration field, so smoke
    swirls instead of compressing. ``frequency`` in 1/m, ``scroll`` in m/s (the pattern rises)."""

    strength: NonNeg = 0.0  # m/s²
    frequency: Positive = 1.0
    scroll: Finite = 0.5
    octaves: Annotated[int, Field(ge=1, le=4)] = 2


class Attractor(Strict):
    """Pulls particles toward ``position`` (negative strength pushes): a = s · d̂ / (1 + (|d|/r)²)."""

    position: Vec3
    strength: Finite = 1.0
    radius: Positive = 1.0


class Vortex(Strict):
    """Swirls particles around the axis through ``position``: tangential a = s · g(ρ/r), with
    g peaking at ρ = r."""

    position: Vec3 = [0.0, 0.0, 0.0]
    axis: Vec3 = [0.0, 1.0, 0.0]
    strength: Finite = 1.0
    radius: Positive = 1.0

    @model_validator(mode="after")
    def _check(self):
        return _report(self, [("axis", f"must not be zero, got {self.axis}"
                               if math.fsum(c * c for c in self.axis) < 1e-12 else None)])


class EnergyTerm(Strict):
    """One energy term of a soft body (engine.forces.terms): ``spring`` (the body's Hooke springs,
    stiffness N/m replacing ``stiffness``), ``bending`` (dihedral, per hinge, N·m; cloth),
    ``area`` (½K(A − A₀)²/A₀ per triangle, K in N/m; cloth), ``volume`` (½K(V − V₀)²/V₀ per
    tetrahedron, K in Pa; jelly or solid)."""

    type: Literal["spring", "bending", "area", "volume"]
    stiffness: Annotated[float, Field(gt=0, le=1e12)]


class Material(Strict):
    """A solid's hyperelastic material: ``model``, Young's modulus ``young`` (Pa) and Poisson's
    ratio ``poisson`` (−1 < ν < 0.5)."""

    model: Literal["neo_hookean", "stvk", "corotated"] = "neo_hookean"
    young: Annotated[float, Field(gt=0, le=1e12)] = 1e5
    poisson: Annotated[float, Field(gt=-1, lt=0.5)] = 0.3


_TERM_BODIES = {"spring": ("chain", "hair", "cloth", "jelly"), "bending": ("cloth",), "area": ("cloth",),
                "volume": ("jelly", "solid")}


# The soft bodies: a union tagged by ``type`` (as the colliders are). Each type's model holds only
# the keys its topology builder reads (engine/bodies.py), so a key of another type (``strands`` on a
# cloth) is refused, naming the key, instead of being accepted and silently ignored.


class _BodyBase(Strict):
    """What every soft body takes: where it starts, its pins, how it steps and collides, its look,
    and its energy terms. ``damping`` is N·s/m per spring (a solid's: Kelvin–Voigt viscosity, Pa·s).
    ``energies``: the body's energy terms (none given: its springs, as always; given: exactly those
    terms, ``spring`` among them or not)."""

    name: Name = ""
    position: Vec3 = [0.0, 1.0, 0.0]
    damping: NonNeg = 0.0
    pins: Union[Literal["none", "start", "corners", "top"], List[Annotated[int, Field(ge=0)]]] = "start"
    pin_path: List[Keyframe] = []  # pinned nodes follow this path (offsets from their start)
    release_at: Optional[NonNeg] = None  # seconds: every pin lets go
    integrator: Optional[Literal[BODY_INTEGRATORS]] = None
    substeps: Union[Literal["auto"], Annotated[int, Field(ge=1, le=10_000)]] = "auto"
    iterations: Annotated[int, Field(ge=1, le=200)] = 10  # XPBD solver iterations per substep
    max_stretch: Optional[Annotated[float, Field(ge=0, le=10)]] = None  # inextensibility cap
    thickness: Annotated[float, Field(ge=0, le=1)] = 0.015  # m kept between nodes and colliders
    color: Annotated[List[Annotated[float, Field(ge=0, le=10)]], Field(min_length=3, max_length=3)] = [0.55, 0.6, 0.7]
    contacts: bool = False  # record node–collider contacts (the game API's contacts(body=name))
    self_collision: bool = False  # nodes no spring joins keep 2 × thickness apart (the shared grid)
    energies: Optional[Annotated[List[EnergyTerm], Field(max_length=8)]] = None

    def _problems(self) -> list:
        """(key, message or None) pairs for the cross-key checks; variants add their own."""
        wrong = [t.type for t in (self.energies or []) if self.type not in _TERM_BODIES[t.type]]
        return [
            ("pin_path", _check_path(self.pin_path)),
            ("self_collision", "needs thickness > 0 (nodes collide at 2 × thickness)"
             if self.self_collision and self.thickness <= 0 else None),
            ("energies", f"{wrong[0]!r} does not apply to a {self.type} (it needs "
             f"{' or '.join(_TERM_BODIES[wrong[0]])})" if wrong else None),
        ]

    @model_validator(mode="after")
    def _check(self):
        return _report(self, self._problems())


class _SpringBody(_BodyBase):
    """A spring network: ``mass`` per node (kg) and spring ``stiffness`` (N/m). A solid takes
    ``density`` and a ``material`` instead, so it has neither."""

    mass: Annotated[float, Field(gt=0, le=1e3)] = 0.01
    stiffness: Annotated[float, Field(gt=0, le=1e9)] = 1e3


class _StrandBody(_SpringBody):
    """Chains and hair: strands of ``segments`` springs over ``length`` (m) along ``direction``;
    ``bend_stiffness`` (N/m) adds bend springs from each node to the one after next."""

    direction: Vec3 = [0.0, -1.0, 0.0]
    length: Annotated[float, Field(gt=0, le=100)] = 1.0
    segments: Annotated[int, Field(ge=1, le=1000)] = 20
    bend_stiffness: Optional[Annotated[float, Field(ge=0, le=1e9)]] = None

    def _problems(self) -> list:
        return super()._problems() + [
            ("direction", f"must not be zero, got {self.direction}"
             if math.fsum(c * c for c in self.direction) < 1e-12 else None)]


def _grid_length(kind: str, v, dims: int):
    """A grid body's ``resolution`` and ``size`` hold one number per axis: checked before the
    items so the message says what the type needs (the schema's min/max length says the same)."""
    if isinstance(v, list) and len(v) != dims:
        raise ValueError(f"{kind} needs {dims} numbers, got {v}")
    return v


class ChainBody(_StrandBody):
    """A chain: ``segments`` + 1 nodes from ``position`` along ``direction`` over ``length``
    (``pins = "start"`` holds its first node; ``"none"`` lets it fall)."""

    type: Literal["chain"]


class HairBody(_StrandBody):
    """Hair: ``strands`` strands of ``segments`` from roots on a scalp cap (centre ``position``,
    ``radius``, ``cap_angle`` in degrees, growing along the cap's normals) or on a line
    (``position`` → ``line_end``, growing along ``direction``). Without ``bend_stiffness`` the
    bend springs take 0.1 × ``stiffness``."""

    type: Literal["hair"]
    strands: Annotated[int, Field(ge=1, le=5000)] = 40
    roots: Literal["scalp", "line"] = "scalp"
    radius: Annotated[float, Field(gt=0, le=100)] = 0.3
    cap_angle: Annotated[float, Field(gt=0, le=180)] = 60.0  # degrees
    line_end: Vec3 = [1.0, 1.0, 0.0]


class ClothBody(_SpringBody):
    """Cloth: a ``resolution = [nx, ny]`` grid of ``size = [w, d]`` (m) from ``position``, in
    ``plane`` "xz" (flat), "xy" or "zy" (hanging); ``bend_stiffness`` (N/m): its bend springs
    (without it: 0.1 × ``stiffness``)."""

    type: Literal["cloth"]
    resolution: Annotated[List[Annotated[int, Field(ge=2, le=512)]], Field(min_length=2, max_length=2)] = [16, 16]
    size: Annotated[List[Positive], Field(min_length=2, max_length=2)] = [1.0, 1.0]
    plane: Literal["xz", "xy", "zy"] = "xz"
    bend_stiffness: Optional[Annotated[float, Field(ge=0, le=1e9)]] = None

    @field_validator("resolution", "size", mode="before")
    @classmethod
    def _dims(cls, v):
        return _grid_length("cloth", v, 2)


# a lattice's resolution and size: three numbers, no default (a jelly or solid must say its shape)
Resolution3 = Annotated[List[Annotated[int, Field(ge=2, le=512)]], Field(min_length=3, max_length=3)]
Size3 = Annotated[List[Positive], Field(min_length=3, max_length=3)]


class JellyBody(_SpringBody):
    """Jelly: a ``resolution = [nx, ny, nz]`` lattice of springs filling ``size = [x, y, z]`` (m)
    from ``position``."""

    type: Literal["jelly"]
    resolution: Resolution3
    size: Size3

    @field_validator("resolution", "size", mode="before")
    @classmethod
    def _dims(cls, v):
        return _grid_length("jelly", v, 3)


class SolidBody(_BodyBase):
    """An elastic solid: a box of ``size = [x, y, z]`` (m) with ``resolution = [nx, ny, nz]`` nodes
    cut into tetrahedra, ``density`` (kg/m³) and a hyperelastic ``material``; its ``damping`` is a
    Kelvin–Voigt viscosity (Pa·s)."""

    type: Literal["solid"]
    resolution: Resolution3
    size: Size3
    density: Annotated[float, Field(gt=0, le=1e5)] = 1000.0  # kg/m³
    material: Material = Material()

    @field_validator("resolution", "size", mode="before")
    @classmethod
    def _dims(cls, v):
        return _grid_length("solid", v, 3)


BODY_TYPES = {"chain": ChainBody, "hair": HairBody, "cloth": ClothBody, "jelly": JellyBody, "solid": SolidBody}
# A soft body (the name the config's ``bodies`` list has always used): one of the types above.
Body = Annotated[Union[ChainBody, HairBody, ClothBody, JellyBody, SolidBody], Field(discriminator="type")]


class Camera(Strict):
    position: Vec3 = [0.0, 2.0, 8.0]
    look_at: Vec3 = [0.0, 1.0, 0.0]
    fov: Annotated[float, Field(gt=1, lt=170)] = 45.0  # vertical, degrees

    @model_validator(mode="after")
    def _check(self):
        gap = math.dist(self.position, self.look_at)
        return _report(self, [("look_at", f"{self.look_at} is where the camera stands (position "
                               f"{self.position}): it must look at another point"
                               if gap < 1e-6 else None)])


class Solver(Strict):
    integrator: Literal[INTEGRATORS] = "symplectic_euler"
    h: Annotated[float, Field(gt=0, le=1.0)] = 1.0 / 120.0  # base (fixed) step, seconds
    adaptive: bool = False  # step doubling
    tolerance: Annotated[float, Field(gt=0, le=1.0)] = 1e-3  # rtol for step doubling
    atol: Optional[Annotated[float, Field(gt=0, le=1.0)]] = None  # default: tolerance
    extrapolate: bool = True  # step doubling keeps y2 + Δ/(2^p − 1) (order p + 1; README)
    impacts: Literal["located", "projected"] = "located"  # collisions found in time, or projected after the step
    max_steps_per_frame: Annotated[int, Field(ge=1, le=100_000)] = 1000


class Forces(Strict):
    gravity: Vec3 = [0.0, -9.81, 0.0]
    drag: NonNeg = 0.0  # linear drag k: a = −k (v − wind), 1/s
    wind: Vec3 = [0.0, 0.0, 0.0]  # air velocity seen by drag, m/s
    turbulence: Turbulence = Turbulence()
    attractors: Annotated[List[Attractor], Field(max_length=16)] = []
    vortices: Annotated[List[Vortex], Field(max_length=16)] = []


class Render(Strict):
    width: Annotated[int, Field(ge=16, le=8192)] = 640
    height: Annotated[int, Field(ge=16, le=8192)] = 360
    exposure: Annotated[float, Field(gt=0, le=100)] = 1.0
    background: Annotated[List[Annotated[float, Field(ge=0, le=1)]],
                          Field(min_length=3, max_length=3)] = [0.02, 0.025, 0.035]
    grid: bool = True
    show_colliders: bool = True
    density_shading: Annotated[float, Field(ge=0, le=20)] = 0.6  # thick smoke/dust darkens
    # large soft sprites drawn into a reduced buffer (Cantlay 2007): "auto", or 1 (off), 0.5, 0.25
    particle_resolution: Literal["auto", 1, 0.5, 0.25] = "auto"


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


class Scene(Strict):
    name: str = ""
    output: Optional[str] = None  # folder under renders/ (default: name); --out overrides
    seed: Annotated[int, Field(ge=0, le=2**32 - 1)] = 0
    fps: Annotated[float, Field(ge=1, le=1000)] = 30.0
    duration: Optional[Annotated[float, Field(gt=0, le=3600)]] = None
    frames: Optional[Annotated[int, Field(ge=1, le=MAX_FRAMES)]] = None
    camera: Camera = Camera()
    solver: Solver = Solver()
    forces: Forces = Forces()
    render: Render = Render()
    emitters: Annotated[List[Emitter], Field(max_length=64)] = []
    bodies: Annotated[List[Body], Field(max_length=32)] = []
    colliders: Annotated[List[Collider], Field(max_length=64)] = []
    rigid: Rigid = Rigid()
    rigid_bodies: Annotated[List[RigidBody], Field(max_length=20_000)] = []
    joints: Annotated[List[Joint], Field(max_length=1024)] = []

    @field_validator("name")
    @classmethod
    def _name(cls, v):
        return _check_name(v)

    @field_validator("output")
    @classmethod
    def _output(cls, v):
        return _check_output(v)

    @model_validator(mode="after")
    def _check(self):
        problems = [("frames", "give either duration or frames, not both"
                     if self.duration is not None and self.frames is not None else None),
                    ("emitters", "a scene needs at least one emitter, body or rigid body"
                     if not self.emitters and not self.bodies and not self.rigid_bodies else None)]
        names = [e.name for e in self.emitters]
        targets = set()
        for i, em in enumerate(self.emitters):
            for j, sub in enumerate(em.sub_emitters):
                key = ("emitters", i, "sub_emitters", j, "emitter")
                if not sub.emitter:
                    problems.append((key, "'' is not allowed: name the emitter to feed (a named one)"))
                elif sub.emitter not in names:
                    known = ", ".join(repr(n) for n in names if n) or "none"
                    problems.append((key, f"{sub.emitter!r} names no emitter (names: {known})"))
                elif sub.emitter == em.name:
                    problems.append((key, "an emitter cannot feed itself"))
                targets.add(sub.emitter)
        for i, em in enumerate(self.emitters):
            if em.rate == 0 and not em.bursts and em.name not in targets and em.emitting:
                problems.append((("emitters", i, "rate"), "an emitter needs a rate > 0, a burst, "
                                 "to be another emitter's sub-emitter, or emitting = false (driven "
                                 "from code)"))
        for key, items in (("emitters", self.emitters), ("colliders", self.colliders),
                           ("bodies", self.bodies), ("rigid_bodies", self.rigid_bodies),
                           ("joints", self.joints)):
            problems.append((key, _repeated_names([x.name for x in items])))
        problems += _check_rigid(self)
        problems += _check_two_way(self)
        if self.frames is None and self.duration is not None and self.frame_count > MAX_FRAMES:
            problems.append(("duration", f"{self.duration:g} s at fps {self.fps:g} is "
                             f"{self.frame_count:,} frames; at most {MAX_FRAMES:,}"))
        slots = pool_sizes(self.emitters, 1.0 / self.fps)
        problems += _check_interact(self.emitters, slots)
        if sum(slots) > MAX_POOL:
            e = max(range(len(slots)), key=slots.__getitem__)
            problems.append(("emitters", f"the pool would need {sum(slots):,} particle slots "
                             f"(emitters[{e}] alone {slots[e]:,}: rate × lifetime + bursts); at most "
                             f"{MAX_POOL:,}: lower rate or lifetime, or set an emitter's capacity"))
        return _report(self, problems)

    @property
    def frame_count(self) -> int:
        if self.frames is not None:
            return self.frames
        return max(1, round((self.duration if self.duration is not None else 4.0) * self.fps))
