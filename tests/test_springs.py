"""Spring networks: oscillation period, momentum, energy behaviour, the stiffness guard, XPBD,
collisions, gather vs atomics, topology counts, step doubling. Numerics in float64."""
import numpy as np
import pytest
import taichi as ti

from engine.colliders import Colliders, ColliderSpec
from engine.springs import (BEND, BODY, SHEAR, STRUCTURAL, SimulationDiverged, SpringSystem,
                            StiffnessError, chain, cloth, hair, jelly, merge, scalp_roots, write_energy_csv)
from engine.control import Control
from engine.springs.forces import ACCUMULATORS, accel_launcher
from engine.springs.model import SpringModel, SpringState

NO_GRAVITY = (0.0, 0.0, 0.0)


def _spring(k=100.0, m=1.0, rest=1.0, stretch=0.1):
    """Node 0 pinned at the origin, node 1 free at rest + stretch along x."""
    top = chain(2, start=(0, 0, 0), end=(rest + stretch, 0, 0), mass=m, ks=k)
    top.rest_length[:] = rest
    return top


def _stretch(sys):
    x, e = sys.positions().astype(np.float64), sys.top.edges
    s = sys.top.kind == STRUCTURAL
    return np.linalg.norm(x[e[s, 0]] - x[e[s, 1]], axis=1) / sys.top.rest_length[s] - 1.0


# -- topology -------------------------------------------------------------------------------------
def test_topology_spring_counts():
    nx, ny = 7, 5
    c = cloth(nx, ny, pin="corners")
    assert c.count(STRUCTURAL) == nx * (ny - 1) + ny * (nx - 1)
    assert c.count(SHEAR) == 2 * (nx - 1) * (ny - 1)
    assert c.count(BEND) == nx * (ny - 2) + ny * (nx - 2)
    assert len(c.triangles) == 2 * (nx - 1) * (ny - 1) and list(c.pinned) == [28, 34]
    assert np.allclose(np.sort(c.rest_length[c.kind == STRUCTURAL]), [1 / 6] * 30 + [1 / 4] * 28)
    j = jelly(3, 4, 5)
    cells = 2 * 3 * 4
    assert j.count(STRUCTURAL) == 2 * 4 * 5 + 3 * 3 * 5 + 3 * 4 * 4
    assert j.count(SHEAR) == 2 * (2 * 3 * 5 + 2 * 4 * 4 + 3 * 3 * 4)
    assert j.count(BODY) == 4 * cells
    assert len(j.triangles) == 4 * (2 * 3 + 2 * 4 + 3 * 4)
    # outer faces point outward: the signed volume of the closed surface is the box volume
    p = j.positions[j.triangles]
    vol = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6
    assert vol == pytest.approx(1.0)
    h = hair(*scalp_roots((0, 0, 0), 0.1, 6), segments=5)
    assert h.node_count == 36 and h.count(STRUCTURAL) == 30 and h.count(BEND) == 24
    assert list(h.pinned) == [0, 6, 12, 18, 24, 30]
    m = merge(c, h)
    assert m.node_count == c.node_count + h.node_count
    assert m.spring_count == c.spring_count + h.spring_count
    assert list(m.pinned) == list(c.pinned) + list(h.pinned + c.node_count)
    assert np.array_equal(m.edges[c.spring_count:], h.edges + c.node_count)


