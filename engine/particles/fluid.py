"""Position-based fluids' terms (Macklin & Müller 2013) for :class:`~engine.particles.interact.Interactions`:
the kernels (poly6 for density, spiky's gradient; Müller et al. 2003), the rest density of a cubic
lattice, and the per-slot gathers — λ (eqs. 1, 8–11), Δp with s_corr (eqs. 13–14), XSPH viscosity
(eq. 17), vorticity (eqs. 15–16) and Akinci et al. 2013's cohesion. Each gather visits slot i's
neighbour list (engine.geometry.grid) and sums its own terms: Jacobi, no float atomics.
"""
import math

import numpy as np
import taichi as ti

S_CORR_K, S_CORR_DQ, S_CORR_N = 0.1, 0.2, 4  # Macklin & Müller 2013, §4 (k, Δq/h, n)
FLUID_EPS = 0.01  # λ relaxation ε, as a fraction of the lattice's Σ|∇C|²


def poly6(r, h):
    """Müller et al. 2003's poly6 kernel W(r, h), 1/m³."""
    return 315.0 / (64.0 * math.pi * h ** 9) * (h * h - r * r) ** 3 if r < h else 0.0


def spiky_grad(r, h):
    """|∇W_spiky(r, h)|, 1/m⁴ (the gradient points along −r̂)."""
    return 45.0 / (math.pi * h ** 6) * (h - r) ** 2 if 0 < r < h else 0.0


def lattice_constants(s, h):
    """ρ₀ = Σ W over a cubic lattice of spacing s (self included) and G₀ = Σ_k |∇_k C|² there
    (the denominator of λ at rest), both with m = 1."""
    n = int(math.ceil(h / s))
    rho, grads = 0.0, []
    for a in range(-n, n + 1):
        for b in range(-n, n + 1):
            for c in range(-n, n + 1):
                r = s * math.sqrt(a * a + b * b + c * c)
                rho += poly6(r, h)
                if r > 0:
                    g = spiky_grad(r, h)
                    grads.append(np.array([a, b, c], float) * s / r * g)
    grads = np.array(grads) / rho
    g0 = float((grads ** 2).sum() + (grads.sum(0) ** 2).sum())
    return rho, g0


