"""The rigid room: bodies (sphere, box, capsule) with joints, stepped by XPBD (Müller et al. 2020)
or by the ODE driver on Baraff's state; one :class:`RigidSystem` per scene (engine.system)."""
from .model import RigidModel, RigidState
from .system import RigidSystem

__all__ = ["RigidModel", "RigidState", "RigidSystem"]
