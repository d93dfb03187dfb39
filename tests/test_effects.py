"""Effects: ramps, curl noise, buoyancy, order-independent blending, sub-emitters, golden images."""
import os

import numpy as np
import pytest
import taichi as ti
from PIL import Image

from engine.config import load_config
from engine.particles.curves import Curves
from engine.particles.noise import curl_noise
from engine.particles.pool import PARTICLE_FIELDS
from engine.scene import Scene
from helpers import scene_dict

GOLDEN = os.path.join(os.path.dirname(__file__), "golden")


def test_ramps_hit_their_stops_and_interpolate_between():
    stops = [[[0.0, 1.0, 0.5, 0.0], [0.25, 0.0, 1.0, 0.5], [0.7, 0.2, 0.2, 0.9], [1.0, 0.0, 0.0, 0.0]],
             [[0.3, 2.0, 2.0, 2.0]]]
    curves = Curves(stops, 3)
    ev = curves.make_func()
    ts = np.array([0.0, 0.25, 0.7, 1.0, 0.125, 0.85, 0.0, 0.3, 0.9], np.float32)
    es = np.array([0, 0, 0, 0, 0, 0, 1, 1, 1], np.int32)
    T, E = ti.field(ti.f32, len(ts)), ti.field(ti.i32, len(ts))
    out = ti.Vector.field(3, ti.f32, len(ts))
    T.from_numpy(ts)
    E.from_numpy(es)

    @ti.kernel
    def run():
        for k in T:
            out[k] = ev(E[k], T[k])

    run()
    o = out.to_numpy()
    np.testing.assert_allclose(o[:4], [s[1:] for s in stops[0]], atol=1e-6)
    np.testing.assert_allclose(o[4], [0.5, 0.75, 0.25], atol=1e-6)  # halfway between stops 0 and 1
    np.testing.assert_allclose(o[5], [0.1, 0.1, 0.45], atol=1e-6)
    np.testing.assert_allclose(o[6:], [[2.0, 2.0, 2.0]] * 3, atol=1e-6)  # one stop: constant


@pytest.mark.slow
def test_curl_noise_is_divergence_free():
    n = 2000
    rng = np.random.default_rng(0)
    P = ti.Vector.field(3, ti.f32, n)
    P.from_numpy(rng.uniform(-20, 20, (n, 3)).astype(np.float32))
    div, curl_mag = ti.field(ti.f32, n), ti.field(ti.f32, n)
    eps = 2e-3

    @ti.kernel
    def run():
        for k in P:
            p = P[k]
            d = 0.0
            g = ti.Matrix.zero(ti.f32, 3, 3)  # g[i, j] = ∂u_i/∂x_j by central differences
            for j in ti.static(range(3)):
                e = ti.Vector.unit(3, j) * eps
                du = (curl_noise(p + e, 2) - curl_noise(p - e, 2)) / (2 * eps)
                for i in ti.static(range(3)):
                    g[i, j] = du[i]
                d += du[j]
            div[k] = d
            curl_mag[k] = ti.sqrt((g[2, 1] - g[1, 2]) ** 2 + (g[0, 2] - g[2, 0]) ** 2 + (g[1, 0] - g[0, 1]) ** 2)

    run()
    d, c = np.abs(div.to_numpy()), curl_mag.to_numpy()
    assert np.median(c) > 1.0  # a real swirling field
    assert np.median(d) < 1e-2 * np.median(c) and np.percentile(d, 99) < 0.05 * np.median(c)


