"""Config models for soft bodies: ``[[bodies]]`` of type chain, hair, cloth, jelly or solid (a
union tagged by ``type``), their energy terms and a solid's hyperelastic material."""
from __future__ import annotations

import math
from typing import Annotated, List, Literal, Optional, Union

from pydantic import Field, field_validator, model_validator

from ..ode.methods import INTEGRATORS
from .base import Keyframe, Name, NonNeg, Positive, Strict, Vec3, _check_path, _report

BODY_INTEGRATORS = (*INTEGRATORS, "xpbd")  # soft bodies may also take XPBD (engine.xpbd)


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
