"""``particles bench``: the engine's costs measured side by side in one process run.

Sections (``--only`` takes their names): ``step`` (the particle step against NumPy and the
bandwidth limit), ``frame`` (a full 1M-particle frame), ``effects`` (every shipped config as a game
runs it, and an empty scene's fixed frame cost), ``ode`` (adaptive RK4 against scipy's
RK45 at equal error), ``startup`` (cold and warm ``particles run``), ``features`` (the cost of each
optional feature and proof that an unused one compiles nothing), ``cloth`` (when
``engine.springs`` exists), ``output`` (``particles run``'s frame rate against sim + render),
``wedge`` (``particles wedge`` on local Dask workers against the same variants run one after
another), ``api`` (the game API's level restart, memory over build/discard cycles, add_emitter, a
new render size, the cost of its argument checks), ``interact`` (the neighbour grid and a
granular sweep per 100k particles against numba, and the sand, water and galaxy configs at
1280×720), ``rigid`` (1,000 boxes into piles on the XPBD
path, 10,000 free bodies with RK4 on the ODE path), ``energy`` (a neo-Hookean solid's forces by the
closed form against autodiff on the same tetrahedra, and configs/jelly_solid.toml per frame). ``quick`` uses small sizes so CI can run it in
seconds.
"""
from __future__ import annotations

import importlib
import sys
import time

from .common import Row, format_table

SECTIONS = ("step", "frame", "effects", "ode", "startup", "features", "cloth", "output", "wedge",
            "api", "interact", "rigid", "energy")
_MODULES = {"step": "step", "frame": "frame", "effects": "effects", "ode": "ode_vs_scipy",
            "startup": "startup", "features": "features", "cloth": "cloth", "output": "output",
            "wedge": "wedge", "api": "api", "interact": "interact", "rigid": "rigid", "energy": "energy"}


def run(quick: bool = False, only=None, echo=None, quiet: bool = True):
    """Run the sections (all, or those named in ``only``) and return their rows in order.
    ``echo(text)`` is called with each section's rows as it finishes; a progress display over
    the sections is drawn on a terminal unless ``quiet``."""
    from engine import runtime
    from ..progress import progress

    runtime.ensure_init()
    names = list(SECTIONS) if not only else list(only)
    unknown = [n for n in names if n not in SECTIONS]
    if unknown:
        raise ValueError(f"--only: unknown section(s) {', '.join(unknown)}; allowed: {', '.join(SECTIONS)}")
    rows = []
    with progress(len(names), unit="sections", label="particles bench", quiet=quiet) as bar:
        for name in names:
            bar.advance(0, note=name)
            mod = importlib.import_module(f".{_MODULES[name]}", __name__)
            t0 = time.perf_counter()
            got = mod.run(quick=quick)
            rows += got
            if echo is not None:
                echo(format_table(got) + f"\n  ({name}: {time.perf_counter() - t0:.1f} s)")
            bar.advance(note=name)
    return rows


def header() -> str:
    import os
    import platform

    cpu = "?"
    try:
        with open("/proc/cpuinfo") as fh:
            cpu = next(line.split(":", 1)[1].strip() for line in fh if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    import taichi as ti

    from engine import runtime

    # (the CPU pool's workers held one to a core, or not: engine.affinity)
    pinned = len(runtime.pinned())
    return (f"# particles bench  {time.strftime('%Y-%m-%d %H:%M %Z')}  nproc={os.cpu_count()}  "
            f"cpu={cpu}  python={platform.python_version()}  taichi={'.'.join(map(str, ti.__version__))}  "
            f"workers pinned={pinned}")


def main(quick: bool = False, only=None, quiet: bool = False) -> int:
    print(header(), flush=True)
    rows = run(quick=quick, only=only, echo=lambda s: print(s, flush=True), quiet=quiet)
    bad = [r for r in rows if not r.finite_positive]
    if bad:
        print("non-finite or non-positive figures: " + ", ".join(r.name for r in bad), file=sys.stderr)
        return 1
    return 0


__all__ = ["Row", "SECTIONS", "run", "main", "format_table"]
