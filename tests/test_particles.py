"""Particle pipeline: emission, lifetimes, colliders, closed-form motion, determinism."""
import math

import numpy as np
import pytest
import taichi as ti

from engine.colliders import ColliderSpec, Colliders
from engine.config import load_config
from engine.scene import Scene
from helpers import scene_dict


def make(d, render=False):
    return Scene(load_config(d), render=render)


def test_continuous_emission_matches_rate_times_time():
    # 37.3 particles/s over 2 s at 30 fps with h = 1/120: fractional carry-over between steps
    s = make(scene_dict(frames=60, emitters=[{"rate": 37.3, "lifetime": 100.0}]))
    counts = []
    for k in range(60):
        s.advance_frame()
        counts.append(s.stats.alive)
    t = np.arange(1, 61) / 30.0
    assert np.all(np.abs(np.array(counts) - 37.3 * t) <= 1.0), (counts, 37.3 * t)


def test_bursts_add_exactly_their_count_and_repeat():
    s = make(scene_dict(frames=30, emitters=[{"rate": 0.0, "lifetime": 100.0, "bursts": [
        {"time": 0.1, "count": 1234, "cycles": 3, "interval": 0.25}]}]))
    seen = []
    for k in range(30):
        s.advance_frame()
        seen.append(s.stats.alive)
    t = np.arange(1, 31) / 30.0
    expected = [1234 * sum(1 for c in range(3) if 0.1 + 0.25 * c < tk) for tk in t]
    assert seen == expected
    assert s.dropped() == 0


def test_lifetimes_end_on_time():
    s = make(scene_dict(frames=1, fps=100, solver={"integrator": "euler", "h": 0.01},
                        emitters=[{"rate": 0.0, "lifetime": 0.5, "bursts": [{"time": 0.0, "count": 500}]}]))
    alive = []
    for k in range(60):
        s.advance_frame()
        alive.append(s.stats.alive)
    # born at t = 0 and aged through its birth step, so at frame k (t = (k+1)·0.01) age = t; retired
    # at the step where age reaches 0.5 (t = 0.50), or one step later when the float32 sum of
    # fifty 0.01 steps lands just below 0.5
    assert alive[47] == 500 and alive[50] == 0, alive[44:52]


def _collide_batch(colliders, x0, v0):
    """Positions and velocities after one pass of the colliders' projection over (x0, v0) (a
    step of length 0 that starts where it ends: no resting, every contact responds)."""
    X = ti.Vector.field(3, ti.f32, shape=len(x0))
    V = ti.Vector.field(3, ti.f32, shape=len(x0))

    @ti.kernel
    def run():
        for i in X:
            x, v, _hits, _killed, _which, _n, _speed = colliders.project(X[i], V[i], X[i], V[i], 0.0)
            X[i] = x
            V[i] = v

    X.from_numpy(x0)
    V.from_numpy(v0)
    run()
    return X.to_numpy(), V.to_numpy()


@pytest.mark.parametrize("e,mu", [(0.8, 0.0), (0.5, 0.3), (1.0, 0.0), (0.0, 1.0)])
def test_plane_impact_invariants(e, mu):
    n_hat = np.array([0.3, 1.0, -0.2]) / np.linalg.norm([0.3, 1.0, -0.2])
    c = Colliders([ColliderSpec("plane", point=(0.0, 0.5, 0.0), normal=tuple(n_hat), restitution=e,
                                friction=mu)])
    rng = np.random.default_rng(0)
    n = 4096
    x0 = rng.uniform(-2, 2, (n, 3)).astype(np.float32)
    v0 = rng.normal(0, 3, (n, 3)).astype(np.float32)
    x1, v1 = _collide_batch(c, x0, v0)
    d0 = (x0 - [0.0, 0.5, 0.0]) @ n_hat
    d1 = (x1 - [0.0, 0.5, 0.0]) @ n_hat
    assert d1.min() > -1e-5  # no penetration after projection
    vn0, vn1 = v0 @ n_hat, v1 @ n_hat
    hit = (d0 < 0) & (vn0 < 0)
    assert hit.sum() > 500
    np.testing.assert_allclose(vn1[hit], -e * vn0[hit], rtol=1e-4, atol=1e-5)
    vt0 = v0 - np.outer(vn0, n_hat)
    vt1 = v1 - np.outer(vn1, n_hat)
    assert np.all(np.linalg.norm(vt1[hit], axis=1) <= np.linalg.norm(vt0[hit], axis=1) + 1e-5)
    ke0, ke1 = (v0 ** 2).sum(1), (v1 ** 2).sum(1)
    assert np.all(ke1 <= ke0 * (1 + 1e-5) + 1e-6)  # kinetic energy never grows (e <= 1)
    away = d0 >= 0
    np.testing.assert_array_equal(v1[away], v0[away])  # untouched when not in contact


