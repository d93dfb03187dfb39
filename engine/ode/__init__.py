"""The ODE core: integrators as data, steppers fused or staged, one adaptive driver, ``solve``.

Generic over the state: nothing here imports particles, emitters or springs. The method data
(:mod:`.tableau`, :mod:`.splitting`, :mod:`.methods`) and the controller are plain Python and load
eagerly, so ``engine.config`` can read :data:`INTEGRATORS` without a compiler; the Taichi parts
(steppers, driver, ``solve``, stability) load on first use of one of their names.
"""
import importlib

from .controller import StepDoublingController
from .methods import INTEGRATORS, METHODS, Method
from .splitting import SPLITTINGS, Splitting
from .tableau import EULER, MIDPOINT, RK4, TABLEAUS, ButcherTableau

_LAZY = {  # name -> submodule holding it (imports Taichi)
    "solve": "ivp", "OdeResult": "ivp",
    "Driver": "driver", "StepPolicy": "driver", "DriverStats": "driver",
    "SimulationDiverged": "driver", "clip_to_target": "driver",
    "make_step": "steppers", "doubling_step": "steppers", "scaled_error": "steppers",
    "is_finite": "steppers", "FieldStepper": "staged", "StagedDoubling": "staged",
}


def __getattr__(name):  # PEP 562: called for names not yet bound here
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    globals()[name] = value
    return value


__all__ = [
    "ButcherTableau", "Splitting", "EULER", "MIDPOINT", "RK4", "TABLEAUS", "SPLITTINGS", "METHODS",
    "INTEGRATORS", "Method", "StepDoublingController", *_LAZY,
]
