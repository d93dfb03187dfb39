"""The bouncing-ball chart (issue 14): the dropped ball of :mod:`particles_tools.bounce` on a plane
and off a sphere, with and without drag — position error at t = 2 s against the closed form or
scipy's DOP853 with events, over f-evaluations, for

* impacts located in time, RK4 at fixed h (engine.ode.solve, f64): order ≥ 3 (5 on the plane
  with drag), rounding without drag (RK4 and the Hermite are exact on parabolas);
* impacts located, adaptive RK4 with local extrapolation over tol = rtol = atol (f64);
* impacts located and projected in a particle scene (float32, RK4 at fixed h): what a scene gets —
  projected impacts are first order (the bounce, not the integrator, sets the error), located
  ones reach float32 rounding at frame-sized steps.

Zero errors (exact to rounding) are drawn at 1e-16.
"""
import time

from engine.ode import METHODS
from .. import bounce

FIELDS = ["problem", "method", "mode", "h_or_tol", "nfev", "wall_s", "error"]
CASES = [(scene, drag) for scene in ("plane", "sphere") for drag in (False, True)]
FLOOR = 1e-16


def case_name(scene: str, drag: bool) -> str:
    return ("ball on a plane" if scene == "plane" else "ball off a sphere, onto a plane") + (
        ", drag 0.5/s" if drag else "")


def bounce_rows(quick: bool = False):
    ns = (60, 240) if quick else (30, 60, 120, 240, 480, 960)
    tols = (1e-3, 1e-7) if quick else tuple(10.0 ** -k for k in range(3, 11))
    scene_h = (1 / 60,) if quick else (1 / 60, 1 / 120, 1 / 240, 1 / 480, 1 / 960)
    rk4 = METHODS["rk4"]
    rows = []

    def add(scene, drag, method, mode, knob, nfev, wall, err):
        rows.append(dict(problem=case_name(scene, drag),
                         method=method, mode=mode, h_or_tol=knob, nfev=int(nfev), wall_s=wall,
                         error=max(err, FLOOR)))

    for scene, drag in CASES:
        for n in ns:
            t0 = time.perf_counter()
            r = bounce.run(scene, drag, h=bounce.T_END / n)
            add(scene, drag, "rk4 located (f64)", "fixed", bounce.T_END / n, r.nfev, time.perf_counter() - t0,
                bounce.position_error(r, scene, drag))
        for tol in tols:
            t0 = time.perf_counter()
            r = bounce.run(scene, drag, tol=tol)
            add(scene, drag, "rk4+extrap located (f64)", "adaptive", tol, r.nfev, time.perf_counter() - t0,
                bounce.position_error(r, scene, drag))
        for impacts in ("located", "projected"):
            for h in scene_h:
                t0 = time.perf_counter()
                err, steps = bounce.scene_error(scene, drag, {"integrator": "rk4", "h": h, "impacts": impacts})
                add(scene, drag, f"rk4 {impacts} (scene, f32)", "fixed", h, steps * rk4.fevals,
                    time.perf_counter() - t0, err)
    return rows


STYLE = {"rk4 located (f64)": dict(color="tab:blue", ls="-", marker="o"),
         "rk4+extrap located (f64)": dict(color="tab:cyan", ls="--", marker="s"),
         "rk4 located (scene, f32)": dict(color="tab:green", ls="-", marker="D"),
         "rk4 projected (scene, f32)": dict(color="tab:red", ls="-", marker="v")}


def bounce_png(path, rows) -> str:
    from .plot import _save, require_matplotlib

    plt = require_matplotlib()
    problems = list(dict.fromkeys(r["problem"] for r in rows))
    fig, axes = plt.subplots(2, 2, figsize=(13, 10), sharex=True, sharey=True)
    for ax, prob in zip(axes.flat, problems):
        for method, style in STYLE.items():
            rs = sorted((r for r in rows if r["problem"] == prob and r["method"] == method), key=lambda r: r["nfev"])
            if rs:
                ax.plot([r["nfev"] for r in rs], [r["error"] for r in rs], ms=4, label=method, **style)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(prob)
        ax.grid(True, which="major", alpha=0.4)
        ax.axhline(1e-4, color="0.5", lw=0.8, ls=":")
    for ax in axes[1]:
        ax.set_xlabel("work: f-evaluations over 2 s")
    for ax in axes[:, 0]:
        ax.set_ylabel("position error at t = 2 s [m]")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Dropped ball, e = 0.8 (drag 0.5/s): impacts located in time vs projected after the step; "
                 "dotted: the 1e-4 m target")
    fig.tight_layout()
    return _save(fig, path)
