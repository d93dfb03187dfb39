"""Energy of the energy-based soft bodies over an undamped fixed-step run (issue 24): a neo-Hookean
solid and a cloth with dihedral bending, released from a deformed shape without gravity, under
explicit Euler (forced past the stiffness guard), symplectic Euler and Verlet at the same h. Every
term (kinetic, the material's, the springs', the bending) comes from SpringSystem.energy(), whose
interaction terms are engine.forces.terms' own; the chart shows |E − E₀|/E₀ (Euler grows, the
symplectic methods stay bounded)."""
from __future__ import annotations

from typing import List

import numpy as np

H = 1.0 / 2400.0  # 40 steps a 1/60 s frame: inside the symplectic limits of both bodies
METHODS = ("euler", "symplectic_euler", "verlet")
TITLES = {"solid": "neo-Hookean solid 3³ nodes (E = 5 kPa, ν = 0.3)",
          "cloth_bending": "cloth 6×6, springs + dihedral bending"}


def _bodies():
    from engine.forces.terms import lame
    from engine.springs import cloth, solid
    from engine.springs.topology import hinges

    sol = solid(3, 3, 3, size=(0.3, 0.3, 0.3), density=500.0)
    cl = cloth(6, 6, size=(0.5, 0.5), mass=0.01, ks=200.0)
    return {"solid": (sol, [dict(kind="elastic", nodes=sol.tets, material=("neo_hookean", *lame(5e3, 0.3)),
                                 name="neo_hookean")]),
            "cloth_bending": (cl, [dict(kind="bending", nodes=hinges(cl.triangles), stiffness=0.02)])}


def soft_energy_drift(quick: bool = False) -> List[dict]:
    """Rows (system, method, step, t, energy, rel_error) once a frame for each body and method."""
    import taichi as ti

    from engine.springs import SpringSystem

    frames = 20 if quick else 120
    rows = []
    for name, (top, elements) in _bodies().items():
        for m in METHODS:
            s = SpringSystem(top, gravity=(0.0, 0.0, 0.0), integrator=m, substeps=40, dtype=ti.f64,
                             elements=elements, check_stability=False)
            x = top.positions.copy()
            x[:, 1] += 0.15 * np.sin(3 * x[:, 0]) * x[:, 0]  # a bend and a stretch, then let go
            s.set_positions(x)
            e0 = s.energy()["total"]
            for f in range(1, frames + 1):
                s.step(40 * H)
                e = s.energy()["total"]
                rows.append(dict(system=name, method=m, step=40 * f, t=40 * f * H, energy=e,
                                 rel_error=abs(e - e0) / abs(e0)))
    return rows
