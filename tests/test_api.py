"""The engine from a game loop: the Python API, fixed timestep, control, contacts, read-back."""
import numpy as np
import pytest

from engine.api import FixedTimestep, ParticleScene, SceneBuilder
from engine.render.camera import Camera


def cloud(**extra):
    """A still cloud of particles filling a box around the origin (no gravity, long lives)."""
    b = (SceneBuilder(seed=2, fps=60).forces(gravity=[0.0, 0.0, 0.0], drag=0.5)
         .render(width=96, height=54)
         .emitter(name="cloud", shape="box", box_size=[3.0, 1.0, 1.0], position=[0.0, 0.5, 0.0],
                  speed=[0.0, 0.0], lifetime=100.0, bursts=[{"time": 0.0, "count": 3000}]))
    b.collider(type="sphere", name="ball", center=[-2.5, 0.5, 0.0], radius=0.35, restitution=0.2)
    return b.build(**extra)


@pytest.mark.slow
def test_moving_sphere_pushes_particles_and_none_end_inside():
    s = cloud(contacts=True)
    s.step(1 / 60)
    x0 = s.particles()["position"].copy()
    for k in range(150):  # the ball sweeps through the cloud along +x at 2 m/s
        centre = np.array([-2.5 + 2.0 * (k + 1) / 60, 0.5, 0.0])
        s.move_collider("ball", centre, over=1 / 60)
        s.step(1 / 60)
        p = s.particles()["position"]
        assert np.linalg.norm(p - centre, axis=1).min() >= 0.35 * (1 - 1e-5)
    p = s.particles()
    moved = p["position"][:, 0] - x0[:, 0]
    swept = np.abs(x0[:, 1] - 0.5) ** 2 + x0[:, 2] ** 2 < 0.3 ** 2  # in the ball's path
    assert swept.sum() > 100
    assert np.median(moved[swept]) > 0.05  # pushed along +x
    assert np.abs(np.median(moved[~swept])) < 0.02  # the rest stays put


@pytest.mark.slow
def test_variable_frame_times_give_the_same_state_as_fixed_frames():
    def run(frame_times):
        s = ParticleScene.from_file("configs/sparks.toml", render=False)
        clock = FixedTimestep(1 / 120)
        steps = sum(clock.advance(s, ft) for ft in frame_times)
        return steps, s.particles()["position"]

    rng = np.random.default_rng(0)
    jitter = 1 / 144 * rng.uniform(0.5, 1.5, 300)
    jitter = np.concatenate([jitter, [1.0 - jitter.sum() + 1e-12]]) if jitter.sum() < 1 else jitter
    game144 = list(jitter[np.cumsum(jitter) <= 1.0 + 1e-9])
    game144.append(1.0 - sum(game144))
    steps_a, a = run(game144)
    steps_b, b = run([1 / 30] * 30)
    assert steps_a == steps_b == 120
    assert np.array_equal(a, b)


def test_burst_from_code_adds_exactly_its_count():
    s = (SceneBuilder(fps=30).forces(gravity=[0.0, 0.0, 0.0])
         .emitter(name="pop", emitting=False, lifetime=10.0, speed=[0.5, 1.0], spread=180.0,
                  capacity=1200)
         .build(render=False))
    s.step(1 / 30)
    assert len(s.particles()["position"]) == 0
    s.burst("pop", 777, position=[1.0, 2.0, 3.0])
    s.step(1 / 30)
    p = s.particles()
    assert len(p["position"]) == 777
    assert np.linalg.norm(p["position"] - [1.0, 2.0, 3.0], axis=1).max() < 1.0 / 30 + 1e-5
    s.set_rate("pop", 300.0)
    s.set_emitting("pop", True)
    s.step(1.0)
    assert abs(len(s.particles()["position"]) - (777 + 300)) <= 1


