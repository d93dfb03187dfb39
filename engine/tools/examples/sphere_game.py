"""A game prototype: steer a ball through smoke and a hanging cloth; sparks fly where it hits the
ground, and collision events print.

    python -m engine.tools.examples.sphere_game              # window: arrows/WASD move, space jumps
    python -m engine.tools.examples.sphere_game --headless --frames 240   # scripted input, no window

The whole game is the loop below: read input, move the collider (its velocity is inferred, so it
pushes smoke and cloth), step the scene, react to contacts.
"""
from __future__ import annotations

import argparse
import math

import numpy as np

from engine.api import ParticleScene, SceneBuilder

RADIUS = 0.3


def build_scene(contacts=True) -> ParticleScene:
    return (SceneBuilder(name="sphere_game", seed=4, fps=60)
            .camera(position=[0.0, 2.2, 5.0], look_at=[0.0, 0.6, 0.0], fov=50.0)
            .solver(integrator="symplectic_euler", h=1 / 120)
            .forces(gravity=[0.0, -9.81, 0.0], wind=[0.3, 0.0, 0.0],
                    turbulence={"strength": 0.6, "frequency": 0.9, "scroll": 0.6})
            .render(width=480, height=270)
            .emitter(name="smoke", effect="smoke", shape="disc", radius=0.5, position=[-1.2, 0.05, -0.6],
                     rate=120.0, lifetime=4.0)
            .emitter(name="sparks", effect="sparks", emitting=False, direction=[0.0, 1.0, 0.0], spread=70.0,
                     speed=[2.0, 5.0], lifetime=0.8)
            .collider(type="plane", name="ground", restitution=0.3, friction=0.4)
            .collider(type="sphere", name="player", center=[0.0, RADIUS, 1.2], radius=RADIUS,
                      restitution=0.3, friction=0.2)
            .body(type="cloth", name="curtain", resolution=[16, 16], size=[1.6, 1.4], plane="xy",
                  position=[-0.8, 0.25, 0.0], pins="top", mass=0.01, stiffness=3000.0, damping=0.02,
                  integrator="xpbd", iterations=10, color=[0.3, 0.45, 0.85])
            .build(contacts=contacts))


class Player:
    """The ball: walks on the ground, jumps, lands (and throws sparks when it lands hard)."""

    def __init__(self):
        self.pos = np.array([0.0, RADIUS, 1.2])
        self.vel = np.zeros(3)

    def update(self, move: np.ndarray, jump: bool, dt: float) -> float:
        """Integrate the ball; returns its landing speed (0 when it did not land this frame)."""
        self.vel[0], self.vel[2] = 2.2 * move[0], 2.2 * move[2]
        on_ground = self.pos[1] <= RADIUS + 1e-6
        if jump and on_ground:
            self.vel[1] = 4.5
        self.vel[1] -= 9.81 * dt
        self.pos += self.vel * dt
        self.pos[[0, 2]] = np.clip(self.pos[[0, 2]], [-2.5, -1.5], [2.5, 2.5])
        if self.pos[1] < RADIUS:
            impact = -self.vel[1]
            self.pos[1], self.vel[1] = RADIUS, 0.0
            return impact
        return 0.0


def play_frame(scene: ParticleScene, player: Player, move, jump, dt, log) -> None:
    landing = player.update(np.asarray(move, float), jump, dt)
    scene.move_collider("player", player.pos, over=dt)
    if landing > 1.0:  # hard landing: sparks at the contact point, more for harder hits
        scene.burst("sparks", int(40 * landing), position=player.pos - [0.0, RADIUS - 0.02, 0.0])
        log.append(f"t={scene.time:5.2f} s  landed at {landing:.1f} m/s: {int(40 * landing)} sparks")
    scene.step(dt)
    hits = scene.contacts(min_speed=0.5)
    on_player = hits.collider == 1
    if on_player.any():
        log.append(f"t={scene.time:5.2f} s  {int(on_player.sum())} particle hits on the ball, fastest "
                   f"{hits.speed[on_player].max():.1f} m/s")


def scripted_input(frame: int):
    """Headless play: circle through the smoke, walk into the curtain, jump every 1.5 s."""
    t = frame / 60.0
    move = [math.cos(0.8 * t), 0.0, -0.9 * math.sin(0.8 * t)]
    return move, frame % 90 == 30


def run_headless(frames: int, quiet=False):
    scene, player, log = build_scene(), Player(), []
    for k in range(frames):
        move, jump = scripted_input(k)
        play_frame(scene, player, move, jump, 1 / 60, log)
    if not quiet:
        print("\n".join(log[-12:]))
    return scene, player, log


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--headless", action="store_true", help="scripted input, no window")
    ap.add_argument("--frames", type=int, default=None)
    ap.add_argument("--screenshot", default=None)
    args = ap.parse_args(argv)
    if args.headless:
        import time

        t0 = time.perf_counter()
        run_headless(args.frames or 240)
        n = args.frames or 240
        print(f"{n} frames headless in {time.perf_counter() - t0:.2f} s")
        return 0

    import taichi as ti

    from engine.tools.viewer import run_viewer

    player, log = Player(), []

    def on_frame(scene, gui, dt):
        move = np.zeros(3)
        for keys, axis, sign in (((ti.GUI.LEFT, "a"), 0, -1), ((ti.GUI.RIGHT, "d"), 0, 1),
                                 ((ti.GUI.UP, "w"), 2, -1), ((ti.GUI.DOWN, "s"), 2, 1)):
            if any(gui.is_pressed(k) for k in keys):
                move[axis] += sign
        play_frame(scene, player, move, gui.is_pressed(ti.GUI.SPACE), min(dt, 1 / 20), log)
        while log:
            print(log.pop(0))

    # the game steps the scene itself in on_frame: the viewer's own clock is paused via a scene
    # whose step is driven here, so the viewer only draws
    r = run_viewer(build_scene, "sphere game", frames=args.frames, screenshot=args.screenshot,
                   on_frame=on_frame, drive=False)
    print(f"{r['frames']} frames: {r['fps']:.1f} frames/s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
