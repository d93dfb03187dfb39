"""Rigid bodies (issue 22) against the closed forms of ../shared/PHYSICS.md, on both paths (XPBD,
Müller et al. 2020; Baraff's state on the ODE driver), and their bad input."""
import math
import os

import numpy as np
import pytest

from helpers import on_thread_counts
from scipy.special import ellipk

from engine.config import ConfigError, load_config
from engine.rigid import quat
from engine.scene import Scene
from rigid_scenes import GROUND, G, ROOT, run, scene


def angular_momentum(s, i=0):
    S, m = s.rigid.state, s.rigid.model
    wb = quat.rotate_inv(S.q[i], S.w[i])
    return quat.rotate(S.q[i], m.body_inertia[i] * wb), 0.5 * float(np.sum(m.body_inertia[i] * wb ** 2))


TUMBLER = {"name": "t", "shape": "box", "half_extents": [0.05, 0.15, 0.3], "position": [0.0, 2.0, 0.0]}


def test_torque_free_angular_momentum_kept_to_rounding_on_the_ode_path():
    s = scene([dict(TUMBLER, angular_velocity=[0.3, 4.0, 0.2])], colliders=(), gravity=(0, 0, 0),
              integrator="rk4", solver_h=1 / 240)
    L0, E0 = angular_momentum(s)
    run(s, 3.0)
    L1, E1 = angular_momentum(s)
    assert np.abs(L1 - L0).max() <= 1e-12 * np.linalg.norm(L0)  # L' = τ = 0 exactly
    assert abs(E1 - E0) <= 1e-6 * E0  # RK4 at h = 1/240: the energy to the method's order


@pytest.mark.parametrize("integrator, fps, tol", [
    ("rk4", 240, 0.01),
    pytest.param("xpbd", 60, 0.02, marks=pytest.mark.slow),  # measured 0.8 % (energy -2 % in 3.5 flips)
])
def test_intermediate_axis_flip_period_matches_landau_lifshitz(integrator, fps, tol):
    """ω₂ (the intermediate axis) changes sign every 2K(m)/λ (PHYSICS.md), on both paths."""
    s = scene([dict(TUMBLER, angular_velocity=[0.05, 3.0, 0.05])], colliders=(), gravity=(0, 0, 0),
              integrator=integrator, solver_h=1 / 480, fps=fps)
    I = s.rigid.model.body_inertia[0]
    order = np.argsort(I)  # I1 < I2 < I3
    L, E = angular_momentum(s)
    L2 = float(L @ L)
    I1, I2, I3 = I[order]
    if L2 < 2 * E * I2:  # PHYSICS.md: swap the roles of I1 and I3
        I1, I3 = I3, I1
    lam = math.sqrt((I3 - I2) * (L2 - 2 * E * I1) / (I1 * I2 * I3))
    m = (I2 - I1) * (2 * E * I3 - L2) / ((I3 - I2) * (L2 - 2 * E * I1))
    expected = 2 * ellipk(m) / lam
    signs, times = [], []

    def record(sc):
        S = sc.rigid.state
        w2 = quat.rotate_inv(S.q[0], S.w[0])[order[1]]
        signs.append(np.sign(w2))
        times.append(sc.t)

    run(s, 2.5 * expected + 1.0, record)
    flips = [times[k] for k in range(1, len(signs)) if signs[k] != signs[k - 1]]
    assert len(flips) >= 2
    period = np.diff(flips).mean()
    assert abs(period - expected) <= tol * expected, (period, expected)


def test_box_slides_to_the_coulomb_stop_distance():
    """v0²/(2μg) with μ = 0.5 on both surfaces (combined by average: 0.5, not their product)."""
    v0, mu = 3.0, 0.5
    s = scene([{"name": "b", "shape": "box", "half_extents": [0.2, 0.2, 0.2], "position": [0.0, 0.2, 0.0],
                "velocity": [v0, 0.0, 0.0], "friction": mu, "restitution": 0.0}], sleep=False)
    run(s, 1.5)
    d = s.rigid.state.x[0, 0]
    expected = v0 ** 2 / (2 * mu * G)
    assert abs(d - expected) <= 0.08 * expected, (d, expected)  # measured: 6 % short (0.86 m of 0.917)