# -- force accumulation -----------------------------------------------------------------------------
def test_gather_and_atomic_forces_agree():
    top = jelly(4, 3, 3, ks=50.0, kd=0.3)
    rng = np.random.default_rng(1)
    model = SpringModel(top, ti.f64)
    control = Control(gravity=(0.0, -9.81, 0.0), dtype=ti.f64)
    state = SpringState(top.node_count, ti.f64)
    state.node_pos.from_numpy(top.positions + 0.05 * rng.standard_normal(top.positions.shape))
    state.node_vel.from_numpy(rng.standard_normal(top.positions.shape))
    out = {}
    for name in ACCUMULATORS:
        A = ti.Vector.field(3, ti.f64, (1, top.node_count))
        accel_launcher(model, control.gravity, name)(state.node_pos, state.node_vel, A, 0)
        out[name] = A.to_numpy()[0]
    assert np.abs(out["gather"]).max() > 1.0  # the perturbation produced real forces
    np.testing.assert_allclose(out["gather"], out["atomic"], rtol=1e-12, atol=1e-12)
    # internal forces cancel: Σ m (a − g) = 0
    net = (top.masses[:, None] * (out["gather"] - np.array([0.0, -9.81, 0.0]))).sum(0)
    assert np.abs(net).max() < 1e-11


# -- oscillation, momentum, energy --------------------------------------------------------------------
def test_single_spring_period():
    k, m = 100.0, 1.0
    sys = SpringSystem(_spring(k, m), gravity=NO_GRAVITY, integrator="rk4", dtype=ti.f64, substeps=10)
    h, xs = 1e-2, []  # samples every 10 steps of 1 ms
    for _ in range(200):  # 2 s ≈ 3.2 periods
        sys.step(h)
        xs.append(sys.positions()[1, 0] - 1.0)
    xs = np.array(xs)
    t = h * np.arange(1, len(xs) + 1)
    i = np.nonzero(np.sign(xs[:-1]) != np.sign(xs[1:]))[0]
    crossings = t[i] - xs[i] * h / (xs[i + 1] - xs[i])  # linear interpolation
    period = 2 * np.mean(np.diff(crossings))
    assert len(crossings) >= 6
    assert period == pytest.approx(2 * np.pi / np.sqrt(k / m), rel=0.01)


@pytest.mark.parametrize("integrator", ["symplectic_euler", pytest.param("rk4", marks=pytest.mark.slow)])
def test_momentum_conserved_in_free_network(integrator):
    top = jelly(3, 3, 3, ks=80.0, kd=0.2, mass=0.05)
    rng = np.random.default_rng(7)
    sys = SpringSystem(top, gravity=NO_GRAVITY, integrator=integrator, dtype=ti.f64, substeps="auto")
    sys.set_positions(top.positions + 0.05 * rng.standard_normal(top.positions.shape))
    sys.set_velocities(rng.standard_normal(top.positions.shape))
    p0 = (top.masses[:, None] * sys.velocities()).sum(0)
    for _ in range(30):
        sys.step(1 / 60)
    p1 = (top.masses[:, None] * sys.velocities()).sum(0)
    assert np.abs(sys.velocities() - rng.standard_normal(1)).max() > 0  # state moved on
    assert np.abs(p1 - p0).max() < 1e-12 * max(1.0, np.abs(top.masses[:, None] * sys.velocities()).sum())


