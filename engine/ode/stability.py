"""Largest stable step of each stepper on a damped spring on an anchor, measured and predicted.

The spring: m q'' = −ks q − kd q' (ω² = ks/m, c = kd/m), y = (q, v), q(0) = 1, v(0) = 0.

*Measured* (:func:`largest_stable_h`): the engine's own ``ti.func`` stepper runs ``steps`` steps in
a batched kernel, one Taichi thread per candidate h (and per spring), deterministic. A run counts
as stable when it stays finite and the largest energy E = ½ m v² + ½ ks q² over the last tenth of
the run is at most a growth limit times the largest over the first tenth:

* damped (kd > 0): limit :data:`GROWTH_LIMIT_DAMPED` = 1.001. A stable damped run loses energy, so
  any net growth means instability. Growth below the limit goes unnoticed, so the measurement sits
  slightly above the linear-stability limit where the growth rate there is tiny (explicit Euler with
  kd = 1: +0.5% at ks = 1e5, <0.01% at ks = 100, over 20,000 steps).
* undamped (kd = 0): limit :data:`GROWTH_LIMIT_UNDAMPED` = 2. A stable run's energy only stays
  bounded and oscillates; when the rotation per step is close to a rational fraction of 2π the
  sampled peaks differ between windows by up to ~(hω)³/16 (a 1.001 limit flagged 28 of 8,000
  stable symplectic-Euler steps), so growth must be unmistakable. Methods with no stable step
  (explicit Euler, midpoint) then get the finite-run artefact: the h at which the energy doubles
  within the run, which → 0 as ``steps`` → ∞.

Bisection refines a grid of :data:`GRID` candidates per round to the first unstable step.

*Predicted* (:func:`theory_limit`): the spectral radius of the one-step matrix of the linear
spring, built in NumPy from the method's own data, independently of the Taichi steppers: R(hA)
with the tableau's stability polynomial for the RK methods, the product of the kick and drift
matrices for symplectic Euler and velocity Verlet in the engine's explicit form.

*For a network of damped oscillators* (:func:`oscillator_stable_step`, the springs' stiffness
guard): the largest h keeping every mode of λ² + cλ + ω² = 0 up to a bound ω_max stable.
"""
import math
from typing import Sequence, Union

import numpy as np
import taichi as ti

from ..runtime import ensure_init, on_reset
from .methods import method as _method
from .splitting import DRIFT, Splitting
from .steppers import is_finite, make_step

GRID = 64  # candidate steps per spring per bisection round
CAPACITY = 8192  # threads per kernel launch
GROWTH_LIMIT_DAMPED, GROWTH_LIMIT_UNDAMPED = 1.001, 2.0

_probes: dict = {}  # per method; dropped with the Taichi program (runtime.reset)


