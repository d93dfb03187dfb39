"""Behaviour kept: what the simulation did when the fixtures were recorded (tests/make_behaviour.py).

The particles of shipped configs after a few frames (slots and emitters exactly, positions,
velocities and ages to float32 rounding), fixed-step cloths, and the step-size sequences of an
adaptive particle scene and an adaptive cloth. A refactor of the stepping code must leave these
alone; a change of policy re-records them on purpose (and says so in its commit).
"""
import os

import numpy as np
import pytest

from behaviour_scenes import FRAME_SHOTS, adaptive_cloth, adaptive_particles, fixed_cloths, particle_frames

HERE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "behaviour")
TOL = dict(rtol=1e-5, atol=1e-5)  # float32 rounding over a few hundred steps; any change of
# physics, emission order or slot assignment moves particles by far more (or changes `slot`)


def fixture(name):
    with np.load(os.path.join(HERE, f"{name}.npz")) as d:
        return {k: d[k] for k in d.files}


def assert_same_particles(got, want):
    np.testing.assert_array_equal(got["slot"], want["slot"])
    np.testing.assert_array_equal(got["emitter"], want["emitter"])
    for key in ("pos", "vel", "age"):
        np.testing.assert_allclose(got[key], want[key], err_msg=key, **TOL)


@pytest.mark.parametrize("name", sorted(FRAME_SHOTS))
def test_particle_frames_kept(name):
    want = fixture(f"frames_{name}")
    assert len(want["slot"]) > 50
    assert_same_particles(particle_frames(name, FRAME_SHOTS[name]), want)


def test_adaptive_particle_step_sizes_kept():
    want, got = fixture("h_particles"), adaptive_particles()
    assert want["rejected"] > 0 and want["per_frame"].max() > 4  # a sequence worth pinning
    np.testing.assert_array_equal(got["per_frame"], want["per_frame"])
    np.testing.assert_allclose(got["h"], want["h"], rtol=1e-9)
    assert int(got["rejected"]) == int(want["rejected"])
    assert_same_particles(got, want)


def test_adaptive_cloth_step_sizes_kept():
    want, got = fixture("h_cloth"), adaptive_cloth()
    np.testing.assert_array_equal(got["per_frame"], want["per_frame"])
    np.testing.assert_allclose(got["h"], want["h"], rtol=1e-9)
    assert int(got["rejected"]) == int(want["rejected"])
    np.testing.assert_allclose(got["pos"], want["pos"], **TOL)


def test_fixed_step_cloths_kept():
    want, got = fixture("cloth_fixed"), fixed_cloths()
    assert sorted(got) == sorted(want)
    for method in want:
        np.testing.assert_allclose(got[method], want[method], err_msg=method, **TOL)
