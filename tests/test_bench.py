"""``particles bench --quick`` in-process: every row present, every figure finite and positive.
No timing assertions (the machines are noisy)."""
import math

from engine.tools import bench
from engine.tools.bench import cloth

EXPECTED = {
    "step": ["engine step 20k", "fused kernel alone 20k", "NumPy in-place 20k", "bandwidth limit 20k",
             "engine step 100k", "fused kernel alone 100k", "NumPy in-place 100k",
             "bandwidth limit 100k"],
    "frame": ["frame, tiled splat", "frame, serial splat (before)", "step (advance_frame)",
              "background", "splat, tiled", "splat, serial", "resolve + tone map", "image read-back"],
    "ode": ["engine RK4 step doubling (f32)", "scipy solve_ivp RK45 (f64)"],
    "startup": ["cold (empty offline cache)", "warm (offline cache filled)"],
    "features": ["all features", "none of them"],
    "wedge": ["2 x particles run, one after another", "particles wedge, 2 workers x 1 thread"],
}


def test_quick_bench_has_every_row_with_finite_positive_figures():
    rows = bench.run(quick=True)
    names = [r.name.strip() for r in rows]
    for section, expected in EXPECTED.items():
        for name in expected:
            assert name in names, (section, name, names)
    if cloth.available():
        assert any("cloth" in r.section for r in rows)
    for r in rows:
        assert math.isfinite(r.value) and r.value > 0, r
    table = bench.format_table(rows)
    assert all(n in table for n in names)
    # the wedge renders the same bytes as `particles run` with the same seeds
    assert all(r.extra["same"] for r in rows if r.section.startswith("wedge") and "wedge" in r.name)
    feats = {r.name: r.extra["kernels"] for r in rows if r.section.startswith("features")}
    # a scene without optional features compiles no more kernels than the full one
    assert len(feats["none of them"]) <= len(feats["all features"])
