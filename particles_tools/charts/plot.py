"""Matplotlib (Agg) figures and CSV writing for the charts. matplotlib is imported lazily."""
import csv
import math
from typing import Dict, List, Sequence

import numpy as np

from engine.render.output import replacing

COLORS = {"euler": "tab:red", "midpoint": "tab:orange", "rk4": "tab:blue",
          "rk4+extrap": "tab:cyan", "symplectic_euler": "tab:green", "verlet": "tab:purple",
          "scipy RK45": "0.45", "scipy DOP853": "black", "rk4 projected": "tab:brown",
          "mujoco rk4": "tab:pink"}
MODE_STYLE = {"fixed": dict(ls="-", marker="o", ms=4), "adaptive": dict(ls="--", marker="s", ms=4),
              "scipy": dict(ls=":", marker="^", ms=5), "mujoco": dict(ls="-.", marker="D", ms=5)}


def require_matplotlib():
    try:
        import matplotlib
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError('charts need matplotlib and scipy: pip install -e ".[chart]"') from e
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def write_csv(path, rows: List[dict], fields: Sequence[str]) -> str:
    with replacing(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(fields), extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6e}" if isinstance(v, float) else v) for k, v in r.items()})
    return str(path)


def _save(fig, path) -> str:
    """Write the figure as PNG under a temporary name, renamed when whole; close it."""
    import matplotlib.pyplot as plt

    with replacing(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return str(path)


def _curves(rows):
    out: Dict[tuple, list] = {}
    for r in rows:
        if math.isfinite(r["error"]) and r["error"] > 0:
            out.setdefault((r["mode"], r["method"]), []).append(r)
    return out


def work_precision_png(path, rows: List[dict], title: str, refs=()) -> str:
    """Two panels sharing the error axis: work as f-evaluations, and as wall time.
    ``refs``: (label, color, [(nfev, error), ...]) points quoted in NUMERICS.md, drawn as ×."""
    plt = require_matplotlib()
    fig, axes = plt.subplots(1, 2, figsize=(14, 6), sharey=True)
    order = {"fixed": 0, "adaptive": 1, "scipy": 2, "mujoco": 3}
    for (mode, method), rs in sorted(_curves(rows).items(), key=lambda kv: order[kv[0][0]]):
        rs = sorted(rs, key=lambda r: r["nfev"])
        label = f"{method} ({'fixed h' if mode in ('fixed', 'mujoco') else 'tol sweep'})"
        for ax, key in zip(axes, ("nfev", "wall_s")):
            ax.plot([r[key] for r in rs], [r["error"] for r in rs], color=COLORS[method],
                    label=label, **MODE_STYLE[mode])
    for label, color, pts in refs:
        n, e = zip(*pts)
        axes[0].plot(n, e, ls="none", marker="X", ms=11, mec="black", mew=0.8, color=color,
                     label=label)
    for ax, xl in zip(axes, ("work: f-evaluations", "work: wall time [s], best of ≤3 warm calls\n"
                                           "(fixed h: one kernel; step doubling: one launch per "
                                           "attempt; scipy: pure Python)")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(xl)
        ax.grid(True, which="major", alpha=0.4)
        ax.grid(True, which="minor", alpha=0.12)
    axes[0].set_ylabel("max-norm error of y(T)")
    ymax = max(r["error"] for r in rows if math.isfinite(r["error"]))
    axes[0].set_ylim(top=min(ymax * 3, 1e2))
    fig.suptitle(title + "\nlower left is better: less error for less work", fontsize=12)
    h, lab = axes[0].get_legend_handles_labels()
    fig.legend(h, lab, loc="center right", fontsize=8.5, frameon=True)
    fig.tight_layout(rect=(0, 0, 0.82, 1))
    return _save(fig, path)


def stability_png(path, rows: List[dict], table: dict) -> str:
    """One panel per kd: measured largest stable h (markers) and linear theory (lines)."""
    from engine.ode.stability import theory_limit

    plt = require_matplotlib()
    kds = sorted({r["kd"] for r in rows})
    methods = list(dict.fromkeys(r["method"] for r in rows))
    markers = {"euler": "o", "midpoint": "v", "rk4": "s", "symplectic_euler": "D", "verlet": "^"}
    fig, axes = plt.subplots(1, len(kds), figsize=(5.2 * len(kds) + 2, 5.6), sharey=True)
    for ax, kd in zip(np.atleast_1d(axes), kds):
        for m in methods:
            rs = sorted((r for r in rows if r["kd"] == kd and r["method"] == m), key=lambda r: r["ks"])
            ks = np.array([r["ks"] for r in rs])
            dense = np.logspace(np.log10(ks.min()), np.log10(ks.max()), 41)
            th = np.array([theory_limit(m, k, kd) for k in dense])
            if np.all(th > 0):
                ax.plot(dense, th, color=COLORS[m], lw=1.6, alpha=0.75)
            ax.plot(ks, [r["h_measured"] for r in rs], ls="none", marker=markers[m], mfc="none",
                    mew=1.4, ms=8 if m in ("verlet", "midpoint") else 6, color=COLORS[m], label=m)
        if kd in table:
            hs = list(table[kd].values())
            ax.plot([100.0] * len(hs), hs, ls="none", marker="+", ms=14, mew=1.5, color="black",
                    label="NUMERICS.md table")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("spring stiffness ks (m = 1)")
        ax.set_title("undamped, kd = 0\n(Euler, midpoint: no stable h; markers = energy +0.1% in the run)"
                     if kd == 0 else f"kd = {kd:g}" + (" (overdamped for ks < kd²/4)" if kd > 2 else ""),
                     fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("largest stable step h")
    steps = rows[0]["steps"]
    fig.suptitle("Largest stable h on a damped spring on an anchor. Markers: measured (energy bounded "
                 f"over {steps:,} steps, bisection);\nlines: linear theory (spectral radius of the "
                 "step matrix: Euler kd/ks, symplectic Euler h²ω²+2hc<4, RK4 |R(hλ)|≤1, 2/ω).",
                 fontsize=10.5)
    h, lab = np.atleast_1d(axes)[0].get_legend_handles_labels()
    for ax in np.atleast_1d(axes)[1:]:
        for hh, ll in zip(*ax.get_legend_handles_labels()):
            if ll not in lab:
                h.append(hh)
                lab.append(ll)
    fig.legend(h, lab, loc="lower center", ncol=len(lab), fontsize=9.5)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    return _save(fig, path)


def energy_png(path, rows: List[dict], h: float, titles=None) -> str:
    """One panel per system: |E − E0| / E0 against time, log scale."""
    plt = require_matplotlib()
    systems = list(dict.fromkeys(r["system"] for r in rows))
    fig, axes = plt.subplots(1, len(systems), figsize=(7 * len(systems), 5.6), sharey=True)
    for ax, s in zip(np.atleast_1d(axes), systems):
        for m in dict.fromkeys(r["method"] for r in rows):
            rs = [r for r in rows if r["system"] == s and r["method"] == m]
            e = np.array([r["rel_error"] for r in rs])
            ax.plot([r["t"] for r in rs], np.maximum(e, 1e-17), color=COLORS[m], lw=1.1, label=m)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(f"time t (log scale; {rows[-1]['step']:,} steps of h = 1/{round(1 / h)})")
        ax.set_title((titles or {}).get(s, s))
        ax.grid(True, which="major", alpha=0.35)
    np.atleast_1d(axes)[-1].legend(fontsize=9.5, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    np.atleast_1d(axes)[0].set_ylabel("relative energy error |E − E₀| / E₀")
    fig.suptitle("Energy drift with fixed steps (undamped): Euler's energy grows exponentially, "
                 "midpoint's slowly, RK4's decays slowly;\nsymplectic Euler's and Verlet's error "
                 "stays bounded (a straight rising line here is error ∝ t)", fontsize=11)
    fig.tight_layout()
    return _save(fig, path)
