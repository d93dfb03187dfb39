"""Cloth row: a hook for ``engine.springs`` (a teammate's package). When it exists, a 128×128
cloth with structural, shear and bend springs is timed per 1/60 s frame with the explicit method
(and the substeps its stiffest spring needs) and with the stiff method. Without it the section
reports that it was skipped (one row, value 0 is not used: the row is omitted)."""
from __future__ import annotations

import importlib.util



def available() -> bool:
    return importlib.util.find_spec("engine.springs") is not None


def run(quick: bool = False):
    if not available():
        return []
    from . import cloth_springs

    return cloth_springs.run(quick=quick)
