"""The game API's event queue, restarts without compiling, and the game features: bursts at a
point, local-space emitters, the particle budget, drawing between two steps, overlays."""
import numpy as np
import pytest
from taichi.lang import impl

from engine import reuse
from engine.api import Camera, FixedTimestep, ParticleScene, SceneBuilder, particle_budget, set_particle_budget

RAIN = dict(seed=1, fps=60, forces={"gravity": [0.0, -9.81, 0.0]}, render={"width": 64, "height": 36},
            emitters=[{"name": "rain", "shape": "box", "box_size": [2.0, 0.1, 2.0], "position": [0.0, 1.0, 0.0],
                       "direction": [0.0, -1.0, 0.0], "speed": [1.0, 2.0], "rate": 3000.0, "lifetime": 2.0}],
            colliders=[{"type": "plane", "name": "ground", "restitution": 0.5},
                       {"type": "sphere", "name": "ball", "center": [0.3, 0.6, 0.0], "radius": 0.4}])
# (the ball stands clear of the ground: no particle touches both in one step, so the kernels' count
# of resolved contacts equals the number of contact records)


def compiled(taichi_own=False):
    """Compiled instances of the engine's kernels. (Taichi's own ``fill_ndarray_matrix`` is
    instantiated once per new ndarray filled with a vector: a new render size costs one such small
    compile, measured in ``particles bench --only api``.)"""
    return sum(len(k.compiled_kernels) for k in impl.get_runtime().kernels
               if taichi_own or not k.func.__module__.startswith("taichi"))


def rows(c):
    return sorted(zip(c.time.tolist(), c.slot.tolist(), c.collider.tolist(), c.speed.tolist()))


@pytest.mark.slow
def test_contacts_drain_every_step_since_the_last_call_and_restarts_compile_nothing():
    """One drain per 1/60 s frame with 1/120 s steps gets exactly the contacts of draining after
    every step; the second run is the first scene reused (reset), so it also pins that a restart
    gives the same simulation and compiles nothing."""
    s = ParticleScene(RAIN, contacts=True)
    per_step = []
    for _ in range(60):
        for _ in range(2):
            s.step(1 / 120)
            per_step.append(s.contacts())
    image = s.render()
    total = sum(len(c) for c in per_step)
    assert total > 500 and all(c.dropped == 0 for c in per_step)
    hits = s.scene.particles.integrator.hits[None]  # the kernels' own count of resolved contacts
    assert total == hits
    s.close()
    before, reused = compiled(taichi_own=True), reuse.counts["reused"]
    s = ParticleScene(RAIN, contacts=True)  # a level restart: the closed scene, reset
    clock = FixedTimestep(1 / 120)
    per_frame = []
    for _ in range(60):
        assert clock.advance(s, 1 / 60) == 2
        per_frame.append(s.contacts())
    assert reuse.counts["reused"] == reused + 1 and compiled(taichi_own=True) == before
    assert np.array_equal(s.render(), image)
    got = [r for c in per_frame for r in rows(c)]
    assert sorted(got) == sorted(r for c in per_step for r in rows(c))
    c = per_frame[30]
    assert set(c.collider_name) <= {"ground", "ball"} and len(set(c.collider_name)) == 2
    first = next(c.rows())
    assert first["name"] == ("ground", "ball")[first["collider"]]
    fast = s.contacts(min_speed=1.0)  # drained: nothing since the last call
    assert len(fast) == 0
    s.step(1 / 60)
    assert np.all(s.contacts(min_speed=2.0).speed >= 2.0)
    key, idle = s._key, reuse.idle(s._key)
    del s  # dropped without close(): back to the pool all the same
    assert reuse.idle(key) == idle + 1


@pytest.mark.slow
def test_contact_buffer_overflow_is_counted_not_written_over():
    s = ParticleScene(RAIN, contacts=16, render=False)
    for _ in range(30):
        s.step(1 / 60)
    c = s.contacts()
    hits = s.scene.particles.integrator.hits[None]
    assert len(c) == 16 and c.dropped == hits - 16 > 0
    assert np.all(np.diff(c.time) >= 0)


@pytest.mark.slow
def test_soft_body_node_contacts_when_the_body_asks():
    s = (SceneBuilder(fps=60).forces(gravity=[0.0, -9.81, 0.0])
         .collider(type="sphere", name="rock", center=[0.0, 0.0, 0.0], radius=0.5)
         .body(type="cloth", name="sheet", resolution=[6, 6], size=[1.0, 1.0], position=[-0.5, 0.8, -0.5],
               pins="none", integrator="xpbd", contacts=True)
         .build(contacts=256, render=False))
    got = []
    for _ in range(40):
        s.step(1 / 60)
        got.append(s.contacts(body="sheet"))
    c = [x for x in got if len(x)]
    assert c, "the falling sheet never touched the rock"
    allc = c[0]
    assert np.all(allc.slot < 36) and set(allc.collider_name) == {"rock"}
    radial = allc.position / np.linalg.norm(allc.position, axis=1, keepdims=True)
    np.testing.assert_allclose(allc.normal, radial, atol=1e-4)
    assert len(s.contacts()) == 0  # no particles: the particle queue is empty


