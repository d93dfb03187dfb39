"""A game prototype on the engine's API, drawn with pygame: steer a ball through smoke and a
hanging cloth; sparks fly where it lands, particle hits flash the ball, the level restarts.

    python -m particles_tools.examples.sphere_game                      # window: arrows/WASD, space, r
    python -m particles_tools.examples.sphere_game --headless --frames 300   # scripted input, no window

(needs ``pip install -e ".[game]"``: pygame). What it shows of the API:

* the game draws its own frame (sky, ground, the ball) with pygame and lays the particles over it:
  ``scene.render(W, H, transparent=True, alpha=clock.alpha)`` is premultiplied RGBA (alpha 0
  where nothing is drawn), blitted with ``BLEND_PREMULTIPLIED`` — the blend
  (ONE, ONE_MINUS_SRC_ALPHA); ``alpha`` draws the particles between the last two fixed steps;
* ``FixedTimestep`` steps the scene in 1/120 s whatever the frame time;
* contacts as events: every hit since the last frame, with the collider's name — hits on the
  ball flash it, a hard landing throws sparks there (``burst(..., position=p)``);
* a level restart (``r``, or every 6 s headless): ``close()`` then a new scene of the same
  config, which reuses the closed one's fields and kernels — it starts without compiling.
"""
from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np

from engine.api import Camera, FixedTimestep, SceneBuilder

RADIUS = 0.3
CAMERA = Camera((0.0, 2.2, 5.0), (0.0, 0.6, 0.0), 50.0)
SKY_TOP, SKY_LOW, GROUND = (40, 60, 110), (150, 170, 200), (70, 80, 60)


def build_scene():
    return (SceneBuilder(name="sphere_game", seed=4, fps=60)
            .camera(position=CAMERA.position, look_at=CAMERA.look_at, fov=CAMERA.fov)
            .solver(integrator="symplectic_euler", h=1 / 120)
            .forces(gravity=(0.0, -9.81, 0.0), wind=(0.3, 0.0, 0.0),
                    turbulence={"strength": 0.6, "frequency": 0.9, "scroll": 0.6})
            .render(width=480, height=270, grid=False, show_colliders=False)
            .emitter(name="smoke", effect="smoke", shape="disc", radius=0.5, position=(-1.2, 0.05, -0.6),
                     rate=120.0, lifetime=4.0)
            .emitter(name="sparks", effect="sparks", emitting=False, direction=(0.0, 1.0, 0.0), spread=70.0,
                     speed=(2.0, 5.0), lifetime=0.8)
            .collider(type="plane", name="ground", restitution=0.3, friction=0.4)
            .collider(type="sphere", name="player", center=(0.0, RADIUS, 1.2), radius=RADIUS,
                      restitution=0.3, friction=0.2)
            .body(type="cloth", name="curtain", resolution=(16, 16), size=(1.6, 1.4), plane="xy",
                  position=(-0.8, 0.25, 0.0), pins="top", mass=0.01, stiffness=3000.0, damping=0.02,
                  integrator="xpbd", iterations=10, color=(0.3, 0.45, 0.85))
            .build(contacts=True, interpolate=True))


class Player:
    """The ball: walks on the ground, jumps, lands; ``flash`` fades after particle hits."""

    def __init__(self):
        self.pos = np.array([0.0, RADIUS, 1.2])
        self.vel = np.zeros(3)
        self.flash = 0.0

    def update(self, move: np.ndarray, jump: bool, dt: float) -> float:
        """Integrate the ball; returns its landing speed (0 when it did not land this frame)."""
        self.vel[0], self.vel[2] = 2.2 * move[0], 2.2 * move[2]
        on_ground = self.pos[1] <= RADIUS + 1e-6
        if jump and on_ground:
            self.vel[1] = 4.5
        self.vel[1] -= 9.81 * dt
        self.pos += self.vel * dt
        self.pos[[0, 2]] = np.clip(self.pos[[0, 2]], [-2.5, -1.5], [2.5, 2.5])
        self.flash = max(0.0, self.flash - 3.0 * dt)
        if self.pos[1] < RADIUS:
            impact = -self.vel[1]
            self.pos[1], self.vel[1] = RADIUS, 0.0
            return impact
        return 0.0