def _energy_series(integrator, h, n_steps, every=10):
    sys = SpringSystem(_spring(), gravity=NO_GRAVITY, integrator=integrator, dtype=ti.f64,
                       substeps=every, check_stability=False)
    e = [sys.energy()["total"]]
    for _ in range(n_steps // every):
        sys.step(h * every)
        e.append(sys.energy()["total"])
    return np.array(e)


@pytest.mark.slow
def test_symplectic_energy_bounded_while_euler_grows(tmp_path):
    h = 0.01  # hω = 0.1, well below symplectic Euler's limit of 2
    se = _energy_series("symplectic_euler", h, 10_000, every=50)
    eu = _energy_series("euler", h, 10_000, every=50)
    e0 = se[0]
    assert np.abs(se - e0).max() < 0.1 * e0
    first, last = np.abs(se[:20] - e0).max(), np.abs(se[-20:] - e0).max()
    assert last < 1.5 * first + 1e-12  # no secular drift
    assert eu[-1] > 100 * e0 and np.all(np.diff(eu[::20]) > 0)  # grows ×(1 + h²ω²) per step
    path = tmp_path / "energy.csv"
    write_energy_csv(path, [dict(t=i * h, kinetic=0, gravitational=0, spring=v, total=v) for i, v in enumerate(se[:3])])
    lines = path.read_text().splitlines()
    assert lines[0] == "t,kinetic,gravitational,spring,total" and len(lines) == 4


# -- stiff cloth: the guard, divergence, XPBD ----------------------------------------------------------
def _stiff_cloth():
    return cloth(16, 16, size=(0.5, 0.5), plane="xy", mass=0.01, ks=1e4, kd=0.01, pin="corners")


@pytest.mark.slow
def test_guard_refuses_stiff_cloth_and_forced_run_diverges():
    with pytest.raises(StiffnessError, match=r"symplectic_euler needs h < .* s for ω_max = \d+ rad/s .*"
                                             r"got h = 0.0167: use substeps >= \d+ or solver 'xpbd'"):
        SpringSystem(_stiff_cloth(), integrator="symplectic_euler").step(1 / 60)
    with pytest.raises(StiffnessError, match="euler is unstable at every h"):
        SpringSystem(_spring(), gravity=NO_GRAVITY, integrator="euler").step(1 / 60)
    forced = SpringSystem(_stiff_cloth(), integrator="symplectic_euler", check_stability=False)
    with pytest.raises(SimulationDiverged, match=r"symplectic_euler diverged: non-finite state at t=[\d.]+ s with h=0.01667 s"):
        for _ in range(300):
            forced.step(1 / 60)
    assert forced.time < 5.0


@pytest.mark.slow
def test_xpbd_stiff_cloth_stable_at_frame_rate():
    sys = SpringSystem(_stiff_cloth(), integrator="xpbd", xpbd_iterations=20, substeps=2)
    for _ in range(45):
        sys.step(1 / 60)
        assert np.isfinite(sys.positions()).all()
    stretch = _stretch(sys)
    assert np.abs(stretch).max() < 0.1, stretch.max()
    assert np.abs(stretch).mean() < 0.01
    assert np.isfinite(sys.energy()["total"])


def test_auto_substeps_keep_symplectic_euler_stable():
    sys = SpringSystem(_stiff_cloth(), integrator="symplectic_euler", substeps="auto")
    n = sys.substeps_for(1 / 60)
    assert (1 / 60) / n < sys.stable_step() and n > 10
    for _ in range(20):
        sys.step(1 / 60)
    assert np.isfinite(sys.positions()).all()
    assert np.abs(_stretch(sys)).max() < 0.05


# -- collisions ----------------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["xpbd", "symplectic_euler"])
def test_cloth_drapes_over_sphere_without_penetration(integrator):
    centre, R = np.array([0.5, 0.0, 0.5]), 0.25
    col = Colliders([ColliderSpec("sphere", point=tuple(centre), radius=R, restitution=0.0, friction=0.3)])
    top = cloth(24, 24, size=(1.0, 1.0), origin=(0.0, 0.4, 0.0), mass=0.01, ks=2e3, kd=0.02)
    sys = SpringSystem(top, colliders=col, integrator=integrator, substeps="auto")
    for _ in range(75):
        sys.step(1 / 60)
        d = np.linalg.norm(sys.positions() - centre, axis=1)
        assert d.min() >= R * (1 - 1e-5)
    x = sys.positions()
    mid = 12 * 24 + 12
    assert x[mid, 1] > centre[1] + R - 0.01  # the centre rests on the sphere's top
    corners = [0, 23, 24 * 23, 24 * 24 - 1]
    assert np.all(x[corners, 1] < centre[1] + R - 0.15)  # the edges hang down


@pytest.mark.slow
def test_moving_pin_and_stretch_limit_and_determinism():
    def run():
        top = chain(8, start=(0, 1, 0), length=1.0, mass=0.02, ks=20.0, kd=0.01)  # soft: gravity stretches it
        sys = SpringSystem(top, integrator="verlet", substeps="auto", max_stretch=0.05, dtype=ti.f64)
        for f in range(30):
            sys.set_pin_target(0, (0.01 * f, 1.0, 0.0))
            sys.step(1 / 60)
            assert np.allclose(sys.positions()[0], (0.01 * f, 1.0, 0.0), atol=1e-12)
        return sys
    a, b = run(), run()
    assert np.array_equal(a.positions(), b.positions())
    assert _stretch(a).max() <= 0.05 + 1e-9
    assert a.velocities()[1:, 0].max() > 0  # the moving pin dragged the chain along


# -- step doubling ----------------------------------------------------------------------------------
@pytest.mark.slow
def test_adaptive_lands_on_frames_and_matches_fine_rk4():
    def small_chain():
        return chain(5, start=(0, 0, 0), end=(0.8, -0.2, 0), mass=0.05, ks=30.0, kd=0.05)
    ada = SpringSystem(small_chain(), integrator="rk4", adaptive=True, tol=1e-9, dtype=ti.f64)
    ref = SpringSystem(small_chain(), integrator="rk4", substeps=40, dtype=ti.f64)
    dt, multi = 1 / 60, 0
    for _ in range(30):
        ada.step(dt)
        ref.step(dt)
        assert abs(sum(ada.step_sizes) - dt) < 1e-15
        multi += len(ada.step_sizes) > 1
    assert multi > 0 and ada.time == pytest.approx(0.5, abs=1e-14)
    assert np.abs(ada.positions() - ref.positions()).max() < 1e-6
    assert np.abs(ada.positions() - small_chain().positions).max() > 0.05  # it really moved


# -- force fields on the nodes (engine/forces/fields.py) -------------------------------------------------
def _wind_scene(bodies, wind=(6.0, 0.0, 0.0), drag=0.5, fps=60):
    from engine.config import load_config
    from engine.scene import Scene
    from helpers import scene_dict

    d = scene_dict(fps=fps, forces={"gravity": [0.0, -9.81, 0.0], "wind": list(wind), "drag": drag},
                   emitters=[], bodies=bodies)
    return Scene(load_config(d), render=False)


def _drift(v0, v_inf, k, h, n):
    """x(nh) − x(0) of a point under a = −k (v − v∞) stepped by symplectic Euler (XPBD's predict:
    v⁺ = v + h a, x⁺ = x + h v⁺): u = v − v∞ shrinks by (1 − kh) per step, so
    x_n − x_0 = n h v∞ + h u₀ (1 − kh)(1 − (1 − kh)ⁿ)/(kh)."""
    r = 1.0 - k * h
    return n * h * v_inf + h * (v0 - v_inf) * r * (1.0 - r ** n) / (k * h)


def test_free_cloth_in_wind_drifts_as_linear_drag_says():
    # a free cloth of equal masses: its springs' forces cancel in the sum, so its mean velocity
    # obeys v̄' = g − k (v̄ − w) exactly; the mean after 1 s is the scheme's closed form (and within
    # O(h) of the ODE's: x̄ − x̄₀ = w (t − (1 − e^(−kt))/k) along the wind, the same with v∞ = −g/k down)
    k, w, g, n, h = 0.5, 6.0, 9.81, 60, 1 / 60
    s = _wind_scene([{"type": "cloth", "resolution": [6, 6], "size": [0.5, 0.5], "plane": "xy", "pins": "none",
                      "integrator": "xpbd", "mass": 0.01, "stiffness": 500.0}])
    x0 = s.bodies[0].positions().astype(np.float64).mean(axis=0)
    for _ in range(n):
        s.advance_frame()
    d = s.bodies[0].positions().astype(np.float64).mean(axis=0) - x0
    assert abs(d[0] - _drift(0.0, w, k, h, n)) < 2e-4 and abs(d[2]) < 1e-5
    assert abs(d[1] - _drift(0.0, -g / k, k, h, n)) < 2e-4
    t = n * h
    assert abs(d[0] - w * (t - (1 - np.exp(-k * t)) / k)) < 0.03 * d[0]  # the ODE's, to O(h)


def test_chain_in_wind_hangs_along_gravity_plus_drag():
    # at rest in wind w a node feels m g + m k w: a chain from a pin hangs straight along that
    # field, at atan(k w / g) from the vertical, downwind
    k, w, g = 2.0, 3.0, 9.81
    s = _wind_scene([{"type": "chain", "segments": 8, "length": 0.8, "position": [0.0, 1.0, 0.0],
                      "integrator": "xpbd", "stiffness": 1e4, "damping": 0.02}], wind=(w, 0.0, 0.0), drag=k)
    for _ in range(360):  # 6 s: the swing dies as e^(−kt)
        s.advance_frame()
    x = s.bodies[0].positions().astype(np.float64)
    off = x[1:] - x[0]
    angle = np.degrees(np.arctan2(off[:, 0], -off[:, 1]))
    np.testing.assert_allclose(angle, np.degrees(np.arctan(k * w / g)), atol=0.5)
    assert np.abs(off[:, 2]).max() < 1e-5


def test_pinned_flag_flutters_downwind_and_no_drag_compiles_none():
    # the flag: [forces] wind = [6, 0, 0], drag = 0.5, a sheet across the wind (plane "zy")
    # pinned along its top. From rest it is pushed at k·w = 3 m/s²: its mean moves downwind from the
    # first frame, never as far as a free cloth's drift, and swings about the tilt at which a node
    # at rest balances gravity and drag, tan φ = k·w/g: x̄ − x_top = (k w/g)·(y_top − ȳ), the flag
    # swinging on its pins as a pendulum (averaged over its last second, 1.4 swings).
    # Without drag no drag term is compiled (gravity alone: the same bytes as before).
    k, w, g, h = 0.5, 6.0, 9.81, 1 / 60
    flag = {"type": "cloth", "name": "flag", "resolution": [8, 8], "size": [0.6, 0.6], "plane": "zy",
            "position": [0.0, 0.4, 0.0], "pins": "top", "integrator": "xpbd", "stiffness": 400.0}
    s = _wind_scene([flag])
    body = s.bodies[0]
    assert body.system.fields.use_drag
    x0 = body.positions().astype(np.float64)
    top = x0[:, 1].max()
    dx, tilt = [], []
    for _ in range(180):
        s.advance_frame()
        x = body.positions().astype(np.float64)
        dx.append(x[:, 0].mean() - x0[:, 0].mean())
        tilt.append(k * w / g * (top - x[:, 1].mean()))
    assert np.all(np.diff(dx[:20]) > 0)  # downwind from the start
    assert 0.0 < max(dx[:60]) < _drift(0.0, w, k, h, 60)  # the pins hold it back
    mean, eq = np.mean(dx[-60:]), np.mean(tilt[-60:])
    assert abs(mean - eq) < 0.25 * eq and eq > 0.05, (mean, eq)
    calm = _wind_scene([flag], drag=0.0)
    assert not calm.bodies[0].system.fields.use_drag


def test_attractors_and_vortices_pull_nodes_as_they_pull_particles():
    # one symplectic Euler step of h from rest: v = h a(x₀) per node, with a the particles'
    # formulas (a = s d̂/(1 + (|d|/r)²); vortex s·2q/(1 + q²) along axis × ρ̂), springs at rest
    from types import SimpleNamespace as NS

    att = NS(position=[1.0, 0.5, 0.0], strength=3.0, radius=0.7)
    vor = NS(position=[0.0, 0.0, 0.0], axis=[0.0, 2.0, 0.0], strength=2.0, radius=0.4)
    top = cloth(2, 2, size=(0.5, 0.3), origin=(0.2, 0.1, -0.3), mass=0.1, ks=10.0, pin="none")
    h = 1e-3
    sys = SpringSystem(top, integrator="symplectic_euler", gravity=NO_GRAVITY, dtype=ti.f64, substeps=1,
                       attractors=[att], vortices=[vor], check_stability=False)
    sys.step(h)
    x = top.positions
    d = np.asarray(att.position) - x
    r = np.linalg.norm(d, axis=1, keepdims=True) + 1e-6
    a = att.strength * (d / r) / (1 + (r / att.radius) ** 2)
    ax = np.array([0.0, 1.0, 0.0])
    rho_v = x - np.outer(x @ ax, ax)
    rho = np.linalg.norm(rho_v, axis=1, keepdims=True) + 1e-6
    q = rho / vor.radius
    a += vor.strength * (2 * q / (1 + q * q)) * np.cross(ax, rho_v / rho)
    np.testing.assert_allclose(sys.velocities(), h * a, rtol=1e-12, atol=1e-15)


@pytest.mark.slow
def test_a_frame_in_one_launch_places_a_moving_collider_as_the_host_does():
    """hair (fewer strands): the head, a sphere collider on a path, moves under the strands. A
    frame's substeps fused into one launch (engine.springs.fused) write the head's pose for each
    substep from a table the host computed as its per-substep ``follow`` would: the same strands
    as the launch-by-launch path (to rounding: the two kernels are compiled apart), the same
    collider pose on the host and in the fields at the frame's end."""
    import os
    import tomllib

    from engine.config import load_config
    from engine.scene import Scene

    with open(os.path.join(os.path.dirname(os.path.dirname(__file__)), "configs", "hair.toml"), "rb") as fh:
        d = tomllib.load(fh)
    d["bodies"][0]["strands"] = 30

    def run(fuse):
        s = Scene(load_config(d), render=False)
        system = s.bodies[0].system
        if not fuse:
            system._fusable = lambda: False
        assert system._fusable() == fuse
        near = 0.0
        for _ in range(30):
            s.advance_frame()
            x = s.bodies[0].positions()
            c = s.colliders.collider_point[0].to_numpy()
            near = max(near, (np.linalg.norm(x - c, axis=1) < 0.24 + 0.02).mean())
        return x, s.colliders.pose(0), c, near

    xa, pa, ca, near = run(True)
    xb, pb, cb, _ = run(False)
    assert near > 0.05  # strands lie on the moving head
    assert np.abs(xa - xb).max() < 1e-5, np.abs(xa - xb).max()
    assert np.array_equal(pa["position"], pb["position"]) and np.array_equal(ca, cb)
    assert np.array_equal(pa["velocity"], pb["velocity"]) and np.abs(pa["velocity"]).max() > 0
    assert np.array_equal(ca, pa["position"].astype(np.float32))


@pytest.mark.slow
@pytest.mark.parametrize("method", ["euler", "midpoint", "rk4"])
def test_a_frame_of_explicit_rk_substeps_in_one_launch_is_the_launched_frame(method):
    """engine.springs.fused runs an explicit tableau's stages (stage sums, then a gather) for a
    whole frame in one launch: the same bytes as FieldStepper's launch per stage and substep, on a
    damped chain swinging from its pin onto a ground plane (contacts located in the steps)."""
    from engine.colliders import ColliderSpec, Colliders
    from engine.springs import chain

    def run(fuse):
        top = chain(12, start=(0.0, 1.0, 0.0), direction=(1.0, -0.2, 0.0), length=1.2, ks=400.0, kd=0.5)
        s = SpringSystem(top, colliders=Colliders([ColliderSpec("plane", point=(0.0, 0.3, 0.0))]),
                         integrator=method, substeps="auto")
        if not fuse:
            s._fusable = lambda: False
        assert s._fusable() == fuse
        for _ in range(12):
            s.step(1 / 30)
        return s.positions()

    a, b = run(True), run(False)
    assert np.array_equal(a, b), np.abs(a - b).max()
    assert a[:, 1].min() > 0.29 and np.abs(a - chain(12, start=(0.0, 1.0, 0.0), direction=(1.0, -0.2, 0.0),
                                                    length=1.2).positions).max() > 0.1  # it swung and landed
