"""Butcher tableaus as frozen, validated data (Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.1).

Coefficients are exact rationals (:class:`fractions.Fraction`): the invariants below are checked
exactly, and kernels emit each coefficient as ``cast(num)/cast(den)`` in the target dtype, so an
f64 kernel never sees a constant rounded through Taichi's f32 default.
"""
from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction as F
from typing import Tuple

Row = Tuple[F, ...]


@dataclass(frozen=True)
class ButcherTableau:
    """An explicit Runge–Kutta method: stages k_i = h f(y + Σ_j a_ij k_j, t + c_i h), y⁺ = y + Σ b_i k_i.

    ``a`` is strictly lower triangular (explicit), given as rows of length i for stage i.
    ``order`` is the classical global order p, used by the step-doubling controller.
    """

    name: str
    order: int
    c: Row
    a: Tuple[Row, ...]
    b: Row

    def __post_init__(self) -> None:
        s = len(self.b)
        if len(self.c) != s or len(self.a) != s:
            raise ValueError(f"{self.name}: c, a and b must all have {s} stages")
        for i, row in enumerate(self.a):
            if len(row) != i:
                raise ValueError(f"{self.name}: row {i} of A must have {i} entries (explicit method)")
            if sum(row, F(0)) != self.c[i]:
                raise ValueError(f"{self.name}: row {i} of A sums to {sum(row, F(0))}, c_{i} = {self.c[i]}")
        if sum(self.b, F(0)) != 1:
            raise ValueError(f"{self.name}: weights b sum to {sum(self.b, F(0))}, not 1")
        if self.order < 1:
            raise ValueError(f"{self.name}: order must be >= 1")

    @property
    def stages(self) -> int:
        return len(self.b)

    def stability_polynomial(self) -> Tuple[F, ...]:
        """Exact coefficients γ_0..γ_s of R(z) = Σ γ_k z^k, the factor one step multiplies a mode
        of y' = λy by (z = hλ): R(z) = 1 + z bᵀ(I − zA)⁻¹𝟙 = 1 + Σ_k bᵀA^(k−1)𝟙 z^k for an explicit
        method (A nilpotent, so the series stops at k = s). Hairer & Wanner, *Solving ODEs II*, §IV.2."""
        s = self.stages
        v = [F(1)] * s  # A^(k−1) 𝟙
        gamma = [F(1)]
        for _ in range(s):
            gamma.append(sum((bi * vi for bi, vi in zip(self.b, v)), F(0)))
            v = [sum((row[m] * v[m] for m in range(len(row))), F(0)) for row in self.a]
        return tuple(gamma)


EULER = ButcherTableau("euler", 1, c=(F(0),), a=((),), b=(F(1),))

# Δx = h f(x, t); x⁺ = x + h f(x + Δx/2, t + h/2)
MIDPOINT = ButcherTableau(
    "midpoint", 2,
    c=(F(0), F(1, 2)),
    a=((), (F(1, 2),)),
    b=(F(0), F(1)),
)

# Classic RK4 with k4 = h f(x + k3, t + h) (NUMERICS.md; the k3/2 variant is only first order).
RK4 = ButcherTableau(
    "rk4", 4,
    c=(F(0), F(1, 2), F(1, 2), F(1)),
    a=((), (F(1, 2),), (F(0), F(1, 2)), (F(0), F(0), F(1))),
    b=(F(1, 6), F(1, 3), F(1, 3), F(1, 6)),
)

TABLEAUS = {t.name: t for t in (EULER, MIDPOINT, RK4)}
