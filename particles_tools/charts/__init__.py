"""``particles chart``: accuracy against cost, stability limits and energy drift, as PNG + CSV.

:func:`run_charts` writes, under ``out_dir``:

* ``workprec_<problem>.csv/.png`` — work–precision diagrams (error at T against f-evaluations and
  wall time) for projectile_drag, damped_spring, lotka-volterra and kepler;
* ``stability.csv/.png`` — largest stable h against spring stiffness, measured and predicted;
* ``energy_drift.csv/.png`` — relative energy error over a long fixed-step run;
* ``bounce.csv/.png`` — the dropped ball's error with impacts located in time and projected;
* ``soft_energy_drift.csv/.png`` — the same for a neo-Hookean solid and a bending cloth (issue 24):
  Euler against symplectic Euler and Verlet at one h;
* ``fluid.csv/.png`` — the density error (compression) position-based fluids leave in a dam break
  and a settling tank, against Jacobi iterations a step, the step h and the work (issue 23).

Needs the ``chart`` extra (matplotlib, scipy): ``pip install -e ".[chart]"``.
"""
import argparse
import os
import sys
from typing import Iterable, List, Optional, Union

CHARTS = ("workprec", "stability", "energy", "scenes", "bounce", "soft_energy", "fluid")
# NUMERICS.md's work–precision figures, drawn over the matching charts as × markers
_NUMERICS_REFS = {
    "lotka-volterra": [
        ("NUMERICS.md: RK4 doubling+extrap", "tab:cyan",
         [(571, 1.4e-4), (1169, 1.4e-6), (2757, 1.7e-8), (10888, 1.4e-11)]),
        ("NUMERICS.md: scipy RK45", "0.45", [(194, 2.3e-2), (446, 2.2e-4), (932, 1.1e-6), (3344, 1.5e-10)]),
        ("NUMERICS.md: scipy DOP853", "black", [(326, 7.1e-4), (518, 1.8e-5), (830, 2.6e-7), (1658, 1.1e-10)]),
    ],
    "kepler": [
        ("NUMERICS.md: RK4 step doubling", "tab:blue", [(2840, 1e-5)]),
        ("NUMERICS.md: RK4 fixed h", "tab:blue", [(64000, 3.7e-6)]),
    ],
}


def selection(which, key: str = "which") -> List[str]:
    """The chart names ``which`` stands for (None: all); ValueError naming ``key`` otherwise."""
    from .workprec import CASES

    allowed = list(CHARTS) + list(CASES)
    if which is None:
        return allowed[: len(CHARTS)]
    names = [which] if isinstance(which, str) else list(which)
    bad = [n for n in names if n not in allowed]
    if bad:
        raise ValueError(f"{key}: unknown chart {bad[0]!r}; allowed: {', '.join(allowed)}")
    return names


def run_charts(out_dir: Union[str, os.PathLike], quick: bool = False,
               which: Optional[Union[str, Iterable[str]]] = None, quiet: bool = True) -> List[str]:
    """Compute and write the charts; return the paths written (CSV and PNG).

    which: None for all, or names among ``workprec``, ``stability``, ``energy``, ``scenes``,
    ``bounce``, ``soft_energy``, ``fluid`` and the work–precision problem names (``kepler`` …) for one problem's diagram only.
    quick: coarser sweeps and shorter runs, for tests: 330 s on two cores with an empty kernel
    cache, most of it compiling (2026-11-28; the sparks scene 76 s, bounce 65 s, soft-body
    energy 40 s, cloth 35 s; the sparks scene 24 s and bounce 27 s warm).
    quiet: no progress display (it is drawn only on a terminal anyway).
    Every file is written under a temporary name and renamed when whole.
    """
    from ..progress import progress
    from . import plot
    from .workprec import require_scipy

    plot.require_matplotlib()
    require_scipy()
    names = selection(which)
    os.makedirs(out_dir, exist_ok=True)
    labels = [label for label, _job in _jobs(names, out_dir, quick)]
    written: List[str] = []
    with progress(len(labels), unit="charts", label="particles chart", quiet=quiet) as bar:
        for k, label in enumerate(labels):
            bar.advance(0, note=label)
            written += _run_child(k, label, names, out_dir, quick)
            bar.advance(note=label)
    return written


class ChartFailed(RuntimeError):
    """A chart's child process failed (a crash, a signal, an error): one line naming the chart."""


def _run_child(k, label, names, out_dir, quick) -> List[str]:
    """Run job ``k`` in a child process and return the paths it wrote. Each chart builds many
    scenes and Taichi's CPU backend holds at most 512 field trees per process (engine.runtime):
    a fresh process per chart never reaches that, and a crash in one (a segmentation fault) is
    reported in one line instead of killing the command without a word."""
    import signal
    import subprocess

    cmd = [sys.executable, "-m", "particles_tools.charts", "--out", os.fspath(out_dir), "--job", str(k)]
    cmd += [a for n in names for a in ("--only", n)] + (["--quick"] if quick else [])
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if r.returncode != 0:
        if r.returncode < 0:
            try:
                why = f"crashed ({signal.Signals(-r.returncode).name})"
            except ValueError:
                why = f"crashed (signal {-r.returncode})"
        else:
            last = [ln for ln in r.stderr.strip().splitlines() if ln.strip()]
            why = f"failed: {last[-1].strip()}" if last else f"failed (exit {r.returncode})"
        raise ChartFailed(f"the {label} chart {why}; the charts before it are written")
    return [ln for ln in r.stdout.splitlines() if ln.strip()]


