"""Step-size control for step doubling. It sees an error norm and an order, never the solver.

err is the scaled max-norm of the error estimate (≤ 1 accepts). The local error of an order-p
method scales as h^(p+1), hence h_new = h · safety · err^(−1/(p+1)) (NUMERICS.md; Hairer §II.4),
clamped to [min_factor, max_factor]·h, and never grown right after a rejection.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class StepDoublingController:
    order: int
    safety: float = 0.9
    min_factor: float = 0.2
    max_factor: float = 5.0
    h_min: float = 1e-12
    h_max: float = math.inf
    _rejected_last: bool = False

    def propose(self, h: float, err: float) -> tuple[bool, float]:
        """Return (accept, next h). A NaN or infinite err is a rejection with the largest cut."""
        accept = math.isfinite(err) and err <= 1.0
        if not math.isfinite(err):
            factor = self.min_factor
        elif err == 0.0:
            factor = self.max_factor
        else:
            factor = self.safety * err ** (-1.0 / (self.order + 1))
            factor = min(self.max_factor, max(self.min_factor, factor))
        if accept and self._rejected_last:
            factor = min(factor, 1.0)
        self._rejected_last = not accept
        return accept, min(self.h_max, h * factor)


def clip_to_target(t: float, h: float, t_target: float) -> tuple[float, bool]:
    """Shorten h so a step lands exactly on ``t_target`` without leaving a sliver step.

    Returns (h, lands). If h reaches the target (within 1%), take exactly the remainder; if two
    steps of h would overshoot, split the remainder in two equal steps instead of one step plus a
    sliver."""
    rem = t_target - t
    if h >= rem * 0.99:
        return rem, True
    if 2.0 * h > rem:
        return rem / 2.0, False
    return h, False
