"""ODE core: tableaus, measured orders, reference values, stability limits, step doubling.

Figures come from ../shared/NUMERICS.md. Convergence tests run in float64: in float32 RK4's slope
collapses to rounding noise.
"""
from fractions import Fraction as F

import numpy as np
import pytest
import taichi as ti

from engine.ode import METHODS, TABLEAUS, ButcherTableau, StepDoublingController, solve
from engine.ode.driver import clip_to_target
from engine.ode.steppers import doubling_step
from particles_tools.problems import DAMPED_SPRING, DRAG, GROWTH, LOTKA_VOLTERRA, OSCILLATOR


def test_tableaus_satisfy_invariants():
    for tab in TABLEAUS.values():
        assert sum(tab.b) == 1
        for row, c in zip(tab.a, tab.c):
            assert sum(row, F(0)) == c
    assert TABLEAUS["rk4"].a[3] == (0, 0, 1)  # k4 = h f(x + k3, t + h), not k3/2


def test_bad_tableau_is_rejected_at_construction():
    with pytest.raises(ValueError, match="sums to"):
        ButcherTableau("bad", 2, c=(F(0), F(1, 2)), a=((), (F(1),)), b=(F(0), F(1)))
    with pytest.raises(ValueError, match="weights"):
        ButcherTableau("bad", 1, c=(F(0),), a=((),), b=(F(1, 2),))


def test_bad_splitting_is_rejected_at_construction():
    from engine.ode.splitting import DRIFT, KICK, Splitting

    with pytest.raises(ValueError, match="first operation must be a kick"):
        Splitting("bad", 1, ((DRIFT, F(1), F(0)), (KICK, F(1), F(0))))
    with pytest.raises(ValueError, match="sum to 1"):
        Splitting("bad", 2, ((KICK, F(1, 2), F(0)), (DRIFT, F(1), F(1, 2))))


def test_stability_polynomials_come_from_the_tableaus():
    # explicit RK with s = p stages: R(z) = Σ_{k ≤ p} z^k / k! (Hairer & Wanner II, §IV.2)
    assert TABLEAUS["euler"].stability_polynomial() == (1, 1)
    assert TABLEAUS["midpoint"].stability_polynomial() == (1, 1, F(1, 2))
    assert TABLEAUS["rk4"].stability_polynomial() == (1, 1, F(1, 2), F(1, 6), F(1, 24))


def _global_errors(method, ns, T=2.0, extrapolate=False):
    errs = []
    for n in ns:
        r = solve(OSCILLATOR.f, OSCILLATOR.y0, (0.0, T), method=method, h=T / n,
                  extrapolate=extrapolate)
        assert r.success
        errs.append(np.abs(r.y[:, -1] - OSCILLATOR.exact(T)).max())
    return np.array(errs)


@pytest.mark.parametrize("method,order,ns", [
    ("euler", 1, [80, 160, 320, 640]),
    ("midpoint", 2, [40, 80, 160, 320]),
    ("rk4", 4, [40, 80, 160, 320]),
    ("symplectic_euler", 1, [80, 160, 320, 640]),
    ("verlet", 2, [40, 80, 160, 320]),
])
def test_measured_global_order(method, order, ns):
    errs = _global_errors(method, ns)
    slopes = np.log2(errs[:-1] / errs[1:])
    assert abs(slopes[-1] - order) < 0.1, slopes
    assert np.all(np.abs(slopes - order) < 0.2), slopes


def test_rk4_with_local_extrapolation_is_fifth_order():
    errs = _global_errors("rk4", [20, 40, 80, 160], extrapolate=True)
    slopes = np.log2(errs[:-1] / errs[1:])
    assert abs(slopes[-1] - 5) < 0.1, slopes


@pytest.mark.parametrize("method,h,expected", [
    ("euler", 1.0, 2.0), ("euler", 0.25, 2.441406),
    ("midpoint", 1.0, 2.5), ("midpoint", 0.25, 2.694856),
    ("rk4", 1.0, 2.708333), ("rk4", 0.25, 2.718210),
])
def test_course_table_for_growth(method, h, expected):
    r = solve(GROWTH.f, [1.0], (0.0, 1.0), method=method, h=h)
    assert r.y[0, -1] == pytest.approx(expected, abs=1e-6)
    assert r.nfev == METHODS[method].fevals * round(1 / h)


