"""Spring networks (soft bodies): topologies, model/state fields, integrators, XPBD, the system.

Layout follows a Model (fixed topology and parameters) / State (positions, velocities) split:
:mod:`.topology` (numpy builders), :mod:`.model` (fields, CSR adjacency, edge colouring),
:mod:`.forces` (gather and atomic accumulation), :mod:`.integrators` (explicit, stage by stage),
:mod:`.xpbd`, :mod:`.constraints` (pins, collisions), :mod:`.limits` (stretch caps), :mod:`.stability` (the
stiffness guard), :mod:`.adaptive` (step doubling buffers), :mod:`.energy`, :mod:`.system`.
"""
from .energy import write_energy_csv
from .stability import StiffnessError
from .system import INTEGRATORS, SimulationDiverged, SpringSystem
from .topology import (BEND, BODY, SHEAR, STRUCTURAL, Topology, chain, cloth, hair, jelly, line_roots,
                       merge, scalp_roots)

__all__ = ["SpringSystem", "SimulationDiverged", "StiffnessError", "INTEGRATORS", "Topology", "chain",
           "hair", "cloth", "jelly", "merge", "line_roots", "scalp_roots", "write_energy_csv",
           "STRUCTURAL", "SHEAR", "BEND", "BODY"]
