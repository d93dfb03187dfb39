"""Every public method of the game API refuses bad arguments in one line naming the method, the
argument and the value — TypeError, ValueError or KeyError — and a refused call changes nothing.
Scenes of any mix (particles only, bodies only, both) answer every method."""
import math

import numpy as np
import pytest

from engine.api import Camera, FixedTimestep, ParticleScene, SceneBuilder, set_particle_budget

NAN, INF = math.nan, math.inf
BAD_VECTORS = [([NAN, 0, 0], ValueError), ([INF, 0, 0], ValueError), ([0, -INF, 0], ValueError),
               ([1, 2], ValueError), (np.zeros((3, 1)), ValueError), ([1e7, 0, 0], ValueError),
               ("abc", TypeError), (5, TypeError), ([1, "a", 2], TypeError), ({"x": 1}, TypeError)]
BAD_REALS = [(NAN, ValueError), (INF, ValueError), (-INF, ValueError), ("1", TypeError), (None, TypeError),
             ([1.0], TypeError), (True, TypeError)]
BAD_NAMES = [("nope", KeyError), (3, TypeError), (None, TypeError)]


def mixed_scene():
    """Particles (one emitter driven from code), a plane, a sphere, a small pinned cloth."""
    return (SceneBuilder(seed=5, fps=60).render(width=64, height=36)
            .emitter(name="jet", emitting=False, lifetime=2.0, speed=(0.5, 1.0), capacity=64)
            .collider(type="plane", name="ground")
            .collider(type="sphere", name="ball", center=np.array([0.0, 0.5, 0.0]), radius=0.2)
            .body(type="cloth", name="flag", resolution=(4, 4), size=[0.5, 0.5], plane="xy",
                  position=[0.0, 1.0, 0.0], pins="top", integrator="xpbd", contacts=True)
            .build(contacts=64, interpolate=True))


def snapshot(s):
    """Everything a call could change: time, inputs, pins, particles, nodes."""
    c = s.scene.control
    return (s.time, c.gravity[None].to_numpy().tobytes(), c.wind[None].to_numpy().tobytes(),
            repr(c.emitters), repr(c.colliders), repr(c.pins), s.particles()["position"].tobytes(),
            s.body_positions("flag").tobytes(), s.scene.t, len(s.cfg.emitters), len(s.cfg.colliders))


