"""External potentials on particles (issue 24, item 3): ``ParticleScene.add_potential``.

Closed forms (PHYSICS.md, "Energy-based models"; NUMERICS.md): with gravity and drag off the
particle step is a pure drift, so kick–drift–kick is velocity Verlet. On U = ½k|x − c|² (ω = √k)
Verlet's discrete frequency is ω̃ = (2/h) arcsin(ωh/2) and it conserves I = v² + ω²x²(1 − (ωh/2)²)
exactly, so E = ½v² + U swings between E₀(1 − (ωh/2)²) (at x = c) and E₀ (at rest): bounded, no
drift. On U = g·y Verlet is exact: y = y₀ − g t²/2 to f32 rounding.
"""
import math
import os

import numpy as np
import pytest

from helpers import on_thread_counts
import taichi as ti

from engine.api import SceneBuilder
from engine.runtime import ensure_init
from engine.scene import SimulationDiverged

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
H = 1 / 120
K = 4 * math.pi ** 2  # ω = 2π: period 1 s
C = (0.0, 1.0, 0.0)


@ti.func
def well(x, p):  # ½ p₀ |x − (0, 1, 0)|²  (J/kg)
    d = x - ti.Vector([0.0, 1.0, 0.0])
    return 0.5 * p[0] * d.dot(d)


@ti.func
def gauss(x, p):  # −p₀ exp(−|x − c|² / (2 p₁²)), c = (p₂, p₃, p₄): a soft crater
    d = x - ti.Vector([p[2], p[3], p[4]])
    return -p[0] * ti.exp(-d.dot(d) / (2 * p[1] * p[1]))


@ti.func
def terrain(x, p):  # p₀ y: a uniform slope of the ground's height field, i.e. gravity p₀
    return p[0] * x[1]


@ti.func
def spike(x, p):  # 1/|x − (0, 1, 0)|: infinite gradient at the centre
    d = x - ti.Vector([0.0, 1.0, 0.0])
    return 1.0 / d.norm()


def scene(*emitters, integrator="symplectic_euler", adaptive=False, h=H, **kw):
    """Still particles (speed 0, long lives), no gravity or drag, one burst at t = 0 per emitter
    ((name, position, count))."""
    b = SceneBuilder(seed=1, fps=60).forces(gravity=[0.0, 0.0, 0.0]).solver(
        h=h, integrator=integrator, adaptive=adaptive)
    for name, pos, n in emitters or (("dot", (0.5, 1.0, 0.0), 1),):
        b.emitter(name=name, shape="point", position=list(pos), speed=[0.0, 0.0], lifetime=100.0,
                  bursts=[{"time": 0.0, "count": n}])
    return b.build(render=False, **kw)


def _crossings(t, x):
    """Times x crosses zero (linear interpolation between samples: x is near-linear there)."""
    i = np.nonzero(np.sign(x[:-1]) * np.sign(x[1:]) < 0)[0]
    return t[i] - x[i] * (t[i + 1] - t[i]) / (x[i + 1] - x[i])


@pytest.mark.parametrize("integrator", ["symplectic_euler", pytest.param("rk4", marks=pytest.mark.slow)])
def test_harmonic_well_oscillates_with_its_period_and_bounded_energy(integrator):
    """Released at rest 0.5 m from the centre of ½k|x − c|²: 5 periods of 2π/√k = 1 s."""
    s = scene(integrator=integrator)
    s.add_potential(well, [K], name="well")
    A, w = 0.5, math.sqrt(K)
    t, x, e = [0.0], [A], [0.5 * K * A * A]
    for k in range(600):
        s.step(H)
        p = s.particles()
        d = p["position"][0].astype(np.float64) - C
        v = p["velocity"][0].astype(np.float64)
        t.append((k + 1) * H), x.append(d[0]), e.append(0.5 * v @ v + 0.5 * K * d @ d)
        assert abs(d[1]) + abs(d[2]) < 1e-6  # stays on its line
    tc = _crossings(np.array(t), np.array(x))
    assert len(tc) == 10
    T = 2 * np.mean(np.diff(tc))
    T_verlet = 2 * math.pi / ((2 / H) * math.asin(w * H / 2))  # ≈ 1 − (ωh)²/24 = 1 − 1.14e-4 s
    # the period of the continuous well within Verlet's O(h²) lead (1.1e-4 s) plus 2e-5 s for f32
    # positions and the interpolated crossings; and Verlet's own discrete period to those 2e-5 s
    assert abs(T - 2 * math.pi / w) < abs(T_verlet - 1.0) + 2e-5, T
    assert abs(T - T_verlet) < 2e-5, (T, T_verlet)
    e = np.array(e)
    deficit = (e[0] - e) / e[0]
    q = (w * H / 2) ** 2  # 6.85e-4: the deficit at x = c; symplectic Euler alone would swing ωh/2 = 2.6e-2
    assert deficit.min() > -1e-5  # never above E₀ (f32 rounding)
    assert 0.97 * q < deficit.max() < q + 1e-5
    assert deficit[-120:].max() < q + 1e-5  # the last period as the first: no drift