def test_burst_at_a_point_local_space_and_drawing_between_steps():
    s = (SceneBuilder(seed=3, fps=60).forces(gravity=[0.0, 0.0, 0.0])
         .render(width=160, height=90, grid=False, show_colliders=False)
         .camera(position=[0.0, 0.0, 5.0], look_at=[0.0, 0.0, 0.0], fov=40.0)
         .emitter(name="world", emitting=False, speed=[0.0, 0.0], lifetime=10.0, capacity=64,
                  color=[[0.0, 4.0, 4.0, 4.0]], size=[[0.0, 0.03]])
         .emitter(name="local", emitting=False, speed=[0.0, 0.0], lifetime=10.0, capacity=64, space="local")
         .build(interpolate=True))
    s.burst("world", 5, position=(1.0, 0.5, 0.0))
    s.burst("local", 5)
    s.step(1 / 60)
    p = s.particles()
    world, local = p["position"][p["emitter"] == 0], p["position"][p["emitter"] == 1]
    np.testing.assert_allclose(world, np.tile([1.0, 0.5, 0.0], (5, 1)), atol=1e-6)
    assert np.all(s.scene.control.emitters[0].position_at(s.time) == 0.0)  # the emitter did not move
    np.testing.assert_allclose(local, 0.0, atol=1e-6)
    for k in range(3):  # the local emitter moves 0.5 m along x per step; its particles go with it
        s.move_emitter("local", [0.5 * (k + 1), 0.0, 0.0], over=1 / 60)
        s.move_emitter("world", [0.5 * (k + 1), 0.0, 0.0], over=1 / 60)
        s.step(1 / 60)
    p = s.particles()
    np.testing.assert_allclose(p["position"][p["emitter"] == 1][:, 0], 1.5, atol=1e-5)
    np.testing.assert_allclose(p["position"][p["emitter"] == 0][:, 0], 1.0, atol=1e-6)  # world space: stays
    # drawing between steps: one bright dot moving along x at 1.2 m/step
    s.burst("world", 1, position=[-1.0, -0.5, 0.0])
    s.step(1 / 60)
    dot = s.scene.particles.state

    def brightest_x(img):
        lum = img[..., :3].astype(int).sum(-1)
        lum[:, :] *= np.arange(90)[:, None] > 55  # the lower half: where the new dot is
        return np.unravel_index(np.argmax(lum), lum.shape)[1]

    slot = int(np.flatnonzero(dot.particle_alive.to_numpy() & (dot.particle_emitter.to_numpy() == 0))[-1])
    dot.particle_vel[slot] = [72.0, 0.0, 0.0]  # 1.2 m per 1/60 s step
    s.step(1 / 60)
    xs = [brightest_x(s.render(alpha=a)) for a in (0.0, 0.5, 1.0)]
    cam = Camera((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), 40.0)
    want = [cam.project(np.array([[-1.0 + 1.2 * a, -0.5, 0.0]]), 160, 90)[0, 0] for a in (0.0, 0.5, 1.0)]
    assert abs(xs[0] - want[0]) <= 1.5 and abs(xs[1] - want[1]) <= 1.5 and abs(xs[2] - want[2]) <= 1.5, (xs, want)
    assert np.array_equal(s.render(alpha=1.0), s.render())
    # the overlay: premultiplied, alpha 0 and black where nothing is drawn, light where dots are
    over = s.render(transparent=True)
    assert np.all(over[:10, :10] == 0)
    assert over[..., :3].max() > 200


def test_particle_budget_shrinks_new_scenes_and_refuses_when_none_is_left():
    data = dict(fps=30, emitters=[{"name": "a", "rate": 1000.0, "lifetime": 1.0},
                                  {"name": "b", "rate": 1000.0, "lifetime": 1.0}])
    held = particle_budget()[1]  # (slots of scenes other tests left alive)
    try:
        set_particle_budget(held + 1500)
        s = ParticleScene(data, render=False)  # wants 2 × 1,042 slots
        assert 1400 < s.scene.capacity <= 1500 and s.budget_scale < 0.75
        assert particle_budget() == (held + 1500, held + s.scene.capacity)
        s.set_rate("a", 5000.0)
        for _ in range(10):
            s.step(1 / 30)
        assert s.dropped() > 0  # births past the shrunk pool: counted, not forced in
        set_particle_budget(held + s.scene.capacity + 1)
        with pytest.raises(ValueError, match="set_particle_budget: .* slots is not enough"):
            ParticleScene(data, render=False)  # one slot left for two emitters
        s.close()
        assert particle_budget()[1] == held
    finally:
        set_particle_budget(None)


