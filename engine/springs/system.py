"""``SpringSystem``: a soft-body network you can step by frames, pin, collide, and read back.

    sys = SpringSystem(cloth(24, 24), colliders=Colliders([...]), integrator="xpbd")
    for frame in range(n):
        sys.step(1 / 60)                        # sub-steps internally, lands exactly on the frame
        draw(sys.positions(), sys.triangles())

Integrators: the five names of engine.ode.steppers.METHODS (explicit, stage by stage) and "xpbd"
(stable at h = 1/60 for stiff springs). ``substeps``: None (one step per frame, or frame/h when
``h`` is given), an int, or "auto" (from the stiffness guard). Explicit steps beyond the stability
limit raise :class:`StiffnessError` unless ``check_stability=False``. ``adaptive=True`` uses step
doubling with the tolerances. A non-finite state raises :class:`SimulationDiverged`, naming the
integrator, h and the simulated time.
"""
import math

import numpy as np
import taichi as ti

from ..ode.controller import StepDoublingController, clip_to_target
from ..ode.steppers import METHODS
from ..runtime import check_stop, ensure_init
from .adaptive import DoublingBuffers
from .constraints import NO_FAILURE, make_constraint_kernels
from .energy import network_energy
from .forces import ACCUMULATORS, make_accel_kernels
from .integrators import ExplicitStepper
from .limits import DistanceLimits
from .model import SpringModel, SpringState
from .stability import SAFETY, StiffnessError, auto_substeps, check_step, network_bounds, stable_step
from .topology import STRUCTURAL, Topology, surface_lines
from .xpbd import XPBDStepper

INTEGRATORS = tuple(METHODS) + ("xpbd",)
__all__ = ["SpringSystem", "SimulationDiverged", "StiffnessError", "INTEGRATORS"]


class SimulationDiverged(RuntimeError):
    """The state became non-finite (or the adaptive step collapsed)."""