def test_a_dropped_scenes_rigid_fields_serve_the_next_of_its_shape_with_the_same_bytes():
    """The XPBD fields (and their compiled kernels) of a scene that is gone go to the next scene
    of that shape, never to a second one while their scene lives, and step it to the same bytes
    as fresh fields: everything a step reads is loaded or written before it is read."""
    from engine.rigid import pool

    def box():  # a spinning box sliding: its inertia and friction matter
        s = scene([{"name": "b", "shape": "box", "half_extents": [0.3, 0.1, 0.2], "position": [0.0, 0.3, 0.0],
                    "velocity": [3.0, 0.0, 0.0], "angular_velocity": [1.0, 2.0, 4.0]}], sleep=False)
        run(s, 0.5)
        return s

    def ball():  # a heavy rolling, bouncing ball: other inertia, masses, contacts and multipliers
        s = scene([{"name": "s", "shape": "sphere", "radius": 0.1, "position": [0.0, 0.6, 0.0], "mass": 3.0,
                    "velocity": [2.0, 0.0, 1.0], "angular_velocity": [0.0, 5.0, 0.0], "restitution": 0.8}],
                  colliders=(dict(GROUND, restitution=0.8, friction=0.3),), sleep=False)
        run(s, 0.5)
        S = s.rigid.state
        return s, S.x.tobytes() + S.q.tobytes() + S.v.tobytes() + S.w.tobytes()

    a = box()
    b, fresh = ball()  # the box lives: the ball gets fields of its own
    Fa, Fb = a.rigid.solver._lease.F, b.rigid.solver._lease.F
    assert Fa is not Fb and Fa.key == Fb.key
    del b, a  # the box's fields are the last given back: the next lease takes them
    c, again = ball()
    assert c.rigid.solver._lease.F is Fa
    assert again == fresh
    held = pool.lease(1, Fa.capacity, 0)  # while c lives its fields are not handed out
    assert held.F is Fb


@pytest.mark.slow  # (default run kept under 5 minutes: the closed forms of the other tests stay in it)
def test_bounce_apex_heights_fall_as_e_squared():
    e, h0, r = 0.7, 1.0, 0.1
    s = scene([{"name": "s", "shape": "sphere", "radius": r, "position": [0.0, h0 + r, 0.0], "restitution": e}],
              colliders=(dict(GROUND, restitution=e),), fps=240, sleep=False)
    ys, vs = [], []
    run(s, 2.2, lambda sc: (ys.append(sc.rigid.state.x[0, 1] - r), vs.append(sc.rigid.state.v[0, 1])))
    apex = [ys[k] for k in range(1, len(vs)) if vs[k - 1] > 0 >= vs[k]]
    assert len(apex) >= 2
    for n, hn in enumerate(apex[:2], start=1):
        assert abs(hn - e ** (2 * n) * h0) <= 0.06 * e ** (2 * n) * h0, (n, hn, e ** (2 * n) * h0)


@pytest.mark.slow  # (default run kept under 5 minutes cold: CI runs it with the slow tests)
def test_a_stack_of_boxes_stands_still():
    boxes = [{"name": f"b{k}", "shape": "box", "half_extents": [0.25, 0.25, 0.25],
              "position": [0.0, 0.25 + 0.5 * k, 0.0], "friction": 0.6} for k in range(5)]
    s = scene(boxes)
    x0 = s.rigid.state.x.copy()
    run(s, 3.0)
    assert np.abs(s.rigid.state.x - x0).max() < 0.01  # measured: 1.3 mm, then asleep
    assert not s.rigid.solver.awake.any()  # asleep: no jitter left


@pytest.mark.slow  # (default run kept under 5 minutes: the closed forms of the other tests stay in it)
@pytest.mark.parametrize("integrator", ["xpbd", "rk4"])
def test_a_fast_small_body_does_not_tunnel(integrator):
    # 200 m/s moves 3.3 m in a 1/60 s frame, 1.7 m in the ODE path's 1/120 s step: both paths
    # meet the ground (the ODE path locates the impact inside the step)
    s = scene([{"name": "bullet", "shape": "sphere", "radius": 0.01, "position": [0.0, 1.0, 0.0],
                "velocity": [0.0, -200.0, 0.0]}], integrator=integrator)
    run(s, 0.5)
    assert s.rigid.state.x[0, 1] > 0.0


