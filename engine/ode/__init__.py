"""The ODE core: integrators as data, step doubling, and a scipy-like ``solve``.

Generic over the state: nothing here imports particles, emitters or springs.
"""
from .controller import StepDoublingController, clip_to_target
from .solve import OdeResult, solve
from .steppers import METHODS, Method, doubling_fevals, doubling_step, make_step, scaled_error
from .tableau import EULER, MIDPOINT, RK4, TABLEAUS, ButcherTableau

__all__ = [
    "ButcherTableau", "EULER", "MIDPOINT", "RK4", "TABLEAUS", "METHODS", "Method", "make_step",
    "doubling_step", "doubling_fevals", "scaled_error", "StepDoublingController", "clip_to_target",
    "solve", "OdeResult",
]