def test_autodiff_gradient_equals_the_closed_forms():
    """∇U by the kick's own kernels at random points against k(x − c) and the Gaussian's
    (p₀/p₁²)(x − c) exp(−|x − c|²/(2p₁²)), to f32 rounding (a few ulp of the terms)."""
    s = scene(("dot", (0.0, 1.0, 0.0), 1))
    s.add_potential(well, [K], name="well")
    s.add_potential(gauss, [3.0, 0.7, 0.2, 0.5, -0.1], name="crater")
    well_pot, crater = s.scene.particles.potentials
    rng = np.random.default_rng(4)
    x = rng.uniform(-2, 2, (64, 3))
    d = x - C
    g = well_pot.gradient(x)
    assert np.all(np.abs(g - K * d) <= 4e-7 * K * (np.abs(x) + 1)), np.abs(g - K * d).max()
    d = x - (0.2, 0.5, -0.1)
    r2 = (d * d).sum(1, keepdims=True)
    exact = 3.0 / 0.49 * d * np.exp(-r2 / (2 * 0.49))
    assert np.abs(crater.gradient(x) - exact).max() <= 1e-6 * np.abs(exact).max()
    # the reported totals: U at where the particle is after a step
    s.step(H)
    e = s.potential_energy()
    x = s.particles()["position"][0].astype(np.float64)
    d = x - (0.2, 0.5, -0.1)
    assert sorted(e) == ["crater", "well"]
    assert e["well"] == pytest.approx(0.5 * K * ((x - C) ** 2).sum(), rel=1e-5, abs=1e-9)
    assert e["crater"] == pytest.approx(-3.0 * math.exp(-(d @ d) / 0.98), rel=1e-6)


@pytest.mark.parametrize("adaptive", [pytest.param(False, marks=pytest.mark.slow), True])
def test_terrain_potential_is_gravity_on_its_emitters_only(adaptive):
    """U = g·y with gravity 0: y = y₀ − g t²/2 (Verlet is exact for a constant force; step
    doubling with RK4 too); the particles of the emitter it does not name stay at rest."""
    g = 9.81
    s = scene(("rock", (0.0, 2.0, 0.0), 3), ("mist", (1.0, 2.0, 0.0), 2),
              integrator="rk4" if adaptive else "symplectic_euler", adaptive=adaptive)
    s.add_potential(terrain, [g], emitters=["rock"], name="ground")
    for k in range(1, 61):
        s.step(H)
        p = s.particles()
        rock, mist = p["position"][p["emitter"] == 0], p["position"][p["emitter"] == 1]
        t = k * H
        assert np.abs(rock[:, 1] - (2.0 - g * t * t / 2)).max() < 2e-5, (t, rock[:, 1])
        assert np.abs(p["velocity"][p["emitter"] == 0][:, 1] + g * t).max() < 2e-5
        assert np.all(mist == np.float32([1.0, 2.0, 0.0]))
    assert s.potential_energy()["ground"] == pytest.approx(3 * g * (2.0 - g / 8), rel=1e-5)
    if adaptive:  # capped at solver.h while a potential acts (the estimate cannot see the kicks)
        assert s.scene.stats.h_max <= H * (1 + 1e-12)


