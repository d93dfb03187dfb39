"""The one adaptive driver's rules, on a system written in plain Python (no kernels): the policy
every Taichi system (particles, springs, solve) gets, checked where it is decided."""
import math

import pytest

from engine import runtime
from engine.ode.driver import (NONFINITE, STEP_TOO_SMALL, TOO_MANY_STEPS, Driver, SimulationDiverged,
                               StepPolicy, clip_to_target, substeps)


class Decay:
    """y' = −y with Euler steps; step doubling error |y2 − y1| (p = 1) scaled by tol; records
    every call. ``nan_after``: attempts past this time return NaN (a blow-up)."""

    label, method, order = "decay", "euler", 1

    def __init__(self, tol=1e-3, nan_after=math.inf, event_at=None):
        self.y, self.trial, self.tol = 1.0, None, tol
        self.nan_after, self.event_at = nan_after, event_at
        self.calls = []

    def fixed_step(self, t0, h, j, n):
        t = t0 + j * h
        self.calls.append(("fixed", t, h))
        self.y *= 1 - h
        return 1

    def attempt(self, t, h):
        self.calls.append(("attempt", t, h))
        y1 = self.y * (1 - h)
        y2 = self.y * (1 - h / 2) ** 2
        self.trial = y2
        if t + h > self.nan_after:
            return math.nan
        return abs(y2 - y1) / (self.tol * max(abs(self.y), abs(y2)))

    def commit(self, t, h):
        self.calls.append(("commit", t, h))
        self.y = self.trial

    def rollback(self):
        self.calls.append(("rollback",))
        self.trial = None

    def first_nonfinite(self):
        return None

    def locate(self, t, h):
        if self.event_at is not None and t < self.event_at < t + h:
            return self.event_at - t
        return None


def steps(sys, kind):
    return [c for c in sys.calls if c[0] == kind]


def test_fixed_steps_are_equal_and_land_exactly():
    sys = Decay()
    d = Driver(sys, StepPolicy(h=0.3))
    d.advance(0.0, 1.0)
    hs = [c[2] for c in steps(sys, "fixed")]
    assert len(hs) == 4 and hs == [0.25] * 4 and d.step_sizes == hs
    assert sys.y == pytest.approx(0.75 ** 4)


def test_an_h_written_to_seven_digits_takes_the_steps_it_means():
    """h = 0.008333333 (1/120 to seven digits) is 2 steps a 1/60 s frame and 4 a 1/30 s one, not
    3 and 5 (span / h = 2.00000008 rounded up); past a relative 1e-6 of a whole number, h is an
    upper bound again; counts in the billions stay exact."""
    assert [substeps(1 / 60, 0.008333333), substeps(1 / 30, 0.008333333)] == [2, 4]
    assert [substeps(1 / 60, 0.004166667), substeps(1 / 30, 0.016666667)] == [4, 2]
    assert substeps(2 * 0.008333333 * (1 + 2e-6), 0.008333333) == 3  # (beyond the tolerance)
    assert [substeps(1.0, 0.3), substeps(0.1, 1.0), substeps(10.0, 1e-9)] == [4, 1, 10_000_000_000]
    sys = Decay()
    d = Driver(sys, StepPolicy(h=0.008333333))
    d.advance(0.0, 1 / 60)
    assert d.step_sizes == [1 / 120, 1 / 120]


def test_adaptive_lands_on_target_controls_error_and_resumes_after_clip():
    sys = Decay(tol=1e-4)
    d = Driver(sys, StepPolicy(h=0.01, adaptive=True))
    d.advance(0.0, 0.5)
    commits = steps(sys, "commit")
    assert sum(c[2] for c in commits) == pytest.approx(0.5, abs=1e-15)
    assert commits[-1][1] + commits[-1][2] == pytest.approx(0.5)
    assert d.stats.steps == len(commits) > 3
    first = steps(sys, "attempt")[0]
    assert first[2] == 0.01  # the policy's first step


def test_after_a_clipped_landing_the_step_the_controller_wanted_resumes():
    class Keep:  # a controller that accepts every step and keeps its h (the driver's rules alone)
        def propose(self, h, err):
            return True, h

    sys = Decay()
    d = Driver(sys, StepPolicy(h=0.3, adaptive=True))
    d.controller = Keep()
    d.advance(0.0, 1.0)
    # approaching the target the remainder is split in two equal steps, not a step and a sliver
    assert [round(c[2], 12) for c in steps(sys, "commit")] == [0.3, 0.3, 0.2, 0.2]
    d.advance(1.0, 1.05)  # a short frame: the step is clipped from 0.2 to 0.05 to land
    assert d.step_sizes == [pytest.approx(0.05)]
    assert d.h_next == pytest.approx(0.2)  # resumes from the step before clipping, not 0.05
    n = len(sys.calls)
    d.advance(1.05, 2.0)
    assert sys.calls[n][0] == "attempt" and sys.calls[n][2] == pytest.approx(0.2)


