"""Curl noise (Bridson, Houriham & Nordenstam, "Curl-Noise for Procedural Fluid Flow", 2007).

A vector potential ψ made of three value-noise fields; the field u = ∇ × ψ is divergence-free by
construction (div curl = 0), so particles swirl without bunching up or thinning out. Gradients are
analytic (quintic fade), so there are no finite differences; the three potentials share one
lattice hash per corner (three 10-bit fields of it), so an octave costs 8 hashes.
"""
import taichi as ti

from .rng import pcg_hash


@ti.func
def _lattice3(ix, iy, iz, seed):
    h = pcg_hash(ti.cast(ix, ti.u32) * ti.u32(73856093) ^ ti.cast(iy, ti.u32) * ti.u32(19349663)
                 ^ ti.cast(iz, ti.u32) * ti.u32(83492791) ^ ti.cast(seed, ti.u32) * ti.u32(2654435761))
    m = ti.u32(1023)
    return ti.Vector([ti.cast(h & m, ti.f32), ti.cast((h >> ti.u32(10)) & m, ti.f32),
                      ti.cast((h >> ti.u32(20)) & m, ti.f32)]) * (2.0 / 1023.0) - 1.0


@ti.func
def value_noise3_grad(p, seed):
    """Three value-noise fields at p: values (vec3, each in [−1, 1]) and their gradients as
    (∂/∂x, ∂/∂y, ∂/∂z), each a vec3 over the three fields."""
    fl = ti.floor(p)
    f = p - fl
    i = ti.cast(fl, ti.i32)
    u = f * f * f * (f * (f * 6.0 - 15.0) + 10.0)
    du = 30.0 * f * f * (f * (f - 2.0) + 1.0)
    a = _lattice3(i[0], i[1], i[2], seed)
    b = _lattice3(i[0] + 1, i[1], i[2], seed)
    c = _lattice3(i[0], i[1] + 1, i[2], seed)
    d = _lattice3(i[0] + 1, i[1] + 1, i[2], seed)
    e = _lattice3(i[0], i[1], i[2] + 1, seed)
    f1 = _lattice3(i[0] + 1, i[1], i[2] + 1, seed)
    g = _lattice3(i[0], i[1] + 1, i[2] + 1, seed)
    h = _lattice3(i[0] + 1, i[1] + 1, i[2] + 1, seed)
    k1, k2, k3 = b - a, c - a, e - a
    k4 = a - b - c + d
    k5 = a - c - e + g
    k6 = a - b - e + f1
    k7 = -a + b + c - d + e - f1 - g + h
    val = a + k1 * u[0] + k2 * u[1] + k3 * u[2] + k4 * (u[0] * u[1]) + k5 * (u[1] * u[2]) \
        + k6 * (u[2] * u[0]) + k7 * (u[0] * u[1] * u[2])
    gx = du[0] * (k1 + k4 * u[1] + k6 * u[2] + k7 * (u[1] * u[2]))
    gy = du[1] * (k2 + k5 * u[2] + k4 * u[0] + k7 * (u[2] * u[0]))
    gz = du[2] * (k3 + k6 * u[0] + k5 * u[1] + k7 * (u[0] * u[1]))
    return val, gx, gy, gz


@ti.func
def curl_noise(p, octaves: ti.template()):
    """∇ × ψ at p for ψ = (N₁, N₂, N₃), summed over octaves (×2 frequency, ×½ amplitude)."""
    out = ti.Vector([0.0, 0.0, 0.0])
    amp = 1.0
    q = p
    for o in ti.static(range(octaves)):
        _, gx, gy, gz = value_noise3_grad(q, 11 + o)
        out += amp * ti.Vector([gy[2] - gz[1], gz[0] - gx[2], gx[1] - gy[0]])
        amp *= 0.5
        q = q * 2.0 + 17.31
    return out
