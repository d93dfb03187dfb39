"""Argument checks for the game API (:mod:`engine.api`), in the command line's one-line style
(``particles_tools.flags``): ``move_collider: position: [nan, 0.0, 0.0] is not allowed: must be 3 finite
numbers within ±1e+06``. Each checker returns the value in the form the engine stores (a float, an
int, a tuple of floats) or raises ``TypeError`` (wrong kind of value), ``ValueError`` (right kind,
not allowed: NaN, ±inf, out of range, wrong length) or ``KeyError`` (no such name). Pure Python
and NumPy: a check touches no field, so a refused call leaves the scene as it was.

The limits are data (:data:`LIMITS`), so the README's table and the checks cannot drift apart.
"""
from __future__ import annotations

import math
import numbers

import numpy as np

COORD = 1e6  # m, m/s, m/s²: beyond this f32 positions lose centimetres (the config's bound too)
MAX_SIDE = 16384  # pixels, either side of a rendered image
MIN_SIDE = 16
MAX_RENDER_BYTES = 4 << 30  # what one render size may allocate (targets + the image)
# bytes per pixel a render size allocates at most (engine.render.targets: background, depth,
# packed background, two splat accumulators, visibility and line sums, the frame's background
# with bodies, the image itself), the reduced level included
RENDER_BYTES_PER_PIXEL = 16 + 8 + 4 + 32 + 8 + 16 + 16 + 8 + 4
MAX_CONTACTS = 10_000_000  # contact records a scene may keep between two contacts() calls
MAX_DT = 1.0  # s, the default longest step(dt)
MAX_STEPS_PER_CALL = 1_000_000  # integrator steps one step(dt) may take (dt / h)

# argument → what is allowed (the README's table is made from this)
LIMITS = {
    "dt (step)": f"finite, > 0 and <= max_dt (default {MAX_DT:g} s; at most {MAX_STEPS_PER_CALL:,} "
                 "integrator steps of solver.h)",
    "max_dt": "finite, > 0 and <= 60 s",
    "frame_time (FixedTimestep.advance)": "finite, >= 0 (a stall is cut to max_steps steps; a step that raised drops the time left)",
    "name (emitter, collider, body)": "a str naming one in the scene (KeyError lists the names)",
    "position, target (m)": f"3 finite numbers within ±{COORD:g}: list, tuple or NumPy array",
    "orientation (set_collider_pose)": f"None or 4 finite numbers [w, x, y, z] within ±{COORD:g}, not all zero",
    "velocity, angular_velocity (set_collider_pose)": f"None or 3 finite numbers (m/s within ±{COORD:g}, "
                                                      "rad/s within ±1e4); a spin needs a collider built to rotate",
    "wind (m/s), gravity (m/s²)": f"3 finite numbers within ±{COORD:g}",
    "over (s)": "None (one frame) or finite, > 0 and <= max_dt",
    "rate (particles/s)": "finite, 0 to 1e8 (the config's bound)",
    "count (burst)": "a whole number, 0 to the emitter's pool ring (its capacity)",
    "node (pin, move_pin, release)": "a whole number, 0 to the body's node count - 1",
    "on, transparent, bgra, show_colliders": "bool (or NumPy bool)",
    "min_speed (contacts)": f"finite, 0 to {COORD:g} m/s",
    "width, height (render)": f"None (the config's size) or whole numbers {MIN_SIDE} to {MAX_SIDE:,}, "
                              f"and at most {MAX_RENDER_BYTES >> 30} GiB of render memory "
                              f"({RENDER_BYTES_PER_PIXEL} B per pixel)",
    "camera (render)": "an engine.api.Camera: finite position and look_at apart, fov in (1, 170) degrees",
    "out (render)": "a writeable, C-contiguous uint8 NumPy array of shape (height, width, 4) (a read-only array, "
                    "one over `bytes` or a read-only `np.memmap` is refused)",
    "alpha (render)": "None or finite in [0, 1]; needs a scene built with interpolate=True",
    "contacts (build)": f"bool or a whole number 0 to {MAX_CONTACTS:,} (records kept between drains)",
    "emitter, collider, body (add_*)": "a dict of config keys, checked as a config is",
    "n (set_particle_budget)": "None (no budget) or a whole number >= 0 of pool slots",
    "render, interpolate (build)": "bool",
    "spare_emitters, spare_slots (build)": "whole numbers, 0 to 64 and 0 to 50,000,000",
    "copies (prepare)": "a whole number, 1 to 64",
    "sizes (warm_up, prepare)": "(width, height) pairs, as render's",
    "dt, max_steps (FixedTimestep)": "dt finite in [1e-06, 1] s; max_steps a whole number, 1 to 100,000",
}


def show(value) -> str:
    """A value as a message shows it: short, one line."""
    if isinstance(value, np.ndarray):
        text = np.array2string(value.ravel()[:6], separator=", ", threshold=6) + \
            (f" (shape {value.shape})" if value.ndim != 1 or value.size > 6 else "")
    else:
        text = repr(value)
    text = " ".join(text.split())
    return text if len(text) <= 60 else text[:57] + "..."


def _is_real(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))


