"""Measured stability limits of the steppers on a damped spring on an anchor (NUMERICS.md tables)."""
import math

import numpy as np
import pytest

from engine.ode.stability import (largest_stable_h, largest_stable_h_batch, numerics_formula,
                                  spectral_radius, theory_limit)

KDS = [1.0, 5.0, 20.0]
# NUMERICS.md, damped spring on an anchor, ks = 100, m = 1, kd = 1 / 5 / 20
TABLE = {
    "euler": [0.010, 0.050, 0.200],
    "symplectic_euler": [0.1902, 0.1562, 0.0828],
    "rk4": [0.2909, 0.2896, 0.2785],
}


@pytest.mark.parametrize("method", sorted(TABLE))
def test_largest_stable_h_matches_numerics_table(method):
    got = largest_stable_h_batch(method, 100.0, KDS)
    np.testing.assert_allclose(got, TABLE[method], rtol=0.01)


@pytest.mark.parametrize("method,hw", [("symplectic_euler", 2.0), ("verlet", 2.0),
                                       ("rk4", 2.0 * math.sqrt(2.0))])
@pytest.mark.parametrize("ks", [100.0, 1e4])
def test_undamped_limit_in_units_of_omega(method, hw, ks):
    h = largest_stable_h(method, ks, 0.0)
    assert h * math.sqrt(ks) == pytest.approx(hw, rel=0.01)


def test_mass_enters_through_omega():
    # ks = 400, m = 4 is the same ω = 10 as ks = 100, m = 1
    assert largest_stable_h("symplectic_euler", 400.0, 0.0, m=4.0) == pytest.approx(0.2, rel=0.01)


def test_measurement_is_deterministic_and_steps_matter_for_euler_undamped():
    a = largest_stable_h("euler", 100.0, 0.0, steps=20000)
    assert a == largest_stable_h("euler", 100.0, 0.0, steps=20000)
    # no stable step exists: the measured h is the finite-run artefact and shrinks with more steps
    b = largest_stable_h("euler", 100.0, 0.0, steps=2000)
    assert 0 < a < 0.5 * b < 0.01


def test_just_below_and_above_the_measured_limit():
    h = largest_stable_h("rk4", 100.0, 5.0)
    assert spectral_radius("rk4", 0.99 * h, 100.0, 5.0) < 1 < spectral_radius("rk4", 1.01 * h, 100.0, 5.0)


@pytest.mark.parametrize("method", ["euler", "symplectic_euler", "verlet", "rk4"])
@pytest.mark.parametrize("kd", [0.0, 1.0, 5.0])
def test_theory_agrees_with_numerics_formulas_and_measurement(method, kd):
    th = theory_limit(method, 100.0, kd)
    formula = numerics_formula(method, 100.0, kd)
    if formula is not None:
        assert th == pytest.approx(formula, rel=1e-6)
    if th > 0:
        assert largest_stable_h(method, 100.0, kd) == pytest.approx(th, rel=0.01)


def test_bad_arguments():
    with pytest.raises(ValueError, match="method"):
        largest_stable_h("rk5", 100.0, 0.0)
    with pytest.raises(ValueError, match="ks > 0"):
        largest_stable_h("rk4", -1.0, 0.0)


@pytest.mark.parametrize("method", ["euler", "midpoint", "rk4", "symplectic_euler", "verlet"])
def test_measurement_tracks_theory_across_stiffness(method):
    ks = np.array([10.0, 1e3, 1e5, 10.0, 1e3, 1e5])
    kd = np.array([1.0, 1.0, 1.0, 20.0, 20.0, 20.0])  # kd = 20, ks = 10 is overdamped
    got = largest_stable_h_batch(method, ks, kd)
    want = [theory_limit(method, a, b) for a, b in zip(ks, kd)]
    np.testing.assert_allclose(got, want, rtol=0.01)