class FluidTerms:
    """The fluid half of :class:`~engine.particles.interact.Interactions` (a mixin: ``f_h``,
    ``f_rho0``, ``f_eps``, ``f_wdq``, ``f_scorr``, ``f_visc``, ``f_vort``, ``f_tension``,
    ``f_cmax``, ``lam``, ``omega``, ``lists``, ``slot_kind`` and ``state`` are the table's)."""

    # The kernels and the gathers below have no branch on the distance: each term is computed and
    # one outside the support is replaced by zero (ti.select). About 4 in 10 listed neighbours lie
    # outside (the lists reach 1.2 h), so a branch on it mispredicts often, and a loop without
    # one is compiled to straight-line code: water's sweep 1.34 → 0.52 ms (2,500 members). The
    # sums' rounding moved with it (the compiler may order a branch-free sum's additions
    # differently): still one fixed order per particle, the same for any thread count.
    @ti.func
    def _w(self, r2):
        """poly6 W at r² = r2 (0 outside the support), 1/m³."""
        h2 = self.f_h * self.f_h
        return ti.select(r2 < h2, 315.0 / (64.0 * math.pi * self.f_h ** 9) * (h2 - r2) ** 3, 0.0)

    @ti.func
    def _gw(self, r, d):
        """∇W_spiky at r (|r| = d): −45/(π h⁶)(h − d)² r̂ for 0 < d < h, else 0 (the value at d = 0,
        a division by zero, is discarded by the select)."""
        return ti.select((0.0 < d) & (d < self.f_h),
                         -45.0 / (math.pi * self.f_h ** 6) * (self.f_h - d) ** 2 / d * r,
                         ti.Vector([0.0, 0.0, 0.0]))

    @ti.func
    def _fluid_lambda(self, i):
        """λ_i = −C_i / (Σ_k |∇_k C_i|² + ε) (Macklin & Müller 2013, eqs. 1, 8–11)."""
        xi = self.state.particle_pos[i]
        rho = self._w(0.0)
        gi = ti.Vector([0.0, 0.0, 0.0])
        sq = 0.0
        self.lists.visit(i, self.slot_kind, 2, self._density_pair, (xi, rho, gi, sq))
        C = ti.max(rho / self.f_rho0 - 1.0, 0.0)
        return -C / (sq + gi.dot(gi) + self.f_eps)

    @ti.func
    def _density_pair(self, j, xi, rho: ti.template(), gi: ti.template(), sq: ti.template()):
        """Fluid slot j's share of the density at xi (rho), of ∇_i C (gi) and of Σ|∇_j C|² (sq)."""
        r = xi - self.state.particle_pos[j]
        d2 = r.dot(r)
        rho += self._w(d2)
        g = self._gw(r, ti.sqrt(d2)) / self.f_rho0
        gi += g
        sq += g.dot(g)

    @ti.func
    def _fluid_delta(self, i):
        """Δp_i = (1/ρ₀) Σ_j (λ_i + λ_j + s_corr) ∇W(p_i − p_j) (eq. 14; s_corr eq. 13)."""
        xi = self.state.particle_pos[i]
        li = self.lam[i]
        dx = ti.Vector([0.0, 0.0, 0.0])
        self.lists.visit(i, self.slot_kind, 2, self._delta_pair, (xi, li, dx))
        return dx / self.f_rho0

    @ti.func
    def _delta_pair(self, j, xi, li, dx: ti.template()):
        r = xi - self.state.particle_pos[j]
        d2 = r.dot(r)
        q = self._w(d2) / self.f_wdq
        s_corr = -self.f_scorr * q ** S_CORR_N
        dx += (li + self.lam[j] + s_corr) * self._gw(r, ti.sqrt(d2))  # (0 where ∇W is)

    @ti.func
    def _fluid_velocity(self, i, h):
        """XSPH (eq. 17, normalised by ρ₀), vorticity confinement (eq. 16: ε (N × ω), ε in m/s) and
        Akinci's cohesion (γ in m/s² at the kernel's peak) for fluid slot i; the new velocity."""
        S = self.state
        xi, vi, wi = S.particle_pos[i], S.particle_vel[i], self.omega[i]
        xs = ti.Vector([0.0, 0.0, 0.0])
        eta = ti.Vector([0.0, 0.0, 0.0])
        st = ti.Vector([0.0, 0.0, 0.0])
        self.lists.visit(i, self.slot_kind, 2, self._velocity_pair, (xi, vi, wi, xs, eta, st))
        v = vi + self.f_visc * xs / self.f_rho0
        if ti.static(self.f_vort > 0):
            en = eta.norm()
            if en > 1e-12:
                v += h * self.f_vort * (eta / en).cross(wi)
        if ti.static(self.f_tension > 0):
            v += h * self.f_tension * st
        return v

    @ti.func
    def _velocity_pair(self, j, xi, vi, wi, xs: ti.template(), eta: ti.template(), st: ti.template()):
        """Fluid slot j's terms for the slot at xi (velocity vi, vorticity wi): XSPH into xs, the
        vorticity's gradient into eta, Akinci's cohesion into st."""
        S = self.state
        hk = self.f_h
        r = xi - S.particle_pos[j]
        d2 = r.dot(r)
        d = ti.sqrt(d2)
        zero = ti.Vector([0.0, 0.0, 0.0])
        inside = (0.0 < d2) & (d2 < hk * hk)  # (branch-free, as the kernels above)
        xs += ti.select(inside, (S.particle_vel[j] - vi) * self._w(d2), zero)
        if ti.static(self.f_vort > 0):
            eta += (self.omega[j].norm() - wi.norm()) * self._gw(r, d)
        if ti.static(self.f_tension > 0):
            cr = ti.select(2.0 * d > hk, (hk - d) ** 3 * d ** 3, 2.0 * (hk - d) ** 3 * d ** 3 - hk ** 6 / 64.0)
            st -= ti.select(inside, (32.0 / (math.pi * hk ** 9) * cr / self.f_cmax) * (r / d), zero)

    @ti.func
    def _vorticity(self, i):
        """ω_i = Σ_j v_ij × ∇_j W(p_i − p_j) / ρ₀ (eq. 15), 1/s."""
        S = self.state
        xi, vi = S.particle_pos[i], S.particle_vel[i]
        w = ti.Vector([0.0, 0.0, 0.0])
        self.lists.visit(i, self.slot_kind, 2, self._vorticity_pair, (xi, vi, w))
        return w / self.f_rho0

    @ti.func
    def _vorticity_pair(self, j, xi, vi, w: ti.template()):
        S = self.state
        r = xi - S.particle_pos[j]
        w += (S.particle_vel[j] - vi).cross(-self._gw(r, ti.sqrt(r.dot(r))))  # (0 outside)
