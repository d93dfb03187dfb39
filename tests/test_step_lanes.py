"""Pools of at least BLOCKED_FROM slots: kept in blocks of LANES slots and stepped LANES slots side
by side (engine.particles.pool, engine.particles.integrate._step_lanes), the steps that settle
without locating an impact included (engine.ode.lanes); the slots whose step has an impact to
locate, or is a birth's or ends non-finite, then slot by slot."""
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


SMALL, BIG = BLOCKED_FROM - 1, BLOCKED_FROM + 1  # the largest pool stepped a slot at a time, and the
# smallest in lanes (+1: a last block of one slot and three of padding)
_BUILT = {}


def fresh(capacity: int):
    """``bouncing(capacity)`` as built: one scene per capacity for this file's tests, put back to
    its build's state by ``Scene.reset`` (the same bytes as a fresh build, kernels kept). A
    second scene of the same config compiles its step kernels again (they are specialised per
    scene): ~55 s a scene on a 2-core AMD EPYC of Zen 1 with the kernel cache cold, and this
    file's tests took 4.5 minutes of a worker when each built its own."""
    if capacity in _BUILT:
        _BUILT[capacity].reset()
    else:
        _BUILT[capacity] = bouncing(capacity)
    return _BUILT[capacity]


FIELDS = ("particle_pos", "particle_vel", "particle_age", "particle_alive")  # a pool's stepped state


def state_bytes(scene):
    """The pool's FIELDS, as bytes."""
    S = scene.particles.state
    return {f: getattr(S, f).to_numpy().tobytes() for f in FIELDS}


def run(scene, seconds: float):
    for _ in range(round(seconds / H)):
        scene.advance(H)


def test_pools_from_the_threshold_are_blocked_and_stepped_in_lanes():
    small, big = fresh(SMALL), fresh(BIG)
    assert not small.particles.state.blocked and not small.particles.integrator.lanes
    S, I = big.particles.state, big.particles.integrator
    assert S.blocked and I.lanes and I.blocks == lanes_of(BIG) // LANES
    assert S.particle_pos.shape == (lanes_of(BIG),) and lanes_of(BIG) % LANES == 0
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
    a, b = fresh(SMALL), fresh(BIG)
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
    assert (y < 1e-3).mean() > 0.3  # many came to rest on the ground: held contacts are exercised
    assert abs(hits[0] - hits[1]) <= 1e-4 * hits[0] and hits[0] > 1e6


def test_a_run_of_steps_is_the_bytes_of_its_steps_one_launch_each():
    """One scene twice from its build (``fresh``): 12 steps a launch each, then as one run."""
    a = fresh(BIG)
    run(a, 0.5)
    t, start = a.t, state_bytes(a)
    for m in range(12):
        integrate.step_fixed(a.particles.integrator, np.float32(t + m * H), H)
    steps = state_bytes(a)
    b = fresh(BIG)
    run(b, 0.5)
    assert b.t == t and state_bytes(b) == start  # the same state before both
    integrate.step_fixed_run(b.particles.integrator, t, H, 0, 12)
    for f, got in state_bytes(b).items():
        assert got == steps[f], f


def test_a_dead_slot_beside_live_ones_is_left_as_it_was():
    """The lanes store every lane's end, then put back the lanes they did not take: a dead slot in
    a block with live ones keeps its bytes, and each live slot steps as it does with its block's
    neighbours alive (a slot's path depends on its own state only). Odd slots killed in one of two
    equal pools (one scene twice from its build: ``fresh``), then 30 steps of the step kernel
    alone (no births to refill them)."""
    a = fresh(BIG)
    run(a, 0.15)
    t, start = a.t, state_bytes(a)
    for m in range(30):
        integrate.step_fixed(a.particles.integrator, np.float32(t + m * H), H)
    x_all = {f: getattr(a.particles.state, f).to_numpy() for f in FIELDS}
    b = fresh(BIG)
    run(b, 0.15)
    assert b.t == t and state_bytes(b) == start
    Sb = b.particles.state
    alive = Sb.particle_alive.to_numpy()
    odd = np.arange(alive.size) % 2 == 1
    live_odd = odd & (alive != 0)
    assert live_odd.sum() > 1000  # blocks with dead and live slots, many of them moving
    alive[odd] = 0
    Sb.particle_alive.from_numpy(alive)
    moved = FIELDS[:3]  # (not the alive flags, which the test set)
    before = {f: getattr(Sb, f).to_numpy() for f in moved}
    for m in range(30):
        integrate.step_fixed(b.particles.integrator, np.float32(t + m * H), H)
    even = ~odd
    for f in moved:
        x, y = x_all[f], getattr(Sb, f).to_numpy()
        assert y[live_odd].tobytes() == before[f][live_odd].tobytes(), f  # the killed slots unchanged
        assert x[even].tobytes() == y[even].tobytes(), f  # their neighbours as with them alive
    assert (x_all["particle_alive"][even] == Sb.particle_alive.to_numpy()[even]).all()


