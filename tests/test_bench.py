"""``particles bench --quick`` in-process: every row present, every figure finite and positive.
No timing assertions (the machines are noisy)."""
import math

import pytest

from particles_tools import bench
from particles_tools.bench import cloth

EXPECTED = {
    "step": ["engine step 20k", "fused kernel alone 20k", "NumPy in-place 20k", "bandwidth limit 20k",
             "engine step 100k", "fused kernel alone 100k", "NumPy in-place 100k",
             "bandwidth limit 100k"],
    "frame": ["frame (step + render)", "frame, per-pixel schedule", "step (advance_frame)", "render",
              "render, background redrawn"],
    "effects": ["sparks", "composite, sparks", "worst effect", "empty scene, render only"],
    "ode": ["engine RK4 step doubling (f32)", "scipy solve_ivp RK45 (f64)"],
    "startup": ["cold (empty offline cache)", "warm (offline cache filled)"],
    "features": ["all features", "none of them", "impacts projected", "impacts located"],
    "output": ["sim + render (no output)", "particles run, 1 encoder"],
    "wedge": ["2 x particles run, one after another", "particles wedge, 2 workers x 1 thread"],
    "api": ["first build of sparks", "level restart", "second copy, prepared", "3 build/discard cycles",
            "add_emitter, effect compiled", "a new render size", "argument checks per frame",
            "first call, new field (template)", "first call, new ndarray"],
    "interact": ["grid build per 100k (Taichi)", "neighbour listing per 100k (Taichi)", "granular sweep per 100k (Taichi)",
                 "sand at 1280x720 (step + render)", "water at 1280x720 (step + render)",
                 "galaxy at 1280x720 (step + render)"],
    "rigid": ["100 boxes into piles (xpbd, 20 substeps)", "1,000 free bodies, rk4 (ode path)"],
}
# the sections that build scenes (a compile each: frame, effects, features, cloth, output, api),
# run `particles run` in subprocesses (startup) or start Dask workers (wedge) run with the slow
# tests; the default run checks the table with the step and ODE sections
SLOW = ("frame", "startup", "output", "effects", "features", "cloth", "wedge", "api", "interact", "rigid")


def check_rows(rows, sections):
    names = [r.name.strip() for r in rows]
    for section in sections:
        for name in EXPECTED[section]:
            assert name in names, (section, name, names)
    for r in rows:
        assert math.isfinite(r.value) and r.value > 0, r
    table = bench.format_table(rows)
    assert all(n in table for n in names)
    # the wedge renders the same bytes as `particles run` with the same seeds
    assert all(r.extra["same"] for r in rows if r.section.startswith("wedge") and "wedge" in r.name)
    return names


@pytest.mark.slow
def test_quick_bench_has_every_row_with_finite_positive_figures():
    fast = [s for s in bench.SECTIONS if s not in SLOW]
    rows = bench.run(quick=True, only=fast)
    check_rows(rows, [s for s in fast if s in EXPECTED])


@pytest.mark.slow
@pytest.mark.parametrize("section", SLOW)
def test_quick_bench_slow_section(section):
    """One test per section, so ``pytest -n 2`` spreads them over both workers."""
    rows = bench.run(quick=True, only=[section])
    check_rows(rows, [section] if section in EXPECTED else [])
    assert rows, section
    if section == "output":
        ratios = [r.extra["ratio"] for r in rows if "ratio" in r.extra]
        # both ratios computed; their size is a timing (CI runs this beside other tests), not asserted
        assert len(ratios) == 2 and all(math.isfinite(q) and q > 0 for q in ratios)
    if section == "effects":
        assert any(r.name == "worst effect" for r in rows)
    if section == "cloth" and cloth.available():
        assert any("cloth" in r.section for r in rows)
    if section == "features":
        feats = {r.name: r.extra["kernels"] for r in rows if "kernels" in r.extra}
        # a scene without optional features compiles no more kernels than the full one
        assert len(feats["none of them"]) <= len(feats["all features"])
    if section == "api":
        share = [r.extra["checks_share"] for r in rows if "checks_share" in r.extra]
        assert len(share) == 1 and 0 < share[0] < 1


def test_the_block_wise_limit_reads_and_writes_every_slot_of_every_field():
    """``stream_rmw_blocks`` (the step section's limit over a blocked pool's own fields) turns
    every value v of the four fields into a·v + b, in every lane of every block: a field, a
    component or a lane it skipped keeps its value."""
    import numpy as np

    from engine.particles.pool import BLOCKED_FROM, LANES, ParticleState, lanes_of
    from particles_tools.bench import kernels

    S = ParticleState(BLOCKED_FROM + 3, adaptive=False)
    assert S.blocked
    n = lanes_of(S.capacity)
    rng = np.random.default_rng(3)
    before = {"particle_pos": rng.normal(size=(n, 3)), "particle_vel": rng.normal(size=(n, 3)),
              "particle_age": rng.normal(size=n), "particle_life": rng.normal(size=n)}
    for name, a in before.items():
        getattr(S, name).from_numpy(a.astype(np.float32))
    kernels.stream_rmw_blocks(S.particle_pos, S.particle_vel, S.particle_age, S.particle_life,
                              2.0, 0.5, n // LANES)
    for name, a in before.items():
        want = (2.0 * a.astype(np.float32) + 0.5).astype(np.float32)
        np.testing.assert_allclose(getattr(S, name).to_numpy(), want, rtol=1e-6, err_msg=name)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["sparks", "smoke"])
def test_the_splat_is_timed_as_the_frame_launches_it(name, monkeypatch):
    """The effects section's splat figure (``splatcost.measure``) launches the per-tile splat
    as the frame just drawn did: sparks' full level alone by the kernel without the other
    levels' code, smoke's coarse level first, then the others (it once timed every scene's
    splat the second way, one launch more, and sparks' kernel was not the one its frames take)."""
    from engine.api import ParticleScene
    from engine.render.renderer import Renderer
    from particles_tools.bench import effects

    scene = ParticleScene.from_file(f"configs/{name}.toml")
    for _ in range(30):
        scene.step(1 / 60)
        scene.render(1280, 720)
    calls = []
    real = Renderer.splat_tiles
    monkeypatch.setattr(Renderer, "splat_tiles",
                        lambda self, t, dep, lo, hi, levels=True: (calls.append((lo, hi, bool(levels))),
                                                                    real(self, t, dep, lo, hi, levels))[1])
    scene.render(1280, 720)
    frame = list(calls)
    assert frame and all(hi > lo for lo, hi, _ in frame)
    assert frame[0][2] is (name != "sparks"), frame  # (the two paths are the ones each takes)
    del calls[:]
    n, t_splat, t_ref = effects.splat_cost(scene, 1280, 720)
    assert n > 0 and t_splat > 0 and t_ref > 0
    assert calls and len(calls) % len(frame) == 0
    assert calls == frame * (len(calls) // len(frame)), (frame, calls[:4])


def test_the_bench_help_names_every_section(capsys):
    # `particles bench --help` lists what --only takes: every section, none left out
    from particles_tools import cli

    with pytest.raises(SystemExit):
        cli.main(["bench", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    listed = text.split("comma-separated sections:")[1].split("--quiet")[0]
    assert [s.strip() for s in listed.split(",")] == list(bench.SECTIONS)