def test_growth_is_capped_by_h_max_and_the_controller():
    sys = Decay(tol=1.0)
    d = Driver(sys, StepPolicy(h=1e-3, adaptive=True, h_max=0.01))
    d.advance(0.0, 0.2)
    hs = d.step_sizes
    assert max(hs) <= 0.01 + 1e-15
    assert all(b <= 5.0 * a * (1 + 1e-12) for a, b in zip(hs, hs[1:]))  # at most 5x growth per step


def test_nan_is_a_rejection_and_h_min_gives_up_naming_method_h_and_t():
    sys = Decay(nan_after=0.05)
    d = Driver(sys, StepPolicy(h=0.01, adaptive=True, h_min=1e-6))
    with pytest.raises(SimulationDiverged) as e:
        d.advance(0.0, 1.0)
    err = e.value
    assert err.kind == NONFINITE and err.method == "euler" and err.t <= 0.05 and err.h < 1e-5
    msg = str(err)
    assert msg.startswith("decay diverged: step size fell below h_min=1e-06") and "t=" in msg and "h=" in msg
    assert len(steps(sys, "rollback")) == d.stats.rejected > 5  # every rejection rolled back


def test_too_many_steps_counts_attempts():
    sys = Decay(tol=1e-12)
    d = Driver(sys, StepPolicy(h=0.01, adaptive=True, max_steps=20, max_steps_hint="raise solver.tolerance"))
    with pytest.raises(SimulationDiverged, match=r"more than 20 steps before t=1 s \(raise solver.tolerance\)") as e:
        d.advance(0.0, 1.0)
    assert e.value.kind == TOO_MANY_STEPS
    assert len(steps(sys, "attempt")) == 20


def test_a_finite_error_too_large_forever_is_a_step_too_small():
    class Stiff(Decay):
        def attempt(self, t, h):
            super().attempt(t, h)
            return 1e6

    d = Driver(Stiff(), StepPolicy(h=0.1, adaptive=True, h_min=1e-9))
    with pytest.raises(SimulationDiverged) as e:
        d.advance(0.0, 1.0)
    assert e.value.kind == STEP_TOO_SMALL


def test_one_stop_check_per_attempted_step():
    polls = []
    runtime.set_stop_check(lambda: polls.append(1) or False)
    try:
        sys = Decay(tol=1e-5)
        d = Driver(sys, StepPolicy(h=0.05, adaptive=True))
        d.advance(0.0, 1.0)
        adaptive_polls = len(polls)
        assert adaptive_polls == len(steps(sys, "attempt"))
        fixed = Decay()
        Driver(fixed, StepPolicy(h=0.1)).advance(0.0, 1.0)
        assert len(polls) - adaptive_polls == len(steps(fixed, "fixed")) == 10
    finally:
        runtime.set_stop_check(None)


def test_locate_cuts_an_accepted_step_at_the_event():
    sys = Decay(tol=1.0, event_at=0.123)
    d = Driver(sys, StepPolicy(h=0.1, adaptive=True))
    d.advance(0.0, 0.5)
    ends = [c[1] + c[2] for c in steps(sys, "commit")]
    assert any(abs(e - 0.123) < 1e-15 for e in ends)  # a step ends exactly at the event
    assert ends[-1] == pytest.approx(0.5)


def test_first_step_from_the_system_when_the_policy_has_none():
    class Hinted(Decay):
        def first_step(self, t, t_end):
            return 0.0625

    sys = Hinted()
    Driver(sys, StepPolicy(adaptive=True)).advance(0.0, 1.0)
    assert steps(sys, "attempt")[0][2] == 0.0625
    plain = Decay()
    Driver(plain, StepPolicy(adaptive=True)).advance(0.0, 1.0)
    assert steps(plain, "attempt")[0][2] == 1.0  # neither: the whole span


def test_clip_to_target_never_leaves_a_sliver():
    assert clip_to_target(0.0, 0.3, 1.0) == (0.3, False)
    assert clip_to_target(0.0, 0.6, 1.0) == (0.5, False)
    assert clip_to_target(0.0, 0.995, 1.0) == (1.0, True)
    assert clip_to_target(0.0, 1.2, 1.0) == (1.0, True)
