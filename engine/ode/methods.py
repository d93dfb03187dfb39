"""The integrators by name: one list, and what the driver and the controller need to know of each.

Pure Python (no Taichi): the config schema builds its choices from :data:`INTEGRATORS` without a
compiler. A method's scheme — a Butcher tableau or a kick–drift splitting — is data read only
inside ``engine.ode`` (the steppers, the stability functions); the rest of the engine sees a name,
an order and a cost.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Union

from .splitting import SPLITTINGS, Splitting
from .tableau import TABLEAUS, ButcherTableau


@dataclass(frozen=True)
class Method:
    """``order``: global order p (the controller's exponent is 1/(p + 1)); ``fevals``: derivative
    evaluations per step; ``partitioned``: needs y = (q, p) of even length."""

    name: str
    scheme: Union[ButcherTableau, Splitting]

    @property
    def order(self) -> int:
        return self.scheme.order

    @property
    def partitioned(self) -> bool:
        return isinstance(self.scheme, Splitting)

    @property
    def symplectic(self) -> bool:
        return self.partitioned

    @property
    def fevals(self) -> int:
        s = self.scheme
        return s.evaluations if isinstance(s, Splitting) else s.stages

    @property
    def doubling_fevals(self) -> int:
        """Evaluations per step-doubling attempt: three steps sharing the first evaluation
        (Numerical Recipes §16.2: Euler 2, midpoint 5, RK4 11)."""
        return 3 * self.fevals - 1


METHODS = {name: Method(name, scheme) for name, scheme in (*TABLEAUS.items(), *SPLITTINGS.items())}
INTEGRATORS = tuple(METHODS)  # "euler", "midpoint", "rk4", "symplectic_euler", "verlet"


def method(name: str, key: str = "method") -> Method:
    """The :class:`Method` called ``name``; a ValueError naming ``key`` and the choices otherwise."""
    if name not in METHODS:
        raise ValueError(f"{key}: unknown value {name!r}; allowed: {', '.join(INTEGRATORS)}")
    return METHODS[name]