def bad_calls():
    """(label, method, args, kwargs, error type, argument named in the message)."""
    out = []
    for v, err in BAD_VECTORS:
        out += [("move_emitter position", "move_emitter", ("jet", v), {}, err, "position"),
                ("move_collider position", "move_collider", ("ball", v), {}, err, "position"),
                ("burst position", "burst", ("jet", 3), {"position": v}, err, "position"),
                ("set_wind", "set_wind", (v,), {}, err, "wind"),
                ("set_gravity", "set_gravity", (v,), {}, err, "g"),
                ("pin target", "pin", ("flag", 2), {"target": v}, err, "target"),
                ("move_pin target", "move_pin", ("flag", 0, v), {}, err, "target")]
    for v, err in BAD_REALS:
        out += [("step dt", "step", (v,), {}, err, "dt"),
                ("set_rate", "set_rate", ("jet", v), {}, err, "rate"),
                ("min_speed", "contacts", (), {"min_speed": v}, err, "min_speed")]
        if v is not None:  # (None is the default of these)
            out += [("over", "move_emitter", ("jet", [0, 1, 0]), {"over": v}, err, "over"),
                    ("collider over", "move_collider", ("ball", [0, 1, 0]), {"over": v}, err, "over"),
                    ("alpha", "render", (), {"alpha": v}, err, "alpha")]
    for v, err in BAD_NAMES:
        out += [("emitter name", m, (v,) + rest, {}, err, "name")
                for m, rest in (("move_emitter", ([0, 0, 0],)), ("set_rate", (1.0,)), ("burst", (1,)),
                                ("set_emitting", (True,)), ("remove_emitter", ()))]
        out += [("collider name", m, (v,) + rest, {}, err, "name")
                for m, rest in (("move_collider", ([0, 0, 0],)), ("remove_collider", ()))]
        out += [("body name", m, (v,) + rest, {}, err, "body")
                for m, rest in (("pin", (0,)), ("move_pin", (0, [0, 0, 0])), ("release", (0,)),
                                ("body_positions", ()), ("remove_body", ()))]
        if v is not None:  # (contacts(body=None): the particles' contacts)
            out.append(("contacts body", "contacts", (), {"body": v}, err, "body"))
    out += [
        ("step negative", "step", (-0.01,), {}, ValueError, "dt"),
        ("step zero", "step", (0.0,), {}, ValueError, "dt"),
        ("step past max_dt", "step", (1e4,), {}, ValueError, "max_dt"),
        ("rate negative", "set_rate", ("jet", -1.0), {}, ValueError, "rate"),
        ("rate huge", "set_rate", ("jet", 1e12), {}, ValueError, "rate"),
        ("emitting type", "set_emitting", ("jet", "yes"), {}, TypeError, "on"),
        ("burst negative", "burst", ("jet", -5), {}, ValueError, "count"),
        ("burst huge", "burst", ("jet", 10**12), {}, ValueError, "count"),
        ("burst past the ring", "burst", ("jet", 65), {}, ValueError, "count"),
        ("burst float", "burst", ("jet", 2.5), {}, TypeError, "count"),
        ("burst nan", "burst", ("jet", NAN), {}, TypeError, "count"),
        ("pin -1", "pin", ("flag", -1), {}, ValueError, "node"),
        ("pin past the nodes", "pin", ("flag", 16), {}, ValueError, "node"),
        ("pin float", "pin", ("flag", 1.0), {}, TypeError, "node"),
        ("release huge", "release", ("flag", 10**9), {}, ValueError, "node"),
        ("render 0x0", "render", (0, 0), {}, ValueError, "width"),
        ("render negative", "render", (-10, 10), {}, ValueError, "width"),
        ("render huge", "render", (100000, 100000), {}, ValueError, "width"),
        ("render memory", "render", (16384, 16384), {}, ValueError, "memory"),
        ("render height nan", "render", (64, NAN), {}, TypeError, "height"),
        ("render width float", "render", (64.0, 36), {}, TypeError, "width"),
        ("render camera type", "render", (), {"camera": "front"}, TypeError, "camera"),
        ("render camera nan", "render", (), {"camera": Camera((NAN, 0, 0))}, ValueError, "camera.position"),
        ("render camera fov", "render", (), {"camera": Camera(fov=0.0)}, ValueError, "camera.fov"),
        ("render camera on itself", "render", (), {"camera": Camera((0, 1, 0), (0, 1, 0))}, ValueError,
         "camera.look_at"),
        ("render out type", "render", (64, 36), {"out": [0] * 4}, TypeError, "out"),
        ("render out shape", "render", (64, 36), {"out": np.zeros((36, 64, 3), np.uint8)}, ValueError, "out"),
        ("render out dtype", "render", (64, 36), {"out": np.zeros((36, 64, 4), np.float32)}, ValueError, "out"),
        ("render transparent", "render", (), {"transparent": "yes"}, TypeError, "transparent"),
        ("render bgra", "render", (), {"bgra": 1}, TypeError, "bgra"),
        ("render alpha > 1", "render", (), {"alpha": 1.5}, ValueError, "alpha"),
        ("contacts negative speed", "contacts", (), {"min_speed": -1.0}, ValueError, "min_speed"),
        ("add_emitter type", "add_emitter", ("sparks",), {}, TypeError, "add_emitter"),
        ("add_emitter key", "add_emitter", ({"name": "x", "rate": 10.0, "lifetim": 1.0},), {}, ValueError,
         "lifetim"),
        ("add_emitter nan", "add_emitter", ({"name": "x", "rate": NAN},), {}, ValueError, "rate"),
        ("add_emitter duplicate", "add_emitter", ({"name": "jet", "rate": 1.0},), {}, ValueError, "jet"),
        ("add_collider bad", "add_collider", ({"type": "cube"},), {}, ValueError, "type"),
        ("add_collider type", "add_collider", ([1, 2],), {}, TypeError, "add_collider"),
        ("add_body bad", "add_body", ({"type": "cloth", "resolution": [1, 1]},), {}, ValueError, "resolution"),
        ("warm_up size", "warm_up", ([(0, 10)],), {}, ValueError, "width"),
    ]
    return out