def test_lotka_volterra_adaptive_rk4_matches_reference():
    r = solve(LOTKA_VOLTERRA.f, LOTKA_VOLTERRA.y0, (0.0, 10.0), method="rk4", tol=1e-8)
    assert r.success, r.message
    assert np.abs(r.y[:, -1] - LOTKA_VOLTERRA.y_end()).max() < 1e-6
    assert r.n_accepted > 0 and r.nfev == 2 + 11 * (r.n_accepted + r.n_rejected)


def test_lotka_volterra_invariant_drift_shrinks_with_tol():
    drifts = []
    for tol in (1e-4, 1e-6, 1e-8):
        r = solve(LOTKA_VOLTERRA.f, LOTKA_VOLTERRA.y0, (0.0, 10.0), method="rk4", tol=tol)
        V = LOTKA_VOLTERRA.invariant(r.y)
        assert V[0] == pytest.approx(2.0, abs=1e-15)
        drifts.append(np.abs(V - 2.0).max())
    assert drifts[0] > 10 * drifts[1] > 100 * drifts[2], drifts


def _energy_ratio(method, hw, steps=20000):
    h = hw / 2.0  # the oscillator has ω = 2
    r = solve(OSCILLATOR.f, OSCILLATOR.y0, (0.0, h * steps), method=method, h=h)
    if not r.success:
        return np.inf, r
    return OSCILLATOR.invariant(r.y[:, -1]) / OSCILLATOR.invariant(r.y[:, 0]), r


@pytest.mark.parametrize("method,stable_hw,unstable_hw", [
    ("symplectic_euler", 1.98, 2.02), ("verlet", 1.98, 2.02), ("rk4", 2.80, 2.86),
])
def test_stability_limit_on_undamped_spring(method, stable_hw, unstable_hw):
    e_ok, _ = _energy_ratio(method, stable_hw)
    e_bad, r_bad = _energy_ratio(method, unstable_hw)
    assert np.isfinite(e_ok) and e_ok < 100.0
    assert not np.isfinite(e_bad) or e_bad > 1e6
    if not r_bad.success:  # a blow-up is a failed status with a message, never NaNs
        assert method in r_bad.message and "h=" in r_bad.message and "t=" in r_bad.message
        assert np.all(np.isfinite(r_bad.y))


def test_explicit_euler_energy_grows_by_one_plus_h2w2_per_step():
    h, w = 0.1, 2.0
    r = solve(OSCILLATOR.f, OSCILLATOR.y0, (0.0, 1.0), method="euler", h=h,
              t_eval=np.linspace(0.1, 1.0, 10))
    E = OSCILLATOR.invariant(r.y)
    np.testing.assert_allclose(E[1:] / E[:-1], 1 + (h * w) ** 2, rtol=1e-12)


def test_divergent_solve_reports_failure_not_nans():
    r = solve(OSCILLATOR.f, OSCILLATOR.y0, (0.0, 5000.0), method="euler", h=1.0)
    assert r.status == -1 and not r.success
    assert "euler" in r.message and "h=1" in r.message and "t=" in r.message
    assert np.all(np.isfinite(r.y))


def _one_doubling_step(method, hs):
    @ti.func
    def growth(y, t, i):
        return y

    dstep = doubling_step(method, growth, 1, ti.f64)
    hf = ti.field(ti.f64, shape=len(hs))
    out = ti.Vector.field(2, ti.f64, shape=len(hs))
    hf.from_numpy(np.asarray(hs, dtype=np.float64))

    @ti.kernel
    def run():
        for j in hf:
            y2, est = dstep(ti.Vector([1.0], dt=ti.f64), 0.0, hf[j], 0)
            out[j] = ti.Vector([y2[0], est[0]])

    run()
    o = out.to_numpy()
    return o[:, 0], o[:, 1]