@pytest.mark.slow
def test_contacts_report_colliders_normals_and_speeds():
    s = (SceneBuilder(seed=1, fps=60).forces(gravity=[0.0, -9.81, 0.0])
         .emitter(name="rain", shape="box", box_size=[2.0, 0.1, 2.0], position=[0.0, 2.0, 0.0],
                  direction=[0.0, -1.0, 0.0], speed=[1.0, 2.0], rate=2000.0, lifetime=3.0)
         .collider(type="plane", name="ground", restitution=0.5)
         .collider(type="sphere", name="ball", center=[0.3, 0.6, 0.0], radius=0.5, restitution=0.5)
         .build(contacts=True, render=False))
    seen = {0: 0, 1: 0}
    for _ in range(60):
        s.step(1 / 60)
        c = s.contacts()
        ground, ball = c.collider == 0, c.collider == 1
        seen[0] += ground.sum()
        seen[1] += ball.sum()
        np.testing.assert_allclose(c.normal[ground], np.tile([0.0, 1.0, 0.0], (ground.sum(), 1)), atol=1e-6)
        radial = c.position[ball] - [0.3, 0.6, 0.0]
        radial /= np.linalg.norm(radial, axis=1, keepdims=True)
        np.testing.assert_allclose(c.normal[ball], radial, atol=1e-4)
        np.testing.assert_allclose(np.linalg.norm(c.position[ball] - [0.3, 0.6, 0.0], axis=1), 0.5, rtol=1e-4)
        assert np.all(c.speed >= 0) and np.all(np.diff(c.time) >= 0)
        fast = s.contacts(min_speed=3.0)
        assert np.all(fast.speed >= 3.0) and len(fast) <= len(c)
    assert seen[0] > 100 and seen[1] > 100


@pytest.mark.slow
def test_read_back_matches_rendered_positions():
    s = (SceneBuilder(seed=3, fps=30).forces(gravity=[0.0, 0.0, 0.0])
         .render(width=160, height=90, grid=False)
         .emitter(name="dots", shape="box", box_size=[2.0, 1.0, 0.5], position=[0.0, 1.0, 0.0],
                  speed=[0.0, 0.0], lifetime=100.0, bursts=[{"time": 0.0, "count": 12}],
                  color=[[0.0, 4.0, 4.0, 4.0]], size=[[0.0, 0.02]])
         .build())
    s.step(1 / 30)
    cam = Camera(position=(0.0, 1.0, 5.0), look_at=(0.0, 1.0, 0.0), fov=40.0)
    img = s.render(160, 90, camera=cam)
    assert img.shape == (90, 160, 4) and np.all(img[..., 3] == 255)
    px = cam.project(s.particles()["position"], 160, 90)
    lum = img[..., :3].astype(int).sum(-1)
    background = np.median(lum)
    for x, y, _ in px:
        assert lum[int(y), int(x)] > background + 100, (x, y)
    mask = np.zeros_like(lum, bool)
    for x, y, _ in px:
        mask[max(0, int(y) - 2):int(y) + 3, max(0, int(x) - 2):int(x) + 3] = True
    assert np.all(lum[~mask] < background + 30)  # nothing bright anywhere else


@pytest.mark.slow
def test_independent_scenes_in_one_process_and_rebuilds_keep_particles():
    a, b = cloud(), cloud()
    for _ in range(5):
        a.step(1 / 60)
    b.step(1 / 60)
    assert a.time != b.time
    before = a.particles()["position"]
    a.add_emitter({"name": "more", "rate": 100.0, "lifetime": 5.0})
    after = a.particles()["position"]
    np.testing.assert_array_equal(before, after)  # carried over by name, in order
    a.step(0.5)
    assert abs((a.particles()["emitter"] == 1).sum() - 50) <= 1
    a.remove_emitter("more")
    assert len(a.particles()["position"]) == 3000
    a.remove_collider("ball")
    assert a.scene.colliders.count == 0
    a.step(1 / 60)
    assert len(a.particles()["position"]) == 3000  # removing a collider keeps the particles


@pytest.mark.slow  # (a scene with smoke, sparks and a cloth, 330 rendered frames: ~40 s under load)
def test_game_example_runs_headless():
    """The pygame example, headless: contacts flash the ball, sparks fly on landings, the level
    restarts by reusing its scene, and the overlay composites over the game's own frame."""
    from engine import reuse
    from particles_tools.examples.sphere_game import SKY_TOP, run_headless

    reused = reuse.counts["reused"]
    game = run_headless(330, size=(160, 90), fps=50.0, restart_every=3.0, quiet=True)
    assert any("landed" in line for line in game.log)
    assert game.flashes > 0 and any("flash" in line for line in game.log)
    assert len(game.restarts) == 2 and reuse.counts["reused"] == reused + 2
    curtain = game.scene.body_positions("curtain")
    assert np.isfinite(curtain).all() and curtain[:, 1].min() > -0.01
    screen = game.pixels()
    assert tuple(screen[0, 0]) == SKY_TOP  # the overlay is transparent where nothing is drawn
    assert game.overlay[..., 3].max() > 0 and (game.overlay[..., 3] == 0).mean() > 0.3