def test_a_potential_on_all_emitters_acts_on_one_added_in_place():
    s = scene(("rock", (0.0, 2.0, 0.0), 1))
    s.add_potential(terrain, [9.81], name="ground")
    s.step(H)
    s.add_emitter(dict(name="late", shape="point", position=[1.0, 2.0, 0.0], speed=[0.0, 0.0], lifetime=100.0,
                       bursts=[{"time": 0.0, "count": 1}]))
    assert s.last_add is None  # written into a spare row: nothing rebuilt or compiled
    for _ in range(10):
        s.step(H)
    p = s.particles()
    late = p["position"][p["emitter"] == 1]
    assert len(late) == 1 and late[0, 1] < 2.0 - 0.5 * 9.81 * (9 * H) ** 2


def test_a_terrain_potential_rests_particles_on_a_floor():
    """Pulled onto a floor by U = g·y: held on it, never through; at rest the velocity keeps
    the last half kick, at most h·g/2 into the floor (the kicks do not see the contact)."""
    b = SceneBuilder(seed=1, fps=60).forces(gravity=[0.0, 0.0, 0.0]).solver(h=H)
    b.emitter(name="rock", shape="point", position=[0.0, 0.3, 0.0], speed=[0.0, 0.0], lifetime=100.0,
              bursts=[{"time": 0.0, "count": 1}])
    b.collider(type="plane", name="floor", point=[0.0, 0.0, 0.0], normal=[0.0, 1.0, 0.0], restitution=0.3)
    s = b.build(render=False)
    s.add_potential(terrain, [9.81], name="ground")
    for _ in range(120):
        s.step(1 / 60)
        assert s.particles()["position"][0, 1] >= 0.0
    p = s.particles()
    assert p["position"][0, 1] < 1e-3 and -H * 9.81 / 2 * (1 + 1e-5) <= p["velocity"][0, 1] <= 0.0


def test_a_rejected_adaptive_attempt_leaves_no_kick():
    """attempt() kicks the velocities by −(h/2)∇U; rollback() must restore them byte for byte."""
    s = scene(integrator="rk4", adaptive=True)
    s.add_potential(well, [K], name="well")
    s.step(5 * H)
    ps = s.scene.particles
    v0 = ps.state.particle_vel.to_numpy()
    ps.attempt(s.time, H)
    assert not np.array_equal(ps.state.particle_vel.to_numpy(), v0)  # the kick is in
    ps.rollback()
    assert ps.state.particle_vel.to_numpy().tobytes() == v0.tobytes()


ensure_init()
_TERRAIN = ti.field(ti.f32, 8)  # a height map: no gradient through its index, so refused


@ti.func
def _reads_terrain(x, p):
    return 9.81 * (x[1] - _TERRAIN[0])


def test_wrong_use_is_refused_in_one_line_and_changes_nothing():
    s = scene()
    cases = [
        (dict(potential=lambda x, p: 0.0), ValueError, "add_potential: potential: must be a @ti.func"),
        (dict(potential=_reads_terrain), ValueError,
         r"add_potential: potential: _reads_terrain reads the Taichi field\(s\) _TERRAIN: "),
        (dict(params="k"), ValueError, "add_potential: params: 'k' is not a 1-D sequence"),
        (dict(params=2.0), ValueError, r"add_potential: params: .* \(a scalar: give \[2.0\]\)"),
        (dict(params=[[1.0, 2.0]]), ValueError, r"add_potential: params: shape \(1, 2\)"),
        (dict(params=[]), ValueError, r"add_potential: params: shape \(0,\)"),
        (dict(params=[1.0] * 17), ValueError, r"add_potential: params: shape \(17,\)"),
        (dict(params=[1.0, float("nan")]), ValueError, "add_potential: params: .* finite"),
        (dict(params=[1e39]), ValueError, "add_potential: params: .* finite float32"),
        (dict(emitters=["nope"]), KeyError, "add_potential: emitters: no emitter named 'nope'"),
        (dict(emitters=[]), ValueError, "add_potential: emitters: .* non-empty list"),
        (dict(name=""), ValueError, "add_potential: name: '' is not allowed"),
    ]
    for kw, err, msg in cases:
        args = dict(potential=well, params=[K])
        args.update(kw)
        with pytest.raises(err, match=msg) as e:
            s.add_potential(**args)
        assert "\n" not in str(e.value)
    s.add_potential(well, [K], name="well")
    with pytest.raises(ValueError, match="add_potential: name: 'well' is not allowed: .*taken: 'well'"):
        s.add_potential(well, [K], name="well")

    @ti.func
    def vector_valued(x, p):  # not a scalar: Taichi refuses it at compile time
        return x * p[0]

    with pytest.raises(ValueError, match=r"add_potential: potential: Taichi could not compile vector_valued") as e:
        s.add_potential(vector_valued, [1.0], name="bad")
    assert "\n" not in str(e.value)
    assert list(s.potential_energy()) == ["well"] and len(s.scene.particles.potentials) == 1


