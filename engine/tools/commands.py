"""``particles run``, ``validate`` and ``list``: configs in, frames out, one-line errors."""
from __future__ import annotations

import glob
import os
import sys
import time

from .errors import OutputFailure, SimulationError, Stopped, UserError
from ..config import ConfigError, load_config, read_toml

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


def scene_config(path, args=None):
    """The validated config ``particles run`` and ``validate`` both use: the TOML file, its name
    from the file name unless it sets one, and the command line's overrides. Raises ConfigError."""
    data = read_toml(path)
    if data.get("name", "") == "":
        data["name"] = os.path.splitext(os.path.basename(path))[0]
    if getattr(args, "frames", None) is not None:
        data.pop("duration", None)
        data["frames"] = args.frames
    return load_config(data, _overrides(args) if args is not None else None)


def load_scene_config(path, args):
    if getattr(args, "frames", None) is not None and args.frames < 1:
        raise UserError(f"--frames: {args.frames} is not allowed: must be >= 1")
    try:
        return scene_config(path, args)
    except ConfigError as e:
        raise UserError("\n".join(f"{path}: {p}" for p in e.problems)) from None


def output_dir(cfg, args) -> str:
    """--out as given, else renders/<output or name>; a config's ``output`` must stay inside
    renders/, also through symbolic links."""
    if args.out:
        return args.out
    out_dir = os.path.join(OUTPUT_ROOT, cfg.output or cfg.name)
    root = os.path.realpath(OUTPUT_ROOT)
    if os.path.commonpath([root, os.path.realpath(out_dir)]) != root:
        raise UserError(f"output: {out_dir!r} leads outside {OUTPUT_ROOT}/ (through a symbolic "
                        f"link); use --out for other places")
    return out_dir


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


def _open_output(cfg, args, out_dir) -> int:
    """Prepare the output folder; returns the first frame to render (> 0 only with --resume)."""
    from .. import runtime
    from ..render.output import OutputError, OutputRefused, prepare_dir
    from ..render.resume import prepare_resume, run_record, write_record

    if args.resume and args.overwrite:
        raise UserError("--resume and --overwrite: choose one")
    if args.resume and args.format != "png":
        raise UserError(f"--resume: works for PNG frames only, not --format {args.format} "
                        f"(a partial movie is never kept)")
    record = run_record(cfg, args.format, runtime.ensure_init())
    try:
        first = prepare_resume(out_dir, record) if args.resume and os.path.isdir(out_dir) else 0
        if first == 0:
            prepare_dir(out_dir, args.overwrite)
        write_record(out_dir, record)
    except OutputRefused as e:
        raise UserError(str(e)) from None
    except OutputError as e:
        raise OutputFailure(str(e)) from None
    except OSError as e:
        raise OutputFailure(f"--out: cannot write to {out_dir}: {e.strerror or e}") from None
    return first


def cmd_run(args) -> int:
    from ..render.output import FrameWriter, OutputError
    from ..scene import DivergenceError, Scene
    from .signals import StopRequest

    cfg = load_scene_config(args.config, args)
    out_dir = output_dir(cfg, args)
    first = _open_output(cfg, args, out_dir)
    t_start = time.perf_counter()
    scene = Scene(cfg)
    t_built = time.perf_counter()
    total = cfg.frame_count
    writer = FrameWriter(out_dir, args.format, cfg.fps, cfg.name)
    progress = Progress(total, args.quiet)
    failure = out_failure = None
    with StopRequest() as stop:
        try:
            for k in range(total):
                if stop.requested:
                    break
                scene.advance_frame()
                if k >= first:  # --resume: frames before `first` are on disk already
                    writer.submit(k, scene.render())
                progress.update(k + 1, scene.stats.alive)
        except DivergenceError as e:
            failure = e
        except OutputError as e:
            out_failure = e
        finally:
            progress.done()
        try:
            writer.close(finished=failure is None and out_failure is None and not stop.requested)
        except OutputError as e:
            out_failure = out_failure or e
    wall = time.perf_counter() - t_start
    st = scene.stats
    done = first + len(writer.written) if args.format == "png" else 0
    kept = f"frames 0..{done - 1} kept in {out_dir}" if done else f"no frames kept in {out_dir}"
    if out_failure is not None:
        raise OutputFailure(f"{out_failure} ({kept})")
    if failure is not None:
        raise SimulationError(f"{failure} ({kept})")
    if stop.requested:
        raise Stopped(f"stopped by {stop.name} after {st.frames} of {total} frames ({kept}); "
                      f"continue with --resume", stop.signum)
    sim_fps = st.frames / max(time.perf_counter() - t_built, 1e-9)
    dropped = scene.dropped()
    parts = []
    if scene.particles is not None:
        parts.append(f"{st.steps} steps ({st.rejected} rejected), {cfg.solver.integrator}"
                     f"{' adaptive' if cfg.solver.adaptive else ''}; peak live particles "
                     f"{st.peak_alive:,} of {scene.capacity:,}; dropped {dropped:,}")
    for b in scene.bodies:
        sysm = b.system
        parts.append(f"{b.cfg.type} {b.cfg.name or ''}: {b.topology.node_count:,} nodes, "
                     f"{b.topology.spring_count:,} springs, {sysm.integrator} × "
                     f"{sysm.substeps_for(scene.frame_dt)} substeps/frame")
    print(f"{cfg.name}: {st.frames} frames ({args.format}) in {out_dir}"
          f"{f' (resumed at frame {first})' if first else ''}; " + "; ".join(parts)
          + f"; {wall:.2f} s wall ({sim_fps:.1f} frames/s after {t_built - t_start:.2f} s build)")
    if dropped:
        print(f"warning: {dropped:,} particles did not fit their emitters' pools "
              f"(raise the emitter's capacity)", file=sys.stderr)
    return 0


def cmd_validate(args) -> int:
    bad = 0
    for path in args.configs:
        try:
            scene_config(path)
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
            what = [f"{len(cfg.emitters)} emitter(s)"] if cfg.emitters else []
            what += [f"{b.type} ({b.integrator or cfg.solver.integrator})" for b in cfg.bodies]
            info = f"{', '.join(what)}, {len(cfg.colliders)} collider(s), " \
                   f"{cfg.frame_count} frames at {cfg.fps:g} fps" + \
                   (f", {cfg.solver.integrator}" if cfg.emitters else "")
        except ConfigError as e:
            info = f"INVALID: {e.problems[0]}"
        print(f"  {os.path.basename(path):<20} {info}")
    print("effect presets:")
    for name, mod in PRESETS.items():
        doc = " ".join((mod.__doc__ or "").split()).split(": ", 1)[-1]
        doc = doc if len(doc) <= 72 else doc[:69].rsplit(" ", 1)[0] + " ..."
        print(f"  {name:<20} {doc}")
    return 0
