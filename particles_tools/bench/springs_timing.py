"""Spring-network timings on this machine: gather vs atomic force accumulation, and ms per 1/60 s
frame for a 128×128 cloth (structural + shear + bend) with symplectic Euler + auto substeps vs XPBD.

    TI_SKIP_VERSION_CHECK=ON python -m particles_tools.bench.springs_timing [n]   (the cloth row of `particles bench` uses it)
Medians of several repeats after a warm-up call (compile excluded). Not a test: numbers vary ±20%.
"""
import statistics
import sys
import time

import taichi as ti

from engine import runtime
from engine.springs import SpringSystem, cloth


def _median_ms(fn, reps, inner=1):
    fn()
    ti.sync()
    out = []
    for _ in range(reps):
        t0 = time.perf_counter()
        for _ in range(inner):
            fn()
        ti.sync()
        out.append((time.perf_counter() - t0) * 1e3 / inner)
    return statistics.median(out)


def main(n=128):
    runtime.init("cpu")
    top = cloth(n, n, size=(1.0, 1.0), plane="xy", mass=0.01, ks=1e4, kd=0.01, pin="corners")
    print(f"cloth {n}x{n}: {top.node_count} nodes, {top.spring_count} springs "
          f"(ks = 1e4 structural/shear, 1e3 bend, kd = 0.01, m = 0.01)")
    for acc in ("gather", "atomic"):
        s = SpringSystem(top, integrator="symplectic_euler", substeps="auto", accumulate=acc)
        A = s.stepper.a
        ms = _median_ms(lambda: s.accel(s.state.node_pos, s.state.node_vel, A, 0), 7, 20)
        print(f"force evaluation, {acc}: {ms:.3f} ms")
    s = SpringSystem(top, integrator="symplectic_euler", substeps="auto")
    k = s.substeps_for(1 / 60)
    ms = _median_ms(lambda: s.step(1 / 60), 5)
    print(f"symplectic_euler, auto substeps = {k} (h = {1 / 60 / k:.2e} s, limit {s.stable_step():.2e}): "
          f"{ms:.1f} ms per frame")
    for it, sub in ((10, 1), (20, 2)):
        s = SpringSystem(top, integrator="xpbd", xpbd_iterations=it, substeps=sub)
        ms = _median_ms(lambda: s.step(1 / 60), 5)
        print(f"xpbd, {it} iterations x {sub} substeps, {len(s.model.color_ranges)} colours: "
              f"{ms:.1f} ms per frame")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 128)