@pytest.mark.slow
def test_a_new_render_size_and_a_warmed_up_scene_compile_nothing():
    s = (SceneBuilder(fps=60).render(width=64, height=36)
         .emitter(name="e", effect="sparks", rate=200.0)
         .collider(type="sphere", name="ball", center=[0.0, 0.3, 0.0], radius=0.3)
         .build(contacts=True))
    s.warm_up(sizes=[(64, 36)])
    assert s.time == 0.0 and s.live_count() == 0
    before = compiled()
    s.step(1 / 60)
    s.burst("e", 10, position=[0.0, 1.0, 0.0])
    s.move_collider("ball", [0.1, 0.3, 0.0])
    s.step(1 / 60)
    s.contacts()
    s.particles()
    s.render()
    s.render(200, 120)  # a size never drawn before
    s.render(33, 17, transparent=True, bgra=True)
    assert compiled() == before


@pytest.mark.slow
def test_a_warmed_up_scene_takes_single_steps_and_fused_runs_without_compiling():
    """Steps with no birth due are fused into one launch, the others launched one by one
    (ParticleSystem.fixed_step): the warm-up compiles both (ParticleSystem.warm_steps), whichever
    its own steps took, so a slow emitter's first steps, with births due now and then, compile
    nothing."""
    s = ParticleScene(dict(fps=60, render={"width": 64, "height": 36},
                           emitters=[{"name": "e", "rate": 20.0, "lifetime": 1.0}]))
    s.warm_up()
    before = compiled()
    for _ in range(30):
        s.step(1 / 60)
    assert s.live_count() > 0 and compiled() == before
    s.close()


@pytest.mark.slow
def test_a_warmed_up_scene_draws_its_first_smoke_in_the_reduced_layer_without_compiling():
    """A frame with nothing at the reduced and coarse levels takes smaller kernels than one that
    draws there (engine.render.renderer.Renderer._splat): warm_up compiles both, so puffs that
    grow past the layer's size only after the warm-up's step compile nothing either."""
    s = ParticleScene(dict(fps=60, render={"width": 320, "height": 180, "particle_resolution": 0.25},
                           camera={"position": [0.0, 1.0, 4.0], "look_at": [0.0, 1.0, 0.0]},
                           emitters=[{"name": "puff", "position": [0.0, 1.0, 0.0], "speed": [0.0, 0.1],
                                      "rate": 40.0, "lifetime": 1.0, "blend": "alpha",
                                      "size": [[0.0, 0.005], [0.4, 2.5]], "alpha": [[0.0, 0.5]]}]))
    s.warm_up(sizes=[(320, 180)])
    before = compiled()
    levels = set()
    for _ in range(40):
        s.step(1 / 60)
        s.render()
        info = s.scene.renderer.records.spr_info.to_numpy()
        levels |= set(np.unique(info[info[:, 0] != 0, 2]).tolist())
    assert {0, 1, 2} <= levels  # tiny at birth (full level), then the reduced and coarse levels
    assert compiled() == before
    s.close()


@pytest.mark.slow
def test_add_emitter_of_a_compiled_kind_writes_spare_rows_and_a_restart_takes_it_away():
    data = dict(fps=60, render={"width": 48, "height": 32},
                emitters=[{"name": "e", "effect": "sparks", "rate": 200.0}])
    s = ParticleScene(data)
    s.warm_up(sizes=[(48, 32)])
    before = compiled(taichi_own=True)
    s.step(1 / 60)
    s.add_emitter({"name": "jet", "effect": "sparks", "rate": 300.0, "position": (1.0, 0.0, 0.0),
                   "space": "local"})
    assert s.last_add is None and [e.name for e in s.cfg.emitters] == ["e", "jet"]
    for _ in range(6):
        s.step(1 / 60)
    s.move_emitter("jet", [1.5, 0.0, 0.0])
    s.burst("jet", 20, position=[0.0, 3.0, 0.0])
    s.step(1 / 60)
    p = s.particles()
    jet = p["emitter"] == 1
    assert 25 <= jet.sum() - 20 <= 40 and (p["position"][jet, 1] > 2.9).sum() == 20
    s.render()
    assert compiled(taichi_own=True) == before  # nothing compiled for the new emitter
    s.close()
    s = ParticleScene(data)  # a restart: the same scene, the emitter it gained taken away
    assert compiled(taichi_own=True) == before
    assert [e.name for e in s.cfg.emitters] == ["e"] and s.scene.particles.layout.spare == 16_384
    s.step(1 / 60)
    assert set(s.particles()["emitter"].tolist()) == {0}
    s.add_emitter({"name": "haze", "effect": "smoke", "rate": 10.0})  # alpha blending: not compiled
    assert "blend mode" in s.last_add and [e.name for e in s.cfg.emitters] == ["e", "haze"]


def test_a_scene_of_an_earlier_taichi_program_is_not_kept():
    from engine import runtime

    s = ParticleScene({"emitters": [{"name": "e", "rate": 10.0}]}, render=False)
    key = s._key
    runtime.reset()  # every field and kernel of the program dies
    runtime.init("cpu")
    del s
    assert reuse.idle(key) == 0
