"""Step-size control for step doubling. It sees an error norm and an order, never the solver.

err is the scaled max-norm of the error estimate (≤ 1 accepts). The local error of an order-p
method scales as h^(p+1), hence h_new = h · safety · err^(−1/(p+1)) (NUMERICS.md; Hairer §II.4),
clamped to [min_factor, max_factor]·h, and never grown right after a rejection. Only the driver
(:mod:`engine.ode.driver`) calls it; the step-size limits (h_min, h_max, landing on a target)
are the driver's.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 5.0  # scipy's 0.9 / 0.2; Numerical Recipes' 5× growth


@dataclass
class StepDoublingController:
    order: int
    safety: float = SAFETY
    min_factor: float = MIN_FACTOR
    max_factor: float = MAX_FACTOR
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
        return accept, h * factor