def test_buoyant_particles_rise_and_stop_accelerating_as_they_cool():
    b, tau = 3.0, 0.5
    d = scene_dict(frames=1, fps=60, solver={"integrator": "rk4", "h": 1 / 240},
                   forces={"gravity": [0.0, -9.81, 0.0]},
                   emitters=[{"rate": 0.0, "lifetime": 100.0, "bursts": [{"time": 0.0, "count": 1}],
                              "speed": [0.0, 0.0], "gravity_scale": 0.0, "buoyancy": b, "cooling": tau}])
    s = Scene(load_config(d), render=False)
    vy = []
    for _ in range(180):
        s.advance_frame()
        vy.append(s.velocities()[0, 1])
    t = np.arange(1, 181) / 60
    np.testing.assert_allclose(vy, b * tau * (1 - np.exp(-t / tau)), atol=1e-4)  # v = bτ(1 − e^(−t/τ))
    acc = np.diff(vy) * 60
    assert acc[0] > 2.5 and acc[-1] < 0.01 and np.all(np.diff(acc) < 1e-4)


def _render_with_pool_order(d, perm=None):
    s = Scene(load_config(d), render=True)
    for _ in range(20):
        s.advance_frame()
    if perm is not None:
        S, cap = s.particles.state, s.capacity
        order = perm(cap)  # one permutation for every field
        for f in PARTICLE_FIELDS:
            a = getattr(S, f).to_numpy()
            a[:cap] = a[:cap][order]
            getattr(S, f).from_numpy(a)
    return s.render()[..., :3].astype(float)


@pytest.mark.slow
def test_alpha_blending_does_not_depend_on_particle_order():
    d = scene_dict(frames=1, render={"width": 160, "height": 90},
                   camera={"position": [0.0, 1.0, 4.0], "look_at": [0.0, 1.0, 0.0]},
                   emitters=[{"effect": "smoke", "shape": "sphere", "radius": 0.6, "position": [0.0, 1.0, 0.0],
                              "rate": 400.0, "color": [[0.0, 0.8, 0.3, 0.2], [1.0, 0.2, 0.4, 0.9]]},
                             {"effect": "dust", "shape": "box", "box_size": [2.0, 0.5, 1.0],
                              "position": [0.0, 1.0, 0.5], "rate": 300.0}])
    a = _render_with_pool_order(d)
    rng = np.random.default_rng(1)
    b = _render_with_pool_order(d, lambda n: rng.permutation(n))
    c = _render_with_pool_order(d, lambda n: np.arange(n)[::-1])
    assert a.std() > 3
    for other in (b, c):
        diff = np.abs(a - other)
        assert diff.mean() < 0.05 and diff.max() <= 2, (diff.mean(), diff.max())


def test_sub_emitters_fire_the_expected_number_of_children():
    d = scene_dict(frames=1, fps=60, forces={"gravity": [0.0, -9.81, 0.0]},
                   emitters=[{"name": "parent", "rate": 0.0, "lifetime": 0.5, "speed": [0.0, 0.0],
                              "position": [0.0, 5.0, 0.0], "bursts": [{"time": 0.0, "count": 300}],
                              "sub_emitters": [{"event": "death", "emitter": "child", "count": 3}]},
                             {"name": "child", "rate": 0.0, "lifetime": 100.0, "speed": [0.1, 0.2],
                              "spread": 180.0},
                             {"name": "drop", "rate": 0.0, "lifetime": 100.0, "speed": [0.0, 0.0],
                              "position": [3.0, 1.0, 0.0], "bursts": [{"time": 0.0, "count": 200}],
                              "sub_emitters": [{"event": "collision", "emitter": "splash", "count": 2,
                                                "min_speed": 1.0}]},
                             {"name": "splash", "rate": 0.0, "lifetime": 100.0, "speed": [1.0, 2.0],
                              "spread": 45.0, "gravity_scale": 0.0}],
                   colliders=[{"type": "plane", "restitution": 0.0, "friction": 1.0}])
    s = Scene(load_config(d), render=False)
    for _ in range(90):
        s.advance_frame()
    emitted = s.particles.emitters.emitted_counts()
    assert emitted[0] == 300 and emitted[1] == 900  # every parent death: 3 children
    assert emitted[2] == 200 and emitted[3] == 400  # one hard landing each (e = 0: no re-bounce)
    assert s.dropped() == 0



