""""Model no more than a scene needs": the cost of each optional feature, measured by switching
it off, and proof that a scene without a feature compiles none of its code.

The base scene has the optional particle features: colliders (a ground plane and a sphere), drag,
curl-noise turbulence, sub-emitters (sparks feed dust on death), streaks and alpha blending (an
alpha emitter beside the additive one); it has no spring bodies (the cloth row times springs). Each variant turns one off
and is timed per frame (step + tiled render) in the same process. The proof records the kernels
each variant compiles (Taichi's ``Kernel.materialize``) and what was compiled into them: the
force terms (``Forces.names``), collider code, the OIT (alpha) path, streak geometry.

The last rows price located impacts (issue 14): the same scene with ``solver.impacts =
"located"`` (each particle's impacts found in time inside the step) and ``"projected"`` (put
back after the step), stepped only (no render), with the contacts per frame each one resolves
(target: located costs at most 15% more per step at the same contacts).
"""
from __future__ import annotations

import copy

from .common import Row, time_median

W, H = 640, 360


def base_config(n: int) -> dict:
    n_add = n // 2
    common = {"shape": "sphere", "radius": 0.5, "position": [0.0, 1.0, 0.0], "speed": [0.5, 3.0],
              "spread": 180.0, "lifetime": 2.0}
    return {
        "seed": 4, "fps": 60.0, "frames": 1,
        "solver": {"integrator": "symplectic_euler", "h": 1.0 / 240.0},
        "forces": {"gravity": [0.0, -9.81, 0.0], "drag": 0.4, "turbulence": {"strength": 2.0}},
        "render": {"width": W, "height": H},
        "emitters": [
            dict(common, name="sparks", blend="additive", rate=n_add, capacity=n_add, streak=0.02,
                 sub_emitters=[{"event": "death", "emitter": "dust", "count": 1}],
                 color=[[0.0, 4.0, 2.0, 0.6], [1.0, 1.0, 0.2, 0.05]], size=[[0.0, 0.012]]),
            dict(common, name="dust", blend="additive", rate=n - n_add, capacity=n - n_add,
                 color=[[0.0, 0.3, 0.28, 0.25]], alpha=[[0.0, 0.0], [0.2, 0.25], [1.0, 0.0]],
                 size=[[0.0, 0.02], [1.0, 0.04]]),
        ],
        "colliders": [{"type": "plane", "restitution": 0.3, "friction": 0.2},
                      {"type": "sphere", "center": [1.0, 0.5, 0.0], "radius": 0.5}],
    }


def variants(n: int):
    base = base_config(n)
    base["emitters"][1]["blend"] = "alpha"
    out = {"all features": base}
    v = copy.deepcopy(base)
    v["colliders"] = []
    out["no colliders"] = v
    v = copy.deepcopy(base)
    v["forces"]["drag"] = 0.0
    out["no drag"] = v
    v = copy.deepcopy(base)
    v["emitters"][0]["streak"] = 0.0
    out["no streaks"] = v
    v = copy.deepcopy(base)
    v["emitters"][1]["blend"] = "additive"
    out["no alpha blending"] = v
    v = copy.deepcopy(base)
    v["forces"]["turbulence"]["strength"] = 0.0
    out["no turbulence"] = v
    v = copy.deepcopy(base)
    v["emitters"][0]["sub_emitters"] = []
    out["no sub-emitters"] = v
    v = copy.deepcopy(base)
    v["colliders"] = []
    v["forces"]["drag"] = 0.0
    v["forces"]["turbulence"]["strength"] = 0.0
    v["emitters"][0]["streak"] = 0.0
    v["emitters"][0]["sub_emitters"] = []
    v["emitters"][1]["blend"] = "additive"
    out["none of them"] = v
    return out


class KernelLog:
    """Names of the Taichi kernels materialised (compiled or loaded) while active."""

    def __enter__(self):
        from taichi.lang import kernel_impl

        self._K = kernel_impl.Kernel
        self._orig = self._K.materialize
        self.names = []
        log, orig = self.names, self._orig

        def materialize(kernel, key=None, args=None, arg_features=None):
            if key is None or key not in kernel.compiled_kernels:
                log.append(kernel.func.__name__)
            return orig(kernel, key, args, arg_features)

        self._K.materialize = materialize
        return self

    def __exit__(self, *exc):
        self._K.materialize = self._orig