# (the default run keeps two of the eight; CI's slow run takes all: the default suite's time budget)
@pytest.mark.parametrize("integrator, adaptive", [pytest.param("rk4", False, marks=pytest.mark.slow),
                                                   pytest.param("midpoint", False, marks=pytest.mark.slow),
                                                   ("verlet", False), ("rk4", True)])
@pytest.mark.parametrize("e", [1.0, pytest.param(0.5, marks=pytest.mark.slow)])
def test_ode_path_locates_the_impact_so_the_bounce_keeps_its_closed_form(integrator, adaptive, e):
    # a ball dropped 1 m onto the ground at h = 1/60 (a 4.4 m/s impact moves 7 cm a step): these
    # methods are exact under constant gravity, so with the impact located inside the step the
    # rebound's energy height is 0.2 + e²·1 m to rounding; met at the step's end instead, it is
    # off by up to v·h·g (≈ 7 cm of penetration turned into height)
    ball = {"name": "s", "shape": "sphere", "radius": 0.2, "position": [0.0, 1.2, 0.0], "restitution": e}
    s = Scene(load_config({"fps": 60, "colliders": [dict(GROUND, restitution=e)], "rigid_bodies": [ball],
                           "rigid": {"integrator": integrator},
                           "solver": {"adaptive": True, "tolerance": 1e-9} if adaptive else {"h": 1 / 60}}),
              render=False)
    g = -float(s.control.gravity[None][1])  # (the control's f32 of 9.81, read back exactly)
    heights, lowest = [], np.inf
    for _ in range(40):  # the impact at 0.45 s, the rebound's apex at 0.45 + 0.45·e s
        s.advance_frame()
        y, v = s.rigid.state.x[0, 1], s.rigid.state.v[0, 1]
        heights.append(y + v * v / (2.0 * g))
        lowest = min(lowest, y)
    assert heights[0] == pytest.approx(1.2, abs=1e-9)
    assert lowest > 0.2 - 1e-9  # never ended a frame inside the ground
    assert heights[-1] == pytest.approx(0.2 + e * e * 1.0, abs=1e-8)


def test_ode_path_ball_comes_to_rest_on_the_ground():
    s = scene([{"name": "s", "shape": "sphere", "radius": 0.2, "position": [0.0, 1.0, 0.0], "restitution": 0.5}],
              colliders=(dict(GROUND, restitution=0.5),), integrator="rk4", solver_h=1 / 240)
    run(s, 3.0)
    assert abs(s.rigid.state.x[0, 1] - 0.2) < 2e-3
    assert abs(s.rigid.state.v[0, 1]) < 0.05


@pytest.mark.parametrize("e", [1.0, 0.5, 0.0])
def test_ode_path_head_on_collision_of_two_balls_matches_newton(e):
    # two balls in free flight meet head on (ODE path, RK4): momentum is kept and the relative
    # velocity reverses times e (Newton's law of restitution): v1' = (m1 v1 + m2 v2 + m2 e (v2 − v1))/(m1 + m2)
    m1, m2, v1, v2 = 2.0, 0.5, 1.5, -2.0
    s = scene([{"name": "a", "shape": "sphere", "radius": 0.2, "mass": m1, "position": [-0.6, 1.0, 0.0],
                "velocity": [v1, 0.0, 0.0], "restitution": e},
               {"name": "b", "shape": "sphere", "radius": 0.2, "mass": m2, "position": [0.6, 1.0, 0.0],
                "velocity": [v2, 0.0, 0.0], "restitution": e}],
              colliders=(), gravity=(0.0, 0.0, 0.0), integrator="rk4", solver_h=1 / 600)
    run(s, 0.5)
    v = s.rigid.state.v[:, 0]
    w1 = (m1 * v1 + m2 * v2 + m2 * e * (v2 - v1)) / (m1 + m2)
    w2 = (m1 * v1 + m2 * v2 + m1 * e * (v1 - v2)) / (m1 + m2)
    assert abs(m1 * v[0] + m2 * v[1] - (m1 * v1 + m2 * v2)) < 1e-12  # momentum, to rounding
    assert v[0] == pytest.approx(w1, abs=1e-9) and v[1] == pytest.approx(w2, abs=1e-9)
    assert np.abs(s.rigid.state.v[:, 1:]).max() < 1e-12 and np.abs(s.rigid.state.w).max() < 1e-12
    x = s.rigid.state.x[:, 0]
    assert x[1] - x[0] >= 0.4 - 1e-9  # never inside each other


