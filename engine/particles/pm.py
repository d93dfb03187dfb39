"""Pair gravity beyond the direct sum: a particle–mesh (PM) approximation (Hockney & Eastwood,
*Computer Simulation Using Particles*, 1988, ch. 5–6), in NumPy on the host.

The direct sum a_i = G m Σ_j r_ij / (|r_ij|² + ε²)^{3/2} costs N² (engine.particles.interact, up to
``MAX_DIRECT`` slots; by default up to ``AUTO_DIRECT``). Beyond it the mass goes onto a grid of ``cells`` nodes per axis spanning the
particles' bounding box (each axis its own spacing) (cloud-in-cell: each particle's mass shared among the 8 nodes around it by
trilinear weights), the potential φ = ρ ∗ g with the softened Green's function
g(r) = −G / √(r² + ε²) by FFT on a grid padded to twice the size (so the convolution is the
isolated one, not a periodic image sum), the field a = −∇φ by central differences, and each
particle's acceleration gathered from the nodes with the *same* weights it deposited with.

Why this scheme: with the same weights for deposit and gather, a symmetric Green's function and an
antisymmetric difference operator, Σ_i m a_i = −ρᵀ (D g) ρ = 0 — no self-force, and the total
momentum is kept to the rounding of the FFT (Hockney & Eastwood §5-4; a tree code would not keep it).
Deterministic: ``np.add.at`` deposits in particle order and NumPy's FFT is serial, so the same
positions give the same bytes on any thread count. The price: forces are smoothed over about a
cell, so the effective softening is max(ε, ~1 cell) and close pairs are weaker than the direct sum's
(P3M would add the short-range pairs back; not built).

Cost: the deposit and gather are O(N) in NumPy, the FFTs O(M³ log M) on the (2M)³ padded grid:
about 10 ms for M = 32 and 30,000 particles on this machine's two cores.
"""
import numpy as np

CELLS = 32  # grid nodes per axis over the particles' bounding box (the FFTs run on 2·CELLS)
MAX_DIRECT = 20_000  # gravity slots summed over all pairs at most (method = "direct")
AUTO_DIRECT = 5_000  # method = "auto": the pair sum up to this many gravity slots, the mesh beyond
# (on two cores the two cost about the same near 5,500 slots, ~17 ms a step: the pair sum 2.5 ms at
# 2,000, 8.7 at 4,000, 34 at 8,000; the mesh 16–19 ms over that range, measured 2026-11-24 loaded)
MAX_MESH = 2_000_000  # gravity slots at most on the mesh (host arrays of N × 3 float64)


def _cic(x, origin, d, M):
    """(base node index (N, 3) int, trilinear fractions (N, 3)) of positions x on the grid."""
    u = (x - origin) / d
    i0 = np.clip(np.floor(u).astype(np.int64), 0, M - 2)
    return i0, u - i0


def _corners():
    for cx in (0, 1):
        for cy in (0, 1):
            for cz in (0, 1):
                yield cx, cy, cz


def _weights(f, c):
    wx = f[:, 0] if c[0] else 1.0 - f[:, 0]
    wy = f[:, 1] if c[1] else 1.0 - f[:, 1]
    wz = f[:, 2] if c[2] else 1.0 - f[:, 2]
    return wx * wy * wz


def pm_accelerations(x, G: float, mass: float, softening: float, cells: int = CELLS) -> np.ndarray:
    """(N, 3) float64 accelerations (m/s²) of N particles of equal ``mass`` (kg) at ``x`` (N, 3)
    under softened pair gravity (``G`` m³/(kg·s²), ``softening`` ε m), by particle–mesh on a grid
    of ``cells`` nodes per axis (module docstring)."""
    x = np.asarray(x, np.float64).reshape(-1, 3)
    N, M = len(x), int(cells)
    if N < 2:
        return np.zeros((N, 3))
    lo, hi = x.min(0), x.max(0)
    ext = hi - lo
    # cells fitted to each axis (a thin disk gets as many nodes across its thickness as along its
    # radius), a node of margin on each side; an axis with no extent takes the widest one's
    d = np.maximum(ext, max(float(ext.max()), 1e-9) * 1e-3) / (M - 3)
    origin = 0.5 * (lo + hi) - 0.5 * (M - 1) * d
    i0, f = _cic(x, origin, d, M)
    n = 2 * M
    rho = np.zeros((n, n, n))
    for c in _corners():  # mass on the nodes, in particle order (np.add.at: unbuffered, sequential)
        np.add.at(rho, (i0[:, 0] + c[0], i0[:, 1] + c[1], i0[:, 2] + c[2]), mass * _weights(f, c))
    k = np.minimum(np.arange(n), n - np.arange(n))  # node offsets on the padded, wrapped grid
    r2 = (k[:, None, None] * d[0]) ** 2 + (k[None, :, None] * d[1]) ** 2 + (k[None, None, :] * d[2]) ** 2
    green = -G / np.sqrt(r2 + softening * softening)
    phi = np.fft.irfftn(np.fft.rfftn(rho) * np.fft.rfftn(green), s=rho.shape, axes=(0, 1, 2))
    acc = np.zeros((N, 3))
    for axis in range(3):  # a = −∇φ, central differences (antisymmetric: no self-force)
        g = -(np.roll(phi, -1, axis) - np.roll(phi, 1, axis)) / (2.0 * d[axis])
        for c in _corners():
            acc[:, axis] += _weights(f, c) * g[i0[:, 0] + c[0], i0[:, 1] + c[1], i0[:, 2] + c[2]]
    return acc


def direct_accelerations(x, G: float, mass: float, softening: float) -> np.ndarray:
    """The direct sum a_i = G m Σ_{j≠i} r_ij / (|r_ij|² + ε²)^{3/2} in float64 (N² memory: a
    reference for tests and small N)."""
    x = np.asarray(x, np.float64).reshape(-1, 3)
    r = x[None, :, :] - x[:, None, :]
    d2 = (r ** 2).sum(-1) + softening * softening
    w = d2 ** -1.5
    np.fill_diagonal(w, 0.0)
    return G * mass * (r * w[..., None]).sum(1)