def test_sphere_impact_invariants():
    c = Colliders([ColliderSpec("sphere", point=(0.0, 1.0, 0.0), radius=0.7, restitution=0.6,
                                friction=0.2)])
    rng = np.random.default_rng(1)
    n = 4096
    x0 = (rng.normal(0, 0.5, (n, 3)) + [0, 1, 0]).astype(np.float32)
    v0 = rng.normal(0, 3, (n, 3)).astype(np.float32)
    x1, v1 = _collide_batch(c, x0, v0)
    r1 = np.linalg.norm(x1 - [0, 1, 0], axis=1)
    assert r1.min() >= 0.7 * (1 - 1e-5)
    nrm = (x0 - [0, 1, 0]) / np.linalg.norm(x0 - [0, 1, 0], axis=1, keepdims=True)
    vn0, vn1 = (v0 * nrm).sum(1), (v1 * nrm).sum(1)
    hit = (np.linalg.norm(x0 - [0, 1, 0], axis=1) < 0.7) & (vn0 < 0)
    np.testing.assert_allclose(vn1[hit], -0.6 * vn0[hit], rtol=1e-3, atol=1e-4)
    assert np.all((v1 ** 2).sum(1) <= (v0 ** 2).sum(1) * (1 + 1e-5) + 1e-6)


def test_scene_keeps_particles_out_of_plane_and_sphere():
    d = scene_dict(frames=1, forces={"gravity": [0.0, -9.81, 0.0]},
                   emitters=[{"rate": 3000.0, "lifetime": 3.0, "position": [0.0, 2.0, 0.0],
                              "direction": [0.0, -1.0, 0.0], "spread": 40.0, "speed": [2.0, 6.0]}],
                   colliders=[{"type": "plane", "restitution": 0.5, "friction": 0.2},
                              {"type": "sphere", "center": [0.3, 0.6, 0.0], "radius": 0.5,
                               "restitution": 0.7}])
    s = make(d)
    for k in range(45):
        s.advance_frame()
        p = s.positions()
        assert p[:, 1].min() >= -1e-5
        assert np.linalg.norm(p - [0.3, 0.6, 0.0], axis=1).min() >= 0.5 * (1 - 1e-5)
    assert s.particles.integrator.hits[None] > 1000
    assert not s.particles.integrator.lean  # planes and spheres: compiled with it (engine.runtime)


def test_single_particle_with_drag_matches_closed_form_rk4():
    g, k, v0 = -9.81, 0.8, np.array([3.0, 5.0, -1.0])
    fps, T = 60, 2.0
    d = scene_dict(frames=1, fps=fps, solver={"integrator": "rk4", "h": 1 / 60},
                   forces={"gravity": [0.0, g, 0.0], "drag": k},
                   emitters=[{"rate": 0.0, "lifetime": 100.0, "bursts": [{"time": 0.0, "count": 1}],
                              "direction": v0.tolist(), "speed": [float(np.linalg.norm(v0))] * 2,
                              "position": [0.0, 1.0, 0.0]}])
    s = make(d)
    for _ in range(int(T * fps)):
        s.advance_frame()
    x = s.positions()[0].astype(np.float64)
    # born at t = 0 and integrated by RK4 from its birth: the closed form from (x0, v0) at t = 0
    tau, ginf = 1 / k, np.array([0.0, g, 0.0]) / k
    exact = np.array([0.0, 1.0, 0.0]) + ginf * T + (v0 - ginf) * tau * (1 - math.exp(-T / tau))
    assert np.abs(x - exact).max() < 2e-5 * max(1.0, np.abs(exact).max())  # float32 precision


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["euler", "midpoint", "rk4", "symplectic_euler", "verlet"])
def test_every_integrator_runs_a_scene(integrator):
    d = scene_dict(frames=1, solver={"integrator": integrator, "h": 1 / 120},
                   forces={"gravity": [0.0, -9.81, 0.0], "drag": 0.3},
                   colliders=[{"type": "plane"}])
    s = make(d)
    for _ in range(15):
        s.advance_frame()
    p = s.positions()
    assert len(p) > 40 and np.isfinite(p).all() and p[:, 1].min() >= -1e-5


