"""Kick–drift splittings (symplectic Euler, velocity Verlet) as frozen, validated data.

A partitioned method for y = (q, p) with q' = f_q(q, p, t), p' = f_p(q, p, t) — for particles and
spring nodes q = position, p = velocity, f_q = v, f_p = a(x, v, t). A step is a short sequence of
operations, each moving one half of y by weight·h with the derivative at the state reached so far:

* kick (weight w, time c):  p ← p + w·h·f_p(q, p, t + c·h)
* drift (weight w, time c): q ← q + w·h·f_q(q, p, t + c·h)

(Hairer, Lubich & Wanner, *Geometric Numerical Integration*, §II.5: symplectic Euler is one kick
then one drift; Störmer–Verlet is half a kick, a drift, half a kick.) The first operation is a kick
at c = 0, so it uses f(y₀, t): step doubling shares that evaluation between the full step and the
first half step, as it does for a tableau's first stage.
"""
from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction as F
from typing import Tuple

KICK, DRIFT = "kick", "drift"
Op = Tuple[str, F, F]  # (KICK or DRIFT, weight, c)


@dataclass(frozen=True)
class Splitting:
    """``ops``: the kicks and drifts of one step, in order. ``order``: the global order for
    position-only forces. A closing kick evaluates f_p(q⁺, p½): with velocity-dependent forces
    (drag, spring damping) Verlet in this explicit form drops to order 1 (NUMERICS.md)."""

    name: str
    order: int
    ops: Tuple[Op, ...]

    def __post_init__(self) -> None:
        ops = self.ops
        sums = {kind: sum((w for k, w, _ in ops if k == kind), F(0)) for kind in (KICK, DRIFT)}
        for bad, why in (
                (not ops or ops[0][0] != KICK or ops[0][2] != 0, "the first operation must be a kick at c = 0"),
                (any(k not in sums for k, _, _ in ops), f"operations are {KICK!r} or {DRIFT!r}"),
                (any(not 0 <= c <= 1 for _, _, c in ops), "every time c must lie in [0, 1]"),
                (any(total != 1 for total in sums.values()),
                 f"kick and drift weights must each sum to 1 (consistency), got {sums}"),
                (self.order < 1, "order must be >= 1")):
            if bad:
                raise ValueError(f"{self.name}: {why}")

    @property
    def evaluations(self) -> int:
        """Derivative evaluations per step: one per kick (f_p) and one per drift (f_q)."""
        return len(self.ops)


SYMPLECTIC_EULER = Splitting("symplectic_euler", 1, ((KICK, F(1), F(0)), (DRIFT, F(1), F(0))))
VERLET = Splitting("verlet", 2, ((KICK, F(1, 2), F(0)), (DRIFT, F(1), F(1, 2)), (KICK, F(1, 2), F(1))))

SPLITTINGS = {s.name: s for s in (SYMPLECTIC_EULER, VERLET)}
