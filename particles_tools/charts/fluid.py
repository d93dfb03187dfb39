"""The fluid chart (issue 23): the density error position-based fluids (engine.particles.interact,
kind "fluid", Macklin & Müller 2013) leave, against Jacobi iterations a step and the step h.

Two small scenes in an open-top glass tank of five wall planes, particles of radius 0.015 m (rest
spacing s = 0.03 m) dropped as a seeded random block at the rest number density:

* ``dam``: a 0.2 × 0.4 × 0.2 m column (592 particles) let go at one end of a 0.6 × 0.2 m tank;
* ``tank``: a 0.3 × 0.2 × 0.3 m block (666 particles) filling a 0.3 × 0.3 m tank, settling.

Each runs T = 1.5 s at 30 frames/s for every (iterations, h). The density is measured in NumPy,
float64, from the positions the solver leaves at each frame: ρ_i = Σ_j W_poly6(|x_i − x_j|, 2s)
(self included), over ρ₀ = the kernel sum over a cubic lattice of spacing s — the solver's own
kernel, support and rest density (:func:`engine.particles.fluid.lattice_constants`). The error
is the compression max(ρ/ρ₀ − 1, 0) (surface particles are under-dense by construction; the solver's
constraint is clamped the same way), its mean and its max over the particles, averaged over the
frames of the last 0.5 s. Work: particle-iterations per simulated second, N · iterations / h.

A run whose mean compression over the window exceeds :data:`BLOWN_UP` (particles clumped: ρ above
twice ρ₀ on average, never a liquid's state; some are flung out of the open tank at km/s) has blown
up: drawn as ×. The largest particle speed in the window is kept too (``max_speed``): a few m/s in
runs that hold, from a particle thrown up a corner by the random start's overlaps and falling back.
"""
from __future__ import annotations

import math
import time
from typing import List

import numpy as np

RADIUS = 0.015  # m; rest spacing s = 2·radius, kernel support 2s (engine.particles.interact)
FPS = 30.0
T, WINDOW = 1.5, 0.5  # s: the run, and its end over which the error is averaged
ITERATIONS = (1, 2, 4, 8)
STEPS = (1 / 60, 1 / 120, 1 / 240)
QUICK_ITERATIONS, QUICK_STEPS, QUICK_T = (2, 8), (1 / 120,), 1.0
BLOWN_UP = 1.0  # mean compression: measured ≤ 0.013 in the runs that hold, ≥ 2.8 in the others
FLOOR = 1e-6  # compressions below this (none at all, or rounding) are drawn here
SEED = 1
# name: (tank half-widths (x, z), the block's centre and size), m
SCENES = {"dam": ((0.3, 0.1), (-0.2, 0.2, 0.0), (0.2, 0.4, 0.2)),
          "tank": ((0.15, 0.15), (0.0, 0.15, 0.0), (0.3, 0.2, 0.3))}
TITLES = {"dam": "dam break: 0.2 × 0.4 m column in a 0.6 × 0.2 m tank",
          "tank": "settling tank: 0.3 × 0.2 × 0.3 m block"}
FIELDS = ["scene", "n", "iterations", "h", "seconds", "steps_per_s", "work", "wall_s", "mean_compression",
          "max_compression", "max_speed", "blown_up"]


def count(scene: str) -> int:
    """Particles of ``scene``: its block's volume at the rest number density 1/s³."""
    return int(np.prod(SCENES[scene][2]) / (2 * RADIUS) ** 3)