@ti.kernel
def _settle_and_locate(I: ti.template(), xa: ti.types.ndarray(), va: ti.types.ndarray(), xo: ti.types.ndarray(),
                       vo: ti.types.ndarray(), out: ti.types.ndarray(), h: ti.f32):
    """Row i: the plain step of (xa, va) over h, ``settle``'s answer on it (xo/vo[i, 0], out[i, 0:2]:
    ok, held) and the located step's (xo/vo[i, 1], out[i, 2:4]: impacts located, contact k)."""
    for i in range(out.shape[0]):
        x0 = ti.Vector([xa[i, 0], xa[i, 1], xa[i, 2]])
        v0 = ti.Vector([va[i, 0], va[i, 1], va[i, 2]])
        y0 = integrate._pack(x0, 0.0, v0)
        y1 = I.step(y0, 0.0, h, i)
        ok, xs, vs, held = I.settle(x0, v0, integrate._x(y1), integrate._v(y1), h)
        y, _err, count, k, _lag, _xh, _nh, _speed, _dv, _stopped = I.locate(y0, 0.0, h, i, 1.0, 1.0, 0.0)
        for c in ti.static(range(3)):
            xo[i, 0, c], vo[i, 0, c] = xs[c], vs[c]
            xo[i, 1, c], vo[i, 1, c] = y[c], y[4 + c]
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = ok, held, count, k


def test_settled_steps_are_the_located_steps_answers():
    """Where ``settle`` (engine.ode.lanes.settled: the lanes' branch-free test) lets a step
    through, the located step locates nothing and ends where ``settle`` says: the plain step's
    end, or a plane's held contact (then the located step reports that plane). Over steps near,
    along and onto a ground plane and a sphere, resting points included; most of them are
    settled: the points at rest on the ground, and those that skim it without a contact."""
    s = fresh(BIG)
    I = s.particles.integrator
    rng = np.random.default_rng(3)
    n, h = 240_000, np.float32(H)
    xa = rng.uniform([-1, -0.01, -0.5], [1, 0.6, 0.5], (n, 3)).astype(np.float32)
    va = rng.normal(0, 2, (n, 3)).astype(np.float32)
    rest = slice(0, n // 4)  # on the ground, at rest or sliding
    xa[rest, 1], va[rest, 1] = 0.0, 0.0
    skim = slice(n // 4, n // 2)  # just above the ground, moving mostly along it
    xa[skim, 1] = rng.uniform(0, 2e-3, n // 4)
    va[skim, 1] = rng.normal(0, 0.05, n // 4)
    xo, vo = np.zeros((n, 2, 3), np.float32), np.zeros((n, 2, 3), np.float32)
    out = np.zeros((n, 4), np.int32)
    _settle_and_locate(I, xa, va, xo, vo, out, h)
    ok, held, count, k = (out[:, c] for c in range(4))
    ok, held = ok != 0, held != 0
    assert (count[ok] == 0).all()
    assert (k[ok & held] == 0).all() and (k[ok & ~held] == -1).all()  # the plane (collider 0) held them
    np.testing.assert_allclose(xo[ok, 0], xo[ok, 1], rtol=0, atol=2e-6)
    np.testing.assert_allclose(vo[ok, 0], vo[ok, 1], rtol=0, atol=2e-5)
    away = np.linalg.norm(xa - [0.4, 0.25, 0.0], axis=1) > 0.5  # far from the sphere
    assert held[rest].mean() > 0.6 and ok[rest][away[rest]].mean() > 0.99
    quiet = (count == 0) & (k == -1) & away  # steps the located step ends without a contact
    assert ok[skim][quiet[skim]].mean() > 0.99 and ok[quiet].mean() > 0.99
    assert 0.01 < (~ok).mean() < 0.2  # impacts are left to the located step


PROBE = """
import hashlib, sys
sys.path[:0] = [".", "tests"]
from engine import runtime
runtime.init("cpu", threads=int(sys.argv[1]))
from test_step_lanes import FIELDS, bouncing, run
from engine.particles.pool import BLOCKED_FROM
s = bouncing(BLOCKED_FROM + 2)
run(s, 0.6)
h = hashlib.sha256()
for f in FIELDS:
    h.update(getattr(s.particles.state, f).to_numpy().tobytes())
print(h.hexdigest(), s.particles.count_alive())
"""


@pytest.mark.slow
def test_blocked_pools_are_byte_identical_on_one_and_two_threads():
    out = on_thread_counts(PROBE)
    assert out[0] == out[1] and int(out[0][1]) > 10000, out
