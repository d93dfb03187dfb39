"""The same free-flight and hinge scenes in MuJoCo (the outside anchor of ../shared/PHYSICS.md) and
in this engine, both against the closed forms (slow; skipped where ``mujoco`` is not installed:
``pip install mujoco``)."""
import math

import numpy as np
import pytest
from scipy.special import ellipk

from rigid_scenes import G, run, scene
from test_rigid import TUMBLER

mujoco = pytest.importorskip("mujoco")
pytestmark = pytest.mark.slow

HALF = TUMBLER["half_extents"]


def flip_period_closed_form(I, w0):
    order = np.argsort(I)
    L = I * w0
    L2, E = float(L @ L), 0.5 * float(np.sum(I * w0 ** 2))
    I1, I2, I3 = I[order]
    if L2 < 2 * E * I2:
        I1, I3 = I3, I1
    lam = math.sqrt((I3 - I2) * (L2 - 2 * E * I1) / (I1 * I2 * I3))
    m = (I2 - I1) * (2 * E * I3 - L2) / ((I3 - I2) * (L2 - 2 * E * I1))
    return 2 * ellipk(m) / lam, order


def flips(times, w2):
    s = np.sign(w2)
    t = [times[k] for k in range(1, len(s)) if s[k] != s[k - 1]]
    return float(np.diff(t).mean())


def test_free_flight_flip_period_mujoco_and_engine_against_the_closed_form():
    w0 = np.array([0.05, 3.0, 0.05])
    ours = scene([dict(TUMBLER, angular_velocity=w0.tolist())], colliders=(), gravity=(0, 0, 0),
                 integrator="rk4", solver_h=1 / 480, fps=240)
    I = ours.rigid.model.body_inertia[0]
    expected, order = flip_period_closed_form(I, w0)
    xml = f"""<mujoco><option timestep="{1 / 480}" integrator="RK4" gravity="0 0 0"/>
      <worldbody><body><freejoint/><geom type="box" size="{HALF[0]} {HALF[1]} {HALF[2]}" density="1000"/>
      </body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    data.qvel[3:6] = w0  # body frame (identity at t = 0)
    times, w2 = [], []
    for _ in range(int(2.5 * expected * 480)):
        mujoco.mj_step(model, data)
        times.append(data.time)
        w2.append(data.qvel[3 + order[1]])  # a free joint's angular velocity is in the body frame
    mj = flips(times, w2)
    from engine.rigid import quat

    times, w2 = [], []

    def rec(sc):
        S = sc.rigid.state
        times.append(sc.t)
        w2.append(quat.rotate_inv(S.q[0], S.w[0])[order[1]])

    run(ours, 2.5 * expected, rec)
    eng = flips(times, w2)
    print(f"flip period: closed form {expected:.4f} s, MuJoCo RK4 {mj:.4f} s, engine RK4 {eng:.4f} s")
    assert abs(mj - expected) <= 0.01 * expected
    assert abs(eng - expected) <= 0.01 * expected


def test_hinged_rod_period_mujoco_and_engine_against_the_closed_form():
    L, th0 = 1.0, math.radians(30)
    xml = f"""<mujoco><option timestep="{1 / 1200}" gravity="0 {-G} 0"/>
      <worldbody><body pos="0 2 0" euler="0 0 {math.degrees(th0)}">
        <joint type="hinge" axis="0 0 1" pos="0 0 0"/>
        <geom type="box" size="0.01 {L / 2} 0.01" pos="0 {-L / 2} 0" density="1000"/>
      </body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mass = 1000 * 0.02 * L * 0.02
    Ip = mass * (L ** 2 + 0.02 ** 2) / 12 + mass * (L / 2) ** 2
    expected = 4 * math.sqrt(Ip / (mass * G * L / 2)) * ellipk(math.sin(th0 / 2) ** 2)
    times, q = [], []
    for _ in range(int(2.5 * expected * 1200)):
        mujoco.mj_step(model, data)
        times.append(data.time)
        q.append(data.qpos[0] + th0)
    mj = flips(times, q) * 2
    print(f"rod period: closed form {expected:.4f} s, MuJoCo {mj:.4f} s")
    assert abs(mj - expected) <= 0.01 * expected
