"""The shape table (issue 21, item 2; engine/colliders.py, engine/geometry/shapes.py): planes,
spheres, boxes and capsules that translate and spin, met by particles and soft-body nodes.

Closed forms: a point hitting a surface point that moves at v_s = v + ω × r leaves with
v_r' = v_t' − e v_n in that point's frame and Coulomb friction v_t' = max(0, 1 − μ(1 + e)|v_n|/|v_t|) v_t
(NUMERICS.md, "Collisions"), so a ball dropped onto the top of a sphere of radius R spinning at ω
about z gets a sideways kick −min(μ(1 + e) v₁, ωR) (v₁ = √(2 g Δh) its impact speed), and one
dropped at x = a onto a box spinning at ω about y gets −min(μ(1 + e) v₁, ω a) along z. A box of half
height b turning about z at ω shows a falling point at x = 0 its top face at height b / cos(ωt):
the impact is where y₀ − g t²/2 = b / cos(ωt)."""
import math

import numpy as np
import pytest
import taichi as ti

from engine.api import SceneBuilder
from engine.geometry.shapes import inertia, quat_from_rotvec, signed_distance, spun

G = 9.81


# -- geometry against the NumPy reference --------------------------------------------------------------
def test_inertia_helpers_match_the_closed_forms():
    m = 2.0
    np.testing.assert_allclose(inertia("sphere", m, radius=0.5), np.eye(3) * 0.4 * m * 0.25)
    np.testing.assert_allclose(inertia("box", m, half_extents=(0.5, 1.0, 1.5)),
                               np.diag([1.0 + 2.25, 0.25 + 2.25, 0.25 + 1.0]) * m / 3)
    # a capsule of zero length is a sphere; a very thin one a rod of length 2L: m (2L)²/12 across it
    np.testing.assert_allclose(inertia("capsule", m, radius=0.5, half_length=0.0), inertia("sphere", m, radius=0.5))
    rod = inertia("capsule", m, radius=1e-6, half_length=1.0)
    assert abs(rod[0, 0] - m * 4 / 12) < 1e-5 and abs(rod[2, 2] - m * 4 / 12) < 1e-5 and rod[1, 1] < 1e-9
    with pytest.raises(ValueError, match="plane"):
        inertia("plane", m)


