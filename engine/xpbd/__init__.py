"""XPBD as its own room: one substep loop (:mod:`.solver`), the colour schedule (from
:mod:`engine.geometry.colouring`, the shared room below: soft-body models and energy terms colour
their elements with it too, without importing this room) and constraint groups (:mod:`.constraints`: springs; energy terms bring their own, see
engine.forces.elements). Systems build an :class:`XPBDSolver` over their nodes and groups."""
from .constraints import SpringConstraints
from ..geometry.colouring import greedy_colors, schedule
from .solver import XPBDSolver

__all__ = ["XPBDSolver", "SpringConstraints", "greedy_colors", "schedule"]
