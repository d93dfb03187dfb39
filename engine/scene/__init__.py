"""The scene room: the System protocol, the coupler that steps systems together, and the Scene
that builds them from a config (:mod:`.system`, :mod:`.scene`)."""
from .scene import DivergenceError, Scene, SimulationDiverged, Stats, collider_specs
from ..system import Coupling, System, SystemBase
from .coupler import Coupler

__all__ = ["Scene", "SimulationDiverged", "DivergenceError", "Stats", "collider_specs", "System",
           "SystemBase", "Coupler", "Coupling"]
