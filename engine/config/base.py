"""The schema's shared pieces: the strict base model, number and vector types, keyframes, and
the cross-key report (one error per problem, each at its own key). Pure pydantic."""
from __future__ import annotations

import re
from typing import Annotated, List

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError
from pydantic_core import InitErrorDetails, PydanticCustomError


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False,
                              validate_default=True)


Vec3 = Annotated[List[float], Field(min_length=3, max_length=3)]
Finite = Annotated[float, Field(ge=-1e6, le=1e6)]
Positive = Annotated[float, Field(gt=0, le=1e6)]
NonNeg = Annotated[float, Field(ge=0, le=1e6)]
Fraction01 = Annotated[float, Field(ge=0, le=1)]
# A curve over normalised life t ∈ [0, 1]: [[t, v...], ...] with t increasing.
ColorStop = Annotated[List[Annotated[float, Field(ge=0, le=100)]], Field(min_length=4, max_length=4)]
ScalarStop = Annotated[List[Annotated[float, Field(ge=0, le=1e3)]], Field(min_length=2, max_length=2)]


def _check_item_name(name: str) -> str:
    """A name the API finds an emitter, collider or body by and the run summary prints: "" (or
    no key) leaves it unnamed; otherwise printable, not blank, no control characters (newline,
    NUL) and no leading or trailing spaces."""
    if name and (re.search(r"[\x00-\x1f\x7f]", name) or not name.strip() or name != name.strip()):
        raise ValueError(f"{name!r} is not allowed: a name must be printable text without control characters "
                         f"(newline, NUL, tab), not blank and without leading or trailing spaces (\"\" or no "
                         f"name key: unnamed)")
    return name


# Names of emitters, colliders and bodies: the API finds things by them, the run summary prints them
Name = Annotated[str, Field(max_length=64), AfterValidator(_check_item_name)]


def _check_path(path):
    """Keyframe times must increase: the message names the first keyframe that does not (a path
    may hold a million keyframes; the message stays one short line)."""
    for i in range(1, len(path or ())):
        a, b = path[i - 1].time, path[i].time
        if b <= a:
            return (f"keyframe times must increase: keyframe {i} has time {b:g}, not after keyframe {i - 1}'s "
                    f"{a:g} ({len(path):,} keyframes)")
    return None


def _report(model, problems):
    """Raise every cross-key problem found in ``model`` at once, each at its own key:
    ``problems`` is a list of (key, message) with message None for "no problem"."""
    errors = [InitErrorDetails(type=PydanticCustomError("config_check", "{text}", {"text": text}),
                               loc=key if isinstance(key, tuple) else (key,),
                               input=getattr(model, key, None) if isinstance(key, str) else None)
              for key, text in problems if text]
    if errors:
        raise ValidationError.from_exception_data(type(model).__name__, errors)
    return model


class Keyframe(Strict):
    """A point on a path: where something is at ``time`` (linear in between, held at the ends)."""

    time: NonNeg
    position: Vec3