class SpringSystem:
    def __init__(self, topology: Topology, colliders=None, gravity=(0.0, -9.81, 0.0),
                 integrator: str = "symplectic_euler", h=None, substeps=None, adaptive: bool = False,
                 tol: float = 1e-4, rtol=None, atol=None, accumulate: str = "gather",
                 xpbd_iterations: int = 10, max_stretch=None, limit_iterations: int = 2,
                 check_stability: bool = True, dtype=ti.f32, record_energy: bool = False,
                 move_colliders=None):
        ensure_init()
        if integrator not in INTEGRATORS:
            raise ValueError(f"integrator: unknown value {integrator!r}; allowed: {', '.join(INTEGRATORS)}")
        if accumulate not in ACCUMULATORS:
            raise ValueError(f"accumulate: unknown value {accumulate!r}; allowed: {', '.join(ACCUMULATORS)}")
        if not (substeps is None or substeps == "auto" or (isinstance(substeps, int) and substeps >= 1)):
            raise ValueError(f"substeps: expected None, a positive int or 'auto'; got {substeps!r}")
        if adaptive and integrator == "xpbd":
            raise ValueError("adaptive: step doubling needs an explicit integrator, not 'xpbd'")
        self.top, self.dtype, self.integrator = topology, dtype, integrator
        self.h, self.substeps, self.adaptive = h, substeps, adaptive
        self.rtol = tol if rtol is None else rtol
        self.atol = self.rtol if atol is None else atol
        self.max_stretch, self.limit_iterations = max_stretch, limit_iterations
        self.check_stability, self.record_energy = check_stability, record_energy
        self.model = SpringModel(topology, dtype, gravity)
        self.state = SpringState(topology.node_count, dtype)
        self.set_positions(topology.positions)
        self.set_velocities(np.zeros_like(topology.positions))
        self.accel = make_accel_kernels(self.model)[accumulate]
        if integrator == "xpbd":
            self.stepper = XPBDStepper(self.model, self.state, xpbd_iterations)
        else:
            self.stepper = ExplicitStepper(self.model, self.state, self.accel, integrator)
        self.colliders = colliders
        if move_colliders is None:
            move_colliders = colliders is not None and any(s.path for s in colliders.specs)
        self.move_colliders = move_colliders
        self._c = make_constraint_kernels(self.model, self.state, colliders)
        self._limits = DistanceLimits(self.model, self.state) if max_stretch is not None else None
        self._buf = DoublingBuffers(self.model, self.state) if adaptive else None
        self._ctrl = StepDoublingController(order=self.stepper.order, max_factor=5.0)
        self._h_next = None
        self.bounds = network_bounds(topology, self.model.pinned_mask)
        self.time = 0.0
        self.step_sizes = []  # h of every accepted step in the last frame
        self.n_rejected = 0
        self.energy_log = []

    # -- stepping ---------------------------------------------------------------------------------
    def stable_step(self) -> float:
        """Largest stable step of the explicit integrator for these springs (inf for xpbd)."""
        return math.inf if self.integrator == "xpbd" else stable_step(self.integrator, self.bounds)

    def substeps_for(self, dt: float) -> int:
        if self.substeps == "auto":
            return 1 if self.integrator == "xpbd" else auto_substeps(self.integrator, dt, self.bounds)
        if isinstance(self.substeps, int):
            return self.substeps
        return max(1, math.ceil(dt / self.h - 1e-9)) if self.h else 1

    def step(self, dt: float) -> None:
        """Advance by dt seconds (a frame of any length), landing exactly on time + dt."""
        if not dt > 0:
            raise ValueError(f"dt: must be positive, got {dt}")
        self._c["begin_frame"]()
        if self.adaptive:
            self._step_adaptive(dt)
        else:
            self._step_fixed(dt)
        self.time += dt
        if self.record_energy:
            self.energy_log.append(self.energy())

    def _step_fixed(self, dt: float) -> None:
        n = self.substeps_for(dt)
        h = dt / n
        if self.check_stability and self.integrator != "xpbd" and self.substeps != "auto":
            check_step(self.integrator, h, self.bounds, dt)
        for k in range(n):
            check_stop()
            self._advance(h, (k + 1) / n)
            self._post((k + 1) / n, k, self.time + (k + 1) * h)
        self.step_sizes = [h] * n
        self._raise_if_bad(lambda k: (h, self.time + (k + 1) * h))

    def _advance(self, h: float, alpha_end: float) -> None:
        if self.model.pinned_mask.any():
            self._c["pin_drive"](alpha_end, h)
        self.stepper.step(h)

    def _post(self, alpha: float, k: int, t_end: float) -> None:
        if self._limits is not None:
            self._limits.apply(self.max_stretch, self.limit_iterations)
        if self.move_colliders:
            self.colliders.move_to(t_end)
        self._c["finalize"](alpha, k)

    def _raise_if_bad(self, where) -> None:
        bad = self._c["bad"]
        k = int(bad[None])
        if k != NO_FAILURE:
            bad[None] = NO_FAILURE
            h, t = where(k)
            raise SimulationDiverged(f"{self.integrator} diverged: non-finite state at t = {t:.6g} s "
                                     f"with h = {h:.3g} s")

    def _step_adaptive(self, dt: float) -> None:
        buf, ctrl, order = self._buf, self._ctrl, self.stepper.order
        h = self._h_next or min(dt, SAFETY * self.stable_step())
        t, k, sizes = 0.0, 0, []
        while t < dt:
            check_stop()
            hs, lands = clip_to_target(t, h, dt)
            buf.save()
            self._advance(hs, (t + hs) / dt)
            buf.keep_single()
            buf.restore()
            self._advance(hs / 2, (t + hs / 2) / dt)
            self._advance(hs / 2, (t + hs) / dt)
            err = buf.error(order, self.atol, self.rtol)
            accept, h_new = ctrl.propose(hs, err)
            if accept:
                t = dt if lands else t + hs
                self._post(t / dt, k, self.time + t)
                sizes.append(hs)
                k += 1
            else:
                buf.restore()
                self.n_rejected += 1
                if h_new < ctrl.h_min or not math.isfinite(h_new):
                    raise SimulationDiverged(f"{self.integrator} diverged: adaptive step fell to "
                                             f"h = {h_new:.3g} s at t = {self.time + t:.6g} s (err = {err:.3g})")
            h = h_new
        self.step_sizes = sizes
        self._h_next = h
        starts = np.concatenate([[0.0], np.cumsum(sizes)])
        self._raise_if_bad(lambda j: (sizes[j], self.time + starts[j + 1]))

    # -- state, pins, energy, render data ---------------------------------------------------------
    def _np(self, a) -> np.ndarray:
        return np.asarray(a, np.float64 if self.dtype == ti.f64 else np.float32)

    def _padded(self, a) -> np.ndarray:
        out = np.zeros((max(1, self.top.node_count), 3), self._np([]).dtype)
        out[: self.top.node_count] = a
        return out

    def positions(self) -> np.ndarray:
        return self.state.node_pos.to_numpy()[: self.top.node_count]

    def velocities(self) -> np.ndarray:
        return self.state.node_vel.to_numpy()[: self.top.node_count]

    def set_positions(self, x) -> None:
        self.state.node_pos.from_numpy(self._padded(np.asarray(x).reshape(-1, 3)))

    def set_velocities(self, v) -> None:
        self.state.node_vel.from_numpy(self._padded(np.asarray(v).reshape(-1, 3)))

    def pin(self, node: int, target=None) -> None:
        """Hold ``node`` at ``target`` (default: where it is now)."""
        pos = self.state.node_pos[node] if target is None else [float(c) for c in target]
        self.model.pin_start[node] = self.state.node_pos[node]
        self.model.pin_target[node] = pos
        self.model.set_pinned(node, True)
        self._pins_changed()

    def release(self, node: int) -> None:
        self.model.set_pinned(node, False)
        self._pins_changed()

    def _pins_changed(self) -> None:
        self.bounds = network_bounds(self.top, self.model.pinned_mask)
        if self._limits is not None:
            self._limits.refresh()

    def set_pin_target(self, node: int, pos) -> None:
        """Where a pinned node should be at the end of the next ``step``: it moves there linearly
        over the frame, its velocity inferred. Pins the node if it was free."""
        if not self.model.pinned_mask[node]:
            self.pin(node)
        self.model.pin_target[node] = [float(c) for c in pos]

    def energy(self) -> dict:
        e = network_energy(self.top, self.model.pinned_mask, self.positions(), self.velocities(),
                           self.model.gravity[None].to_numpy())
        return dict(t=self.time, **e)

    def lines(self, kinds=(STRUCTURAL,)) -> np.ndarray:
        """(K, 2) node index pairs to draw as lines (structural springs by default)."""
        return surface_lines(self.top, kinds)

    def triangles(self) -> np.ndarray:
        """(T, 3) node indices of the render surface (cloth sheet, jelly outer faces)."""
        return self.top.triangles
