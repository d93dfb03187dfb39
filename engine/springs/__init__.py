"""Spring networks (soft bodies): topologies, model/state fields, integrators, XPBD, the system.

Layout follows a Model (fixed topology and parameters) / State (positions, velocities) / Control
(gravity, collider positions: engine.control) split: :mod:`.topology` (numpy builders),
:mod:`.model` (fields, CSR adjacency, edge colouring), :mod:`.forces` (gather and atomic
accumulation of the Hooke term of engine.forces.terms), :mod:`.constraints` (pins, collisions), :mod:`.limits` (stretch caps),
:mod:`.stability` (the stiffness guard), :mod:`.energy`, :mod:`.system`. The explicit methods and
step doubling are the ODE core's, staged over the network's fields (engine.ode.staged), and the
steps are chosen by its driver (engine.ode.driver); XPBD is engine.xpbd's loop over the springs and
the body's energy terms (engine.forces.elements).
"""
from .energy import write_energy_csv
from .stability import StiffnessError
from .system import INTEGRATORS, SimulationDiverged, SpringSystem
from .topology import (BEND, BODY, SHEAR, STRUCTURAL, Topology, chain, cloth, hair, jelly, line_roots,
                       merge, scalp_roots, solid)

__all__ = ["SpringSystem", "SimulationDiverged", "StiffnessError", "INTEGRATORS", "Topology", "chain",
           "hair", "cloth", "jelly", "merge", "solid", "line_roots", "scalp_roots", "write_energy_csv",
           "STRUCTURAL", "SHEAR", "BEND", "BODY"]
