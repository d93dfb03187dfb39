"""Config models for rigid bodies and joints: ``[[rigid_bodies]]``, ``[[joints]]`` and ``[rigid]``
(issue 22). Pure pydantic like the rest of the schema (no Taichi).

Shapes: ``sphere`` (``radius``), ``box`` (``half_extents``, m) or ``capsule`` (``radius``,
``half_length``, axis along the body's local y). ``density`` (kg/m³) or ``mass`` (kg), not both;
``orientation`` a unit quaternion [w, x, y, z]; ``angular_velocity`` in rad/s, world frame.
``fixed = true``: a static body (no velocity); ``path``: a kinematic one following keyframes.
"""
from __future__ import annotations

import math
from typing import Annotated, List, Literal, Optional

from pydantic import Field, model_validator

from ..ode.methods import INTEGRATORS
from .base import Finite, Fraction01, Keyframe, Name, NonNeg, Strict, Vec3, _check_path, _report

RIGID_INTEGRATORS = ("xpbd", *INTEGRATORS)
SHAPES = ("sphere", "box", "capsule")
QUAT_TOL = 1e-3  # |q| must be 1 within this (a typo, not rounding, is what it catches)

Size = Annotated[float, Field(gt=0, le=1e4)]
Color = Annotated[List[Annotated[float, Field(ge=0, le=10)]], Field(min_length=3, max_length=3)]


class RigidBody(Strict):
    name: Name = ""
    shape: Literal[SHAPES]
    radius: Optional[Size] = None  # sphere, capsule
    half_extents: Optional[Annotated[List[Size], Field(min_length=3, max_length=3)]] = None  # box
    half_length: Optional[Size] = None  # capsule: half the segment between the caps' centres
    density: Optional[Annotated[float, Field(gt=0, le=1e6)]] = None  # kg/m³ (default 1000)
    mass: Optional[Annotated[float, Field(gt=0, le=1e7)]] = None  # kg
    position: Vec3 = [0.0, 0.0, 0.0]
    orientation: Annotated[List[Finite], Field(min_length=4, max_length=4)] = [1.0, 0.0, 0.0, 0.0]
    velocity: Vec3 = [0.0, 0.0, 0.0]
    angular_velocity: Vec3 = [0.0, 0.0, 0.0]
    restitution: Fraction01 = 0.3
    friction: NonNeg = 0.5
    fixed: bool = False
    path: List[Keyframe] = []  # kinematic: follows the keyframes (orientation kept)
    color: Color = [0.7, 0.55, 0.35]

    @model_validator(mode="after")
    def _check(self):
        q2 = math.fsum(c * c for c in self.orientation)
        need = {"sphere": ("radius",), "box": ("half_extents",), "capsule": ("radius", "half_length")}[self.shape]
        problems = [(k, f"a {self.shape} needs {k}") for k in need if getattr(self, k) is None]
        unused = [k for k in ("radius", "half_extents", "half_length")
                  if k not in need and getattr(self, k) is not None]
        problems += [(k, f"a {self.shape} takes no {k} (it needs {', '.join(need)})") for k in unused]
        moving = any(c != 0 for c in self.velocity) or any(c != 0 for c in self.angular_velocity)
        problems += [
            ("orientation", f"must be a unit quaternion [w, x, y, z], got {self.orientation} "
             f"(length {math.sqrt(q2):.4g})" if abs(math.sqrt(q2) - 1.0) > QUAT_TOL else None),
            ("mass", "give density or mass, not both"
             if self.mass is not None and self.density is not None else None),
            ("velocity", "a fixed body cannot move: drop velocity and angular_velocity, or "
             "set fixed = false" if self.fixed and moving else None),
            ("path", "a fixed body has no path (a path makes it kinematic)"
             if self.fixed and self.path else None),
            ("path", _check_path(self.path)),
        ]
        return _report(self, problems)

class Joint(Strict):
    """``bodies = [a, b]`` (b may be "world"); ``anchor``: a world point at t = 0 (on a; for
    ``distance``, ``anchor_b`` is the point on b, default b's centre or the anchor for the
    world). ``axis`` (hinge, world at t = 0); ``limits``: degrees (hinge) or m (distance)."""

    name: Name = ""
    type: Literal["ball", "hinge", "fixed", "distance"]
    bodies: Annotated[List[Name], Field(min_length=2, max_length=2)]
    anchor: Optional[Vec3] = None  # default: the middle of the two bodies' centres
    anchor_b: Optional[Vec3] = None  # distance joints only
    axis: Vec3 = [0.0, 0.0, 1.0]
    limits: Optional[Annotated[List[Finite], Field(min_length=2, max_length=2)]] = None
    compliance: Annotated[float, Field(ge=0, le=1e3)] = 0.0  # m/N (inverse stiffness)

    @model_validator(mode="after")
    def _check(self):
        lim = self.limits
        problems = [
            ("axis", f"must not be zero, got {self.axis}"
             if math.fsum(c * c for c in self.axis) < 1e-12 else None),
            ("limits", f"[min, max] needs min <= max, got {lim}" if lim and lim[0] > lim[1] else None),
            ("limits", f"a {self.type} joint takes no limits (hinge: degrees, distance: m)"
             if lim and self.type in ("ball", "fixed") else None),
            ("limits", f"hinge limits are degrees within [-180, 180], got {lim}"
             if lim and self.type == "hinge" and (lim[0] < -180 or lim[1] > 180) else None),
            ("limits", f"distance limits must be >= 0, got {lim}"
             if lim and self.type == "distance" and lim[0] < 0 else None),
            ("anchor_b", "only distance joints take anchor_b"
             if self.anchor_b is not None and self.type != "distance" else None),
            ("bodies", f"a joint needs two different bodies, got {self.bodies}"
             if self.bodies[0] == self.bodies[1] else None),
            ("bodies", "the first body cannot be 'world' (write [body, \"world\"])"
             if self.bodies[0] == "world" else None),
        ]
        return _report(self, problems)

class Rigid(Strict):
    """How rigid bodies are stepped: ``xpbd`` (Müller et al. 2020, ``substeps`` per step of
    at most ``h``), or one of the five integrators on Baraff's state (x, q, P, L) through the
    ODE driver ([solver] h, adaptive and tolerance apply)."""

    integrator: Literal[RIGID_INTEGRATORS] = "xpbd"
    substeps: Annotated[int, Field(ge=1, le=1000)] = 20
    h: Annotated[float, Field(gt=0, le=0.1)] = 1.0 / 60.0  # xpbd: the step contacts are found once in
    sleep: bool = True  # bodies at rest for sleep_time stop moving until touched
    sleep_time: Annotated[float, Field(gt=0, le=100)] = 0.5
    sleep_speed: Annotated[float, Field(ge=0, le=10)] = 0.05  # m/s (and rad/s × size)



def check_scene(scene) -> list:
    """Cross-key problems of a scene's rigid part: (key, message) pairs for ``_report``."""
    names = [b.name for b in scene.rigid_bodies]
    problems = []
    for i, j in enumerate(scene.joints):
        for k, n in enumerate(j.bodies):
            if n == "world" and k == 1:
                continue
            if n not in names or not n:
                known = ", ".join(repr(x) for x in names if x) or "none"
                problems.append((("joints", i, "bodies"), f"{n!r} names no rigid body (names: {known})"))
        if scene.rigid.integrator != "xpbd":
            problems.append((("joints", i), f"joints need [rigid] integrator = \"xpbd\", not "
                             f"{scene.rigid.integrator!r}"))
    if "world" in names:
        problems.append(("rigid_bodies", "'world' is the name of the static world (joints' bodies)"))
    return problems