def scene_config(scene: str, iterations: int, h: float, seconds: float = T) -> dict:
    """The config dict of ``scene`` (a key of :data:`SCENES`) with ``iterations`` sweeps, step h."""
    (X, Z), pos, box = SCENES[scene]
    walls = [{"type": "plane", "point": p, "normal": nrm, "restitution": 0.0}
             for p, nrm in (([0, 0, 0], [0, 1, 0]), ([-X, 0, 0], [1, 0, 0]), ([X, 0, 0], [-1, 0, 0]),
                            ([0, 0, -Z], [0, 0, 1]), ([0, 0, Z], [0, 0, -1]))]
    # impacts "projected": five planes' located-impact code takes long to compile, and the
    # interaction projects its particles onto the colliders after the solve either way
    return {"seed": SEED, "fps": FPS, "frames": round(seconds * FPS),
            "solver": {"integrator": "symplectic_euler", "h": h, "impacts": "projected"},
            "emitters": [{"shape": "box", "position": list(pos), "box_size": list(box),
                          "speed": [0.0, 0.0], "bursts": [{"time": 0.0, "count": count(scene)}],
                          "lifetime": 100.0,
                          "interact": {"kind": "fluid", "radius": RADIUS, "iterations": iterations}}],
            "colliders": walls}


def relative_density(x: np.ndarray, radius: float = RADIUS) -> np.ndarray:
    """ρ_i/ρ₀ for each of the points ``x`` (N, 3), in float64, with the fluid solver's kernel:
    poly6 of support 2s (s = 2·radius), m = 1, self included, ρ₀ its lattice sum at spacing s."""
    from engine.particles.fluid import lattice_constants, poly6

    s = 2.0 * radius
    hk = 2.0 * s
    rho0, _ = lattice_constants(s, hk)
    x = np.asarray(x, np.float64)
    rho = np.empty(len(x))
    for a in range(0, len(x), 512):  # (N × 512 pairs at a time)
        d2 = ((x[a:a + 512, None, :] - x[None, :, :]) ** 2).sum(-1)
        rho[a:a + 512] = np.where(d2 < hk * hk, (hk * hk - d2) ** 3, 0.0).sum(1)
    return rho * (poly6(0.0, hk) / hk ** 6) / rho0  # poly6(0, h) / h⁶: the kernel's constant


def compression(x: np.ndarray, radius: float = RADIUS):
    """(mean, max) over the points of max(ρ/ρ₀ − 1, 0)."""
    c = np.maximum(relative_density(x, radius) - 1.0, 0.0)
    return float(c.mean()), float(c.max())


def run_point(scene: str, iterations: int, h: float, seconds: float = T) -> dict:
    """One chart row: ``scene`` run ``seconds`` with ``iterations`` sweeps a step of h."""
    from engine.config.load import load_config
    from engine.runtime import reset
    from engine.scene import Scene

    from .scenes import _fresh_program_now_and_then

    _fresh_program_now_and_then(reset)
    sc = Scene(load_config(scene_config(scene, iterations, h, seconds)), render=False)
    frames, window = round(seconds * FPS), round(WINDOW * FPS)
    errs, speed, wall = [], 0.0, 0.0
    for f in range(frames):
        t0 = time.perf_counter()
        sc.advance_frame()
        wall += time.perf_counter() - t0
        if f >= frames - window:
            x, v = sc.positions(), sc.velocities().astype(np.float64)
            errs.append(compression(x))
            speed = max(speed, float(np.sqrt((v * v).sum(1)).max()) if len(v) else 0.0)
    mean, peak = np.mean(errs, axis=0) if errs else (math.nan, math.nan)
    n = len(sc.positions())
    return dict(scene=scene, n=n, iterations=iterations, h=h, seconds=seconds, steps_per_s=round(1 / h),
                work=n * iterations * round(1 / h), wall_s=wall, mean_compression=float(mean),
                max_compression=float(peak), max_speed=speed,
                blown_up=int(not mean <= BLOWN_UP))


def fluid_rows(quick: bool = False, scenes=tuple(SCENES)) -> List[dict]:
    """Rows (:data:`FIELDS`) for every scene, h and iterations (quick: the tank at h = 1/120 with
    2 and 8 iterations over 1 s). Wall time includes each scene's first-frame compile."""
    its, hs, seconds = (QUICK_ITERATIONS, QUICK_STEPS, QUICK_T) if quick else (ITERATIONS, STEPS, T)
    scenes = ("tank",) if quick else scenes
    return [run_point(sc, it, h, seconds) for sc in scenes for h in hs for it in its]


