"""Reference kernels for the bench: the STREAM-like in-place bandwidth limit (two ways).

(no ``from __future__ import annotations``: Taichi reads kernel annotations at definition)
"""
import taichi as ti


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
def stream_rmw_rows(rows: ti.template(), a: ti.f32, b: ti.f32):
    """The same read-modify-write over a field of 8-float rows (32 bytes each, one a particle):
    whole-row loads and stores, the compiler's vector instructions. On the engine's own fields
    the kernel above is only as fast as their layout lets a slot-at-a-time loop be (on 2 cores of
    an AMD EPYC at 4M: 49 GB/s against this one's 64, 2026-12-02); the bench takes the faster."""
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
