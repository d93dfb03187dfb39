"""``particles view CONFIG``: play a scene in real time in a window (Taichi's GUI).

Keys: space pause/resume, s single step (while paused), r restart, c show/hide colliders,
Esc quit. Drag with the left mouse button to orbit the camera around its look-at point, wheel or
+/- to zoom. The title bar area shows frames per second and the live particle count.
"""
from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

from .errors import UserError
from .overlay import draw_text


WARM_FRAMES = 30  # frames shown before the steady rate is timed (compiling, filling the pools)


def has_display() -> bool:
    if sys.platform.startswith("linux"):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


class Orbit:
    """Camera orbiting its look-at point: azimuth, elevation (radians) and distance."""

    def __init__(self, camera):
        self.cam = camera
        d = np.asarray(camera.position, float) - np.asarray(camera.look_at, float)
        self.dist = float(np.linalg.norm(d))
        self.az = math.atan2(d[0], d[2])
        self.el = math.asin(max(-1.0, min(1.0, d[1] / max(self.dist, 1e-9))))

    def apply(self):
        c = np.asarray(self.cam.look_at, float)
        d = self.dist * np.array([math.cos(self.el) * math.sin(self.az), math.sin(self.el),
                                  math.cos(self.el) * math.cos(self.az)])
        self.cam.position = tuple(c + d)

    def drag(self, dx, dy):
        self.az -= 3.0 * dx
        self.el = max(-1.45, min(1.45, self.el - 3.0 * dy))
        self.apply()

    def zoom(self, factor):
        self.dist = max(0.2, self.dist * factor)
        self.apply()


def _open_window(ti, scene, title: str, W: int, H: int):
    """The window, or one line naming the display when none opens there (a DISPLAY set to a
    server that is gone or will not take us): Taichi logs its own error line, writes blank lines
    to the process's stdout and raises with a traceback, so for the call its log is quiet and
    file descriptor 1 points at /dev/null, and the scene is closed before the message."""
    from taichi import _logging

    levels = (ti.TRACE, ti.DEBUG, ti.INFO, ti.WARN, ti.ERROR, ti.CRITICAL)
    before = next((lv for lv in levels if _logging.is_logging_effective(lv)), ti.WARN)
    ti.set_logging_level(ti.CRITICAL)
    sys.stdout.flush()
    saved, null = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    try:
        return ti.GUI(title, res=(W, H), fast_gui=True, show_gui=True)
    except RuntimeError:
        scene.close()
        where = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
        raise UserError(f"view: cannot open a window on display {where!r} (no X server there accepts "
                        "one): check DISPLAY, or run under Xvfb (xvfb-run particles view ...); "
                        "`particles run` renders frames off-screen") from None
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)
        ti.set_logging_level(before)


def run_viewer(make_scene, title: str, frames: int | None = None, screenshot: str | None = None,
               on_frame=None, size=None, drive: bool = True) -> dict:
    """Open a window and play ``make_scene()`` (a ParticleScene) in real time. ``on_frame(scene,
    gui, dt)`` lets a game read keys and steer the scene; with ``drive=False`` the game steps the
    scene itself and the viewer only draws. Returns figures for the caller."""
    import taichi as ti

    from engine.api import FixedTimestep

    if not has_display():
        raise UserError("view: no display (DISPLAY is not set): run it from a desktop session or under "
                        "Xvfb (xvfb-run particles view ...); `particles run` renders frames off-screen")
    scene = make_scene()
    W, H = size or (scene.cfg.render.width, scene.cfg.render.height)
    # fast GUI: the window shows a packed 0x00RRGGBB buffer, top row first — the renderer's BGRA
    # output byte for byte, so frames are drawn straight into it (no conversion, no copy)
    gui = _open_window(ti, scene, title, W, H)
    frame = gui.img.view(np.uint8).reshape(H, W, 4)
    orbit = Orbit(scene.scene.camera)
    clock = FixedTimestep(scene.scene.frame_dt, max_steps=4)
    paused, show_colliders, last_cursor, shown = False, scene.cfg.render.show_colliders, None, 0
    t_prev = t_start = time.perf_counter()
    t_warm = None  # when frame WARM_FRAMES was shown: the steady rate is measured from there
    fps = 0.0
    while gui.running:
        step_once = False
        for e in gui.get_events(ti.GUI.PRESS):
            if e.key == ti.GUI.ESCAPE:
                gui.running = False
            elif e.key == ti.GUI.SPACE:
                paused = not paused
            elif e.key == "s":
                step_once = True
            elif e.key == "r":
                scene = make_scene()
                orbit = Orbit(scene.scene.camera)
            elif e.key == "c":
                show_colliders = not show_colliders
            elif e.key in ("=", "+", ti.GUI.WHEEL) and (e.key != ti.GUI.WHEEL or e.delta[1] > 0):
                orbit.zoom(0.9)
            elif e.key in ("-", ti.GUI.WHEEL):
                orbit.zoom(1.1)
        cursor = gui.get_cursor_pos()
        if gui.is_pressed(ti.GUI.LMB) and last_cursor is not None:
            orbit.drag(cursor[0] - last_cursor[0], cursor[1] - last_cursor[1])
        last_cursor = cursor
        now = time.perf_counter()
        dt = now - t_prev
        t_prev = now
        if on_frame is not None:
            on_frame(scene, gui, dt)
        if not drive:
            pass
        elif not paused:
            clock.advance(scene, dt)
        elif step_once:
            scene.step(scene.scene.frame_dt)
        scene.render(W, H, show_colliders=show_colliders, out=frame, bgra=True)
        fps = 0.9 * fps + 0.1 / max(dt, 1e-6) if shown else 1.0 / max(dt, 1e-6)
        draw_text(frame, f"{fps:5.1f} fps   {scene.live_count():,} particles   t={scene.time:5.2f} s"
                         f"{'   [paused]' if paused else ''}")
        shown += 1
        if shown == WARM_FRAMES:
            t_warm = time.perf_counter()
        last = frames is not None and shown >= frames
        if last and screenshot:  # (the fast GUI's own screenshot holds only its canvas, not our frame)
            from PIL import Image

            Image.fromarray(np.ascontiguousarray(frame[..., 2::-1])).save(screenshot)
        gui.show()
        if last:
            break
    end = time.perf_counter()
    gui.close()
    steady = (shown - WARM_FRAMES) / (end - t_warm) if t_warm is not None and shown > WARM_FRAMES else None
    return {"frames": shown, "seconds": end - t_start, "fps": shown / max(end - t_start, 1e-9),
            "fps_steady": steady}


def cmd_view(args) -> int:
    from .commands import scene_from_file

    def make():
        return scene_from_file(args.config)

    make()  # a scene that cannot be built fails before a window opens
    r = run_viewer(make, f"particles: {args.config}", frames=args.frames, screenshot=args.screenshot)
    steady = f" ({r['fps_steady']:.1f} frames/s after the first {WARM_FRAMES})" if r["fps_steady"] else ""
    print(f"{r['frames']} frames in {r['seconds']:.2f} s: {r['fps']:.1f} frames/s{steady}")
    return 0
