"""Pools of at least BLOCKED_FROM slots: kept in blocks of LANES slots and stepped LANES slots side
by side (engine.particles.pool, engine.particles.integrate._step_lanes), the slots whose step could
meet a surface, or is a birth's or ends non-finite, then slot by slot."""
import numpy as np
import pytest
import taichi as ti

from engine.particles import integrate
from engine.particles.pool import BLOCKED_FROM, LANES, lanes_of
from helpers import on_thread_counts, scene_dict, sim_scene

H = 1.0 / 240.0


def bouncing(capacity: int, **extra):
    """A stream thrown down onto a ground plane and a sphere (restitution 0.5), under gravity
    and drag: most steps far from both, some bounces, some rests. ``capacity`` slots; 36,000
    births over 1.8 s, fewer than any capacity below, so ring slot s is the same particle in
    every pool."""
    d = scene_dict(solver={"integrator": "symplectic_euler", "h": H},
                   forces={"gravity": [0.0, -9.81, 0.0], "drag": 0.3},
                   emitters=[{"position": [0.0, 1.0, 0.0], "direction": [0.3, -1.0, 0.1], "spread": 40.0,
                              "speed": [0.5, 4.0], "rate": 20000.0, "lifetime": 100.0,
                              "capacity": capacity}],
                   colliders=[{"type": "plane", "restitution": 0.5, "friction": 0.0},
                              {"type": "sphere", "center": [0.4, 0.25, 0.0], "radius": 0.25,
                               "restitution": 0.5}])
    d.update(extra)
    return sim_scene(d)


def run(scene, seconds: float):
    for _ in range(round(seconds / H)):
        scene.advance(H)


def test_pools_from_the_threshold_are_blocked_and_stepped_in_lanes():
    small, big = bouncing(BLOCKED_FROM - 1), bouncing(BLOCKED_FROM + 1)  # (+1: a last block of one slot)
    assert not small.particles.state.blocked and not small.particles.integrator.lanes
    S, I = big.particles.state, big.particles.integrator
    assert S.blocked and I.lanes and I.blocks == lanes_of(BLOCKED_FROM + 1) // LANES
    assert S.particle_pos.shape == (lanes_of(BLOCKED_FROM + 1),) and lanes_of(BLOCKED_FROM + 1) % LANES == 0
    run(big, 0.2)
    alive = S.particle_alive.to_numpy()
    assert alive[: big.particles.layout.capacity].sum() == big.particles.count_alive() > 3000
    assert alive[big.particles.layout.capacity:].sum() == 0  # the padding's slots stay dead
    # step doubling, projected impacts, sub-emitters and turbulence take a slot at a time
    for extra in ({"solver": {"integrator": "rk4", "h": H, "adaptive": True}},
                  {"solver": {"integrator": "symplectic_euler", "h": H, "impacts": "projected"}},
                  {"forces": {"gravity": [0.0, -9.81, 0.0], "turbulence": {"strength": 1.0}}}):
        s = bouncing(BLOCKED_FROM, **extra)
        assert s.particles.state.blocked and not s.particles.integrator.lanes, extra


def test_lanes_step_what_the_slot_at_a_time_step_does():
    """The blocked pool's particles end where the slot-at-a-time pool's do, to rounding (the
    same arithmetic per slot, vector instructions in one; 1.8 s of bounces on a plane and a
    sphere: 1.9e-5 m and 8.2e-5 m/s apart at most, 2026-12-02), with the same births, deaths and
    contacts."""
    a, b = bouncing(BLOCKED_FROM - 3), bouncing(BLOCKED_FROM + 3)
    assert not a.particles.integrator.lanes and b.particles.integrator.lanes  # the two paths compared
    for _ in range(round(1.8 / H)):
        a.advance(H)
        b.advance(H)
    hits = [int(s.particles.integrator.hits[None]) for s in (a, b)]  # particle-steps in contact
    pa, pb = a.live_particles(), b.live_particles()
    assert len(pa["position"]) == len(pb["position"]) > 35000
    for key in ("age", "life"):
        np.testing.assert_array_equal(pa[key], pb[key])
    np.testing.assert_allclose(pb["position"], pa["position"], rtol=0, atol=2e-4)
    np.testing.assert_allclose(pb["velocity"], pa["velocity"], rtol=0, atol=2e-3)
    y = pa["position"][:, 1]
    assert (y < 1e-3).mean() > 0.3  # many came to rest on the ground: the slow slots are exercised
    assert abs(hits[0] - hits[1]) <= 1e-4 * hits[0] and hits[0] > 1e6