def test_pose_arithmetic_matches_rodrigues_and_composes_spins():
    # the host's pose arithmetic (floats, engine.geometry.shapes' *_t, and its NumPy wrappers):
    # exp of a rotation vector is Rodrigues' rotation R = I + sin θ K + (1 − cos θ) K², two spins
    # about one axis add, and a zero quaternion is refused naming the key
    from engine.geometry.shapes import quat_matrix_t, quat_to_matrix, spun_t
    rng = np.random.default_rng(3)
    for w in rng.normal(size=(50, 3)) * 2.0:
        th = np.linalg.norm(w)
        k = w / th
        K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        rod = np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K
        q = quat_from_rotvec(w)
        np.testing.assert_allclose(quat_to_matrix(q), rod, atol=1e-14)
        np.testing.assert_allclose(np.reshape(quat_matrix_t(q.tolist()), (3, 3)), rod, atol=1e-14)
        q0 = quat_from_rotvec(rng.normal(size=3)).tolist()
        a, b = rng.uniform(-1.0, 1.0, 2)
        np.testing.assert_allclose(spun_t(spun_t(q0, w.tolist(), a), w.tolist(), b), spun(q0, w, a + b), atol=1e-14)
    with pytest.raises(ValueError, match="orientation: a quaternion"):
        spun([0.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.1)


def test_kernel_distances_match_the_reference_for_moving_spinning_shapes():
    # f64 table; at `lag` before the step's end a shape is at p − v·lag turned by −ω·lag: the
    # kernel's (g, N) there equal the reference's for that pose, for every kind
    from engine.colliders import ColliderSpec, Colliders

    q = quat_from_rotvec([0.3, 0.5, -0.2])
    specs = [ColliderSpec("plane", point=(0, 0.1, 0), normal=(0.1, 1, 0), rotates=True),
             ColliderSpec("sphere", point=(1, 1, 0), radius=0.5, rotates=True),
             ColliderSpec("box", point=(0, 1, 1), half_extents=(0.3, 0.2, 0.5), orientation=tuple(q), rotates=True),
             ColliderSpec("capsule", point=(1, 0, 1), radius=0.2, half_length=0.4, orientation=tuple(q), rotates=True)]
    shape = [dict(normal=(0.1, 1, 0)), dict(radius=0.5), dict(half_extents=(0.3, 0.2, 0.5)),
             dict(radius=0.2, half_length=0.4)]
    c = Colliders(specs, dtype=ti.f64)
    vel, omega, h = np.array([0.4, -0.3, 0.2]), np.array([1.5, -2.0, 0.7]), 0.1
    p1 = np.array([s.point for s in specs], np.float64) + vel * h
    q1 = [spun(s.orientation, omega, h) for s in specs]
    c.move_to(h, p1, since=(0.0, p1 - vel * h), orientations=q1, omegas=[omega] * 4)
    n, lag = 4000, 0.037
    X = ti.Vector.field(3, ti.f64, n)
    Gf = ti.field(ti.f64, (4, n))
    Nf = ti.Vector.field(3, ti.f64, (4, n))

    @ti.kernel
    def run(lag: ti.f64):
        for i in X:
            for k in ti.static(range(4)):
                g, _gd, nn = c.contact(k, X[i], X[i] * 0.0, lag)
                Gf[k, i], Nf[k, i] = g, nn

    rng = np.random.default_rng(0)
    x = rng.uniform(-0.5, 1.6, (n, 3))
    X.from_numpy(x)
    run(lag)
    g, nn = Gf.to_numpy(), Nf.to_numpy()
    for k, s in enumerate(specs):
        p, qk = p1[k] - vel * lag, spun(q1[k], omega, -lag)
        ref = [signed_distance(s.kind, xi, p, qk, **shape[k]) for xi in x]
        np.testing.assert_allclose(g[k], [r[0] for r in ref], atol=1e-12, err_msg=s.kind)
        far = np.abs(g[k]) > 1e-9
        np.testing.assert_allclose(nn[k][far], np.array([r[1] for r in ref])[far], atol=1e-9, err_msg=s.kind)
        assert (g[k] < 0).sum() > 20, s.kind  # points inside every shape were looked at


def test_projected_shapes_match_the_reference_for_moving_spinning_bodies():
    # a rigid body's box or capsule sits at the table's end, met by a run-time loop
    # (Colliders.projected_contact): its (g, N) at `lag` before the step's end equal the
    # reference's for the pose there (p − v·lag, turned by −ω·lag), with and without an offset
    from engine.collider_view import ColliderView
    from engine.colliders import ColliderSpec, Colliders
    q = quat_from_rotvec([-0.4, 0.2, 0.6])
    specs = [ColliderSpec("plane", point=(0, -2, 0)),
             ColliderSpec("box", point=(0, 1, 1), half_extents=(0.3, 0.2, 0.5), orientation=tuple(q),
                          rotates=True, owner="rigid", owner_index=0),
             ColliderSpec("capsule", point=(1, 0, 1), radius=0.2, half_length=0.4, orientation=tuple(q),
                          rotates=True, owner="rigid", owner_index=1)]
    shape = [None, dict(half_extents=(0.3, 0.2, 0.5)), dict(radius=0.2, half_length=0.4)]
    c = Colliders(specs, dtype=ti.f64)
    assert c.event_count == 1 and c.count == 3
    vel, omega, h, d = np.array([0.4, -0.3, 0.2]), np.array([1.5, -2.0, 0.7]), 0.1, 0.05
    p1 = np.array([s.point for s in specs], np.float64) + vel * h
    q1 = [spun(s.orientation, omega, h) for s in specs]
    c.move_to(h, p1, since=(0.0, p1 - vel * h), orientations=q1, omegas=[[0, 0, 0], omega, omega])
    view = ColliderView(c, d)
    n, lag = 4000, 0.037
    X = ti.Vector.field(3, ti.f64, n)
    Gf = ti.field(ti.f64, (2, 2, n))
    Nf = ti.Vector.field(3, ti.f64, (2, 2, n))

    @ti.kernel
    def run(lag: ti.f64):
        for i in X:
            for k in ti.static(range(2)):
                g, nn = c.projected_contact(k + 1, X[i], lag)
                Gf[0, k, i], Nf[0, k, i] = g, nn
                g, nn = view.projected_contact(k + 1, X[i], lag)
                Gf[1, k, i], Nf[1, k, i] = g, nn

    rng = np.random.default_rng(1)
    x = rng.uniform(-0.5, 1.6, (n, 3))
    X.from_numpy(x)
    run(lag)
    g, nn = Gf.to_numpy(), Nf.to_numpy()
    for k in (1, 2):
        p, qk = p1[k] - vel * lag, spun(q1[k], omega, -lag)
        ref = [signed_distance(specs[k].kind, xi, p, qk, **shape[k]) for xi in x]
        np.testing.assert_allclose(g[0, k - 1], [r[0] for r in ref], atol=1e-12, err_msg=specs[k].kind)
        # the view: less the offset (a compile-time constant, rounded to the default f32)
        np.testing.assert_allclose(g[1, k - 1], g[0, k - 1] - d, atol=1e-8)
        far = np.abs(g[0, k - 1]) > 1e-9
        np.testing.assert_allclose(nn[0, k - 1][far], np.array([r[1] for r in ref])[far], atol=1e-9)
        assert (g[0, k - 1] < 0).sum() > 20, specs[k].kind


# -- spinning shapes hand their surface velocity on ------------------------------------------------
def _spin_scene(boxes: bool):
    """Balls dropped from rest at t = 0, each 1 m above a surface: a sphere spinning about z with
    little friction (a partial kick), one with much (the kick saturates at ωR); with ``boxes``, a
    box spun about y from code and a box turning about z (its top face tilts under the ball)."""
    b = (SceneBuilder(seed=1, fps=60).solver(integrator="rk4", h=1 / 60).forces(gravity=[0.0, -G, 0.0]))
    balls = (("c", [6.2, 1.25, 0.0]), ("d", [-4.0, 1.25, 0.0])) if boxes else \
        (("a", [0.0, 1.5, 0.0]), ("b", [3.0, 1.5, 0.0]))
    for name, pos in balls:
        b = b.emitter(name=name, shape="point", position=pos, speed=[0.0, 0.0], lifetime=100.0,
                      bursts=[{"time": 0.0, "count": 1}], rate=0.0)
    if boxes:
        b = (b.collider(type="box", name="turntable", center=[6.0, 0.0, 0.0], half_extents=[0.5, 0.25, 0.5],
                        restitution=0.5, friction=1.0, rotates=True)
             .collider(type="box", name="tilt", center=[-4.0, 0.0, 0.0], half_extents=[1.0, 0.25, 1.0],
                       restitution=0.5, angular_velocity=[0.0, 0.0, 1.0]))
    else:
        b = (b.collider(type="sphere", name="slick", center=[0.0, 0.0, 0.0], radius=0.5, restitution=0.5,
                        friction=0.1, angular_velocity=[0.0, 0.0, 4.0])
             .collider(type="sphere", name="grippy", center=[3.0, 0.0, 0.0], radius=0.5, restitution=0.5,
                       friction=1.0, angular_velocity=[0.0, 0.0, 4.0]))
    s = b.collider(type="plane", name="floor", point=[0.0, -5.0, 0.0]).build(contacts=True, render=False)
    if boxes:
        s.set_collider_pose("turntable", [6.0, 0.0, 0.0], angular_velocity=[0.0, 3.0, 0.0])
    rows = []
    for _ in range(30):  # to t = 0.5 s: every ball has bounced once and is in flight
        s.step(1 / 60)
        c = s.contacts()
        rows += [dict(r, emitter=str(c.a_name[k])) for k, r in enumerate(c.rows())]
    return s, rows


@pytest.fixture(scope="module")
def spheres():
    return _spin_scene(False)


@pytest.fixture(scope="module")
def boxes():
    return _spin_scene(True)


def _velocities(s):
    p = s.particles()
    return {s.cfg.emitters[i].name: p["velocity"][j] for j, i in enumerate(p["emitter"])}


E, T, V1, T1 = 0.5, 0.5, math.sqrt(2 * G * 1.0), math.sqrt(2 * 1.0 / G)
VY = E * V1 - G * (T - T1)  # the balls' vertical velocity at T, after one bounce at T1


def _first_impacts_at_the_drop_time(rows, names):
    first = {r["emitter"]: r for r in reversed(rows)}
    for name in names:
        assert abs(first[name]["time"] - T1) < 2e-6 and abs(first[name]["speed"] - V1) < 1e-4


def test_spinning_sphere_kicks_along_omega_cross_r(spheres):
    # ωR = 2 m/s of slip: little friction takes μ(1 + e)v₁ = 0.664 m/s of it, much takes all
    s, rows = spheres
    vel = _velocities(s)
    np.testing.assert_allclose(vel["a"], [-0.1 * (1 + E) * V1, VY, 0.0], atol=2e-4)
    np.testing.assert_allclose(vel["b"], [-4.0 * 0.5, VY, 0.0], atol=2e-4)
    _first_impacts_at_the_drop_time(rows, "ab")


@pytest.mark.slow
def test_spinning_box_kicks_along_omega_cross_r(boxes):
    # a box spun about y from code (set_collider_pose): ω × r = (0, 3, 0) × (0.2, 0.25, 0) = (0, 0, −0.6)
    s, rows = boxes
    np.testing.assert_allclose(_velocities(s)["c"], [0.0, VY, -3.0 * 0.2], atol=2e-4)
    _first_impacts_at_the_drop_time(rows, "c")


@pytest.mark.slow
def test_impact_is_located_on_a_rotating_box_face(boxes):
    from scipy.optimize import brentq

    _s, rows = boxes
    hit = [r for r in rows if r["emitter"] == "d"][0]
    b, w = 0.25, 1.0
    t_hit = brentq(lambda t: 1.25 - 0.5 * G * t * t - b / math.cos(w * t), 0.0, 0.6)
    th = w * t_hit
    assert abs(hit["time"] - t_hit) < 5e-6 and hit["b_name"] == "tilt"
    np.testing.assert_allclose(hit["position"], [-4.0, b / math.cos(th), 0.0], atol=2e-5)
    np.testing.assert_allclose(hit["normal"], [-math.sin(th), math.cos(th), 0.0], atol=1e-5)
    assert abs(b / math.cos(th) - b) > 0.02  # the tilt moved the face: a still box would be wrong


def test_contact_records_name_both_parties(spheres):
    # party a: the particle (its pool slot) of its emitter; party b: the collider, by index and name
    s, rows = spheres
    cols = [c.name for c in s.cfg.colliders]
    assert {r["emitter"] for r in rows} == {"a", "b"}
    for r in rows:
        assert r["a_kind"] == "particle" and r["a_name"] == r["emitter"] and r["a_index"] == r["slot"]
        assert r["b_kind"] == "collider" and r["b_name"] == r["name"] == cols[r["b_index"]]
        assert r["b_index"] == r["collider"]
    assert {r["a_name"]: r["b_name"] for r in rows} == {"a": "slick", "b": "grippy"}


def test_a_rigid_bodys_shape_is_named_as_the_body():
    # a shape the rigid system publishes into the table is party b as ("rigid", body index, name)
    from engine.contacts import Contacts

    c = Contacts(np.array([1, 0], np.int32), np.zeros((2, 3), np.float32), np.zeros((2, 3), np.float32),
                 np.ones(2, np.float32), np.array([0.1, 0.2], np.float32), np.array([7, 9], np.int32),
                 names=("ground", "crate"), group=np.array([1, 0], np.int32), kind="particle",
                 group_names=("smoke", "sparks"), shapes=(("collider", 0), ("rigid", 3)))
    r = list(c.rows())
    assert (r[0]["a_kind"], r[0]["a_index"], r[0]["a_name"]) == ("particle", 7, "sparks")
    assert (r[0]["b_kind"], r[0]["b_index"], r[0]["b_name"]) == ("rigid", 3, "crate")
    assert (r[1]["a_name"], r[1]["b_kind"], r[1]["b_index"], r[1]["b_name"]) == ("smoke", "collider", 0, "ground")
    m = c.where(c.b_kind == "rigid")
    assert len(m) == 1 and m.a_name.tolist() == ["sparks"] and m.collider_name.tolist() == ["crate"]


@pytest.mark.slow  # (the default run is near its 5 minutes)
def test_a_table_reorients_only_shapes_that_turned_and_a_refusal_writes_no_pose():
    """Colliders._orient keeps the row of a shape whose orientation and ω did not change: after
    moves where some shapes turn and others rest, the fields hold the bytes a fresh table given
    the same pose holds; a refused ω (a shape built without rotation) writes no pose at all."""
    from engine.colliders import Colliders, ColliderSpec

    specs = [ColliderSpec("box", point=(0, 1, 0), half_extents=(0.3, 0.2, 0.5), rotates=True),
             ColliderSpec("capsule", point=(1, 1, 0), radius=0.1, half_length=0.3, rotates=True),
             ColliderSpec("plane", point=(0, 0, 0), normal=(0.1, 1, 0))]
    pos, I = [[0, 1, 0], [1, 1, 0], [0, 0, 0]], [1.0, 0.0, 0.0, 0.0]
    qa, qb = quat_from_rotvec([0.3, 0.2, 0.1]), quat_from_rotvec([0.0, 0.0, 0.5])
    poses = [([qa, I, I], [[0, 0, 1], [0, 0, 0], [0, 0, 0]]),  # the box turns
             ([qa, qb, I], [[0, 0, 1], [0, 0, 0], [0, 0, 0]]),  # the capsule turns, the box rests
             ([qb, qb, I], [[0, 0, 0], [1, 0, 0], [0, 0, 0]])]

    def fields(t):
        return [f.to_numpy() for f in (t.collider_normal, t.collider_axis_x, t.collider_axis_z, t.collider_omega)]

    table = Colliders(specs)
    for k, (qs, ws) in enumerate(poses):
        table.move_to(0.1 * (k + 1), pos, orientations=qs, omegas=ws)
        fresh = Colliders(specs)
        fresh.move_to(0.1 * (k + 1), pos, orientations=qs, omegas=ws)
        assert all(np.array_equal(a, b) for a, b in zip(fields(table), fields(fresh))), k
        assert np.array_equal(table._quat, fresh._quat) and np.array_equal(table._omega, fresh._omega)
    before, quat = fields(table) + [table.collider_point.to_numpy(), table.collider_vel.to_numpy()], table._quat.copy()
    host = table._pos.copy()
    with pytest.raises(ValueError, match="angular_velocity: collider 2 was built without rotation"):
        table.move_to(0.5, np.add(pos, 0.25), orientations=[qa, qa, I], omegas=[[0, 0, 0], [0, 0, 0], [0, 1, 0]])
    after = fields(table) + [table.collider_point.to_numpy(), table.collider_vel.to_numpy()]
    assert all(np.array_equal(a, b) for a, b in zip(after, before)) and np.array_equal(table._quat, quat)
    assert np.array_equal(table._pos, host)  # nor a position (the positions are placed after the check)


def test_a_collider_built_without_rotation_cannot_be_spun(spheres):
    s, _rows = spheres
    with pytest.raises(ValueError, match=r"^set_collider_pose: angular_velocity \[0, 1, 0\] is not allowed: "
                                         r"collider 'floor' was built without rotation"):
        s.set_collider_pose("floor", [0.0, -5.0, 0.0], angular_velocity=[0, 1, 0])
    with pytest.raises(ValueError, match=r"^set_collider_pose: orientation \[0, 0, 0, 0\] is not allowed"):
        s.set_collider_pose("slick", [0.0, 0.0, 0.0], orientation=[0, 0, 0, 0])
    with pytest.raises(KeyError, match="set_collider_pose: name: no collider named 'nope'"):
        s.set_collider_pose("nope", [0.0, 0.0, 0.0])


@pytest.mark.slow
def test_nodes_landing_on_a_spinning_box_take_its_surface_velocity():
    # a small cloth falls 0.25 m flat onto a box turning at ω about y (e = 0, μ = 1): every node
    # meets the top face at t₁ = √(2·0.25/g) (located on the path, as for a still box), stops along
    # the normal and, its slip ω·r < μ|v_n|, takes the surface point's velocity ω × r
    from engine.colliders import ColliderSpec, Colliders
    from engine.springs import SpringSystem, cloth

    w = 2.0
    col = Colliders([ColliderSpec("box", point=(0.0, 0.0, 0.0), half_extents=(1.0, 0.25, 1.0), restitution=0.0,
                                  friction=1.0, angular_velocity=(0.0, w, 0.0))])
    top = cloth(3, 3, size=(0.2, 0.2), origin=(0.05, 0.5, -0.1), mass=0.01, ks=1.0, kd=0.0)
    sys = SpringSystem(top, colliders=col, integrator="rk4", gravity=(0.0, -G, 0.0), dtype=ti.f32, substeps=1,
                       contacts=64)
    t1 = math.sqrt(2 * 0.25 / G)
    n = math.ceil(t1 * 60)
    for _ in range(n):  # to the end of the step holding the impact
        sys.step(1 / 60)
    c = sys.contact_log.drain(col.names, ("sheet",), col.parties)
    assert len(c) == 9 and set(c.a_kind) == {"node"} and set(c.a_name) == {"sheet"}
    np.testing.assert_allclose(c.time, t1, atol=2e-5)
    x, v = sys.positions().astype(np.float64), sys.velocities().astype(np.float64)
    np.testing.assert_allclose(x[:, 1], 0.25, atol=1e-5)
    spin = np.cross([0.0, w, 0.0], x)  # ω × r about the box's centre
    np.testing.assert_allclose(v[:, [0, 2]], spin[:, [0, 2]], atol=2e-3)
    assert np.abs(v[:, 1]).max() < 0.2  # at rest along the normal (gravity over the rest of the step)


# -- boxes and capsules stop particles and nodes ----------------------------------------------------
BOX = dict(center=[0.0, 0.5, 0.0], half_extents=[0.4, 0.2, 0.3], orientation=list(quat_from_rotvec([0, 0.4, 0.15])))
CAPSULE = dict(center=[1.5, 0.4, 0.0], radius=0.2, half_length=0.5,
               orientation=list(quat_from_rotvec([0.0, 0.0, math.pi / 2])))  # lying along x


@pytest.mark.slow
def test_box_and_capsule_stop_particles_and_nodes_at_their_surface():
    from engine.config import load_config
    from engine.scene import Scene
    from helpers import scene_dict

    thick = 0.02
    d = scene_dict(fps=30, solver={"integrator": "rk4", "h": 1 / 120}, forces={"gravity": [0.0, -G, 0.0]},
                   emitters=[{"name": "rain", "shape": "box", "box_size": [3.0, 0.0, 0.6], "position": [0.7, 1.4, 0.0],
                              "rate": 600.0, "lifetime": 3.0, "speed": [0.0, 0.5], "direction": [0.0, -1.0, 0.0]}],
                   colliders=[dict(type="box", name="crate", restitution=0.3, friction=0.3, **BOX),
                              dict(type="capsule", name="log", restitution=0.3, friction=0.3, **CAPSULE)],
                   bodies=[{"type": "cloth", "name": "sheet", "resolution": [8, 8], "size": [0.5, 0.5],
                            "position": [-0.25, 1.0, -0.25], "plane": "xz", "pins": "none", "thickness": thick,
                            "stiffness": 200.0, "mass": 0.05, "integrator": "xpbd"},
                           {"type": "chain", "name": "rope", "segments": 10, "length": 0.8, "position": [1.1, 1.0, 0.0],
                            "direction": [1.0, 0.0, 0.0], "pins": "none", "thickness": thick, "contacts": True}])
    s = Scene(load_config(d), render=False, contacts=4096)
    table = s.colliders
    for body in s.bodies:  # one table: the bodies see it through their thickness, sharing its fields
        assert body.colliders.table is table and body.colliders.offset == thick
        assert body.colliders.collider_point is table.collider_point

    def gap(points, name):
        spec = dict(BOX if name == "crate" else CAPSULE)
        kind = "box" if name == "crate" else "capsule"
        extra = dict(half_extents=spec["half_extents"]) if kind == "box" else dict(radius=spec["radius"],
                                                                                   half_length=spec["half_length"])
        return np.array([signed_distance(kind, x, spec["center"], spec["orientation"], **extra)[0] for x in points])

    touched = set()
    for _ in range(36):
        s.advance_frame()
        c = s.bodies[1].contacts()  # the rope's nodes: party a a "node" of "rope"
        assert set(c.a_kind) <= {"node"} and set(c.a_name) <= {"rope"} and set(c.b_kind) <= {"collider"}
        touched |= set(c.b_name)
        x = s.positions()
        for name in ("crate", "log"):
            assert gap(x, name).min() >= -2e-5, name
        for body in s.bodies:
            for name in ("crate", "log"):
                assert gap(body.positions(), name).min() >= thick - 1e-4, (body.name, name)
    assert s.particles.integrator.hits[None] > 200
    assert s.particles.integrator.lean  # boxes and capsules: its step compiles without the CSE pass
    sheet, rope = (b.positions() for b in s.bodies)
    # the sheet came to lie on the crate (its middle node within a few cm of the offset top face),
    # the rope hangs over the log
    assert abs(gap(sheet[[4 * 8 + 4]], "crate")[0] - thick) < 0.03
    assert gap(rope, "log").min() < thick + 0.01
    assert "log" in touched


# -- bad input: one line naming the key and the value ---------------------------------------------------
@pytest.mark.parametrize("extra, key", [
    ('type = "box"\nhalf_extents = [0.5, 0.0, 0.5]', "half_extents"),
    ('type = "box"\norientation = [0.0, 0.0, 0.0, 0.0]', "orientation"),
    ('type = "box"\norientation = [1.0, 0.0, 0.0]', "orientation"),
    ('type = "box"\nradius = 0.5', "radius"),
    ('type = "capsule"\nradius = -0.1', "radius"),
    ('type = "capsule"\nhalf_length = -1.0', "half_length"),
    ('type = "capsule"\nhalf_extents = [1.0, 1.0, 1.0]', "half_extents"),
    ('type = "sphere"\nangular_velocity = [0.0, 1e5, 0.0]', "angular_velocity"),
    ('type = "cylinder"', "cylinder"),
])
def test_bad_collider_keys_are_one_line_naming_the_key(tmp_path, extra, key):
    from runhelp import call

    path = tmp_path / "fx.toml"
    path.write_text(f"frames = 2\n[[emitters]]\nrate = 5.0\n[[colliders]]\n{extra}\n")
    code, out, err = call("validate", path)
    lines = out.strip().splitlines()
    assert code == 2 and len(lines) == 1 and key in lines[0] and "colliders" in lines[0], (out, err)


@pytest.mark.slow
def test_boxes_and_capsules_are_drawn_where_they_are():
    # the background draws a box and a capsule (slab and capsule ray tests): shown, the pixels at
    # their projected centres change; the sky far from them does not
    s = (SceneBuilder(seed=1, fps=30).forces(gravity=[0, -G, 0]).render(width=160, height=90, grid=False)
         .camera(position=[0.0, 0.4, 4.0], look_at=[0.0, 0.4, 0.0], fov=40.0)
         .emitter(name="e", rate=1.0, position=[0, -50, 0], lifetime=0.1)
         .collider(type="box", name="b", center=[-0.8, 0.4, 0.0], half_extents=[0.3, 0.3, 0.3],
                   orientation=list(quat_from_rotvec([0.0, 0.7, 0.0])))
         .collider(type="capsule", name="c", center=[0.8, 0.4, 0.0], radius=0.2, half_length=0.3,
                   orientation=list(quat_from_rotvec([0.0, 0.0, 0.8])))
         .build(render=True))
    shown, hidden = s.render(show_colliders=True), s.render(show_colliders=False)
    diff = np.abs(shown.astype(int) - hidden.astype(int)).sum(axis=2)
    f = 45 / math.tan(math.radians(20))  # pixels per unit of x/z at the image centre row
    for x in (-0.8, 0.8):
        assert diff[45, int(round(80 + f * x / 4.0))] > 0, x
    assert diff[:10, :10].max() == 0 and diff[:, 75:85].max() == 0  # sky, and the gap between them