@pytest.mark.slow
def test_every_method_refuses_bad_arguments_in_one_line_and_changes_nothing():
    s = mixed_scene()
    s.step(1 / 60)
    s.burst("jet", 10)
    s.step(1 / 60)
    before = snapshot(s)
    assert len(s.particles()["position"]) == 10
    calls = bad_calls()
    assert len(calls) > 150
    for label, method, args, kw, err, arg in calls:
        with pytest.raises(err) as info:
            getattr(s, method)(*args, **kw)
            pytest.fail(f"{label}: no error")
        text = str(info.value)
        assert "\n" not in text, (label, text)
        assert text.strip("'\"").startswith(method) and arg in text, (label, text)
        assert snapshot(s) == before, label
    s.step(1 / 60)  # and it still runs
    assert s.time == pytest.approx(3 / 60)


def test_step_never_runs_unbounded():
    s = (SceneBuilder(fps=60).solver(h=1e-7).emitter(name="e", rate=10.0).build(render=False, max_dt=1.0))
    with pytest.raises(ValueError, match=r"step: dt: 0.5 s is 5,000,000 steps of solver.h"):
        s.step(0.5)  # 5,000,000 fixed steps (the count a step would take): refused at once, not run
    assert s.time == 0.0
    with pytest.raises(ValueError, match="max_dt"):
        ParticleScene({"emitters": [{"rate": 1.0}]}, max_dt=0.0)


@pytest.mark.slow
def test_scenes_of_any_mix_answer_every_method():
    cloth_only = (SceneBuilder(fps=60).render(width=32, height=32)
                  .body(type="cloth", name="c", resolution=[3, 3], integrator="xpbd").build(contacts=True))
    sparks_only = (SceneBuilder(fps=60).render(width=32, height=32)
                   .emitter(name="e", rate=100.0).build(contacts=True))
    for s in (cloth_only, sparks_only):
        s.set_wind([1.0, 0.0, 0.0])
        s.set_gravity((0.0, -1.0, 0.0))
        s.step(1 / 60)
        assert len(s.contacts()) == 0 and s.contacts().dropped == 0
        assert s.render().shape == (32, 32, 4)
        assert isinstance(s.energy(), dict) and s.live_count() >= 0
        assert s.particles()["position"].shape[1] == 3
    assert cloth_only.live_count() == 0 and cloth_only.particles()["color"].shape == (0, 3)
    with pytest.raises(KeyError, match="no emitter named 'e'"):
        cloth_only.burst("e", 1)
    with pytest.raises(KeyError, match="no body named 'c'"):
        sparks_only.pin("c", 0)
    with pytest.raises(RuntimeError, match="contacts = true"):
        cloth_only.contacts(body="c")


def test_clock_budget_and_builder_arguments():
    for bad in (0.0, -1.0, NAN, INF, "x"):
        with pytest.raises((ValueError, TypeError), match="FixedTimestep: dt"):
            FixedTimestep(bad)
    with pytest.raises(ValueError, match="max_steps"):
        FixedTimestep(0.01, max_steps=0)
    clock = FixedTimestep(0.01)
    for bad in (NAN, -1.0, INF):
        with pytest.raises(ValueError, match="frame_time"):
            clock.advance(None, bad)
    assert clock.accumulator == 0.0
    for bad, err in ((-1, ValueError), (1.5, TypeError), ("10", TypeError)):
        with pytest.raises(err, match="set_particle_budget: n"):
            set_particle_budget(bad)
    with pytest.raises(TypeError, match="config"):
        ParticleScene(["not", "a", "config"])
    with pytest.raises(ValueError, match=r"emitters\[0\]\.rate"):
        ParticleScene({"emitters": [{"rate": "fast"}]})
    # tuples, NumPy arrays and NumPy scalars are taken as the lists and numbers a config holds
    a = (SceneBuilder(fps=np.float64(30.0)).forces(gravity=np.array([0.0, -1.0, 0.0]))
         .emitter(name="e", rate=np.float32(5.0), position=(1, 2, 3), color=np.array([[0.0, 1, 1, 1]])))
    b = (SceneBuilder(fps=30.0).forces(gravity=[0.0, -1.0, 0.0])
         .emitter(name="e", rate=5.0, position=[1, 2, 3], color=[[0.0, 1, 1, 1]]))
    assert a.data == b.data


def test_the_readme_table_lists_every_limit():
    import os

    from engine.checks import LIMITS

    text = open(os.path.join(os.path.dirname(__file__), "..", "README.md"), encoding="utf-8").read()
    missing = [k for k, v in LIMITS.items() if f"| {k} | {v} |" not in text]
    assert not missing, missing
