"""Reference kernels for the bench: the STREAM-like in-place bandwidth limit (three ways).

(no ``from __future__ import annotations``: Taichi reads kernel annotations at definition)
"""
import taichi as ti

from engine.particles.pool import LANES


@ti.kernel
def stream_rmw(pos: ti.template(), vel: ti.template(), age: ti.template(), life: ti.template(),
               a: ti.f32, b: ti.f32):
    """Read and write every byte of a particle's 32-byte state once: the physical limit of a
    particle step that must touch its state (a·x + b keeps the values bounded and finite)."""
    for i in pos:
        pos[i] = pos[i] * a + b
        vel[i] = vel[i] * a + b
        age[i] = age[i] * a + b
        life[i] = life[i] * a + b


@ti.kernel
def stream_rmw_blocks(pos: ti.template(), vel: ti.template(), age: ti.template(),
                      life: ti.template(), a: ti.f32, b: ti.f32, blocks: ti.i32):
    """:func:`stream_rmw` over a pool kept in blocks of LANES slots (engine.particles.pool), a
    block at a time, each component's LANES values together (as the step walks them):
    neighbouring memory, so vector loads and stores. The slot-at-a-time loop above is the compiler's scalar
    code on that layout (the bench's 4M pool on 2 cores of an Intel Xeon: 11.5-11.8 ms against
    this one's 5.2-5.4 and the rows' 4.8; at 1M 1.33 against 0.74 and 0.95: the rows alone
    understated the limit there, 2026-12-02)."""
    for k in range(blocks):
        for c in ti.static(range(3)):
            for j in ti.static(range(LANES)):
                pos[k * LANES + j][c] = pos[k * LANES + j][c] * a + b
        for c in ti.static(range(3)):
            for j in ti.static(range(LANES)):
                vel[k * LANES + j][c] = vel[k * LANES + j][c] * a + b
        for j in ti.static(range(LANES)):
            age[k * LANES + j] = age[k * LANES + j] * a + b
        for j in ti.static(range(LANES)):
            life[k * LANES + j] = life[k * LANES + j] * a + b


@ti.kernel
def stream_rmw_rows(rows: ti.template(), a: ti.f32, b: ti.f32):
    """The same read-modify-write over a field of 8-float rows (32 bytes each, one a particle):
    whole-row loads and stores, the compiler's vector instructions. On the engine's own fields
    the kernel above is only as fast as their layout lets a slot-at-a-time loop be (on 2 cores of
    an AMD EPYC at 4M: 49 GB/s against this one's 64, 2026-12-02); the bench takes the fastest
    of the three (a blocked pool's own fields: :func:`stream_rmw_blocks`)."""
    for i in rows:
        rows[i] = rows[i] * a + b


@ti.kernel
def scale_field(x: ti.template(), a: ti.f32):
    """x *= a over a field: specialised (compiled) once per field it is given."""
    for i in x:
        x[i] *= a


@ti.kernel
def scale_ndarray(x: ti.types.ndarray(dtype=ti.f32, ndim=1), a: ti.f32):
    """x *= a over an ndarray: compiled once per dtype and rank, whatever array it is given."""
    for i in x:
        x[i] *= a
