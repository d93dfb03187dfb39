"""``particles run``, ``validate`` and ``list``: configs in, frames out, one-line errors."""
from __future__ import annotations

import glob
import os
import sys
import time

from . import budget, flags
from .errors import OutputFailure, SimulationError, Stopped, UserError
from engine.config import ConfigError, load_config, read_toml

OUTPUT_ROOT = "renders"
COMPILING = "compiling kernels… (a cold first run takes ~10 s; later runs load them from the cache)"


def _overrides(args) -> dict:
    o = {}
    if getattr(args, "integrator", None):
        o["solver.integrator"] = args.integrator
    if getattr(args, "seed", None) is not None:
        o["seed"] = args.seed
    if getattr(args, "size", None):
        o["render.width"], o["render.height"] = flags.checked("--size", flags.size, args.size)
    return o


def scene_config(path, args=None):
    """The validated config ``particles run`` and ``validate`` both use: the TOML file, its name
    from the file name unless it sets one, and the command line's overrides. Raises ConfigError."""
    data = read_toml(path)
    if data.get("name", "") == "":
        data["name"] = os.path.splitext(os.path.basename(path))[0]
    overrides = _overrides(args) if args is not None else None
    if getattr(args, "frames", None) is not None:
        if "duration" in data:  # --frames replaces it, but a duration validate refuses is refused here too
            probe = {k: v for k, v in data.items() if k != "frames"}
            try:
                load_config(probe, overrides)
            except ConfigError as e:
                bad = [p for p in e.problems if p.startswith("duration")]
                if bad:
                    raise ConfigError(bad) from None
        data.pop("duration", None)
        data["frames"] = args.frames
    return load_config(data, overrides)


def load_scene_config(path, args):
    try:
        return scene_config(path, args)
    except ConfigError as e:
        raise UserError("\n".join(f"{path}: {p}" for p in e.problems)) from None


def output_folder(path: str, flag: str = "--out") -> str:
    """The folder a command writes its files into, created and checked writable: one line
    naming ``flag`` and exit 4 otherwise, as ``particles run --out`` (``chart``, ``gallery``)."""
    from engine.render.output import OutputError, writable_dir

    try:
        writable_dir(path, flag)
    except OutputError as e:
        raise OutputFailure(str(e)) from None
    return path


def scene_from_file(path):
    """The game API's scene of the config at ``path`` for the tools that run one as a game does
    (``view``, ``profile``): the checks and messages of ``particles run`` first (one line per
    problem, naming the file and the key; a missing file too), then the API's own, one line —
    a UserError either way, before a window opens or a kernel compiles."""
    from engine.api import ParticleScene

    load_scene_config(path, None)
    try:
        return ParticleScene.from_file(path)
    except (ConfigError, ValueError) as e:
        raise UserError(f"{path}: {e}") from None


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


def _open_output(cfg, args, out_dir):
    """Lock and prepare the output folder; returns (the first frame to render: > 0 only with
    --resume, the folder's lock: release it when the run ends)."""
    from engine import runtime
    from engine.render.output import OutputError, OutputRefused, lock_dir, prepare_dir
    from engine.render.resume import prepare_resume, run_record, write_record

    if args.resume and args.overwrite:
        raise UserError("--resume and --overwrite: choose one")
    if args.resume and args.format != "png":
        raise UserError(f"--resume: works for PNG frames only, not --format {args.format} "
                        f"(a partial movie is never kept)")
    record = run_record(cfg, args.format, runtime.ensure_init())
    lock, existed = None, os.path.isdir(out_dir)
    try:
        lock = lock_dir(out_dir)  # a second run into this folder is refused here
        first = prepare_resume(out_dir, record) if args.resume and existed else 0
        if first == 0:
            prepare_dir(out_dir, args.overwrite)
        write_record(out_dir, record)
    except BaseException as e:
        if lock is not None:
            lock.release()
        if not existed and os.path.isdir(out_dir) and not os.listdir(out_dir):
            os.rmdir(out_dir)  # refused: leave no new folder
        if isinstance(e, OutputRefused):
            raise UserError(str(e)) from None
        if isinstance(e, OutputError):
            raise OutputFailure(str(e)) from None
        if isinstance(e, OSError):
            raise OutputFailure(f"--out: cannot write to {out_dir}: {e.strerror or e}") from None
        raise
    return first, lock


def _even_for_mp4(cfg, args) -> None:
    """H.264 (yuv420p) needs even sides: refuse odd ones naming where they came from."""
    W, H = cfg.render.width, cfg.render.height
    if args.format != "mp4" or not (W % 2 or H % 2):
        return
    fix = f"{W - W % 2}x{H - H % 2}"
    if getattr(args, "size", None):
        raise UserError(f"--size: {args.size} is not allowed with --format mp4: H.264 needs an even "
                        f"width and height (e.g. --size {fix})")
    key = "render.width" if W % 2 else "render.height"
    raise UserError(f"{args.config}: {key}: {W if W % 2 else H} is odd; --format mp4 (H.264) needs "
                    f"an even width and height: set it, or pass --size {fix}")


def _auto_substeps(cfg):
    """Substeps per frame the stiffness guard will pick for bodies with ``substeps = "auto"``
    (engine.bodies builds the same network): bounded work needs them before the run starts."""
    import numpy as np

    from engine.bodies import build_topology
    from engine.springs.stability import StiffnessError, auto_substeps, network_bounds

    def substeps(k, b):
        method = b.integrator or cfg.solver.integrator
        if isinstance(b.substeps, int) or method == "xpbd":
            return b.substeps if isinstance(b.substeps, int) else 1
        top = build_topology(b)
        pinned = np.zeros(top.node_count, bool)
        pinned[np.asarray(top.pinned, np.int64)] = True
        try:
            return auto_substeps(method, 1.0 / cfg.fps, network_bounds(top, pinned))
        except StiffnessError:
            return 1  # the scene refuses it with its own message when it is built
    return substeps