def test_small_launches_on_one_thread_compute_what_the_parallel_ones_do(monkeypatch):
    """Spawning and sub-emitter launches small enough run every loop on the launching thread
    (``engine.runtime.one_thread``, CPU only): a scene of streams, bursts, death and collision
    children, rings that wrap onto live particles (births moved to free slots) and a full segment
    (births dropped) gives bit for bit the particles and counts of the same scene with every loop
    parallel. Both paths are taken (not vacuous)."""
    from engine import runtime

    d = scene_dict(frames=1, fps=60, seed=4, forces={"gravity": [0.0, -9.81, 0.0]},
                   emitters=[{"name": "parent", "rate": 400.0, "lifetime": 0.3, "speed": [0.5, 2.0],
                              "position": [0.0, 2.0, 0.0], "bursts": [{"time": 0.1, "count": 800}],
                              "sub_emitters": [{"event": "death", "emitter": "child", "count": 2}]},
                             {"name": "child", "rate": 0.0, "lifetime": 1.5, "lifetime_randomness": 0.8,
                              "speed": [0.1, 0.4], "spread": 180.0, "capacity": 600},
                             {"name": "drop", "rate": 100.0, "lifetime": 3.0, "speed": [0.0, 1.0],
                              "position": [3.0, 1.0, 0.0], "spread": 60.0,
                              "sub_emitters": [{"event": "collision", "emitter": "splash", "count": 3,
                                                "min_speed": 1.0}]},
                             {"name": "splash", "rate": 0.0, "lifetime": 2.0, "speed": [1.0, 2.0],
                              "spread": 45.0, "capacity": 150}],
                   colliders=[{"type": "plane", "restitution": 0.3, "friction": 0.5}])
    from engine.particles import emitters

    monkeypatch.setattr(emitters, "SERIAL_BIRTHS", 512)  # (so the burst's 800 births take both paths)
    real, taken = runtime.one_thread, []

    def run(serial_ok):
        monkeypatch.setattr(runtime, "one_thread",
                            lambda n, limit: taken.append(real(n, limit)) or (serial_ok and taken[-1]))
        s = Scene(load_config(d), render=False)
        for _ in range(60):
            s.advance_frame()
        E = s.particles.emitters
        p = s.live_particles()
        return p, E.emitted_counts(), E.dropped_counts()

    parallel = run(False)
    taken.clear()
    serial = run(True)
    assert any(taken) and not all(taken)  # (the burst's launch stays parallel: 800 births)
    for k in parallel[0]:
        np.testing.assert_array_equal(serial[0][k], parallel[0][k], err_msg=k)
    np.testing.assert_array_equal(serial[1], parallel[1])
    np.testing.assert_array_equal(serial[2], parallel[2])
    assert parallel[2][1] > 0 or parallel[2][3] > 0  # a segment filled: births dropped (not vacuous)

GOLDEN_SHOTS = {"sparks": 20, "dust": 20, "smoke": 40, "flames": 30, "campfire": 30, "explosion": 12}


def render_small(name, frames):
    cfg = load_config(os.path.join(os.path.dirname(GOLDEN), "..", "configs", f"{name}.toml"),
                      {"render.width": 96, "render.height": 54})
    s = Scene(cfg)
    for _ in range(frames):
        s.advance_frame()
    return s.render()[..., :3]


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(GOLDEN_SHOTS))
def test_golden_image(name):
    """A tiny render of each effect against a stored one, so a change to the look is seen.
    Regenerate after an intended change: python tests/make_golden.py"""
    img = render_small(name, GOLDEN_SHOTS[name]).astype(float)
    ref = np.asarray(Image.open(os.path.join(GOLDEN, f"{name}.png")).convert("RGB")).astype(float)
    diff = np.abs(img - ref)
    assert diff.mean() < 1.0 and np.percentile(diff, 99.5) < 24, (diff.mean(), np.percentile(diff, 99.5))