@pytest.mark.parametrize("method", ["euler", "midpoint", "rk4"])
def test_step_doubling_estimate_matches_true_local_error(method):
    # On x' = x every higher-order term is positive, so Δ/(2^p − 1) approaches the true local error
    # of the two half steps from below: measured ratios 0.77–0.84 at h = 0.4, → 1 as h → 0.
    hs = np.array([0.4, 0.2, 0.1, 0.05, 0.025])
    y2, est = _one_doubling_step(method, hs)
    ratio = est / (np.exp(hs) - y2)
    assert np.all(ratio > 0.75) and np.all(ratio < 1.0 + 1e-6), ratio
    assert np.all(np.diff(np.abs(1 - ratio)) < 0), ratio  # tends to 1 as h shrinks
    assert abs(1 - ratio[-1]) < 0.03


@pytest.mark.parametrize("problem", [GROWTH, DAMPED_SPRING, DRAG, LOTKA_VOLTERRA])
def test_tolerance_bounds_the_global_error_on_smooth_problems(problem):
    # README, "What the tolerance bounds": with rtol = atol = tol (and the default local
    # extrapolation) the error at T stays below 10·tol from 1e-3 to 1e-10 — measured 0.001–6.9·tol
    # on these problems, where scipy's RK45 reaches 55·tol (Lotka–Volterra at 1e-4) — and
    # tightening tol tightens it
    errs = []
    for tol in 10.0 ** -np.arange(3, 11):
        r = solve(problem.f, problem.y0, problem.t_span, method="rk4", tol=tol, t_eval=[problem.t_span[1]])
        assert r.success and r.t[-1] == problem.t_span[1]
        errs.append(np.abs(r.y[:, -1] - problem.y_end()).max())
        assert errs[-1] < 10 * tol, (tol, errs)
    assert errs[-1] < 1e-5 * errs[0], errs


def test_adaptive_lands_exactly_on_output_times_without_slivers():
    t_eval = np.linspace(0.0, 10.0, 31)
    r = solve(LOTKA_VOLTERRA.f, LOTKA_VOLTERRA.y0, (0.0, 10.0), method="rk4", tol=1e-6,
              t_eval=t_eval)
    assert np.array_equal(r.t, t_eval)
    h = np.array(r.h_history)
    assert h.min() > 0.2 * np.median(h)  # no sliver step before an output time


def test_controller_rules():
    c = StepDoublingController(order=4)
    ok, h = c.propose(0.1, float("nan"))
    assert not ok and h == pytest.approx(0.02)
    ok, h = c.propose(0.02, 1e-12)  # accepted right after a rejection: no growth
    assert ok and h == pytest.approx(0.02)
    ok, h = c.propose(0.02, 1e-12)
    assert ok and h == pytest.approx(0.1)  # clamped at 5×
    ok, h = c.propose(0.1, 32.0)  # a rejection: h·0.9·32^(−1/5) = 0.045
    assert not ok and h == pytest.approx(0.045)
    c = StepDoublingController(order=4)
    ok, h = c.propose(0.1, 0.5)  # PI: h·0.9·err_n^(−0.7/5)·err_{n−1}^(0.4/5), err_{n−1} = 1 at first
    assert ok and h == pytest.approx(0.1 * 0.9 * 0.5 ** -0.14)
    ok, h2 = c.propose(h, 0.25)
    assert ok and h2 == pytest.approx(h * 0.9 * 0.25 ** -0.14 * 0.5 ** 0.08)
    assert clip_to_target(0.0, 0.3, 1.0) == (0.3, False)
    assert clip_to_target(0.0, 0.6, 1.0) == (0.5, False)
    assert clip_to_target(0.0, 1.2, 1.0) == (1.0, True)


def test_float32_state_runs_and_is_accurate_to_single_precision():
    r = solve(LOTKA_VOLTERRA.f, LOTKA_VOLTERRA.y0, (0.0, 10.0), method="rk4", h=0.01, dtype=ti.f32)
    assert r.success
    assert np.abs(r.y[:, -1] - LOTKA_VOLTERRA.y_end()).max() < 1e-4


def test_partitioned_method_needs_even_state():
    with pytest.raises(ValueError, match="even"):
        solve(GROWTH.f, [1.0], (0.0, 1.0), method="verlet", h=0.1)