@pytest.mark.slow
def test_adaptive_scene_lands_on_frames_and_matches_fine_fixed_step():
    common = dict(frames=1, forces={"gravity": [0.0, -9.81, 0.0], "drag": 2.0},
                  emitters=[{"rate": 0.0, "lifetime": 100.0, "bursts": [{"time": 0.0, "count": 50}],
                             "spread": 60.0, "speed": [1.0, 8.0], "position": [0.0, 1.0, 0.0]}])
    a = make(scene_dict(solver={"integrator": "rk4", "adaptive": True, "tolerance": 1e-5,
                                "h": 1 / 30}, **common))
    f = make(scene_dict(solver={"integrator": "rk4", "h": 1 / 960}, **common))
    for _ in range(30):
        a.advance_frame()
        f.advance_frame()
    assert a.t == 1.0 and f.t == 1.0
    assert a.stats.steps < f.stats.steps / 4
    # both started the same particles (same seed) and agree to the tolerance's order
    assert np.abs(a.positions() - f.positions()).max() < 1e-4


@pytest.mark.slow
def test_same_seed_gives_identical_frames_and_different_seed_does_not():
    d = scene_dict(frames=1, forces={"gravity": [0.0, -9.81, 0.0]},
                   render={"width": 96, "height": 54},
                   emitters=[{"rate": 500.0, "lifetime": 1.0, "spread": 30.0, "speed": [1.0, 4.0],
                              "blend": "additive", "streak": 0.02},
                             {"rate": 200.0, "lifetime": 2.0, "blend": "alpha",
                              "size": [[0.0, 0.2]], "alpha": [[0.0, 0.3]], "shape": "sphere",
                              "radius": 0.3}],
                   colliders=[{"type": "plane"}])
    imgs = []
    for seed in (5, 5, 6):
        d["seed"] = seed
        s = make(d, render=True)
        for _ in range(12):
            s.advance_frame()
        imgs.append(s.render())
    assert np.array_equal(imgs[0], imgs[1])
    assert not np.array_equal(imgs[0], imgs[2])
    assert imgs[0].std() > 1.0


def test_overflow_is_counted_not_silent():
    d = scene_dict(frames=1, emitters=[{"rate": 1000.0, "lifetime": 5.0, "capacity": 100}])
    s = make(d)
    for _ in range(10):
        s.advance_frame()
    assert s.stats.alive == 100
    assert s.dropped() == pytest.approx(1000 * 10 / 30 - 100, abs=2)


def test_pool_is_sized_from_the_emitters():
    d = scene_dict(frames=1, emitters=[{"rate": 200.0, "lifetime": 1.5},
                                       {"rate": 0.0, "lifetime": 0.5,
                                        "bursts": [{"count": 300, "cycles": 10, "interval": 0.2}]}])
    s = make(d)
    # 200/s × (1.5 s + one frame) + 8 slack; bursts overlapping within a lifetime: 300 × (ceil(0.5/0.2)+1)
    assert s.particles.layout.sizes == [math.ceil(200 * (1.5 + 1 / 30)) + 8, 300 * 4 + 8]


def test_moving_emitter_follows_its_path_and_hands_down_its_velocity():
    d = scene_dict(frames=1, fps=30, emitters=[{
        "rate": 300.0, "lifetime": 100.0, "speed": [0.0, 0.0], "inherit_velocity": 1.0,
        "path": [{"time": 0.0, "position": [0.0, 1.0, 0.0]}, {"time": 1.0, "position": [2.0, 1.0, 0.0]}]}])
    s = make(d)
    for _ in range(15):
        s.advance_frame()
    v = s.velocities()
    np.testing.assert_allclose(v, np.tile([2.0, 0.0, 0.0], (len(v), 1)), atol=1e-4)
    p = s.positions()
    # a particle born at t_b sits where the emitter was then and has moved 2 m/s since: x = 2·t
    np.testing.assert_allclose(p[:, 0], 2.0 * 0.5, atol=1e-3)


