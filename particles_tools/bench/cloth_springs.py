"""The cloth row, with ``engine.springs``: a 128×128 cloth (structural, shear and bend springs;
ks = 1e4 structural/shear, 1e3 bend, m = 0.01 per node), ms per 1/60 s frame for the explicit
method (symplectic Euler with the substeps its stiffest spring needs, from the springs package's
own stability bound) and for the stiff method (XPBD, stable at the frame step)."""
from __future__ import annotations

from .common import Row, time_median


def run(quick: bool = False):
    from engine.springs import SpringSystem, cloth

    n = 32 if quick else 128
    reps = 2 if quick else 5
    top = cloth(n, n, size=(1.0, 1.0), plane="xy", mass=0.01, ks=1e4, kd=0.01, pin="corners")
    dt = 1.0 / 60.0
    sec = f"cloth {n}x{n} ({top.node_count:,} nodes, {top.spring_count:,} springs), per 1/60 s frame"
    s = SpringSystem(top, integrator="symplectic_euler", substeps="auto")
    k = s.substeps_for(dt)
    t_exp = time_median(lambda: s.step(dt), reps, warmup=1)
    x = SpringSystem(top, integrator="xpbd", xpbd_iterations=10, substeps=1)
    t_xpbd = time_median(lambda: x.step(dt), reps, warmup=1)
    return [
        Row(sec, "explicit: symplectic Euler", t_exp * 1e3, "ms/frame",
            f"{k} substeps (h = {dt / k:.2e} s, stable limit {s.stable_step():.2e} s)"),
        Row(sec, "stiff: XPBD, 10 iterations", t_xpbd * 1e3, "ms/frame",
            f"1 substep; explicit takes x{t_exp / t_xpbd:.1f} its time"),
    ]