def check_budget(cfg, args, workers: int) -> budget.Estimate:
    """Refuse a run whose memory or work passes the limits (one line each, naming the flag)."""
    from engine.render.output import FrameWriter

    limits = (getattr(args, "max_memory", None) or budget.DEFAULT_MAX_MEMORY,
              getattr(args, "max_steps", None) or budget.DEFAULT_MAX_STEPS,
              getattr(args, "max_work", None) or budget.DEFAULT_MAX_WORK)
    in_flight = FrameWriter.frames_in_flight(args.format, workers)
    est = budget.estimate(cfg, cfg.render.width, cfg.render.height, in_flight)
    problems = budget.problems(est, *limits)
    if not problems and any(b.substeps == "auto" for b in cfg.bodies):  # memory is known fine now
        est = budget.estimate(cfg, cfg.render.width, cfg.render.height, in_flight,
                              body_substeps=_auto_substeps(cfg))
        problems = budget.problems(est, *limits)
    if problems:
        raise UserError("\n".join(problems))
    return est


def render_frames(scene, writer, first: int, total: int, stop=None, bar=None):
    """The frame loop of ``particles run``: simulate frames 0..total-1, render and submit those
    from ``first`` on, stop early when ``stop.requested`` (a signal; ``runtime.Interrupted``
    ends a frame mid-way), then flush the writer. Returns (simulation failure, output failure),
    each an exception or None; the writer is closed either way."""
    from engine import runtime
    from engine.render.output import OutputError
    from engine.scene import DivergenceError

    failure = out_failure = None
    try:
        for k in range(total):
            if stop is not None and stop.requested:
                break
            scene.advance_frame()  # raises runtime.Interrupted mid-frame on a signal
            if k >= first:  # --resume: frames before `first` are on disk already
                writer.submit(k, scene.render())
            if bar is not None:
                bar.advance(note=f"live {scene.stats.alive:,}")
    except runtime.Interrupted:
        pass  # stop.requested says so
    except DivergenceError as e:
        failure = e
    except OutputError as e:
        out_failure = e
    stopped = stop is not None and stop.requested
    try:
        writer.close(finished=failure is None and out_failure is None and not stopped)
    except OutputError as e:
        out_failure = out_failure or e
    return failure, out_failure


def cmd_run(args) -> int:
    """``particles run``: checks (flags, config, MP4 sizes, output folder, budgets) before any
    work, then simulates every frame and renders from the first one not on disk."""
    from engine.render.output import default_workers

    flags.check(args, flags.RUN_FLAGS)
    if not getattr(args, "format", None):
        args.format = "png"
    cfg = load_scene_config(args.config, args)
    _even_for_mp4(cfg, args)
    out_dir = output_dir(cfg, args)
    workers = getattr(args, "workers", None) or default_workers()
    check_budget(cfg, args, workers)
    total = cfg.frame_count
    first, lock = _open_output(cfg, args, out_dir)
    try:
        return _run(cfg, args, out_dir, workers, total, first)
    finally:
        if lock is not None:
            lock.release()


def _run(cfg, args, out_dir, workers, total, first) -> int:
    from engine.render.output import FrameWriter
    from engine.scene import Scene
    from .progress import progress
    from .signals import stopping

    if first >= total:
        print(f"{cfg.name}: nothing to resume: {out_dir} already holds {first} whole frame(s) of "
              f"{total}")
        return 0
    t_start = time.perf_counter()
    scene = Scene(cfg)
    t_built = time.perf_counter()
    writer = FrameWriter(out_dir, args.format, cfg.fps, cfg.name, workers=workers)
    with stopping(raise_now=False) as stop:
        with progress(total, unit="frames", label=cfg.name, quiet=getattr(args, "quiet", False)) as bar:
            # the first frame compiles every kernel of the scene (~10 s cold; ~1 s from the cache)
            bar.update(0, note=COMPILING)
            failure, out_failure = render_frames(scene, writer, first, total, stop, bar)
    wall = time.perf_counter() - t_start
    st = scene.stats
    done = first + len(writer.written) if args.format == "png" else 0
    kept = f"frames 0..{done - 1} kept in {out_dir}" if done else f"no frames kept in {out_dir}"
    if out_failure is not None:
        raise OutputFailure(f"{out_failure} ({kept})")
    if failure is not None:
        raise SimulationError(f"{failure} ({kept})")
    if stop.requested:
        raise Stopped(f"stopped by {stop.name} after {done} of {total} frames ({kept}); "
                      f"continue with --resume", stop.signum)
    sim_fps = (total - first) / max(time.perf_counter() - t_built, 1e-9)
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
          + f"; {wall:.2f} s wall ({sim_fps:.1f} frames/s rendered after {t_built - t_start:.2f} s build)")
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

    from . import shipped_configs

    root = args.dir
    if root is None:  # ./configs (a checkout), else the configs shipped with the engine
        root = "configs" if os.path.isdir("configs") else shipped_configs()
        if root is None:
            raise UserError(f"--dir: no configs/ folder in {os.getcwd()} and none shipped with this "
                            f"install; pass --dir FOLDER")
    if not os.path.isdir(root):
        raise UserError(f"--dir: {root!r} is not a folder")
    print(f"configs in {root}/:" + ("" if root == "configs" else "  (run one: particles run "
                                     f"{os.path.join(root, '<name>.toml')})"))
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
