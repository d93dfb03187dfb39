"""Reference problems with closed forms or trusted reference values (NUMERICS.md).

Each :class:`Problem` carries a ``@ti.func`` derivative for :func:`engine.ode.solve`, an initial
state, a time span and, where one exists, the exact solution. Constants are exactly representable
so f64 runs are not polluted by f32-rounded literals.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np
import taichi as ti


@dataclass(frozen=True)
class Problem:
    name: str
    f: Callable
    y0: tuple
    t_span: tuple
    exact: Optional[Callable[[float], np.ndarray]] = None
    reference_end: Optional[tuple] = None  # trusted y(t1) when there is no closed form
    invariant: Optional[Callable[[np.ndarray], np.ndarray]] = None
    second_order: bool = False  # y = (q, p): symplectic methods apply
    labels: tuple = ()  # a name per component of y (the CSV header of `particles ode`)

    def y_end(self) -> np.ndarray:
        if self.exact is not None:
            return np.asarray(self.exact(self.t_span[1]), dtype=np.float64)
        return np.asarray(self.reference_end, dtype=np.float64)


# x' = x (growth) and x' = −kx (decay), k = 0.5
@ti.func
def _growth(y, t):
    return y


@ti.func
def _decay(y, t):
    return -0.5 * y


GROWTH = Problem("growth", _growth, (1.0,), (0.0, 1.0), exact=lambda t: np.array([np.exp(t)]),
                 labels=("x",))
DECAY = Problem("decay", _decay, (1.0,), (0.0, 4.0), exact=lambda t: np.array([np.exp(-0.5 * t)]),
                labels=("x",))


# Harmonic oscillator q'' = −ω² q with ω = 2: y = (q, p)
@ti.func
def _oscillator(y, t):
    d = y * 0
    d[0] = y[1]
    d[1] = -4.0 * y[0]
    return d


OSCILLATOR = Problem(
    "oscillator", _oscillator, (1.0, 0.0), (0.0, 10.0), second_order=True, labels=("q", "p"),
    exact=lambda t: np.array([np.cos(2 * t), -2 * np.sin(2 * t)]),
    invariant=lambda y: 0.5 * y[1] ** 2 + 2.0 * y[0] ** 2,
)


# Projectile with linear drag (per component): x'' = g − (c/m) v with g = −9.8125 (exact in binary),
# c/m = 0.5. y = (x, z, vx, vz)
_G, _K = -9.8125, 0.5


@ti.func
def _drag(y, t):
    d = y * 0
    d[0] = y[2]
    d[1] = y[3]
    d[2] = -_K * y[2]
    d[3] = _G - _K * y[3]
    return d


def _drag_exact(t, y0=(0.0, 0.0, 10.0, 10.0)):
    tau = 1.0 / _K
    out = []
    for q0, v0, g in ((y0[0], y0[2], 0.0), (y0[1], y0[3], _G)):
        vinf = g * tau
        v = vinf + (v0 - vinf) * np.exp(-t / tau)
        x = q0 + vinf * t + (v0 - vinf) * tau * (1 - np.exp(-t / tau))
        out.append((x, v))
    return np.array([out[0][0], out[1][0], out[0][1], out[1][1]])


DRAG = Problem("projectile_drag", _drag, (0.0, 0.0, 10.0, 10.0), (0.0, 2.0), exact=_drag_exact,
               second_order=True, labels=("x", "z", "vx", "vz"))


# Lotka–Volterra with scipy's parameters (a, b, c, d) = (1.5, 1, 3, 1):
#   x' = a x − b x y,  y' = −c y + d x y.
# This is the system whose u(10) = (1.02634477, 0.90969108) and invariant
# V = d x − c ln x + b y − a ln y = 2 at (1, 1) NUMERICS.md quotes (checked against DOP853 at
# rtol 1e-13). NUMERICS.md's "x' = Ax − Bxy, y' = Cxy − Dy with (1.5, 1, 3, 1)" reads as
# y' = 3xy − y, a different system (u(10) = (0.16536, 0.42667)); the figures are this one's.
@ti.func
def _lv(y, t):
    d = y * 0
    d[0] = 1.5 * y[0] - y[0] * y[1]
    d[1] = y[0] * y[1] - 3.0 * y[1]
    return d


def _lv_invariant(y):
    x, z = np.asarray(y[0]), np.asarray(y[1])
    return x - 3.0 * np.log(x) + z - 1.5 * np.log(z)


LOTKA_VOLTERRA = Problem(
    "lotka-volterra", _lv, (1.0, 1.0), (0.0, 10.0),
    # NUMERICS.md's (1.02634477, 0.90969108) to 16 digits: DOP853 at rtol 1e-14 (Radau agrees to 2e-14)
    reference_end=(1.026344767575084, 0.9096910781360662), invariant=_lv_invariant, labels=("x", "y"),
)


# Kepler orbit, eccentricity 0.9: q0 = (0.1, 0), p0 = (0, √19), GM = 1, period 2π
@ti.func
def _kepler(y, t):
    d = y * 0
    r2 = y[0] * y[0] + y[1] * y[1]
    inv_r3 = 1.0 / (r2 * ti.sqrt(r2))
    d[0] = y[2]
    d[1] = y[3]
    d[2] = -y[0] * inv_r3
    d[3] = -y[1] * inv_r3
    return d


KEPLER = Problem(
    "kepler", _kepler, (0.1, 0.0, 0.0, float(np.sqrt(19.0))), (0.0, 2 * np.pi),
    reference_end=(0.1, 0.0, 0.0, float(np.sqrt(19.0))), second_order=True,
    labels=("x", "y", "vx", "vy"),
)
# ... and eccentricity 0.6: q0 = (1 − e, 0), p0 = (0, √((1 + e)/(1 − e))) = (0, 2)
KEPLER_06 = Problem(
    "kepler-0.6", _kepler, (0.4, 0.0, 0.0, 2.0), (0.0, 2 * np.pi),
    reference_end=(0.4, 0.0, 0.0, 2.0), second_order=True, labels=("x", "y", "vx", "vy"),
)


# The Arenstorf orbit (Hairer, Nørsett & Wanner I, §II.0): the restricted three-body problem of a
# satellite, the Earth and the Moon (mass ratio μ = 0.012277471) in the rotating frame; periodic
# with period T = 17.0652165601579625588917206249, so the reference at T is the initial state.
# μ is built from integers (exact in f64; a Python float literal would compile as f32).
@ti.func
def _arenstorf(y, t):
    d = y * 0
    mu = ti.cast(12277471, ti.f64) / ti.cast(1000000000, ti.f64)
    nu = 1 - mu
    x, z = y[0], y[1]
    d1 = ((x + mu) ** 2 + z * z) ** 1.5
    d2 = ((x - nu) ** 2 + z * z) ** 1.5
    d[0] = y[2]
    d[1] = y[3]
    d[2] = x + 2 * y[3] - nu * (x + mu) / d1 - mu * (x - nu) / d2
    d[3] = z - 2 * y[2] - nu * z / d1 - mu * z / d2
    return d


_ARENSTORF_Y0 = (0.994, 0.0, 0.0, -2.00158510637908252240537862224)
ARENSTORF = Problem(
    "arenstorf", _arenstorf, _ARENSTORF_Y0, (0.0, 17.0652165601579625588917206249),
    reference_end=_ARENSTORF_Y0, labels=("x", "y", "vx", "vy"),
)


# Damped spring on an anchor, m = 1: q'' = −(ks/m) q − (kd/m) q' with ks = 100, kd = 1 (ω = 10,
# c = 1, underdamped). y = (q, v). Closed form with γ = c/2, ω_d = √(ω² − γ²):
#   q = e^(−γt) (q0 cos ω_d t + (v0 + γ q0)/ω_d sin ω_d t).
_DS_KS, _DS_KD, _DS_M = 100.0, 1.0, 1.0


@ti.func
def _damped_spring(y, t):
    d = y * 0
    d[0] = y[1]
    d[1] = -100.0 * y[0] - 1.0 * y[1]  # −(ks q + kd v)/m with the exact constants above
    return d


def _damped_spring_exact(t, y0=(1.0, 0.0)):
    gamma = 0.5 * _DS_KD / _DS_M
    wd = np.sqrt(_DS_KS / _DS_M - gamma ** 2)
    a, b = y0[0], (y0[1] + gamma * y0[0]) / wd
    e, c, s = np.exp(-gamma * t), np.cos(wd * t), np.sin(wd * t)
    return np.array([e * (a * c + b * s), e * ((b * wd - gamma * a) * c - (a * wd + gamma * b) * s)])


DAMPED_SPRING = Problem(
    "damped_spring", _damped_spring, (1.0, 0.0), (0.0, 2.0), exact=_damped_spring_exact,
    second_order=True, labels=("q", "v"),
    invariant=lambda y: 0.5 * _DS_M * y[1] ** 2 + 0.5 * _DS_KS * y[0] ** 2,
)


# A torque-free rigid body tumbling near its intermediate axis (the "Dzhanibekov" flip), on
# Baraff's state as the engine's ODE path steps it (engine.rigid.baraff): q (unit quaternion
# [w, x, y, z], body to world) and the world angular momentum L, constant with no torque, so
# q' = ½ [0, ω] ⊗ q with ω = R I⁻¹ Rᵀ L (q normalised inside f, as the engine does). Principal
# moments I = (1, 2, 3) kg·m², ω₀ = (1/4, 3, 1/4) rad/s in the body frame (= world at t = 0),
# T = 4 s: one flip (nearer the axis the flip is sharper and errors grow as e^{λt}: at
# ω₀ = (1/16, 3, 1/16) over 8 s explicit Euler stays O(1) wrong down to h = 5e-4). y = (q | L, 0):
# the pad makes the halves equal for the partitioned methods (q-half, p-half). Reference: DOP853
# at rtol 1e-14 (Radau at 1e-13 agrees to 3e-14).
TUMBLE_I = (1.0, 2.0, 3.0)


@ti.func
def _tumbling(y, t):
    q = ti.Vector([y[0], y[1], y[2], y[3]])
    q = q / q.norm()
    u = ti.Vector([q[1], q[2], q[3]])
    L = ti.Vector([y[4], y[5], y[6]])
    tt = 2.0 * (-u).cross(L)  # Rᵀ L: L turned by the conjugate
    Lb = L + q[0] * tt + (-u).cross(tt)
    wb = ti.Vector([Lb[0] / TUMBLE_I[0], Lb[1] / TUMBLE_I[1], Lb[2] / TUMBLE_I[2]])
    t2 = 2.0 * u.cross(wb)  # ω = R ω_body
    w = wb + q[0] * t2 + u.cross(t2)
    d = y * 0
    d[0] = -w.dot(u) * 0.5
    vq = (q[0] * w + w.cross(u)) * 0.5
    d[1], d[2], d[3] = vq[0], vq[1], vq[2]
    return d


TUMBLING = Problem(
    "tumbling", _tumbling, (1.0, 0.0, 0.0, 0.0, 0.25, 6.0, 0.75, 0.0), (0.0, 4.0), second_order=True,
    reference_end=(0.09410488429671887, -0.7155462015061045, 0.02980081727517916, -0.69155608272317,
                   0.25, 6.0, 0.75, 0.0),
    labels=("qw", "qx", "qy", "qz", "Lx", "Ly", "Lz", "pad"),
)

PROBLEMS = {p.name: p for p in (GROWTH, DECAY, OSCILLATOR, DRAG, DAMPED_SPRING, LOTKA_VOLTERRA,
                                  KEPLER, KEPLER_06, ARENSTORF, TUMBLING)}
assert all(len(p.labels) == len(p.y0) for p in PROBLEMS.values())
