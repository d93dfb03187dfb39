"""XPBD as its own room: one substep loop (:mod:`.solver`), the colour schedule (:mod:`.schedule`)
and constraint groups (:mod:`.constraints`: springs; energy terms bring their own, see
engine.forces.elements). Systems build an :class:`XPBDSolver` over their nodes and groups."""
from .constraints import SpringConstraints
from .schedule import greedy_colors, schedule
from .solver import XPBDSolver

__all__ = ["XPBDSolver", "SpringConstraints", "greedy_colors", "schedule"]