@pytest.mark.parametrize("integrator", [pytest.param("rk4", marks=pytest.mark.slow), "symplectic_euler"])
def test_ode_path_box_lands_and_rests_on_a_fixed_box(integrator):
    # a box dropped onto a fixed box (ODE path) comes to rest on its top face: no sinking, no jitter
    s = scene([{"name": "base", "shape": "box", "half_extents": [0.5, 0.25, 0.5], "position": [0.0, 0.25, 0.0],
                "fixed": True},
               {"name": "top", "shape": "box", "half_extents": [0.2, 0.2, 0.2], "position": [0.05, 1.2, 0.0],
                "restitution": 0.3, "friction": 0.5}],
              integrator=integrator, solver_h=1 / 240)
    run(s, 2.0)
    S = s.rigid.state
    assert abs(S.x[1, 1] - 0.7) < 3e-3, S.x[1]  # its bottom on the base's top face (y = 0.5)
    assert np.linalg.norm(S.v[1]) < 0.05 and np.linalg.norm(S.w[1]) < 0.2
    assert np.array_equal(S.x[0], [0.0, 0.25, 0.0])  # the fixed base never moves


@pytest.mark.slow  # (two scene compiles: the default run stays under 5 minutes)
@pytest.mark.parametrize("integrator", ["xpbd", "rk4"])
def test_bodies_rest_on_box_and_capsule_colliders(integrator):
    # a config's box and capsule colliders are met as boxes and capsules on both paths (they were
    # taken for spheres of the default radius: a ball dropped on a table bounced off to the side)
    colliders = (GROUND, {"type": "box", "name": "table", "center": [0.0, 0.5, 0.0], "half_extents": [1.0, 0.5, 1.0],
                          "restitution": 0.0, "friction": 0.5},
                 {"type": "capsule", "name": "pipe", "center": [4.0, 0.3, 0.0], "radius": 0.3, "half_length": 1.0,
                  "orientation": quat.normalize(np.array([1.0, 0.0, 0.0, 1.0])).tolist(), "restitution": 0.0})
    s = scene([{"name": "ball", "shape": "sphere", "radius": 0.1, "position": [0.3, 2.0, 0.0], "restitution": 0.0},
               {"name": "crate", "shape": "box", "half_extents": [0.2, 0.2, 0.2], "position": [-0.5, 2.5, 0.0],
                "restitution": 0.0},
               {"name": "puck", "shape": "sphere", "radius": 0.1, "position": [4.0, 1.5, 0.0], "restitution": 0.0}],
              colliders=colliders, integrator=integrator, solver_h=1 / 240)
    run(s, 2.0)
    x = s.rigid.state.x
    assert abs(x[0, 1] - 1.1) < 5e-3 and abs(x[0, 0] - 0.3) < 0.05, x[0]  # on the table top (y = 1)
    assert abs(x[1, 1] - 1.2) < 5e-3 and abs(x[1, 0] + 0.5) < 0.05, x[1]
    assert abs(x[2, 1] - 0.7) < 5e-3, x[2]  # on top of the pipe (its axis along x at y = 0.3, r = 0.3)


THREADS = """
import hashlib, sys
from engine import runtime
runtime.init("cpu", threads=int(sys.argv[1]))
from engine.config import load_config
from engine.scene import Scene
s = Scene(load_config(sys.argv[2]), render=False)
for _ in range(45):
    s.advance_frame()
S = s.rigid.state
print(hashlib.sha256(S.x.tobytes() + S.q.tobytes() + S.v.tobytes() + S.w.tobytes()).hexdigest())
"""


@pytest.mark.slow  # (default run kept under 5 minutes: the closed forms of the other tests stay in it)
def test_byte_identical_on_one_and_two_threads():
    cfg = os.path.join(ROOT, "configs", "crates.toml")
    out = on_thread_counts(THREADS, cfg)
    assert out[0][-1] == out[1][-1]