def _what_compiled(scene):
    R = scene.renderer
    parts = [f"forces: {'+'.join(scene.particles.forces.names) or 'none'}",
             f"colliders compiled: {scene.colliders.count}",
             f"OIT path: {'yes' if R.uses_alpha else 'no'}",
             f"sub-emitter events: {'yes' if scene.particles.emitters.uses_events else 'no'}",
             f"spring bodies: {len(scene.bodies)}",
             f"streaks: {'yes' if any(e.streak > 0 for e in scene.cfg.emitters) else 'no'}"]
    return "; ".join(parts)


def run(quick: bool = False):
    from .frame import build_scene

    n = 5_000 if quick else 400_000
    repeats = 2 if quick else 7
    rows, base_t = [], None
    sec = f"features: cost per frame by switching one off ({n // 1000}k particles, {W}x{H})"
    chosen = variants(n)
    if quick:  # each variant compiles its own kernels (~1 s each cold): keep CI short
        chosen = {k: chosen[k] for k in ("all features", "none of them")}
    for name, cfg in chosen.items():
        with KernelLog() as log:
            scene = build_scene(n, width=W, height=H, config=cfg)
            R = scene.renderer

            def frame():
                scene.advance_frame()
                scene.render()

            frame()
        t = time_median(frame, repeats, warmup=1)
        if base_t is None:
            base_t = t
            note = "reference"
        else:
            note = f"saves {100 * (base_t - t) / base_t:4.1f}% of the frame"
        kernels = sorted(set(log.names))
        if not scene.cfg.colliders:
            assert scene.colliders.count == 0
        if "drag" not in scene.particles.forces.names:
            assert not scene.particles.forces.use_drag
        if not any(e.sub_emitters for e in scene.cfg.emitters):
            assert not scene.particles.emitters.uses_events
        assert not scene.bodies  # no spring code built or run
        if not R.uses_alpha:
            assert all(e.blend != "alpha" for e in scene.cfg.emitters)
        rows.append(Row(sec, name, t * 1e3, "ms/frame",
                        f"{note}; {len(kernels)} kernels compiled; {_what_compiled(scene)}",
                        {"kernels": kernels}))
    return rows + impacts_rows(n, repeats)


def impacts_rows(n: int, repeats: int, rounds: int = 5):
    """Per-step cost of located impacts against projected ones on the base scene (step only):
    both scenes built first, then timed in alternating rounds (``repeats`` frames each), the
    fastest round of each kept — other load on the machine falls on both alike."""
    from .frame import build_scene

    sec = f"located impacts against projected, {n // 1000}k particles, step only"
    scenes, best, seen = {}, {}, {}
    for impacts in ("projected", "located"):
        cfg = base_config(n)
        cfg["solver"]["impacts"] = impacts
        scenes[impacts] = build_scene(n, width=W, height=H, config=cfg)
        scenes[impacts].advance_frame()  # compile
        best[impacts] = float("inf")
    for _ in range(rounds):
        for impacts, scene in scenes.items():
            I = scene.particles.integrator
            h0, s0 = int(I.hits[None]), scene.stats.steps
            t = time_median(scene.advance_frame, repeats, warmup=0)
            steps = (scene.stats.steps - s0) / repeats
            seen[impacts] = ((int(I.hits[None]) - h0) / repeats, steps)
            best[impacts] = min(best[impacts], t / steps)
    rows = []
    for impacts in scenes:
        contacts, steps = seen[impacts]
        note = f"{contacts:,.0f} contacts/frame, {steps:.0f} steps/frame; fastest of {rounds} alternating rounds"
        extra = {"contacts_per_frame": contacts}
        if impacts == "located":
            extra["ratio"] = best["located"] / best["projected"]
            note += f"; x{extra['ratio']:.2f} of projected (target <= 1.15)"
        rows.append(Row(sec, f"impacts {impacts}", best[impacts] * 1e3, "ms/step", note, extra))
    return rows
