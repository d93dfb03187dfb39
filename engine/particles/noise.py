"""Curl noise (Bridson, Houriham & Nordenstam, "Curl-Noise for Procedural Fluid Flow", 2007).

A vector potential ψ made of three independent value-noise fields; the velocity-like field
u = ∇ × ψ is divergence-free by construction (div curl = 0), so particles swirl without bunching
up or thinning out. The gradient of each noise field is analytic (quintic fade, Quílez-style
derivative), so one evaluation costs 8 hashed lattice corners per component and no finite
differences.
"""
import taichi as ti

from .rng import pcg_hash


@ti.func
def _lattice(ix, iy, iz, seed):
    h = pcg_hash(ti.cast(ix, ti.u32) * ti.u32(73856093) ^ ti.cast(iy, ti.u32) * ti.u32(19349663)
                 ^ ti.cast(iz, ti.u32) * ti.u32(83492791) ^ ti.cast(seed, ti.u32) * ti.u32(2654435761))
    return ti.cast(h >> ti.u32(8), ti.f32) * (2.0 / 16777216.0) - 1.0


@ti.func
def value_noise_grad(p, seed):
    """Value noise in [−1, 1] at p (vec3) and its gradient (vec3)."""
    fl = ti.floor(p)
    f = p - fl
    i = ti.cast(fl, ti.i32)
    u = f * f * f * (f * (f * 6.0 - 15.0) + 10.0)
    du = 30.0 * f * f * (f * (f - 2.0) + 1.0)
    a = _lattice(i[0], i[1], i[2], seed)
    b = _lattice(i[0] + 1, i[1], i[2], seed)
    c = _lattice(i[0], i[1] + 1, i[2], seed)
    d = _lattice(i[0] + 1, i[1] + 1, i[2], seed)
    e = _lattice(i[0], i[1], i[2] + 1, seed)
    f1 = _lattice(i[0] + 1, i[1], i[2] + 1, seed)
    g = _lattice(i[0], i[1] + 1, i[2] + 1, seed)
    h = _lattice(i[0] + 1, i[1] + 1, i[2] + 1, seed)
    k1, k2, k3 = b - a, c - a, e - a
    k4 = a - b - c + d
    k5 = a - c - e + g
    k6 = a - b - e + f1
    k7 = -a + b + c - d + e - f1 - g + h
    val = a + k1 * u[0] + k2 * u[1] + k3 * u[2] + k4 * u[0] * u[1] + k5 * u[1] * u[2] \
        + k6 * u[2] * u[0] + k7 * u[0] * u[1] * u[2]
    grad = du * ti.Vector([
        k1 + k4 * u[1] + k6 * u[2] + k7 * u[1] * u[2],
        k2 + k5 * u[2] + k4 * u[0] + k7 * u[2] * u[0],
        k3 + k6 * u[0] + k5 * u[1] + k7 * u[0] * u[1]])
    return val, grad


@ti.func
def curl_noise(p, octaves: ti.template()):
    """∇ × ψ at p for ψ = (N₁, N₂, N₃), summed over octaves (×2 frequency, ×½ amplitude)."""
    out = ti.Vector([0.0, 0.0, 0.0])
    amp = 1.0
    q = p
    for o in ti.static(range(octaves)):
        _, g1 = value_noise_grad(q, 11 + 3 * o)
        _, g2 = value_noise_grad(q, 12 + 3 * o)
        _, g3 = value_noise_grad(q, 13 + 3 * o)
        out += amp * ti.Vector([g3[1] - g2[2], g1[2] - g3[0], g2[0] - g1[1]])
        amp *= 0.5
        q = q * 2.0 + 17.31
    return out