def _chart(out_dir, stem, rows, fields, draw):
    """Write ``rows`` to ``<stem>.csv`` (``fields``, or the first row's keys) and draw
    ``<stem>.png`` with ``draw(path, rows)``; the two paths written."""
    from . import plot

    base = os.path.join(out_dir, stem)
    return [plot.write_csv(base + ".csv", rows, fields if fields is not None else list(rows[0])),
            draw(base + ".png", rows)]


def _jobs(names, out_dir, quick):
    """(label, job) per chart: each job computes its rows and returns the files it wrote."""
    from . import plot
    from .workprec import CASES, FIELDS, T_LABEL, work_precision

    jobs = []

    def workprec_job(name):
        def job():
            T = T_LABEL.get(name, f"T = {CASES[name].problem.t_span[1]:g}")
            title = (f"Work–precision, {name} ({T}): fixed h for every method, step doubling over "
                     f"tol = rtol (atol = tol·1e-3), scipy solve_ivp as anchor")
            return _chart(out_dir, f"workprec_{name}", work_precision(name, quick=quick), FIELDS,
                          lambda png, rows: plot.work_precision_png(png, rows, title,
                                                                    _NUMERICS_REFS.get(name, ())))
        return job

    for name in CASES:
        if "workprec" in names or name in names:
            jobs.append((f"work-precision {name}", workprec_job(name)))
    if "soft_energy" in names:
        def soft_energy_job():
            from .soft_energy import H, TITLES, soft_energy_drift

            return _chart(out_dir, "soft_energy_drift", soft_energy_drift(quick=quick), None,
                          lambda png, rows: plot.energy_png(png, rows, H, TITLES))
        jobs.append(("soft-body energy drift", soft_energy_job))
    if "scenes" in names:
        from .scenes import cloth_rows, sparks_rows

        def scene_job(name, fn, what):
            def job():
                title = (f"Work–precision on a real scene: {what}; error against the same scene "
                         f"at a much smaller h (RK4)")
                return _chart(out_dir, f"workprec_scene_{name}", fn(quick=quick), FIELDS,
                              lambda png, rows: plot.work_precision_png(png, rows, title))
            return job

        jobs.append(("scene sparks", scene_job("sparks", sparks_rows,
                                               "sparks fountain, T = 1 s, colliders")))
        jobs.append(("scene cloth", scene_job("cloth", cloth_rows,
                                              "16×16 cloth pinned at two corners, T = 1 s")))
    if "bounce" in names:
        def bounce_job():
            from .bounce import FIELDS as BFIELDS
            from .bounce import bounce_png, bounce_rows

            return _chart(out_dir, "bounce", bounce_rows(quick=quick), BFIELDS, bounce_png)
        jobs.append(("bounce", bounce_job))
    if "fluid" in names:
        def fluid_job():
            from .fluid import FIELDS as FFIELDS
            from .fluid import fluid_png, fluid_rows

            return _chart(out_dir, "fluid", fluid_rows(quick=quick), FFIELDS, fluid_png)
        jobs.append(("fluid", fluid_job))
    if "stability" in names:
        def stability_job():
            from .stability import NUMERICS_TABLE, stability_rows

            return _chart(out_dir, "stability", stability_rows(quick=quick), None,
                          lambda png, rows: plot.stability_png(png, rows, NUMERICS_TABLE))
        jobs.append(("stability", stability_job))
    if "energy" in names:
        def energy_job():
            from .energy import H, TITLES, energy_drift

            return _chart(out_dir, "energy_drift", energy_drift(quick=quick), None,
                          lambda png, rows: plot.energy_png(png, rows, H, TITLES))
        jobs.append(("energy drift", energy_job))
    return jobs


def main(argv=None) -> int:
    """Manual runs: ``python -m particles_tools.charts [--out DIR] [--quick] [--only NAME]``."""
    ap = argparse.ArgumentParser(prog="python -m particles_tools.charts", description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=os.path.join("renders", "charts"))
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", action="append", default=None, metavar="NAME")
    ap.add_argument("--job", type=int, default=None, help=argparse.SUPPRESS)  # one chart, in this process
    args = ap.parse_args(argv)
    try:
        if args.job is not None:
            from engine.runtime import ensure_init

            ensure_init()  # a chart's child process: some jobs allocate fields before any scene does
            for p in _jobs(selection(args.only), args.out, args.quick)[args.job][1]():
                print(p)
            return 0
        for p in run_charts(args.out, quick=args.quick, which=args.only):
            print(p)
    except (ValueError, ImportError, ChartFailed) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


__all__ = ["run_charts", "selection", "main", "CHARTS", "ChartFailed"]
