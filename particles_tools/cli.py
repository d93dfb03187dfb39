"""The ``particles`` command line. Exit codes (README has the table with what is left on disk):
0 ok, 2 bad input (config, flags, budgets, a backend that cannot start), 3 simulation failure,
4 output failure, 128 + signal number when stopped by SIGINT (130) or SIGTERM (143), 141 when
the reader of stdout went away (a pipe into ``head``)."""
from __future__ import annotations

import argparse
import os
import signal
import sys

from . import budget, flags
from .errors import EXIT_BROKEN_PIPE, EXIT_OK, SimulationError, UserError

ODE_MAX_STEPS = 10_000_000  # fixed steps run inside one kernel per output interval


def _cmd_ode(args) -> int:
    import numpy as np

    from engine.ode import METHODS, solve
    from .problems import PROBLEMS

    p = PROBLEMS[args.problem]
    if METHODS[args.method].partitioned and len(p.y0) % 2:
        raise UserError(f"--method: {args.method} needs a second-order (q, p) problem; "
                        f"{p.name} is first order")
    t0 = p.t_span[0]
    t1 = args.t_end if args.t_end is not None else p.t_span[1]
    if not t1 > t0:
        raise UserError(f"--t-end: {t1:g} is not allowed: must be after the start t={t0:g}")
    from engine.ode.driver import substeps

    steps = substeps(t1 - t0, args.h)
    if args.tol is None and steps > args.max_steps:
        raise UserError(f"--max-steps: --h {args.h:g} from t={t0:g} to {t1:g} is {steps:,} steps, "
                        f"over the limit of {args.max_steps:,}; raise --h or --max-steps")
    t_eval = np.linspace(t0, t1, args.points + 1)
    r = solve(p.f, p.y0, (t0, t1), method=args.method, h=args.h, tol=args.tol, t_eval=t_eval,
              max_steps=args.max_steps)
    print("t," + ",".join(p.labels))
    for k in range(r.y.shape[1]):
        print(f"{r.t[k]:.6f}," + ",".join(f"{v:.9g}" for v in r.y[:, k]))
    ref = None
    if r.success and t1 == p.t_span[1]:
        ref = np.abs(r.y[:, -1] - p.y_end()).max()
    print(f"# {args.method} {'tol=' + format(args.tol, 'g') if args.tol else 'h=' + format(args.h, 'g')}: "
          f"{r.nfev} f-evals, {r.n_accepted} accepted, {r.n_rejected} rejected steps"
          + (f", error at t={t1:g}: {ref:.3e}" if ref is not None else ""), file=sys.stderr)
    if not r.success:
        raise SimulationError(r.message)
    return EXIT_OK


ARCH_CHOICES = ("cpu", "cuda", "vulkan", "metal", "gpu", "auto")
PROBLEM_NAMES = ("growth", "decay", "oscillator", "projectile_drag", "damped_spring",
                 "lotka-volterra", "kepler", "kepler-0.6", "arenstorf", "tumbling")
T = flags.argtype
THREADS = flags.integer(1, 1024)


def _add_common(p, suppress: bool):
    """--arch and --threads, before the command (defaults) or after it (as before it)."""
    default = (lambda v: argparse.SUPPRESS) if suppress else (lambda v: v)
    p.add_argument("--arch", default=default("cpu"), type=T(flags.choice(*ARCH_CHOICES)),
                   metavar="{" + ",".join(ARCH_CHOICES) + "}",
                   help="Taichi backend (default cpu); one that cannot start is an error, "
                        "auto takes a GPU if one starts, else the CPU")
    p.add_argument("--threads", type=T(THREADS), default=default(None),
                   help="CPU threads for Taichi kernels (default: all cores); frames do not depend on it")


