"""Checks for command-line values, held to the config loader's standard: a bad value is one line
naming the flag and the value (``--h: 'nan' is not allowed: must be a finite number > 0``), exit 2.

Each checker takes the text as typed and returns the parsed value or raises :class:`FlagError`
with the message body; :class:`Parser` puts the flag in front. The same checkers re-check a
Namespace built in Python (``check(args, spec)``), so ``cmd_run(namespace)`` holds to it too.
"""
from __future__ import annotations

import argparse
import math

from engine.ode.methods import INTEGRATORS  # the one list of names (no Taichi behind it)
from .budget import parse_bytes
from .errors import UserError

MAX_SIDE = 8192  # as render.width / render.height


class FlagError(ValueError):
    """The message body for a bad flag value (the flag name is put in front by the caller)."""


def _show(text) -> str:
    r = repr(text)
    return r if len(r) <= 40 else r[:37] + "..."


def integer(lo: int, hi: int):
    def check(text) -> int:
        try:
            v = int(str(text).strip())
        except ValueError:
            raise FlagError(f"{_show(text)} is not a whole number") from None
        if not lo <= v <= hi:
            raise FlagError(f"{_show(text)} is not allowed: must be {lo:,} to {hi:,}")
        return v
    return check


def real(lo: float = -math.inf, hi: float = math.inf, lo_open: bool = False):
    """A finite float in [lo, hi] (or (lo, hi] with ``lo_open``)."""
    def check(text) -> float:
        try:
            v = float(str(text).strip())
        except ValueError:
            raise FlagError(f"{_show(text)} is not a number") from None
        low_ok = v > lo if lo_open else v >= lo
        if not (math.isfinite(v) and low_ok and v <= hi):
            rng = (f"> {lo:g}" if lo_open else f">= {lo:g}") if math.isfinite(lo) else ""
            rng += (" and " if rng and math.isfinite(hi) else "") + (f"<= {hi:g}" if math.isfinite(hi) else "")
            raise FlagError(f"{_show(text)} is not allowed: must be a finite number{' ' + rng if rng else ''}")
        return v
    return check


def size(text):
    """'WxH' with both sides in 16..8192 → (W, H)."""
    parts = str(text).lower().split("x")
    try:
        w, h = (int(p) for p in parts)
    except ValueError:
        raise FlagError(f"{_show(text)} is not WxH (e.g. 640x360)") from None
    if not (16 <= w <= MAX_SIDE and 16 <= h <= MAX_SIDE):
        raise FlagError(f"{_show(text)} is not allowed: width and height must be 16 to {MAX_SIDE}")
    return w, h


def path(text) -> str:
    """A file or folder path: not empty, not only blanks, no NUL."""
    s = str(text)
    if not s.strip():
        raise FlagError(f"{_show(text)} is empty: give a path")
    if "\x00" in s:
        raise FlagError(f"{_show(text)} holds a NUL character")
    return s


def nbytes(text) -> int:
    try:
        return parse_bytes(text)
    except ValueError as e:
        raise FlagError(f"{_show(text)} {e}") from None


def choice(*allowed):
    def check(text) -> str:
        if text not in allowed:
            raise FlagError(f"{_show(text)} is not allowed; choose from {', '.join(allowed)}")
        return text
    return check


def checked(flag: str, fn, text):
    """``fn(text)``, a FlagError turned into the command's one-line UserError."""
    try:
        return fn(text)
    except FlagError as e:
        raise UserError(f"{flag}: {e}") from None


def argtype(fn):
    """``fn`` as an argparse ``type=``: argparse writes 'argument --flag: <message>'."""
    def conv(text):
        try:
            return fn(text)
        except FlagError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
    conv.__name__ = getattr(fn, "__name__", "value")
    return conv


def keep_text(fn):
    """Check with ``fn`` but keep the text as typed (``--size`` stays 'WxH' in the Namespace)."""
    def check(text):
        fn(text)
        return text
    return check


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``error: --frames: 'x' is not a whole number`` (no usage
    block), raised as UserError so every command exits 2 the same way."""

    def error(self, message):
        message = " ".join(message.split())
        if message.startswith("argument "):
            message = message[len("argument "):]
            flag, _, rest = message.partition(": ")
            message = f"{flag.split('/')[-1]}: {rest}" if rest else message
        raise UserError(f"{message} (see {self.prog} --help)")


def check(args, spec) -> None:
    """Re-check the values of a Namespace (``spec``: {dest: (flag, checker)}); a value given as
    text or as a Python value, None skipped."""
    for dest, (flag, fn) in spec.items():
        v = getattr(args, dest, None)
        if v is not None:
            checked(flag, fn, v if isinstance(v, str) else str(v))


# Every checked flag of `particles run`: dest → (flag, checker). The parser uses them, and
# cmd_run re-checks a Namespace built in Python (particles wedge) with them.
RUN_FLAGS = {
    "frames": ("--frames", integer(1, 1_000_000)),
    "out": ("--out", path),
    "format": ("--format", choice("png", "gif", "mp4")),
    "size": ("--size", size),
    "seed": ("--seed", integer(0, 2**32 - 1)),
    "integrator": ("--integrator", choice(*INTEGRATORS)),
    "max_memory": ("--max-memory", nbytes),
    "max_steps": ("--max-steps", integer(1, 10**12)),
    "max_work": ("--max-work", real(1.0, 1e18)),
    "workers": ("--workers", integer(1, 64)),
}