H_COLORS = {60: "tab:red", 120: "tab:blue", 240: "tab:green", 30: "tab:orange", 480: "tab:purple"}
SCENE_MARKERS = {"dam": "o", "tank": "s"}


def _floor(v):
    return max(v, FLOOR)


def fluid_png(path, rows) -> str:
    """One panel per scene, compression against iterations for each h (mean solid, max dashed),
    and a panel of mean compression against work for all of them; blown-up runs as ×."""
    from .plot import _save, require_matplotlib

    plt = require_matplotlib()
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    fig, axes = plt.subplots(1, len(scenes) + 1, figsize=(5.6 * (len(scenes) + 1), 5.8), sharey=True)
    work_ax = axes[-1]
    for ax, scene in zip(axes, scenes):
        for sps in sorted({r["steps_per_s"] for r in rows if r["scene"] == scene}):
            rs = sorted((r for r in rows if r["scene"] == scene and r["steps_per_s"] == sps),
                        key=lambda r: r["iterations"])
            col = H_COLORS.get(sps, "0.3")
            ok = [r for r in rs if not r["blown_up"]]
            bad = [r for r in rs if r["blown_up"]]
            n = rs[0]["n"]
            for key, ls, label in (("mean_compression", "-", "mean"), ("max_compression", "--", "max")):
                ax.plot([r["iterations"] for r in ok], [_floor(r[key]) for r in ok], color=col, ls=ls,
                        marker=SCENE_MARKERS.get(scene, "o"), ms=5, label=f"h = 1/{sps}, {label}")
            ax.plot([r["iterations"] for r in bad], [_floor(r["mean_compression"]) for r in bad],
                    ls="none", marker="x", ms=10, mew=2, color=col)
            work_ax.plot([r["work"] for r in ok], [_floor(r["mean_compression"]) for r in ok], color=col,
                         marker=SCENE_MARKERS.get(scene, "o"), ms=5, ls="-" if scene == scenes[0] else ":",
                         label=f"{scene}, h = 1/{sps}")
            work_ax.plot([r["work"] for r in bad], [_floor(r["mean_compression"]) for r in bad],
                         ls="none", marker="x", ms=10, mew=2, color=col)
        ax.set_xscale("log", base=2)
        ax.set_xticks(sorted({r["iterations"] for r in rows}))
        ax.set_xticklabels([str(i) for i in sorted({r["iterations"] for r in rows})])
        ax.set_xlabel("Jacobi iterations a step")
        ax.set_title(f"{TITLES.get(scene, scene)}\nN = {n}", fontsize=10)
        ax.legend(fontsize=8, loc="lower left")
    axes[0].set_ylabel(f"compression max(ρ/ρ₀ − 1, 0) over the particles,\nframes of the last {WINDOW:g} s "
                       "averaged (mean: solid, max: dashed)")
    work_ax.set_xscale("log")
    work_ax.set_xlabel("work: particle-iterations per simulated second (N · iterations / h)")
    work_ax.set_title("mean compression against work\n(dam: solid, tank: dotted)", fontsize=10)
    work_ax.legend(fontsize=8, loc="lower left")
    for ax in axes:
        ax.set_yscale("log")
        ax.grid(True, which="major", alpha=0.4)
        ax.grid(True, which="minor", alpha=0.12)
        ax.axhline(FLOOR, color="0.5", lw=0.8, ls=":")
    seconds = rows[0]["seconds"]
    fig.suptitle(f"Position-based fluid (Macklin & Müller 2013), radius {RADIUS} m, {seconds:g} s "
                 "per run: density error the solver leaves (poly6 density in float64 from the "
                 f"positions).\n×: blew up (mean compression above {BLOWN_UP:g}: particles clumped, "
                 f"some flung out of the open tank), drawn at its mean; dotted line: {FLOOR:g}, "
                 "no compression at all", fontsize=10.5)
    fig.tight_layout()
    return _save(fig, path)
