"""A full frame of 1M live particles at 1280×720: step + render (background, splat, resolve and
tone map, read-back of the 8-bit image); no file writing.

The pool is pre-filled in a steady state (as the step section does): 90% additive embers and 10%
alpha-blended motes, all in view. The tiled splat (``engine.render.tiles``) is measured against
the serial splat it replaces, both from the same renderer fields.
"""
from __future__ import annotations

import numpy as np

from .common import Row, time_median
from .step import initial_state

W, H = 1280, 720
FPS = 60.0


def scene_config(n: int, streak: float = 0.0) -> dict:
    n_add = int(n * 0.9)
    n_alpha = n - n_add
    life = 2.0
    common = {"shape": "sphere", "radius": 0.5, "position": [0.0, 1.0, 0.0], "speed": [0.5, 3.0],
              "spread": 180.0, "lifetime": life}
    return {
        "seed": 2, "fps": FPS, "frames": 1,
        "solver": {"integrator": "symplectic_euler", "h": 1.0 / FPS},
        "forces": {"gravity": [0.0, -2.0, 0.0], "drag": 0.3},
        "render": {"width": W, "height": H},
        "emitters": [
            dict(common, name="embers", blend="additive", rate=n_add / life, capacity=n_add,
                 color=[[0.0, 3.0, 1.6, 0.5], [1.0, 0.8, 0.15, 0.03]], alpha=[[0.0, 1.0], [1.0, 0.0]],
                 size=[[0.0, 0.014], [1.0, 0.008]], streak=streak),
            dict(common, name="motes", blend="alpha", rate=n_alpha / life, capacity=n_alpha,
                 color=[[0.0, 0.3, 0.28, 0.25]], alpha=[[0.0, 0.0], [0.2, 0.25], [1.0, 0.0]],
                 size=[[0.0, 0.02], [1.0, 0.04]]),
        ],
        "colliders": [{"type": "plane", "restitution": 0.3, "friction": 0.2}],
    }


def build_scene(n: int, streak: float = 0.0, width: int = W, height: int = H, config=None):
    from engine.config import load_config
    from engine.scene import Scene

    scene = Scene(load_config(config or scene_config(n, streak)), width=width, height=height)
    fill_steady(scene)
    return scene


def fill_steady(scene, seed: int = 3):
    """Every slot alive, in view, ages spread so each emitter's ring retires in order."""
    P = scene.particles
    S = P.state
    cap = P.layout.capacity
    pos, vel, _, _ = initial_state(cap, seed=seed)
    age = np.empty(cap, np.float32)
    life = np.empty(cap, np.float32)
    em = np.empty(cap, np.int32)
    for e, (start, size) in enumerate(zip(P.layout.starts, P.layout.sizes)):
        L = scene.cfg.emitters[e].lifetime
        age[start:start + size] = L - (np.arange(size) + 0.75) * (L / size)
        life[start:start + size] = L
        em[start:start + size] = e
    S.particle_pos.from_numpy(pos)
    S.particle_vel.from_numpy(vel)
    S.particle_age.from_numpy(age)
    S.particle_life.from_numpy(life)
    S.particle_alive.from_numpy(np.ones(cap, np.int32))
    S.particle_emitter.from_numpy(em)
    S.particle_rand.from_numpy(np.random.default_rng(seed + 1).random(cap, dtype=np.float32))


def run(quick: bool = False):
    from engine.render.renderer import Renderer

    n, w, h = (50_000, 320, 180) if quick else (1_000_000, W, H)
    repeats = 3 if quick else 7
    scene = build_scene(n, width=w, height=h)
    R = scene.renderer
    cam = scene.camera
    out = np.empty((h, w, 4), np.uint8)
    P = scene.particles
    per_pixel = Renderer(P.state, scene.cfg.emitters, scene.colliders, scene.cfg.render,
                         schedule="pixels")

    def frame():  # the Renderer's own path on this arch: background kept while still valid
        scene.advance_frame()
        return R.render(cam, w, h, out=out)

    def frame_pixels():
        scene.advance_frame()
        return per_pixel.render(cam, w, h, out=out)

    def redraw():
        R.targets(w, h).bg_key = None
        return R.render(cam, w, h, out=out)

    t_frame = time_median(frame, repeats, warmup=1)
    t_pixels = time_median(frame_pixels, max(2, repeats // 2), warmup=1)
    t_step = time_median(scene.advance_frame, repeats, warmup=0)
    t_render = time_median(lambda: R.render(cam, w, h, out=out), repeats, warmup=0)
    t_redraw = time_median(redraw, repeats, warmup=0)
    t = R.targets(w, h)
    live = scene.live_count()
    label = f"{n / 1e6:g}M" if n >= 1_000_000 else f"{n // 1000}k"
    sec = f"full frame, {label} live particles at {w}x{h}"
    return [
        Row(sec, "frame (step + render)", t_frame * 1e3, "ms/frame",
            f"{1 / t_frame:5.1f} frames/s (target 30); live {live:,}; schedule {R.schedule}; "
            f"reduced layer x{t.scale:g}", {"fps": 1 / t_frame, "live": live}),
        Row(sec, "frame, per-pixel schedule", t_pixels * 1e3, "ms/frame",
            f"the GPU's schedule run on this arch: x{t_pixels / t_frame:.1f} the frame"),
        Row(sec, "  step (advance_frame)", t_step * 1e3, "ms"),
        Row(sec, "  render", t_render * 1e3, "ms", f"{R.last_pairs:,} tile-sprite pairs"),
        Row(sec, "  render, background redrawn", t_redraw * 1e3, "ms",
            "when the camera or colliders move"),
    ]