def test_non_finite_gradient_names_the_potential():
    s = scene(("dot", C, 1))  # born at the spike's centre: ∇U = 0/0
    s.add_potential(spike, name="spike")
    with pytest.raises(SimulationDiverged, match="potential 'spike' .* non-finite gradient") as e:
        s.step(H)
    assert "\n" not in str(e.value)


@pytest.mark.slow  # (default run kept under 5 minutes cold: CI runs it with the slow tests)
def test_potentials_carry_over_a_rebuild_and_go_with_their_emitters():
    s = scene(("rock", (0.0, 2.0, 0.0), 1), ("mist", (1.0, 2.0, 0.0), 1))
    s.add_potential(terrain, [9.81], emitters="rock", name="ground")
    s.add_potential(well, [K], name="well")
    s.step(H)
    s.add_collider({"type": "plane", "name": "floor", "point": [0.0, -5.0, 0.0], "normal": [0.0, 1.0, 0.0]})
    s.step(H)
    assert sorted(s.potential_energy()) == ["ground", "well"]
    y = s.particles()["position"][:, 1]
    assert y[0] < 2.0 - 9.81 * (2 * H) ** 2 / 2 + 1e-4  # still falling after the rebuild
    s.remove_emitter("rock")
    assert list(s.potential_energy()) == ["well"]


def test_a_reused_scene_does_not_keep_the_previous_owners_potentials():
    from engine import reuse

    s = scene(("solo", (0.5, 1.0, 0.0), 1))
    s.add_potential(well, [K], name="well")
    built = s.scene
    s.close()
    s = scene(("solo", (0.5, 1.0, 0.0), 1))
    assert s.scene is built and reuse.counts["reused"] >= 1
    assert s.potential_energy() == {} and s.scene.particles.potentials == []
    s.step(H)
    assert np.all(s.particles()["velocity"] == 0)  # nothing pulls it


PROBE = """
import hashlib, sys
sys.path[:0] = ["."]
from engine import runtime
runtime.init("cpu", threads=int(sys.argv[1]))
import taichi as ti
from engine.api import ParticleScene

@ti.func
def bowl(x, p):  # a bowl around the fire, rising as r⁴ (a well that is not quadratic)
    r2 = x[0] * x[0] + x[2] * x[2]
    return p[0] * r2 * r2 + p[1] * x[1]

s = ParticleScene.from_file("configs/sparks.toml", render=False)
s.add_potential(bowl, [2.0, 1.0], name="bowl")
for _ in range(30):
    s.step(1 / 60)
p = s.particles()
print(len(p["position"]), hashlib.sha256(p["position"].tobytes() + p["velocity"].tobytes()).hexdigest())
"""


@pytest.mark.slow  # (two fresh processes: the default run stays under 5 minutes)
def test_frames_with_a_potential_are_byte_identical_on_one_and_two_threads():
    out = [words[-2:] for words in on_thread_counts(PROBE)]
    assert int(out[0][0]) > 100 and out[0] == out[1]


def test_every_adjoint_compiles_with_the_cfg_passes():
    """Taichi's reverse-mode autodiff miscompiled with its CFG passes off (engine.runtime turns
    them off): every ``.grad()`` call in the engine sits inside ``with cfg_optimized():``."""
    import pathlib
    import re

    root = pathlib.Path(__file__).resolve().parent.parent / "engine"
    calls = 0
    for path in root.rglob("*.py"):
        lines = path.read_text().splitlines()
        for k, line in enumerate(lines):
            if re.search(r"[\w\])]\.grad\(\)", line) and "``" not in line:  # a call, not a docstring's mention
                calls += 1
                assert "with cfg_optimized():" in lines[k - 1], f"{path.name}:{k + 1}: {line.strip()}"
    assert calls >= 2