def test_a_run_of_steps_is_the_bytes_of_its_steps_one_launch_each():
    a, b = bouncing(BLOCKED_FROM), bouncing(BLOCKED_FROM)
    run(a, 0.5)
    run(b, 0.5)
    t = a.t
    for m in range(12):
        integrate.step_fixed(a.particles.integrator, np.float32(t + m * H), H)
    integrate.step_fixed_run(b.particles.integrator, t, H, 0, 12)
    for f in ("particle_pos", "particle_vel", "particle_age", "particle_alive"):
        x, y = (getattr(s.particles.state, f).to_numpy() for s in (a, b))
        assert x.tobytes() == y.tobytes(), f


@ti.kernel
def _far_and_clear(far: ti.template(), clear: ti.template(), xa: ti.types.ndarray(), va: ti.types.ndarray(),
                   xb: ti.types.ndarray(), vb: ti.types.ndarray(), out: ti.types.ndarray(), span: ti.f32):
    for i in range(out.shape[0]):
        a = ti.Vector([xa[i, 0], xa[i, 1], xa[i, 2]])
        u = ti.Vector([va[i, 0], va[i, 1], va[i, 2]])
        b = ti.Vector([xb[i, 0], xb[i, 1], xb[i, 2]])
        w = ti.Vector([vb[i, 0], vb[i, 1], vb[i, 2]])
        out[i, 0] = far(b, u, w, span)
        out[i, 1] = clear(a, u, b, w, span)


def test_far_from_a_surface_implies_clear_of_it():
    """``far_from``'s branch-free test answers 1 only where ``clear_of`` does (so the lanes take
    the plain step only where the slot-at-a-time step would), over steps near and through a
    plane and a sphere, and answers 1 for most steps that start and end well away."""
    from engine.ode.events import clear_of, far_from

    s = bouncing(BLOCKED_FROM)
    C = s.particles.integrator.colliders
    rng = np.random.default_rng(3)
    n, span = 200_000, np.float32(1 / 60)
    xa = rng.uniform([-1, -0.2, -0.5], [1, 1.0, 0.5], (n, 3)).astype(np.float32)
    va = rng.normal(0, 3, (n, 3)).astype(np.float32)
    vb = (va + rng.normal(0, 0.5, (n, 3))).astype(np.float32)
    xb = (xa + span * 0.5 * (va + vb)).astype(np.float32)
    out = np.zeros((n, 2), np.int32)
    _far_and_clear(far_from(C, ti.f32), clear_of(C, ti.f32), xa, va, xb, vb, out, span)
    far, clear = out[:, 0] != 0, out[:, 1] != 0
    assert not (far & ~clear).any()
    away = (xa[:, 1] > 0.3) & (xb[:, 1] > 0.3) & (np.linalg.norm(xa - [0.4, 0.25, 0.0], axis=1) > 0.6)
    assert far[away].mean() > 0.95 and 0.05 < (clear & ~far).mean() + (~clear).mean()


PROBE = """
import hashlib, sys
sys.path[:0] = [".", "tests"]
from engine import runtime
runtime.init("cpu", threads=int(sys.argv[1]))
from test_step_lanes import bouncing, run
from engine.particles.pool import BLOCKED_FROM
s = bouncing(BLOCKED_FROM + 2)
run(s, 0.6)
h = hashlib.sha256()
for f in ("particle_pos", "particle_vel", "particle_age", "particle_alive"):
    h.update(getattr(s.particles.state, f).to_numpy().tobytes())
print(h.hexdigest(), s.particles.count_alive())
"""


@pytest.mark.slow
def test_blocked_pools_are_byte_identical_on_one_and_two_threads():
    out = on_thread_counts(PROBE)
    assert out[0] == out[1] and int(out[0][1]) > 10000, out