@pytest.mark.slow  # (both: the default run kept under 5 minutes cold; CI runs them with the slow tests)
@pytest.mark.parametrize("impacts", ["projected", "located"])
def test_fixed_steps_fused_into_runs_give_the_same_bytes_as_step_by_step(monkeypatch, impacts):
    """Where nothing is due between fixed steps (no births, still colliders, no sub-emitters)
    they run in one launch: the same particles, bit for bit, and fewer launches. (With located
    impacts the run kernel compiles the event code into a loop and LLVM may round a located
    bounce differently in the last bit: the same to float32 rounding there; either way a
    config's frames are the same bytes run after run, the runs being decided by the schedule.)"""
    from engine.particles import integrate, system

    d = scene_dict(frames=1, fps=30, seed=2, solver={"integrator": "rk4", "h": 1 / 240, "impacts": impacts},
                   forces={"gravity": [0.0, -9.81, 0.0], "drag": 0.4},
                   emitters=[{"rate": 20.0, "lifetime": 3.0, "speed": [1.0, 3.0], "spread": 40.0,
                              "buoyancy": 4.0, "bursts": [{"time": 0.0, "count": 500}]}],
                   colliders=[{"type": "plane"}])
    runs = []
    fused_kernel = integrate.step_fixed_run
    monkeypatch.setattr(integrate, "step_fixed_run", lambda *a: runs.append(a[-1]) or fused_kernel(*a))
    out = {}
    for max_run in (1, system.MAX_RUN):
        monkeypatch.setattr(system, "MAX_RUN", max_run)
        s = make(d)
        for _ in range(20):
            s.advance_frame()
        out[max_run] = (s.positions(), s.velocities(), s.stats.steps)
    assert runs and min(runs) > 1 and sum(runs) > 100  # births every ~12 steps: runs of up to 11
    assert out[1][2] == out[system.MAX_RUN][2] == 160
    if impacts == "projected":
        np.testing.assert_array_equal(out[1][0], out[system.MAX_RUN][0])
        np.testing.assert_array_equal(out[1][1], out[system.MAX_RUN][1])
    else:
        np.testing.assert_allclose(out[1][0], out[system.MAX_RUN][0], rtol=0, atol=1e-6)
        np.testing.assert_allclose(out[1][1], out[system.MAX_RUN][1], rtol=0, atol=1e-5)


def _pcg_np(v):
    """PCG's output permutation (engine.particles.rng.pcg_hash) in NumPy's uint32 arithmetic."""
    v = np.asarray(v).astype(np.uint32)
    with np.errstate(over="ignore"):
        state = v * np.uint32(747796405) + np.uint32(2891336453)
        word = ((state >> ((state >> np.uint32(28)) + np.uint32(4))) ^ state) * np.uint32(277803737)
    return (word >> np.uint32(22)) ^ word


def test_random_draws_are_the_pcg_hash_exactly():
    """rand01 and pcg_hash, built straight into a kernel (engine.particles.rng), give the bits of
    the hash computed in NumPy: seeds, streams and counters across the u32 range, several k."""
    from engine.particles.rng import pcg_hash, rand01

    rng = np.random.default_rng(11)
    n = 4096
    seed = rng.integers(0, 2**32, size=n, dtype=np.uint64).astype(np.int64)
    stream, counter = rng.integers(0, 64, size=n), rng.integers(0, 2**31, size=n)
    k = rng.integers(0, 11, size=n)
    r, h = ti.field(ti.f32, shape=n), ti.field(ti.u32, shape=n)

    @ti.kernel
    def draw(seed: ti.types.ndarray(), stream: ti.types.ndarray(), counter: ti.types.ndarray(),
             k: ti.types.ndarray()):
        for i in range(n):
            r[i] = rand01(ti.cast(seed[i], ti.u32), stream[i], counter[i], k[i])
            h[i] = pcg_hash(counter[i])

    draw(seed, stream.astype(np.int32), counter.astype(np.int32), k.astype(np.int32))
    s32 = seed.astype(np.uint32)
    inner = _pcg_np(stream.astype(np.uint32) * np.uint32(16) + k.astype(np.uint32) ^ _pcg_np(counter))
    want = (_pcg_np(s32 ^ inner) >> np.uint32(8)).astype(np.float32) * np.float32(1.0 / 16777216.0)
    assert np.array_equal(h.to_numpy(), _pcg_np(counter))
    assert np.array_equal(r.to_numpy(), want)
    assert 0.45 < want.mean() < 0.55 and want.max() < 1.0