def number(where: str, v, lo: float = -math.inf, hi: float = math.inf, *, lo_open: bool = False) -> float:
    """A finite real in [lo, hi] ((lo, hi] with ``lo_open``) as a float."""
    if not _is_real(v):
        raise TypeError(f"{where}: {show(v)} is not a number")
    try:
        x = float(v)
    except OverflowError:  # an int past the float range (10**400)
        x = math.inf if v > 0 else -math.inf
    ok = math.isfinite(x) and (x > lo if lo_open else x >= lo) and x <= hi
    if not ok:
        rng = [f"> {lo:g}" if lo_open else f">= {lo:g}"] if math.isfinite(lo) else []
        rng += [f"<= {hi:g}"] if math.isfinite(hi) else []
        raise ValueError(f"{where}: {show(v)} is not allowed: must be finite"
                         + (f" and {' and '.join(rng)}" if rng else ""))
    return x


def integer(where: str, v, lo: int, hi: int) -> int:
    """A whole number (int or NumPy integer, not bool or float) in [lo, hi]."""
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Integral):
        raise TypeError(f"{where}: {show(v)} is not a whole number (int)")
    if not lo <= int(v) <= hi:
        raise ValueError(f"{where}: {show(v)} is not allowed: must be {lo:,} to {hi:,}")
    return int(v)


def boolean(where: str, v) -> bool:
    if not isinstance(v, (bool, np.bool_)):
        raise TypeError(f"{where}: {show(v)} is not a bool")
    return bool(v)


def vector(where: str, v, n: int = 3, bound: float = COORD) -> tuple:
    """``n`` finite numbers within ±bound (a list, tuple or NumPy array) as a tuple of floats."""
    if isinstance(v, (str, bytes, dict)) or not hasattr(v, "__len__"):
        raise TypeError(f"{where}: {show(v)} is not a sequence of {n} numbers")
    a = np.asarray(v, dtype=object) if not isinstance(v, np.ndarray) else v
    if a.shape != (n,):
        raise ValueError(f"{where}: {show(v)} is not allowed: must be {n} numbers, got shape {a.shape}")
    if not all(_is_real(c) for c in a.tolist()):
        raise TypeError(f"{where}: {show(v)} is not allowed: must be {n} numbers")
    out = tuple(float(c) for c in a.tolist())
    if not all(math.isfinite(c) and abs(c) <= bound for c in out):
        raise ValueError(f"{where}: {show(v)} is not allowed: must be {n} finite numbers within ±{bound:g}")
    return out


def name(where: str, v, names, kind: str) -> str:
    """One of ``names`` (KeyError naming the value and the names of that ``kind`` there are)."""
    if not isinstance(v, str):
        raise TypeError(f"{where}: {show(v)} is not a name (str)")
    if not v or v not in names:  # "" is no name: unnamed items cannot be reached by it
        known = ", ".join(repr(n) for n in names if n) or "none"
        raise KeyError(f"{where}: no {kind} named {show(v)} (names: {known})")
    return v


def image_size(where: str, width, height, default) -> tuple:
    """(W, H): None takes the config's size; each side MIN_SIDE..MAX_SIDE and the memory a size
    allocates at most MAX_RENDER_BYTES."""
    w = default[0] if width is None else integer(f"{where}: width", width, MIN_SIDE, MAX_SIDE)
    h = default[1] if height is None else integer(f"{where}: height", height, MIN_SIDE, MAX_SIDE)
    need = w * h * RENDER_BYTES_PER_PIXEL
    if need > MAX_RENDER_BYTES:
        raise ValueError(f"{where}: width, height: {w}x{h} is not allowed: it needs about {need / 2**30:.1f} "
                         f"GiB of render memory; at most {MAX_RENDER_BYTES >> 30} GiB")
    return w, h


def camera(where: str, cam, cls):
    """A Camera with finite, distinct position and look_at and a fov in (1, 170) degrees."""
    if not isinstance(cam, cls):
        raise TypeError(f"{where}: {show(cam)} is not an engine.api.Camera")
    p = vector(f"{where}.position", cam.position)
    q = vector(f"{where}.look_at", cam.look_at)
    number(f"{where}.fov", cam.fov, 1.0, 170.0, lo_open=True)
    if math.dist(p, q) < 1e-6:
        raise ValueError(f"{where}.look_at: {show(cam.look_at)} is where the camera stands: it must look "
                         f"at another point")
    return cam


def image_array(where: str, out, width: int, height: int) -> np.ndarray:
    """The caller's image array: checked property by property (dtype, shape, C-contiguous,
    writeable: a read-only array, one over ``bytes`` or a read-only ``np.memmap``, is refused,
    never written), each failure named in the message."""
    if not isinstance(out, np.ndarray):
        raise TypeError(f"{where}: {show(out)} is not a NumPy array")
    want = f"must be a writeable C-contiguous uint8 array of shape ({height}, {width}, 4)"
    if out.dtype != np.uint8:
        raise ValueError(f"{where}: dtype {out.dtype} is not allowed: {want}")
    if out.shape != (height, width, 4):
        raise ValueError(f"{where}: shape {out.shape} is not allowed: {want}")
    if not out.flags.c_contiguous:
        raise ValueError(f"{where}: the array is not C-contiguous (strides {out.strides}): {want}; "
                         f"pass np.ascontiguousarray(...) and copy it back")
    if not out.flags.writeable:
        raise ValueError(f"{where}: the array is read-only (writeable=False: a view of bytes, a read-only "
                         f"memmap or flags.writeable cleared): {want}")
    return out


def plain(value):
    """Config values as the strict config takes them: tuples and NumPy arrays become lists, NumPy
    scalars Python numbers (recursively, through dicts and lists)."""
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value
