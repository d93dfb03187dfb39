"""Config models for colliders: ``[[colliders]]`` of type plane, sphere, box or capsule (a union
tagged by ``type``), each optionally following a keyframe path or spinning."""
from __future__ import annotations

import math
from typing import Annotated, List, Literal, Union

from pydantic import Field, model_validator

from .base import Finite, Fraction01, Keyframe, Name, NonNeg, Strict, Vec3, _check_path, _report


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