def build_parser(extra=()) -> argparse.ArgumentParser:
    """The command line's parser; ``extra``: functions adding subcommands (``particles wedge``,
    particles_tools.main), kept out of this module so the wedge's workers can run ``particles run``
    through :func:`main` without an import circle."""
    ap = flags.Parser(prog="particles", description=__doc__)
    _add_common(ap, suppress=False)
    sub = ap.add_subparsers(dest="command", required=True, parser_class=flags.Parser)

    o = sub.add_parser("ode", help="solve a reference ODE and print t and its variables as CSV")
    o.add_argument("problem", type=T(flags.choice(*PROBLEM_NAMES)), metavar="problem",
                   help=", ".join(PROBLEM_NAMES))
    o.add_argument("--method", default="rk4", type=T(flags.choice(*flags.INTEGRATORS)))
    o.add_argument("--h", type=T(flags.real(0.0, 1e3, lo_open=True)), default=0.01,
                   help="fixed step, or first step with --tol")
    o.add_argument("--tol", type=T(flags.real(0.0, 1.0, lo_open=True)), default=None,
                   help="adapt h by step doubling")
    o.add_argument("--t-end", type=T(flags.real(-1e6, 1e6)), default=None)
    o.add_argument("--points", type=T(flags.integer(1, 100_000)), default=20, help="output intervals")
    o.add_argument("--max-steps", type=T(flags.integer(1, 10**9)), default=ODE_MAX_STEPS,
                   help=f"refuse (fixed h) or stop (--tol) past this many steps (default {ODE_MAX_STEPS:,})")
    o.set_defaults(func=_cmd_ode)

    r = sub.add_parser("run", help="simulate a config and render its frames off-screen")
    r.add_argument("config")
    F = flags.RUN_FLAGS
    r.add_argument("--frames", type=T(F["frames"][1]), default=None, help="render this many frames")
    r.add_argument("--out", type=T(F["out"][1]), default=None,
                   help="output folder (default renders/<config name>)")
    r.add_argument("--format", default="png", type=T(F["format"][1]), metavar="{png,gif,mp4}")
    r.add_argument("--size", type=T(flags.keep_text(F["size"][1])), default=None,
                   help="image size WxH, e.g. 1280x720 (even sides for --format mp4)")
    r.add_argument("--seed", type=T(F["seed"][1]), default=None, help="random seed (0 to 2^32-1)")
    r.add_argument("--integrator", default=None, type=T(F["integrator"][1]),
                   metavar="{" + ",".join(flags.INTEGRATORS) + "}")
    r.add_argument("--overwrite", action="store_true", help="replace frames already in --out")
    r.add_argument("--resume", action="store_true",
                   help="continue an interrupted PNG run from its last whole frame")
    r.add_argument("--quiet", action="store_true", help="no progress display")
    r.add_argument("--max-memory", type=T(F["max_memory"][1]), default=budget.DEFAULT_MAX_MEMORY,
                   help="refuse a run estimated to need more memory (default 4GB)")
    r.add_argument("--max-steps", type=T(F["max_steps"][1]), default=budget.DEFAULT_MAX_STEPS,
                   help=f"refuse a run planning more integrator steps (default {budget.DEFAULT_MAX_STEPS:,})")
    r.add_argument("--max-work", type=T(F["max_work"][1]), default=budget.DEFAULT_MAX_WORK,
                   help=f"refuse a run planning more element-steps (default {budget.DEFAULT_MAX_WORK:.0e})")
    r.add_argument("--workers", type=T(F["workers"][1]), default=None,
                   help="PNG encoding threads (default: one per core, at least 2)")
    _add_common(r, suppress=True)
    r.set_defaults(func=lambda a: _commands().cmd_run(a))

    v = sub.add_parser("validate", help="check configs: prints ok or one line per problem")
    v.add_argument("configs", nargs="+")
    v.set_defaults(func=lambda a: _commands().cmd_validate(a), no_taichi=True)

    sc = sub.add_parser("schema", help="print the config schema as JSON Schema (for editors: Taplo, VS Code)")
    sc.add_argument("--out", default=None, type=T(flags.path), help="write it to this file instead")
    sc.set_defaults(func=_cmd_schema)

    ls = sub.add_parser("list", help="list the configs and effect presets")
    ls.add_argument("--dir", default=None, type=T(flags.path),
                    help="folder of configs (default: ./configs, else the configs shipped with the engine)")
    ls.set_defaults(func=lambda a: _commands().cmd_list(a), no_taichi=True)

    b = sub.add_parser("bench", help="measure the engine side by side with NumPy, scipy, bandwidth")
    b.add_argument("--quick", action="store_true", help="small sizes, for tests (figures that only show the code runs; most of the time goes to compiling)")
    from .bench import SECTIONS  # (standard library only: no Taichi at parse time)

    b.add_argument("--only", default=None, help="comma-separated sections: " + ", ".join(SECTIONS))
    b.add_argument("--quiet", action="store_true", help="no progress display")
    b.set_defaults(func=_cmd_bench)

    c = sub.add_parser("chart", help="work-precision, stability and energy-drift charts (PNG + CSV)")
    c.add_argument("--out", default=os.path.join("renders", "charts"), type=T(flags.path))
    c.add_argument("--quick", action="store_true", help="coarse sweeps (under a minute)")
    c.add_argument("--only", default=None,
                   help="workprec, stability, energy, scenes, bounce, soft_energy, fluid, or one problem (kepler, lotka-volterra, ...)")
    c.add_argument("--quiet", action="store_true", help="no progress display")
    c.set_defaults(func=_cmd_chart)

    w = sub.add_parser("view", help="play a config in a window (mouse orbits, space pauses)")
    w.add_argument("config")
    w.add_argument("--frames", type=T(flags.integer(1, 1_000_000)), default=None,
                   help="close after this many frames")
    w.add_argument("--screenshot", default=None, type=T(flags.path),
                   help="save the last frame shown to this PNG")
    w.set_defaults(func=lambda a: __import__("particles_tools.viewer", fromlist=["x"]).cmd_view(a))

    pr = sub.add_parser("profile", help="per-kernel milliseconds of a config's frames (game-style)")
    pr.add_argument("config")
    pr.add_argument("--size", default=(1280, 720), type=T(flags.size),
                    help="image size WxH (default 1280x720)")
    pr.add_argument("--frames", type=T(flags.integer(1, 10_000)), default=20)
    pr.set_defaults(func=_cmd_profile, kernel_profiler=True)

    for add in extra:
        add(sub)

    g = sub.add_parser("gallery", help="regenerate the README's stills in renders/gallery/")
    g.add_argument("--out", default=os.path.join("renders", "gallery"), type=T(flags.path))
    g.add_argument("--configs", default="configs", type=T(flags.path))
    g.add_argument("--quiet", action="store_true", help="no progress display")
    g.set_defaults(func=lambda a: __import__("particles_tools.gallery", fromlist=["x"]).cmd_gallery(a))
    return ap


