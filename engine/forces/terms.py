"""Interaction terms, each defined once: its energy ψ, its gradient (the force is −∇ψ) and, where
one exists, its constraint form C with ψ = ½ k C² (XPBD projects C with compliance α = 1/k).

Every function is a ``ti.func`` of an element's k node positions (3-vectors of the caller's dtype,
passed as ``dt``) and its parameters, so the explicit force kernels (engine.springs.forces,
engine.forces.elements), the XPBD projections (engine.xpbd) and the energy diagnostics evaluate the
same code. Positions in m, energy in J; each term's stiffness unit is given below.

Terms (PHYSICS.md, "Energy-based models"):

* Hooke spring (a, b; rest length r; ks N/m, kd N·s/m): C = |x_a − x_b| − r, ∇_a C = n̂ = −∇_b C;
  ψ = ½ ks C²; the damped force on a is −(ks C + kd (v_a − v_b)·n̂) n̂ (NUMERICS.md).
* dihedral bending (hinge edge a–b, wings c, d; rest angle θ₀; k in N·m per hinge): ψ = ½ k (θ−θ₀)²,
  C = θ − θ₀ with θ the signed angle between the two triangle normals; ∇θ in closed form
  (Bridson, Marino & Fedkiw 2003, "Simulation of clothing with folds and wrinkles", §4, the vectors
  u₁…u₄). A flat hinge is a regular point (θ = 0, ∇θ ≠ 0); a zero-area wing gives no force.
* area (triangle a, b, c; rest area A₀; K in N/m): ψ = ½ (K/A₀)(A − A₀)², C = A − A₀,
  ∇_a A = ½ (b − c) × n̂ (cyclic).
* volume (tetrahedron a, b, c, d; rest volume V₀; K in Pa): ψ = ½ (K/V₀)(V − V₀)², C = V − V₀,
  V = (b − a)·((c − a) × (d − a))/6 signed, ∇_b V = (c − a) × (d − a)/6 (cyclic), ∇_a V = −Σ.
  A collapsed tetrahedron (V = 0) is a regular point.
* hyperelastic tetrahedra (rest inverse edge matrix B = D_m⁻¹, rest volume V₀, Lamé μ, λ in Pa):
  F = D_s B, ψ = V₀ Ψ(F), forces on b, c, d the columns of −V₀ P(F) Bᵀ, on a minus their sum
  (Sifakis & Barbič 2012, "FEM simulation of 3D deformable solids", §4.2). Ψ: StVK; the fixed
  corotated form (Stomakhin et al. 2012), J F⁻ᵀ written as the cofactor so a collapsed tet stays
  defined; and the stable neo-Hookean of Smith, de Goes & Kim 2018 (eq. 14 with their §3.4 Lamé
  mapping μ' = 4μ/3, λ' = λ + 5μ/6, α = 1 + 3μ'/(4λ'): :func:`nh_params`), shifted so Ψ(I) = 0.
  Kelvin–Voigt damping η (Pa·s) adds the viscous stress η (Ḟ + Ḟᵀ) with Ḟ = D_v B.
"""
import math

import taichi as ti

EPS = 1e-12  # below this a length, area or normal is degenerate: the term gives no force

MODELS = ("neo_hookean", "stvk", "corotated")
NEO_HOOKEAN, STVK, COROTATED = 0, 1, 2


def lame(young: float, poisson: float):
    """(μ, λ) in Pa from Young's modulus E (Pa) and Poisson's ratio ν (−1 < ν < 0.5)."""
    mu = young / (2.0 * (1.0 + poisson))
    lam = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson))
    return mu, lam


def nh_params(mu: float, lam: float):
    """Stable neo-Hookean constants (μ', λ', α, Ψ₀) for Lamé (μ, λ) (Smith et al. 2018, §3.4):
    μ' = 4μ/3 and λ' = λ + 5μ/6 reproduce linear elasticity at small strain; α = 1 + 3μ'/(4λ')
    makes F = I stress-free (P(I) = (3μ'/4 + λ'(1 − α)) I = 0); Ψ₀ = Ψ(I) is subtracted."""
    mu_s, lam_s = 4.0 * mu / 3.0, lam + 5.0 * mu / 6.0
    alpha = 1.0 + 0.75 * mu_s / lam_s
    psi0 = 0.5 * lam_s * (1.0 - alpha) ** 2 - 0.5 * mu_s * math.log(4.0)
    return mu_s, lam_s, alpha, psi0


