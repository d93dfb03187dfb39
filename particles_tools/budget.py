"""Budgets checked before a run starts: memory and work estimated from the validated config alone
(no field allocated, no kernel compiled), refused past a stated limit with the estimate and the
flag that raises it.

Memory is the Taichi fields a scene allocates (particle pool, tiled-splat records, render targets,
spring networks) plus the frames in flight to the encoders; work is integrator steps, and steps ×
elements (particle slots + spring nodes). The per-element byte counts are read off the field
definitions (engine/particles/pool.py, engine/render/sprites.py and targets.py, engine/springs/);
tests/test_budget.py builds and renders real scenes and checks the estimate against the fields
and ndarrays they allocate, so a renderer or pool that grows fails that test rather than the
budget going stale.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

from engine.particles.capacity import pool_sizes
from engine.render.resolution import particle_scale

# Particle state per slot (ParticleState): pos, vel (vec3 f32), age, life, rand (f32), alive,
# emitter (i32) = 44 B; sub-emitter events + 8 B; adaptive candidates (two vec3 f32) + 24 B.
PARTICLE_BYTES, EVENT_BYTES, ADAPTIVE_BYTES = 44, 8, 24
# Sprites per slot (engine/render/sprites.py): geometry, look, tail, info, tiles (vec4 each) and
# the soft distance = 84 B, and 1.5 tile pairs of 64 B (at least 2^14 pairs per image size).
SPRITE_BYTES, PAIR_BYTES, MIN_PAIRS = 84, 64, 1 << 14
# Render targets per pixel (engine/render/targets.py): background colour + coverage (vec4),
# depth, packed background, the two splat accumulators (vec4 each) = 56 B; per reduced-layer
# texel depth and accumulators (36 B) and 16 B per pixel for the layer's rows; soft bodies add a
# visibility key, line sums, the frame's background and depth (44 B).
PIXEL_BYTES, TEXEL_BYTES, MESH_PIXEL_BYTES = 56, 36, 44
# Spring networks (f32): per node mass, pins, position, velocity, RK stages (up to 4), adaptive
# copies and the mesh layer; per spring endpoints, rest length, ks, kd, adjacency, colour, XPBD λ.
NODE_BYTES, SPRING_BYTES = 256, 64
# Springs per node at most: chain and hair (structural + bend), cloth (structural, shear, bend
# in both directions), jelly (structural 3, face and body diagonals 10, bend 3).
# A solid: 6 tetrahedra per cell, so per node about 6 tets of ~110 B (nodes, rest volume, B, λ, four
# force slots) plus its four CSR slots: 12 springs' worth. Energy terms on other bodies add at most
# a few per node (hinges, triangles, tets): 4 more.
SPRINGS_PER_NODE = {"chain": 2, "hair": 2, "cloth": 6, "jelly": 16, "solid": 12}

DEFAULT_MAX_MEMORY = 4 << 30  # 4 GiB
DEFAULT_MAX_STEPS = 2_000_000  # integrator steps (particle steps, or a body's substeps) per run
DEFAULT_MAX_WORK = 200_000_000_000  # element-steps: minutes of stepping on 2 cores at ~250 M/s

_UNITS = {"": 1, "b": 1, "k": 1 << 10, "kb": 1 << 10, "m": 1 << 20, "mb": 1 << 20, "g": 1 << 30,
          "gb": 1 << 30, "t": 1 << 40, "tb": 1 << 40, "kib": 1 << 10, "mib": 1 << 20,
          "gib": 1 << 30, "tib": 1 << 40}


def parse_bytes(text: str) -> int:
    """'4GB', '512MB', '1.5g', '1000000' → bytes (binary units: 1 GB = 2^30 bytes). ValueError
    for anything else or a size that is not positive."""
    m = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]*)?|\.[0-9]+)\s*([a-zA-Z]*)\s*", str(text))
    if not m or m.group(2).lower() not in _UNITS:
        raise ValueError("is not a size such as 4GB, 512MB or 100000000")
    value = float(m.group(1)) * _UNITS[m.group(2).lower()]
    if not 1 <= value <= 1 << 60:
        raise ValueError("must be at least 1 byte and at most 1 EB")
    return int(value)


def human_bytes(n: float) -> str:
    for unit, size in (("TB", 1 << 40), ("GB", 1 << 30), ("MB", 1 << 20), ("KB", 1 << 10)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{int(n)} B"


def body_nodes(b) -> int:
    """Nodes of a config Body, from its shape alone (engine/bodies.py builds the same count)."""
    if b.type == "chain":
        return b.segments + 1
    if b.type == "hair":
        return b.strands * (b.segments + 1)
    return math.prod(b.resolution)


@dataclass
class Estimate:
    """What a run will cost. ``memory`` in bytes with its ``parts``; ``steps`` the most
    integrator steps of any one system (particles or a body); ``work`` element-steps."""

    memory: int
    parts: dict
    steps: int
    work: int
    frames: int

    def describe_memory(self) -> str:
        shown = ", ".join(f"{k} {human_bytes(v)}" for k, v in self.parts.items() if v)
        return f"about {human_bytes(self.memory)} ({shown})"


def estimate(cfg, width: int, height: int, frames_in_flight: int, body_substeps=None) -> Estimate:
    """Estimate ``cfg`` (a validated config) rendered at ``width`` × ``height`` with that many
    frames held for encoding. ``body_substeps(k, body)`` gives body k's substeps per frame (None:
    1, or the body's explicit ``substeps``)."""
    frames = cfg.frame_count
    frame_dt = 1.0 / cfg.fps
    parts = {}
    slots = sum(pool_sizes(cfg.emitters, frame_dt)) if cfg.emitters else 0
    events = any(em.sub_emitters for em in cfg.emitters)
    per_slot = (PARTICLE_BYTES + (EVENT_BYTES if events else 0)
                + (ADAPTIVE_BYTES if cfg.solver.adaptive else 0))
    parts["particles"] = slots * per_slot
    parts["sprites"] = slots * SPRITE_BYTES
    nodes = [body_nodes(b) for b in cfg.bodies]
    parts["bodies"] = sum(n * (NODE_BYTES + (SPRINGS_PER_NODE[b.type] + (4 if b.energies else 0)) * SPRING_BYTES)
                          for n, b in zip(nodes, cfg.bodies))
    pixels = width * height
    scale = 1.0
    if slots:
        scale = particle_scale(cfg.render.particle_resolution, height)
    texels = math.ceil(width * scale) * math.ceil(height * scale) if scale < 1 else 0
    rows = math.ceil(height * scale) * width if scale < 1 else 0
    parts["sprites"] += max(MIN_PAIRS, int(1.5 * slots)) * PAIR_BYTES if slots else 0
    parts["render targets"] = (pixels * PIXEL_BYTES + texels * TEXEL_BYTES + rows * 16
                               + (pixels * MESH_PIXEL_BYTES if cfg.bodies else 0))
    parts["frames in flight"] = pixels * 4 * frames_in_flight
    # Steps: fixed steps are exact (equal substeps landing on each frame); adaptive runs start at
    # h and the controller may grow it, so h is the estimate's step there too.
    from engine.ode.driver import substeps

    per_frame = substeps(frame_dt, cfg.solver.h) if slots else 0
    steps = [per_frame * frames]
    work = slots * per_frame * frames
    for k, (b, n) in enumerate(zip(cfg.bodies, nodes)):
        sub = body_substeps(k, b) if body_substeps else (b.substeps if isinstance(b.substeps, int) else 1)
        steps.append(sub * frames)
        work += n * sub * frames
    return Estimate(memory=sum(parts.values()), parts=parts, steps=max(steps), work=work,
                    frames=frames)


def problems(est: Estimate, max_memory: int, max_steps: int, max_work: int) -> list:
    """One line per budget the estimate passes, naming the flag that raises it."""
    out = []
    if est.memory > max_memory:
        out.append(f"--max-memory: the run needs {est.describe_memory()}, over the limit of "
                   f"{human_bytes(max_memory)}; lower the emitters' rate, lifetime or capacity, the "
                   f"image size, or raise --max-memory")
    if est.steps > max_steps:
        out.append(f"--max-steps: the run plans {est.steps:,} integrator steps ({est.frames:,} "
                   f"frames), over the limit of {max_steps:,}; raise solver.h, lower frames or "
                   f"duration, or raise --max-steps")
    if est.work > max_work:
        out.append(f"--max-work: the run plans {est.work:.3g} element-steps (steps × particle "
                   f"slots and spring nodes), over the limit of {max_work:.3g}; shrink the scene "
                   f"or raise --max-work")
    return out
