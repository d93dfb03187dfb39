"""The ``particles`` command line. Exit codes: 0 ok, 2 bad input, 3 simulation failure,
4 output failure (folder cannot be created or written, disk full), 128 + signal number when
stopped by SIGINT (130) or SIGTERM (143)."""
from __future__ import annotations

import argparse
import os
import sys

from .errors import EXIT_OK, SimulationError, UserError
from .wedge import add_parser as add_wedge_parser


def _cmd_ode(args) -> int:
    import numpy as np

    from ..ode import METHODS, solve
    from .problems import PROBLEMS

    if args.problem not in PROBLEMS:
        raise UserError(f"problem: unknown value {args.problem!r}; allowed: {', '.join(PROBLEMS)}")
    if args.method not in METHODS:
        raise UserError(f"--method: unknown value {args.method!r}; allowed: {', '.join(METHODS)}")
    p = PROBLEMS[args.problem]
    if METHODS[args.method].partitioned and len(p.y0) % 2:
        raise UserError(f"--method: {args.method} needs a second-order (q, p) problem; "
                        f"{p.name} is first order")
    t1 = args.t_end if args.t_end is not None else p.t_span[1]
    t_eval = np.linspace(p.t_span[0], t1, args.points + 1)
    r = solve(p.f, p.y0, (p.t_span[0], t1), method=args.method, h=args.h, tol=args.tol,
              t_eval=t_eval)
    names = [f"y{k}" for k in range(len(p.y0))]
    print("t," + ",".join(names))
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


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="particles", description=__doc__)
    ap.add_argument("--arch", default="cpu", choices=["cpu", "cuda", "vulkan", "metal", "gpu"],
                    help="Taichi backend (default cpu)")
    ap.add_argument("--threads", type=int, default=None,
                    help="CPU threads for Taichi kernels (default: all cores); frames do not depend on it")
    sub = ap.add_subparsers(dest="command", required=True)

    o = sub.add_parser("ode", help="solve a reference ODE and print t, y as CSV")
    o.add_argument("problem", help="lotka-volterra, growth, decay, oscillator, projectile_drag, kepler")
    o.add_argument("--method", default="rk4")
    o.add_argument("--h", type=float, default=0.01, help="fixed step, or first step with --tol")
    o.add_argument("--tol", type=float, default=None, help="adapt h by step doubling")
    o.add_argument("--t-end", type=float, default=None)
    o.add_argument("--points", type=int, default=20, help="output intervals")
    o.set_defaults(func=_cmd_ode)

    r = sub.add_parser("run", help="simulate a config and render its frames off-screen")
    r.add_argument("config")
    r.add_argument("--frames", type=int, default=None, help="render this many frames")
    r.add_argument("--out", default=None, help="output folder (default renders/<config name>)")
    r.add_argument("--format", default="png", choices=["png", "gif", "mp4"])
    r.add_argument("--size", default=None, help="image size WxH, e.g. 1280x720")
    r.add_argument("--seed", type=int, default=None)
    r.add_argument("--integrator", default=None,
                   help="euler, midpoint, rk4, symplectic_euler or verlet")
    r.add_argument("--overwrite", action="store_true", help="replace frames already in --out")
    r.add_argument("--resume", action="store_true",
                   help="continue an interrupted PNG run from its last whole frame")
    r.add_argument("--threads", type=int, default=argparse.SUPPRESS,
                   help="CPU threads for Taichi kernels (as before the command)")
    r.add_argument("--arch", default=argparse.SUPPRESS, choices=["cpu", "cuda", "vulkan", "metal", "gpu"],
                   help="Taichi backend (as before the command)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=lambda a: _commands().cmd_run(a))

    v = sub.add_parser("validate", help="check configs: prints ok or one line per problem")
    v.add_argument("configs", nargs="+")
    v.set_defaults(func=lambda a: _commands().cmd_validate(a), no_taichi=True)

    ls = sub.add_parser("list", help="list the configs and effect presets")
    ls.add_argument("--dir", default="configs")
    ls.set_defaults(func=lambda a: _commands().cmd_list(a), no_taichi=True)

    b = sub.add_parser("bench", help="measure the engine side by side with NumPy, scipy, bandwidth")
    b.add_argument("--quick", action="store_true", help="small sizes (CI: well under a minute)")
    b.add_argument("--only", default=None,
                   help="comma-separated sections: step, frame, ode, startup, features, cloth, wedge")
    b.set_defaults(func=_cmd_bench)

    c = sub.add_parser("chart", help="work-precision, stability and energy-drift charts (PNG + CSV)")
    c.add_argument("--out", default=os.path.join("renders", "charts"))
    c.add_argument("--quick", action="store_true", help="coarse sweeps (under a minute)")
    c.add_argument("--only", default=None,
                   help="workprec, stability, energy, or one problem (kepler, lotka-volterra, ...)")
    c.set_defaults(func=_cmd_chart)

    w = sub.add_parser("view", help="play a config in a window (mouse orbits, space pauses)")
    w.add_argument("config")
    w.add_argument("--frames", type=int, default=None, help="close after this many frames")
    w.add_argument("--screenshot", default=None, help="save the last frame shown to this PNG")
    w.set_defaults(func=lambda a: __import__("engine.tools.viewer", fromlist=["x"]).cmd_view(a))

    add_wedge_parser(sub)

    g = sub.add_parser("gallery", help="regenerate the README's stills in renders/gallery/")
    g.add_argument("--out", default=os.path.join("renders", "gallery"))
    g.add_argument("--configs", default="configs")
    g.set_defaults(func=lambda a: __import__("engine.tools.gallery", fromlist=["x"]).cmd_gallery(a))
    return ap


def _cmd_chart(args) -> int:
    from .charts import run_charts

    try:
        paths = run_charts(args.out, quick=args.quick, which=args.only)
    except (ImportError, ValueError) as e:
        raise UserError(str(e)) from None
    for p in paths:
        print(p)
    return EXIT_OK


def _cmd_bench(args) -> int:
    from . import bench

    only = [s.strip() for s in args.only.split(",") if s.strip()] if args.only else None
    try:
        return bench.main(quick=args.quick, only=only)
    except ValueError as e:
        raise UserError(str(e)) from None


def _commands():
    from . import commands

    return commands


def main(argv=None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    try:
        if not getattr(args, "no_taichi", False):
            from .. import runtime

            if args.threads is not None and args.threads < 1:
                raise UserError(f"--threads: {args.threads} is not allowed: must be >= 1")
            runtime.init(getattr(args, "arch", "cpu"), threads=args.threads)
        return args.func(args)
    except UserError as e:
        for line in str(e).splitlines() or [e.__class__.__name__]:
            print(f"error: {line}", file=sys.stderr)
        return e.exit_code
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