@pytest.mark.parametrize("body, key", [
    ({"shape": "box", "half_extents": [0.5, 0.0, 0.5]}, "rigid_bodies[0].half_extents[1]"),
    ({"shape": "sphere", "radius": -1.0}, "rigid_bodies[0].radius"),
    ({"shape": "sphere", "radius": 0.1, "orientation": [0.0, 0.0, 0.0, 0.0]}, "rigid_bodies[0].orientation"),
    ({"shape": "sphere", "radius": 0.1, "orientation": [1.0, 1.0, 0.0, 0.0]}, "rigid_bodies[0].orientation"),
    ({"shape": "sphere", "radius": 0.1, "fixed": True, "velocity": [1.0, 0.0, 0.0]}, "rigid_bodies[0].velocity"),
    ({"shape": "box"}, "rigid_bodies[0].half_extents"),
    ({"shape": "capsule", "radius": 0.1}, "rigid_bodies[0].half_length"),
    ({"shape": "sphere", "radius": 0.1, "mass": 1.0, "density": 10.0}, "rigid_bodies[0].mass"),
])
def test_bad_bodies_are_one_line_naming_the_key(body, key):
    with pytest.raises(ConfigError) as e:
        load_config({"rigid_bodies": [dict(body, name="a")]})
    assert len(e.value.problems) == 1 and e.value.problems[0].startswith(key), e.value.problems


@pytest.mark.parametrize("joint, rigid, key", [
    ({"type": "ball", "bodies": ["a", "nobody"]}, {}, "joints[0].bodies"),
    ({"type": "ball", "bodies": ["a", "a"]}, {}, "joints[0].bodies"),
    ({"type": "hinge", "bodies": ["a", "world"], "limits": [30.0, -30.0]}, {}, "joints[0].limits"),
    ({"type": "distance", "bodies": ["a", "world"], "limits": [2.0, 1.0]}, {}, "joints[0].limits"),
    ({"type": "ball", "bodies": ["a", "world"]}, {"integrator": "rk4"}, "joints[0]"),
])
def test_bad_joints_are_one_line_naming_the_key(joint, rigid, key):
    with pytest.raises(ConfigError) as e:
        load_config({"rigid_bodies": [{"name": "a", "shape": "sphere", "radius": 0.1}], "joints": [joint],
                     "rigid": rigid})
    assert len(e.value.problems) == 1 and e.value.problems[0].startswith(key), e.value.problems


@pytest.mark.slow  # (a 35 s compile: the default run stays under 5 minutes)
def test_sparks_bounce_off_a_tilted_rigid_box_and_a_capsule_named_as_the_bodies():
    # issue 22, item 5: particles meet every rigid body as a posed, turning shape. Sparks rain on
    # a fixed box tilted 30° about z and a fixed capsule lying along x; no live spark ends a
    # frame inside either, the box's tilt sends them down its slope (−x), and the contact
    # records name the bodies
    from engine.api import ParticleScene
    from engine.geometry.shapes import quat_from_rotvec, signed_distance

    tilt = quat_from_rotvec([0.0, 0.0, math.radians(30.0)]).tolist()
    lying = quat_from_rotvec([0.0, 0.0, math.pi / 2]).tolist()
    rain = dict(shape="point", direction=[0.0, -1.0, 0.0], speed=[2.0, 2.0], spread=0.0, rate=400.0,
                lifetime=3.0)
    s = ParticleScene.from_dict({
        "seed": 1, "fps": 60, "forces": {"gravity": [0.0, -G, 0.0]}, "solver": {"h": 1 / 240},
        "colliders": [GROUND],
        "emitters": [dict(rain, name="on_box", position=[0.0, 1.5, 0.0]),
                     dict(rain, name="on_capsule", position=[3.0, 1.5, 0.0])],
        "rigid_bodies": [
            {"name": "crate", "shape": "box", "half_extents": [0.5, 0.25, 0.5], "position": [0.0, 0.6, 0.0],
             "orientation": tilt, "fixed": True, "restitution": 0.2, "friction": 0.1},
            {"name": "pipe", "shape": "capsule", "radius": 0.2, "half_length": 0.6, "position": [3.0, 0.5, 0.0],
             "orientation": lying, "fixed": True, "restitution": 0.2, "friction": 0.1}]},
        contacts=True, render=False)
    bodies = [("box", [0.0, 0.6, 0.0], tilt, dict(half_extents=(0.5, 0.25, 0.5))),
              ("capsule", [3.0, 0.5, 0.0], lying, dict(radius=0.2, half_length=0.6))]
    named = set()
    for _ in range(60):
        s.step(1 / 60)
        p = s.particles()
        for kind, c, q, shape in bodies:
            g = np.array([signed_distance(kind, x, c, q, **shape)[0] for x in p["position"]])
            assert g.min() > -1e-3, (kind, g.min())
        named |= set(s.contacts().collider_name.tolist())
    assert {"crate", "pipe"} <= named
    p = s.particles()
    on_box = p["position"][p["emitter"] == 0]
    assert np.median(on_box[:, 0]) < -0.3  # slid down the box's slope, not straight through it


