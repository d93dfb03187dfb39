"""``particles run``, ``validate`` and ``list``: configs in, frames out, one-line errors."""
from __future__ import annotations

import glob
import os
import sys
import time

from .cli import SimulationError, UserError
from .config import ConfigError, load_config, read_toml

OUTPUT_ROOT = "renders"


def _overrides(args) -> dict:
    o = {}
    if getattr(args, "integrator", None):
        o["solver.integrator"] = args.integrator
    if getattr(args, "seed", None) is not None:
        o["seed"] = args.seed
    if getattr(args, "size", None):
        try:
            w, h = (int(v) for v in args.size.lower().split("x"))
        except ValueError:
            raise UserError(f"--size: {args.size!r} is not WxH (e.g. 640x360)") from None
        o["render.width"], o["render.height"] = w, h
    return o


def load_scene_config(path, args):
    try:
        data = read_toml(path)
        if getattr(args, "frames", None) is not None:
            if args.frames < 1:
                raise UserError(f"--frames: {args.frames} is not allowed: must be >= 1")
            data.pop("duration", None)
            data["frames"] = args.frames
        if not data.get("name"):
            data["name"] = os.path.splitext(os.path.basename(path))[0]
        return load_config(data, _overrides(args))
    except ConfigError as e:
        raise UserError(f"{path}: " + "; ".join(e.problems)) from None


class Progress:
    def __init__(self, total, quiet):
        self.total, self.quiet = total, quiet
        self.t0 = time.perf_counter()
        self.tty = sys.stderr.isatty()
        self._last = 0.0

    def update(self, frame, alive):
        if self.quiet:
            return
        now = time.perf_counter()
        if not self.tty and now - self._last < 2.0 and frame < self.total:
            return
        self._last = now
        fps = frame / max(now - self.t0, 1e-9)
        bar = "#" * int(24 * frame / self.total)
        line = f"[{bar:<24}] frame {frame}/{self.total}  {fps:5.1f} frames/s  live {alive:,}"
        print(("\r" + line) if self.tty else line, end="" if self.tty else "\n", file=sys.stderr,
              flush=True)

    def done(self):
        if not self.quiet and self.tty:
            print(file=sys.stderr)


def cmd_run(args) -> int:
    from .render.output import FrameWriter, OutputError, prepare_dir
    from .scene import DivergenceError, Scene

    cfg = load_scene_config(args.config, args)
    out_dir = args.out or os.path.join(OUTPUT_ROOT, cfg.name)
    try:
        prepare_dir(out_dir, args.overwrite)
    except OutputError as e:
        raise UserError(str(e)) from None
    t_start = time.perf_counter()
    scene = Scene(cfg)
    t_built = time.perf_counter()
    total = cfg.frame_count
    writer = FrameWriter(out_dir, args.format, cfg.fps, cfg.name)
    progress = Progress(total, args.quiet)
    failure = None
    try:
        for k in range(total):
            scene.advance_frame()
            writer.submit(k, scene.render())
            progress.update(k + 1, scene.stats.alive)
    except DivergenceError as e:
        failure = e
    except OutputError as e:
        writer.close(finished=False) if writer._thread.is_alive() else None
        raise UserError(str(e)) from None
    finally:
        progress.done()
    try:
        writer.close(finished=failure is None)
    except OutputError as e:
        raise UserError(str(e)) from None
    wall = time.perf_counter() - t_start
    st = scene.stats
    if failure is not None:
        raise SimulationError(f"{failure} (frames 0..{st.frames - 2} kept in {out_dir})")
    sim_fps = st.frames / max(time.perf_counter() - t_built, 1e-9)
    dropped = scene.dropped()
    if not args.quiet or True:
        print(f"{cfg.name}: {st.frames} frames ({args.format}) in {out_dir}; {st.steps} steps"
              f" ({st.rejected} rejected), {cfg.solver.integrator}"
              f"{' adaptive' if cfg.solver.adaptive else ''}; peak live particles {st.peak_alive:,}"
              f" of {scene.capacity:,}; dropped {dropped:,}; {wall:.2f} s wall"
              f" ({sim_fps:.1f} frames/s after {t_built - t_start:.2f} s build)")
    if dropped:
        print(f"warning: {dropped:,} particles did not fit their emitters' pools "
              f"(raise the emitter's capacity)", file=sys.stderr)
    return 0


def cmd_validate(args) -> int:
    bad = 0
    for path in args.configs:
        try:
            load_config(path)
            print(f"{path}: ok")
        except ConfigError as e:
            bad += 1
            for line in e.problems:
                print(f"{path}: {line}")
    return 2 if bad else 0


def cmd_list(args) -> int:
    from effects import PRESETS

    root = args.dir
    print(f"configs in {root}/:")
    for path in sorted(glob.glob(os.path.join(root, "*.toml"))):
        try:
            cfg = load_config(path)
            info = f"{len(cfg.emitters)} emitter(s), {len(cfg.colliders)} collider(s), " \
                   f"{cfg.frame_count} frames at {cfg.fps:g} fps, {cfg.solver.integrator}"
        except ConfigError as e:
            info = f"INVALID: {e.problems[0]}"
        print(f"  {os.path.basename(path):<20} {info}")
    print("effect presets:")
    for name, mod in PRESETS.items():
        doc = (mod.__doc__ or "").strip().splitlines()[0]
        print(f"  {name:<20} {doc}")
    return 0