# -- Hooke spring ----------------------------------------------------------------------------------
@ti.func
def hooke_constraint(dt: ti.template(), xa: ti.template(), xb: ti.template(), r: ti.template()):
    """(C, n̂, ok): C = |x_a − x_b| − r and ∇_a C = n̂ = −∇_b C; ok is 0 when a and b coincide
    (no direction: the term gives nothing). Arguments are templates (substituted, not copied):
    Taichi compiles with fast math, so copies change which operations LLVM fuses, and the springs'
    bytes depend on that."""
    L = xa - xb
    ln = L.norm()
    return ln - r, L / ln, ln > EPS  # n̂ and C are used only where ok (no branch: same bytes)


@ti.func
def hooke_force(dt: ti.template(), xa: ti.template(), xb: ti.template(), va: ti.template(), vb: ti.template(),
                ks: ti.template(), kd: ti.template(), r: ti.template()):
    """The damped Hooke force on end a, −(ks C + kd (v_a − v_b)·n̂) n̂ with C = |L| − r, n̂ = L/|L|
    (end b receives its negative): −∂ψ/∂x_a of ψ = ½ ks C² plus the dashpot along the spring, from
    the term's own C and n̂. Template arguments, as for the constraint: the springs' bytes."""
    C, n, ok = hooke_constraint(dt, xa, xb, r)
    f = ti.Vector.zero(dt, 3)
    if ok:
        f = -(ks * C + kd * (va - vb).dot(n)) * n
    return f


@ti.func
def hooke_energy(dt: ti.template(), xa, xb, ks, r):
    """ψ = ½ ks (|x_a − x_b| − r)² (J); the same C as the force and the constraint."""
    C, n, ok = hooke_constraint(dt, xa, xb, r)
    return 0.5 * ks * C * C


# -- dihedral bending --------------------------------------------------------------------------------
@ti.func
def dihedral_angle(dt: ti.template(), a, b, c, d):
    """(θ, ∇_a θ, ∇_b θ, ∇_c θ, ∇_d θ, ok) for the hinge a–b with wings c (triangle a, b, c) and d.
    θ ∈ (−π, π] is 0 for a flat hinge. Bridson et al. 2003, §4: with E = b − a,
    N₁ = (c − a) × (c − b), N₂ = (d − b) × (d − a): ∇_c θ = |E| N₁/|N₁|², ∇_d θ = |E| N₂/|N₂|²,
    ∇_a θ = (c − b)·E/|E| N₁/|N₁|² + (d − b)·E/|E| N₂/|N₂|², ∇_b θ = −(∇_a + ∇_c + ∇_d)."""
    E = b - a
    el = E.norm()
    N1 = (c - a).cross(c - b)
    N2 = (d - b).cross(d - a)
    n1, n2 = N1.norm_sqr(), N2.norm_sqr()
    th = ti.cast(0, dt)
    ga = ti.Vector.zero(dt, 3)
    gb = ti.Vector.zero(dt, 3)
    gc = ti.Vector.zero(dt, 3)
    gd = ti.Vector.zero(dt, 3)
    ok = 0
    if el > EPS and n1 > EPS * EPS and n2 > EPS * EPS:
        e = E / el
        th = ti.atan2(N2.cross(N1).dot(e), N1.dot(N2))  # |N₁||N₂| sin θ, |N₁||N₂| cos θ
        u1, u2 = N1 / n1, N2 / n2
        gc = el * u1
        gd = el * u2
        ga = (c - b).dot(e) * u1 + (d - b).dot(e) * u2
        gb = -(ga + gc + gd)
        ok = 1
    return th, ga, gb, gc, gd, ok


@ti.func
def wrap_angle(x):
    """x mapped into (−π, π] (a hinge folding through ±π keeps a small C)."""
    y = x
    if y > math.pi:
        y -= 2 * math.pi
    elif y <= -math.pi:
        y += 2 * math.pi
    return y


# -- area -------------------------------------------------------------------------------------------
@ti.func
def triangle_area(dt: ti.template(), a, b, c):
    """(A, ∇_a A, ∇_b A, ∇_c A): A = ½|(b − a) × (c − a)|; ∇_a A = ½ (b − c) × n̂ (cyclic);
    zero gradients for a degenerate triangle."""
    n = (b - a).cross(c - a)
    nl = n.norm()
    ga = ti.Vector.zero(dt, 3)
    gb = ti.Vector.zero(dt, 3)
    gc = ti.Vector.zero(dt, 3)
    if nl > EPS * EPS:
        nh = n / nl
        ga = 0.5 * (b - c).cross(nh)
        gb = 0.5 * (c - a).cross(nh)
        gc = 0.5 * (a - b).cross(nh)
    return 0.5 * nl, ga, gb, gc