def test_the_kept_pair_list_gives_the_broad_phases_pairs_at_every_step():
    # bodies drifting (some fast, some still), margins growing and shrinking, a body jumping far
    # and a NaN, given as arrays or as strided views: at every call the kept list gives exactly
    # broad_phase's pairs and order, and it is rebuilt only now and then (the free-flight case it
    # is for)
    from engine.rigid import broad

    rng = np.random.default_rng(3)
    n = 400
    x = rng.uniform(0.0, 6.0, (n, 3))
    v = rng.normal(size=(n, 3)) * np.where(rng.random(n) < 0.2, 2.0, 0.05)[:, None]
    bound = rng.uniform(0.05, 0.3, n)
    keep, built = broad.PairList(), 0
    for step in range(300):
        x = x + v / 240.0
        margin = 0.01 + 0.01 * rng.random(n) * (step % 5 == 0)
        if step == 150:
            x[7] += 3.0
        if step == 200:
            x[9, 0] = np.nan
        before = keep.x0
        if step % 2:  # as the ODE state passes them: a strided view of its position columns
            wide = np.zeros((n, 14))
            wide[:, 2:5] = x
            got = keep.pairs(wide[:, 2:5], bound, margin)
        else:
            got = keep.pairs(x, bound, margin)
        built += keep.x0 is not before
        assert np.array_equal(got, broad.broad_phase(x, bound, margin)), step
    assert built < 100  # kept most steps (rebuilt on a far jump, a NaN, or after enough drift)


@pytest.mark.parametrize("table", ["dense", "sparse", "all pairs"])
def test_the_grid_broad_phase_finds_the_sweeps_pairs_in_the_same_order(table, monkeypatch):
    # the broad phase (a uniform grid) gives exactly the sorted sweep's pairs and order, on
    # clouds, flat layers, coincident bodies and a lattice (where the sweep lists every slab),
    # through its dense table of cells and through its binary search among occupied cells — and
    # so does its test of every pair at once (what it does for a few bodies), here at every size
    from engine.rigid import broad
    from engine.rigid.broad import broad_phase, sweep_phase

    monkeypatch.setattr(broad, "ALL_PAIRS", 10 ** 9 if table == "all pairs" else 0)
    if table == "sparse":
        monkeypatch.setattr(broad, "DENSE_CELLS", -10 ** 9)

    rng = np.random.default_rng(0)
    for trial in range(200):
        n = int(rng.integers(2, 300))
        x = rng.normal(size=(n, 3)) * float(rng.choice([0.5, 2.0, 10.0, 100.0]))
        if trial % 3 == 0:
            x[:, 1] = 0.1 * rng.normal(size=n)
        if trial % 7 == 0:
            x[: n // 2] = x[0]
        bound, margin = rng.uniform(0.05, 0.5, n), rng.uniform(0.0, 0.05, n)
        assert np.array_equal(broad_phase(x, bound, margin), sweep_phase(x, bound, margin)), trial
    g = np.stack(np.meshgrid(*[np.arange(6.0) * 0.35] * 3), -1).reshape(-1, 3)
    a = broad_phase(g, np.full(len(g), 0.2), np.zeros(len(g)))
    assert len(a) > 0 and np.array_equal(a, sweep_phase(g, np.full(len(g), 0.2), np.zeros(len(g))))
    x = np.array([[0.0, 0.0, 0.0], [np.nan, 0.0, 0.0], [0.1, 0.0, 0.0]])
    assert np.array_equal(broad_phase(x, np.full(3, 0.1), np.zeros(3)), [[0, 2]])  # the sweep takes over