class _Probe:
    """Fields and the batched kernel for one method (built once)."""

    def __init__(self, method: str):
        self.par = par = ti.Vector.field(5, ti.f64, shape=CAPACITY)  # ks, kd, m, h, growth limit
        self.ok = ok = ti.field(ti.i32, shape=CAPACITY)

        @ti.func
        def spring(y, t, i):
            p = par[i]
            d = y * 0
            d[0] = y[1]
            d[1] = -(p[0] * y[0] + p[1] * y[1]) / p[2]
            return d

        step = make_step(method, spring, 2, ti.f64)

        @ti.kernel
        def probe(n: ti.i32, steps: ti.i32):
            for j in range(n):
                p = par[j]
                h = p[3]
                y = ti.Vector([1.0, 0.0], dt=ti.f64)
                w = ti.max(1, steps // 10)
                e_first = ti.cast(0.0, ti.f64)
                e_last = ti.cast(0.0, ti.f64)
                blown = 0
                for k in range(steps):
                    y = step(y, ti.cast(k, ti.f64) * h, h, j)
                    e = 0.5 * (p[2] * y[1] * y[1] + p[0] * y[0] * y[0])
                    if not is_finite(e) or e > 1e30:
                        blown = 1
                        break
                    if k < w:
                        e_first = ti.max(e_first, e)
                    if k >= steps - w:
                        e_last = ti.max(e_last, e)
                good = 0
                if blown == 0 and e_last <= p[4] * e_first:
                    good = 1
                ok[j] = good

        self.probe = probe

    def run(self, ks, kd, m, h, steps: int) -> np.ndarray:
        out = np.empty(len(h), dtype=bool)
        for s in range(0, len(h), CAPACITY):
            e = min(len(h), s + CAPACITY)
            buf = np.zeros((CAPACITY, 5))
            limit = np.where(kd[s:e] > 0, GROWTH_LIMIT_DAMPED, GROWTH_LIMIT_UNDAMPED)
            buf[: e - s] = np.stack([ks[s:e], kd[s:e], m[s:e], h[s:e], limit], axis=1)
            buf[e - s:, 2] = 1.0
            self.par.from_numpy(buf)
            self.probe(e - s, steps)
            out[s:e] = self.ok.to_numpy()[: e - s].astype(bool)
        return out


on_reset(_probes.clear)


def _probe(method: str) -> _Probe:
    _method(method)
    ensure_init()
    if method not in _probes:
        _probes[method] = _Probe(method)
    return _probes[method]


def largest_stable_h_batch(method: str, ks, kd, m=1.0, steps: int = 20000,
                           rel_tol: float = 1e-4) -> np.ndarray:
    """:func:`largest_stable_h` for many springs at once (arrays broadcast together)."""
    ks, kd, m = (np.asarray(a, dtype=np.float64).ravel() for a in np.broadcast_arrays(ks, kd, m))
    if np.any(ks <= 0) or np.any(kd < 0) or np.any(m <= 0):
        raise ValueError("need ks > 0, kd >= 0, m > 0")
    pr = _probe(method)
    n = len(ks)
    lo = np.zeros(n)
    hi = 4.0 / np.sqrt(ks / m)  # hω = 4 is outside every explicit method's stability region
    frac = np.arange(1, GRID + 1) / GRID
    for _ in range(40):
        todo = np.nonzero((hi - lo) > rel_tol * hi)[0]
        if todo.size == 0:
            break
        grid = lo[todo, None] + (hi - lo)[todo, None] * frac[None, :]
        rep = lambda a: np.repeat(a[todo], GRID)  # noqa: E731
        ok = pr.run(rep(ks), rep(kd), rep(m), grid.ravel(), steps).reshape(len(todo), GRID)
        for r, i in enumerate(todo):
            bad = np.nonzero(~ok[r])[0]
            if bad.size == 0:  # the whole bracket is stable: look further out
                lo[i], hi[i] = hi[i], 4.0 * hi[i]
            else:
                g = bad[0]
                lo[i], hi[i] = (grid[r, g - 1] if g > 0 else lo[i]), grid[r, g]
    return lo


def largest_stable_h(method: str, ks: float, kd: float, m: float = 1.0, steps: int = 20000) -> float:
    """Largest step h for which ``method`` keeps a damped spring on an anchor (m q'' = −ks q − kd q')
    bounded over ``steps`` steps (see the module docstring for the criterion), to 1e-4 relative."""
    return float(largest_stable_h_batch(method, ks, kd, m, steps)[0])


# ---- linear stability theory (NumPy, independent of the Taichi steppers) ----

def _polynomial(method: str) -> np.ndarray:
    """The tableau's stability polynomial γ_0..γ_s as floats (engine.ode.tableau, exact there)."""
    return np.array([float(g) for g in _method(method).scheme.stability_polynomial()])


def step_matrix(method: str, h, ks: float, kd: float, m: float = 1.0) -> np.ndarray:
    """The 2×2 matrices M with (q, v)⁺ = M (q, v) for one step of ``method`` on the spring; ``h``
    may be an array (result shape ``h.shape + (2, 2)``)."""
    scheme = _method(method).scheme
    h = np.asarray(h, dtype=np.float64)[..., None, None]
    w2, c = ks / m, kd / m
    one, zero = np.ones_like(h), np.zeros_like(h)
    mat = lambda a, b, cc, d: np.concatenate(  # noqa: E731
        [np.concatenate([a, b], -1), np.concatenate([cc, d], -1)], -2)
    if not isinstance(scheme, Splitting):  # R(hA) = Σ γ_k (hA)^k
        A = h * np.array([[0.0, 1.0], [-w2, -c]])
        M, term = 0.0, np.broadcast_to(np.eye(2), A.shape)
        for g in _polynomial(method):
            M = M + g * term
            term = term @ A
        return M
    M = np.broadcast_to(np.eye(2), h.shape[:-2] + (2, 2))
    for kind, w, _c in scheme.ops:  # drift: q += w h v; kick: v += w h a(q, v)
        wh = float(w) * h
        op = mat(one, wh, zero, one) if kind == DRIFT else mat(one, zero, -wh * w2, 1.0 - wh * c)
        M = op @ M
    return M


def spectral_radius(method: str, h, ks: float, kd: float, m: float = 1.0):
    """Largest |eigenvalue| of :func:`step_matrix` (vectorised over ``h``)."""
    r = np.max(np.abs(np.linalg.eigvals(step_matrix(method, h, ks, kd, m))), axis=-1)
    return float(r) if r.ndim == 0 else r


def theory_limit(method: str, ks: float, kd: float, m: float = 1.0) -> float:
    """Largest h with spectral radius ≤ 1 (first crossing from h = 0). 0.0 for explicit Euler and
    midpoint on an undamped spring, whose |R(iy)| exceeds 1 for every y > 0."""
    if kd == 0 and method in ("euler", "midpoint"):
        return 0.0
    w = math.sqrt(ks / m)
    tol = 1e-10
    hs = np.linspace(0.0, 4.0 / w, 4001)[1:]
    bad = np.nonzero(spectral_radius(method, hs, ks, kd, m) > 1 + tol)[0]
    if bad.size == 0:
        return math.inf
    g = bad[0]
    lo, hi = (hs[g - 1] if g > 0 else 0.0), hs[g]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if spectral_radius(method, mid, ks, kd, m) <= 1 + tol else (lo, mid)
    return float(lo)


def numerics_formula(method: str, ks: float, kd: float, m: float = 1.0) -> Union[float, None]:
    """The closed forms NUMERICS.md quotes, where it quotes one: explicit Euler h < kd/ks (damped,
    underdamped), symplectic Euler h²ω² + 2hc < 4, Verlet 2/ω (undamped). None elsewhere."""
    w2, c = ks / m, kd / m
    if method == "euler" and kd > 0 and c * c < 4 * w2:
        return kd / ks
    if method == "symplectic_euler":
        return (-c + math.sqrt(c * c + 4 * w2)) / w2
    if method == "verlet" and kd == 0:
        return 2.0 / math.sqrt(w2)
    return None


def rk_stable_step(method: str, lams) -> float:
    """Largest h with |R(hλ)| ≤ 1 for every λ in ``lams`` (complex), R the tableau's stability
    polynomial; 0.0 when some λ on the imaginary axis is outside the region for every h."""
    coeffs = _polynomial(method)[::-1]  # highest power first for np.polyval
    lam = np.asarray(lams, complex)
    if np.any((lam.real == 0) & (lam.imag != 0)) and abs(np.polyval(coeffs, 0.01j)) > 1:
        return 0.0  # undamped modes sit on the imaginary axis, outside this method's region

    def stable(h):
        return bool(np.all(np.abs(np.polyval(coeffs, h * lam)) <= 1 + 1e-12))

    lo, hi = 0.0, 8.0 / np.max(np.abs(lam))
    if stable(hi):
        return hi
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def oscillator_stable_step(method: str, omega: float, c: float, q_values) -> float:
    """Largest stable h for damped oscillators with frequencies up to ``omega`` (rad/s):

    * kick–drift methods (symplectic Euler, Verlet): h²ω² + 2hc < 4 with the damping rate bound
      c (1/s), i.e. h < (√(c² + 4ω²) − c)/ω² (NUMERICS.md; 2/ω undamped).
    * tableaus: |R(hλ)| ≤ 1 for the modes of λ² + cλ + ω² = 0 with ω in (0, omega] and damping
      proportional to stiffness, c = q ω², for each ratio q in ``q_values`` (kd/ks of the springs).
    """
    if omega <= 0:
        return math.inf
    if _method(method).partitioned:
        return (math.sqrt(c * c + 4 * omega * omega) - c) / (omega * omega)
    w = omega * np.linspace(1.0 / 400, 1.0, 400)
    lams = []
    for q in q_values:
        cq = q * w * w
        disc = np.sqrt((cq * cq - 4 * w * w).astype(complex))
        lams += [(-cq + disc) / 2, (-cq - disc) / 2]
    return rk_stable_step(method, np.concatenate(lams))


__all__: Sequence[str] = ["largest_stable_h", "largest_stable_h_batch", "theory_limit",
                          "numerics_formula", "step_matrix", "spectral_radius", "rk_stable_step",
                          "oscillator_stable_step"]
