"""The scene config: strict models for what a TOML effect config may say. This module holds the
scene-wide tables (camera, solver, forces and their fields, render) and :class:`Scene` with its
cross-key checks; each kind of thing has its own module (emitters, colliders, bodies, rigid),
re-exported here.

Every model forbids unknown keys (the error names the key and the nearest valid one), is strict
about types (a string is not a number), and rejects NaN and Inf.

Units: metres, seconds, degrees for angles; colours are linear RGB (values above 1 glow).
"""
from __future__ import annotations

import math
import re
from typing import Annotated, List, Literal, Optional

from pydantic import Field, field_validator, model_validator

from ..ode.methods import INTEGRATORS
from ..particles.capacity import MAX_POOL, pool_sizes
from .base import Finite, NonNeg, Positive, Strict, Vec3, _report
from .bodies import (BODY_INTEGRATORS, BODY_TYPES, Body, ChainBody, ClothBody, EnergyTerm, HairBody, JellyBody,
                     Material, Resolution3, Size3, SolidBody)
from .colliders import BoxCollider, CapsuleCollider, Collider, Extent, PlaneCollider, Quaternion, SphereCollider
from .emitters import (INTERACT_KINDS, MAX_INTERACT_RADIUS, MAX_STOPS, Burst, Emitter, Interact, SubEmitter,
                       _check_interact, _check_two_way)
from .rigid import Joint, Rigid, RigidBody, check_scene as _check_rigid

__all__ = [
    # this module
    "MAX_FRAMES", "Turbulence", "Attractor", "Vortex", "Camera", "Solver", "Forces", "Render", "Scene",
    # re-exported from their own modules: emitters, colliders, soft bodies, rigid bodies
    "MAX_STOPS", "INTERACT_KINDS", "MAX_INTERACT_RADIUS", "Burst", "SubEmitter", "Interact", "Emitter",
    "Collider", "PlaneCollider", "SphereCollider", "BoxCollider", "CapsuleCollider", "Quaternion", "Extent",
    "BODY_INTEGRATORS", "BODY_TYPES", "Body", "EnergyTerm", "Material", "ChainBody", "HairBody", "ClothBody",
    "JellyBody", "SolidBody", "Resolution3", "Size3",
    "Joint", "Rigid", "RigidBody", "INTEGRATORS",
]

MAX_FRAMES = 1_000_000  # frames in one run, whether given as `frames` or as duration × fps


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