class Game:
    """The loop's state: scene, clock, player, the event log; ``frame`` draws one frame."""

    def __init__(self, width: int, height: int):
        import pygame

        self.pg, self.W, self.H = pygame, width, height
        self.screen = pygame.display.set_mode((width, height))
        self.background = self._background()
        self.overlay = np.empty((height, width, 4), np.uint8)  # rendered into, no allocation per frame
        self.log, self.flashes, self.restarts = [], 0, []
        self.start()

    def start(self):
        self.scene, self.clock, self.player = build_scene(), FixedTimestep(1 / 120), Player()

    def restart(self):
        """A level restart: the closed scene is reused by the new one (nothing compiles)."""
        t0 = time.perf_counter()
        self.scene.close()
        self.start()
        self.scene.step(1 / 120)
        self.restarts.append(time.perf_counter() - t0)
        self.log.append(f"level restarted in {1e3 * self.restarts[-1]:.0f} ms")

    def _background(self):
        """The game's own frame: a sky gradient over the ground plane's horizon."""
        pg, W, H = self.pg, self.W, self.H
        surf = pg.Surface((W, H))
        horizon = int(CAMERA.project(np.array([[0.0, 0.0, -200.0]]), W, H)[0, 1])
        for y in range(H):
            a = min(1.0, y / max(1, horizon))
            col = GROUND if y > horizon else tuple(int(t + a * (b - t)) for t, b in zip(SKY_TOP, SKY_LOW))
            pg.draw.line(surf, col, (0, y), (W, y))
        return surf

    def frame(self, move, jump, dt: float) -> None:
        sc, pl = self.scene, self.player
        landing = pl.update(np.asarray(move, float), jump, dt)
        sc.move_collider("player", pl.pos, over=dt)
        if landing > 1.0:  # hard landing: sparks at the contact point, more for harder hits
            n = int(40 * landing)
            sc.burst("sparks", n, position=pl.pos - [0.0, RADIUS - 0.02, 0.0])
            self.log.append(f"t={sc.time:5.2f} s  landed at {landing:.1f} m/s: {n} sparks")
        self.clock.advance(sc, dt)
        hits = sc.contacts(min_speed=0.5)  # every hit since the last frame, however many steps ran
        on_ball = hits.collider_name == "player"
        if on_ball.sum() >= 3:
            pl.flash, self.flashes = 1.0, self.flashes + 1
            self.log.append(f"t={sc.time:5.2f} s  {int(on_ball.sum())} particle hits on the ball, fastest "
                            f"{hits.speed[on_ball].max():.1f} m/s: flash")
        self.draw()

    def draw(self) -> None:
        pg, W, H = self.pg, self.W, self.H
        self.screen.blit(self.background, (0, 0))
        x, y, z = CAMERA.project(self.player.pos[None], W, H)[0]
        r = max(2, int(RADIUS * 0.5 * H / (z * CAMERA.tan_half)))
        glow = self.player.flash
        col = tuple(int(c + glow * (255 - c)) for c in (200, 60, 40))
        pg.draw.circle(self.screen, col, (int(x), int(y)), r)
        self.scene.render(W, H, out=self.overlay, transparent=True, alpha=self.clock.alpha)
        layer = pg.image.frombuffer(self.overlay, (W, H), "RGBA")
        self.screen.blit(layer, (0, 0), special_flags=pg.BLEND_PREMULTIPLIED)  # ONE, ONE_MINUS_SRC_ALPHA

    def pixels(self) -> np.ndarray:
        """(H, W, 3) uint8: what the screen shows now."""
        return np.frombuffer(self.pg.image.tobytes(self.screen, "RGB"), np.uint8).reshape(self.H, self.W, 3)


def scripted_input(frame: int, fps: float):
    """Headless play: circle through the smoke, walk into the curtain, jump every 1.5 s."""
    t = frame / fps
    move = [math.cos(0.8 * t), 0.0, -0.9 * math.sin(0.8 * t)]
    return move, frame % round(1.5 * fps) == round(0.5 * fps)


def run_headless(frames: int, size=(320, 180), fps: float = 50.0, restart_every: float = 6.0, quiet=False):
    """Play ``frames`` frames of scripted input at ``fps`` (not a multiple of the 120 Hz steps: the
    overlay is drawn between steps) with no window (SDL's dummy video driver); restart the level
    every ``restart_every`` seconds. Returns the Game."""
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    import pygame

    pygame.display.init()  # (no audio: the headless machine has no sound device)
    game = Game(*size)
    level_frame = 0
    for k in range(frames):
        if level_frame / fps >= restart_every:
            game.restart()
            level_frame = 0
        move, jump = scripted_input(level_frame, fps)
        game.frame(move, jump, 1.0 / fps)
        level_frame += 1
    if not quiet:
        print("\n".join(game.log[-12:]))
    return game


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--headless", action="store_true", help="scripted input, no window")
    ap.add_argument("--frames", type=int, default=None)
    ap.add_argument("--size", default="640x360")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    if args.headless:
        t0 = time.perf_counter()
        n = args.frames or 300
        game = run_headless(n, (w, h))
        print(f"{n} frames headless in {time.perf_counter() - t0:.2f} s; {game.flashes} flashes, "
              f"{len(game.restarts)} restarts")
        return 0

    import pygame

    pygame.display.init()
    game, clock, frames = Game(w, h), pygame.time.Clock(), 0
    pygame.display.set_caption("sphere game: arrows/WASD move, space jumps, r restarts")
    while args.frames is None or frames < args.frames:
        dt = min(clock.tick(60) / 1000.0, 0.1)
        jump = False
        for ev in pygame.event.get():
            if ev.type == pygame.QUIT or (ev.type == pygame.KEYDOWN and ev.key == pygame.K_ESCAPE):
                return 0
            if ev.type == pygame.KEYDOWN and ev.key == pygame.K_SPACE:
                jump = True
            if ev.type == pygame.KEYDOWN and ev.key == pygame.K_r:
                game.restart()
        keys = pygame.key.get_pressed()
        move = np.zeros(3)
        for ks, axis, sign in (((pygame.K_LEFT, pygame.K_a), 0, -1), ((pygame.K_RIGHT, pygame.K_d), 0, 1),
                               ((pygame.K_UP, pygame.K_w), 2, -1), ((pygame.K_DOWN, pygame.K_s), 2, 1)):
            if any(keys[k] for k in ks):
                move[axis] += sign
        game.frame(move, jump, dt)
        pygame.display.flip()
        while game.log:
            print(game.log.pop(0))
        frames += 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