def _cmd_schema(args) -> int:
    from engine.config.export import schema_text

    text = schema_text()
    if args.out is None:
        sys.stdout.write(text)
        return EXIT_OK
    tmp = f"{args.out}.tmp"
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, args.out)
    except OSError as e:
        raise UserError(f"--out: cannot write {args.out}: {e.strerror or e}") from None
    print(args.out)
    return EXIT_OK


def _cmd_chart(args) -> int:
    from .charts import ChartFailed, run_charts, selection
    from .charts.plot import require_matplotlib
    from .charts.workprec import require_scipy
    from .commands import output_folder

    try:
        which = selection(args.only, key="--only")
        require_matplotlib()
        require_scipy()
    except (ValueError, ImportError) as e:
        raise UserError(str(e)) from None
    output_folder(args.out)  # (after every refusal above: a refused call leaves no folder)
    try:
        paths = run_charts(args.out, quick=args.quick, which=which, quiet=args.quiet)
    except ImportError as e:
        raise UserError(str(e)) from None
    except ChartFailed as e:
        raise SimulationError(str(e)) from None
    for p in paths:
        print(p)
    return EXIT_OK


def _cmd_profile(args) -> int:
    from .commands import scene_from_file
    from .profile import profile

    print(profile(args.config, *args.size, args.frames, scene=scene_from_file(args.config)))
    return EXIT_OK


def _cmd_bench(args) -> int:
    from . import bench

    only = [s.strip() for s in args.only.split(",") if s.strip()] if args.only else None
    try:
        return bench.main(quick=args.quick, only=only, quiet=args.quiet)
    except ValueError as e:
        raise UserError(str(e)) from None


def _commands():
    from . import commands

    return commands


def main(argv=None, extra=()) -> int:
    """Run one command; returns its exit code (README: "Exit codes")."""
    try:
        return _main(argv, extra)
    except BrokenPipeError:
        # the reader of stdout went away (`particles list | head -3`): stop quietly, and keep
        # Python's flush at exit from raising again on the closed pipe
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return EXIT_BROKEN_PIPE


def _main(argv, extra=()) -> int:
    from .signals import StopRequest

    with StopRequest() as stop:
        try:
            args = build_parser(extra).parse_args(argv)
            if not getattr(args, "no_taichi", False):
                _init_taichi(args)
            return args.func(args)
        except UserError as e:
            _print_error(e)
            return e.exit_code
        except KeyboardInterrupt:
            signum = stop.signum or signal.SIGINT
            name = signal.Signals(signum).name
            _print_error(f"stopped by {name}; files already written are whole (each is written "
                         f"under a temporary name and renamed)")
            return 128 + signum


def _init_taichi(args) -> None:
    from engine import runtime

    try:  # "error": Taichi's warnings (offline-cache lock contention) stay off our stderr
        runtime.init(args.arch, threads=args.threads, log_level="error",
                     kernel_profiler=getattr(args, "kernel_profiler", False))
    except runtime.ArchUnavailable as e:
        raise UserError(f"--arch: {e}; use --arch cpu, or --arch auto to take a GPU where one "
                        f"starts and the CPU otherwise") from None
    except RuntimeError as e:  # called in a process whose Taichi already runs on another arch
        raise UserError(f"--arch: {e}") from None


def _print_error(e) -> None:
    for line in str(e).splitlines() or [e.__class__.__name__]:
        print(f"error: {line}", file=sys.stderr)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
