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


@pytest.mark.parametrize("integrator", ["symplectic_euler", "rk4"])
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