# -- volume -----------------------------------------------------------------------------------------
@ti.func
def tet_volume(dt: ti.template(), a, b, c, d):
    """(V, ∇_a V, ∇_b V, ∇_c V, ∇_d V): the signed volume (b − a)·((c − a) × (d − a))/6."""
    e1, e2, e3 = b - a, c - a, d - a
    gb = e2.cross(e3) / 6
    gc = e3.cross(e1) / 6
    gd = e1.cross(e2) / 6
    return e1.dot(gb), -(gb + gc + gd), gb, gc, gd


# -- hyperelastic tetrahedra ------------------------------------------------------------------------
@ti.func
def cofactor(F):
    """J F⁻ᵀ without the inverse: columns F₁ × F₂, F₂ × F₀, F₀ × F₁ (defined for J = 0)."""
    c0 = F[:, 1].cross(F[:, 2])
    c1 = F[:, 2].cross(F[:, 0])
    c2 = F[:, 0].cross(F[:, 1])
    return ti.Matrix.cols([c0, c1, c2])


@ti.func
def elastic_density(dt: ti.template(), model: ti.template(), F, mu, lam):
    """(Ψ(F) in J/m³, P(F) = ∂Ψ/∂F in Pa) for ``model`` (a compile-time index into MODELS); for the
    neo-Hookean, (mu, lam) are already μ', λ' and α, Ψ₀ follow from them (:func:`nh_params`)."""
    I3 = ti.Matrix.identity(dt, 3)
    psi = ti.cast(0, dt)
    P = ti.Matrix.zero(dt, 3, 3)
    J = F.determinant()
    if ti.static(model == NEO_HOOKEAN):
        Ic = (F.transpose() @ F).trace()
        alpha = 1 + 0.75 * mu / lam
        psi0 = 0.5 * lam * (1 - alpha) ** 2 - 0.5 * mu * ti.log(ti.cast(4.0, dt))
        psi = 0.5 * mu * (Ic - 3) + 0.5 * lam * (J - alpha) ** 2 - 0.5 * mu * ti.log(Ic + 1) - psi0
        P = mu * (1 - 1 / (Ic + 1)) * F + lam * (J - alpha) * cofactor(F)
    elif ti.static(model == STVK):
        E = 0.5 * (F.transpose() @ F - I3)
        trE = E.trace()
        psi = mu * (E * E).sum() + 0.5 * lam * trE * trE
        P = F @ (2 * mu * E + lam * trE * I3)
    else:
        R, _ = ti.polar_decompose(F, dt)
        D = F - R
        psi = mu * (D * D).sum() + 0.5 * lam * (J - 1) ** 2
        P = 2 * mu * D + lam * (J - 1) * cofactor(F)
    return psi, P


@ti.func
def tet_elastic(dt: ti.template(), model: ti.template(), a, b, c, d, B, V0, mu, lam):
    """(ψ = V₀ Ψ(F) in J, ∇_a ψ, ∇_b ψ, ∇_c ψ, ∇_d ψ) for the tet with rest inverse edge matrix
    B = D_m⁻¹ (1/m) and rest volume V₀ (m³); F = [b − a, c − a, d − a] B."""
    Ds = ti.Matrix.cols([b - a, c - a, d - a])
    psi, P = elastic_density(dt, model, Ds @ B, mu, lam)
    H = V0 * P @ B.transpose()  # columns: ∂ψ/∂b, ∂ψ/∂c, ∂ψ/∂d
    gb, gc, gd = H[:, 0], H[:, 1], H[:, 2]
    return V0 * psi, -(gb + gc + gd), gb, gc, gd


@ti.func
def tet_viscous(dt: ti.template(), va, vb, vc, vd, B, V0, eta):
    """Kelvin–Voigt damping forces (N) on a, b, c, d: stress η (Ḟ + Ḟᵀ), Ḟ = [v_b − v_a, …] B;
    zero for a rigid motion at rest shape (Ḟ skew)."""
    Fd = ti.Matrix.cols([vb - va, vc - va, vd - va]) @ B
    H = -V0 * eta * (Fd + Fd.transpose()) @ B.transpose()
    fb, fc, fd = H[:, 0], H[:, 1], H[:, 2]
    return -(fb + fc + fd), fb, fc, fd
