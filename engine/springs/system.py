"""``SpringSystem``: a soft-body network you can step by frames, pin, collide, and read back.

    sys = SpringSystem(cloth(24, 24), colliders=Colliders([...]), integrator="xpbd")
    for frame in range(n):
        sys.step(1 / 60)                        # sub-steps internally, lands exactly on the frame
        draw(sys.positions(), sys.triangles())

Integrators: the names of engine.ode's :data:`~engine.ode.methods.INTEGRATORS`, staged over the
network's fields by :class:`~engine.ode.staged.FieldStepper`, and "xpbd" (stable at h = 1/60 for
stiff springs). ``substeps``: None (one step per frame, or frame/h when ``h`` is given), an int,
or "auto" (from the stiffness guard). Explicit steps beyond the stability limit raise
:class:`StiffnessError` unless ``check_stability=False``. ``adaptive=True`` uses step doubling with
the tolerances. The steps are taken by the ODE core's :class:`~engine.ode.driver.Driver` (this
class implements its protocol); a non-finite state raises :class:`SimulationDiverged`, naming the
integrator, h and the simulated time.
"""
import math

import numpy as np
import taichi as ti

from ..contacts import ContactBuffer
from ..control import ColliderInput, Control
from ..forces.elements import ElementGroup
from ..forces.fields import PointForces
from ..ode.driver import Driver, SimulationDiverged, StepPolicy, substeps
from ..ode.methods import INTEGRATORS as ODE_INTEGRATORS
from ..ode.staged import FieldStepper, StagedDoubling, copy_nodes
from ..runtime import _arch_in_use, ensure_init
from . import constraints, fused
from .energy import network_energy
from .forces import ACCUMULATORS, accel_launcher, spring_energy
from .limits import DistanceLimits
from .model import SpringModel, SpringState
from .stability import SAFETY, StiffnessError, auto_substeps, check_step, network_bounds, stable_step
from .topology import STRUCTURAL, Topology, surface_lines
from ..xpbd import SpringConstraints, XPBDSolver

INTEGRATORS = ODE_INTEGRATORS + (XPBDSolver.method,)
__all__ = ["SpringSystem", "SimulationDiverged", "StiffnessError", "INTEGRATORS"]


class SpringSystem:
    def __init__(self, topology: Topology, colliders=None, gravity=(0.0, -9.81, 0.0),
                 integrator: str = "symplectic_euler", h=None, substeps=None, adaptive: bool = False,
                 tol: float = 1e-4, rtol=None, atol=None, accumulate: str = "gather",
                 xpbd_iterations: int = 10, max_stretch=None, limit_iterations: int = 2,
                 check_stability: bool = True, dtype=ti.f32, record_energy: bool = False,
                 control: Control = None, name: str = "", contacts: int = 0, drag: float = 0.0, wind=None,
                 attractors=(), vortices=(), self_collision: float = 0.0, elements=()):
        """``control``: the scene's inputs (gravity, wind, collider poses); without one the system
        has its own, with ``gravity``, ``wind`` (m/s) and the colliders' own paths. ``drag``: linear
        drag toward the wind, k in 1/s (a = −k (v − wind) on every free node; 0: not compiled,
        gravity alone); ``attractors``, ``vortices``: the config's ``[forces]`` lists, pulling the
        nodes as they pull particles. ``name`` prefixes messages.
        ``contacts``: keep up to this many node–collider contact records between drains
        (:meth:`contacts`; 0: none, and no recording is compiled). ``self_collision``: a thickness
        > 0 keeps nodes that no spring joins 2 × that apart (engine.springs.self_collision, through
        the shared neighbour grid); 0: none, nothing built. ``elements``: energy terms over
        the nodes besides the springs — dicts of :class:`~engine.forces.elements.ElementGroup`'s
        arguments (kind, nodes, stiffness, material, damping, name) or built groups (user energies,
        engine.forces.user); none: nothing of them is built or compiled."""
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
        self.method, self.label = integrator, f"{name}: {integrator}" if name else integrator
        self.h, self.substeps, self.adaptive = h, substeps, adaptive
        self.rtol = tol if rtol is None else rtol
        self.atol = self.rtol if atol is None else atol
        self.max_stretch, self.limit_iterations = max_stretch, limit_iterations
        self.check_stability, self.record_energy = check_stability, record_energy
        if control is None:  # standalone: its own inputs, the colliders following their specs' paths
            specs = colliders.specs if colliders is not None else ()
            control = Control(gravity, (0.0, 0.0, 0.0) if wind is None else wind,
                              colliders=[ColliderInput.from_spec(s) for s in specs], dtype=dtype)
        elif wind is not None:
            control.set_wind(wind)
        self.control = control
        self.gravity = self.control.gravity
        # the force fields on the nodes (engine.forces.fields): gravity, drag toward the wind
        self.fields = PointForces(self.control.gravity, self.control.wind, drag, dtype, attractors, vortices)
        self.model = SpringModel(topology, dtype)
        self.state = SpringState(topology.node_count, dtype)
        self.set_positions(topology.positions)
        self.set_velocities(np.zeros_like(topology.positions))
        n = topology.node_count
        self.accumulate, self.xpbd_iterations = accumulate, xpbd_iterations
        self.elements = [e if not isinstance(e, dict) else self._group(e) for e in elements]
        self._make_stepper()
        self.order = self.stepper.order
        self.colliders = colliders
        self._contacts = constraints.NodeContacts(colliders)
        if self._contacts.on:  # the start of each step, for locating impacts in it
            self._x0 = ti.Vector.field(3, dtype, max(1, n))
            self._v0 = ti.Vector.field(3, dtype, max(1, n))
        self.contact_log = ContactBuffer(contacts if self._contacts.on else 0, kind="node")
        self._bad = ti.field(ti.f64, ())
        self._bad[None] = constraints.NO_FAILURE
        self._self = None
        if self_collision > 0 and n:
            from .self_collision import SelfCollision

            self._self = SelfCollision(self.model, self.state, self_collision)
        self._limits = DistanceLimits(self.model, self.state) if max_stretch is not None else None
        self._doubling = StagedDoubling(self.stepper) if adaptive else None
        self.driver = Driver(self, StepPolicy(adaptive=adaptive, rtol=self.rtol, atol=self.atol))
        self.bounds = self._bounds()
        self.time = 0.0
        self._frame = (0.0, 1.0)  # (start, length) of the frame being stepped: pins move over it
        self.energy_log = []
        # pin targets set on moving pins, written at the next step (engine.springs.fused takes
        # them into its launch); the fused run's bad_t, so first_nonfinite needs no read-back
        self._moves, self._bad_seen = {}, None

    def _move_rows(self) -> np.ndarray:
        """The pin targets set since the last step as (≥ 1, 4) f64 rows (node, x, y, z)."""
        moves = np.zeros((max(1, len(self._moves)), 4), np.float64)
        if self._moves:
            moves[: len(self._moves), 0] = list(self._moves)
            moves[: len(self._moves), 1:] = list(self._moves.values())
        return moves

    def _flush_moves(self) -> None:
        if self._moves:
            constraints.pin_moves(self.model, self._move_rows(), len(self._moves))
        self._moves = {}

    def _make_stepper(self) -> None:
        n = self.top.node_count
        if self.integrator == "xpbd":
            self.stepper = XPBDSolver(n, self.state.node_pos, self.state.node_vel, self.model.node_inv_mass,
                                      self.fields, [SpringConstraints(self.model), *self.elements],
                                      self.xpbd_iterations)
        else:
            self.accel = accel_launcher(self.model, self.fields, self.accumulate)
            if self.elements:  # springs and gravity first (as without terms), then each term in order
                springs, w = self.accel, self.model.node_inv_mass

                def accel(X, V, A, j):
                    springs(X, V, A, j)
                    for g in self.elements:
                        g.add_forces(X, V, w, A, j)

                self.accel = accel
            self.stepper = FieldStepper(self.integrator, self.state.node_pos, self.state.node_vel, n, self.accel)

    def add_elements(self, group) -> None:
        """Add an energy term after construction (a user energy, engine.forces.user): the stepper
        is rebuilt around it (its fields and kernels kept), the guard's bounds refreshed."""
        if group.n_nodes != self.top.node_count:
            raise ValueError(f"elements: built for {group.n_nodes} nodes, the body has {self.top.node_count}")
        self.elements.append(group)
        self._make_stepper()
        if self._doubling is not None:
            self._doubling = StagedDoubling(self.stepper)
        self.bounds = self._bounds()

    def _group(self, spec: dict):
        return ElementGroup(positions=self.top.positions, dtype=self.dtype, **spec)

    def _bounds(self) -> dict:
        extra = None
        if self.elements:
            n = self.top.node_count
            extra = (sum((g.node_bounds()[0] for g in self.elements), np.zeros(n)),
                     sum((g.node_bounds()[1] for g in self.elements), np.zeros(n)))
        return network_bounds(self.top, self.model.pinned_mask, extra)

    # -- stepping ---------------------------------------------------------------------------------
    def stable_step(self) -> float:
        """Largest stable step of the explicit integrator for these springs (inf for xpbd)."""
        return math.inf if self.integrator == "xpbd" else stable_step(self.integrator, self.bounds)

    def substeps_for(self, dt: float) -> int:
        if self.substeps == "auto":
            if self.integrator == "xpbd":
                # springs: one step a frame (stable at any h). A material's C = √(2ψ) converges
                # poorly in a few iterations at h = 1/30 (the jelly spread to 1.7× its width);
                # substeps that resolve its stiffest mode, as the explicit step would, keep it
                # (small steps beat iterations: Macklin et al. 2019, "Small steps in physics
                # simulation")
                solid = any(getattr(g, "kind", "") == "elastic" for g in self.elements)
                return auto_substeps("symplectic_euler", dt, self.bounds) if solid else 1
            return auto_substeps(self.integrator, dt, self.bounds)
        if isinstance(self.substeps, int):
            return self.substeps
        return substeps(dt, self.h) if self.h else 1

    def step(self, dt: float) -> None:
        """Advance by dt seconds (a frame of any length), landing exactly on time + dt."""
        if not dt > 0:
            raise ValueError(f"dt: must be positive, got {dt}")
        fuse = self._fusable()
        if not fuse:
            self._flush_moves()
        if self.model.node_count and not fuse:  # (the fused run does it in its launch)
            constraints.begin_frame(self.model, self.state)
        if not self.adaptive:
            n = self.substeps_for(dt)
            if self.check_stability and self.integrator != "xpbd" and self.substeps != "auto":
                check_step(self.integrator, dt / n, self.bounds, dt)
            self.driver.policy.h = dt / n
        self._frame = (self.time, dt)
        self.driver.advance(self.time, self.time + dt)
        self.time += dt
        if self.record_energy:
            self.energy_log.append(self.energy())

    @property
    def step_sizes(self) -> list:
        """h of every accepted step in the last frame."""
        return self.driver.step_sizes

    @property
    def n_rejected(self) -> int:
        return self.driver.stats.rejected

    # -- the driver's protocol (engine.ode.driver) -----------------------------------------------
    def _alpha(self, t: float) -> float:
        t0, dt = self._frame
        return (t - t0) / dt

    def _drive_pins(self, h: float, t_end: float) -> None:
        if self.model.pinned_mask.any():
            constraints.pin_drive(self.model, self.state, self._alpha(t_end), h)

    def _post(self, t_end: float, h: float, x0, v0) -> None:
        """After a step of h ending at t_end that started from (x0, v0): limits, colliders."""
        if self.model.node_count == 0:
            return
        if self._self is not None:  # before the colliders: they have the last word
            self._self.apply(h)
        if self._limits is not None:
            self._limits.apply(self.max_stretch, self.limit_iterations)
        if self._contacts.on:  # the shared table placed at this step's end (engine.colliders)
            self.colliders.follow(self.control, t_end - h, t_end)
        constraints.finalize(self.model, self.state, self._contacts, x0, v0, self._bad,
                             self._alpha(t_end), t_end, h, self.contact_log)

    def _fusable(self) -> bool:
        """Whether a frame's substeps run in one launch (engine.springs.fused): nothing needs the
        host between them and the network is small enough for one CPU thread."""
        if (self.adaptive or self._limits is not None or self._self is not None
                or not (self.model.spring_count or self.elements)):  # (self-collision runs between steps, on the host's call)
            return False
        if not all(isinstance(g, ElementGroup) for g in self.elements):
            return False  # a user energy's autodiff kernels run launch by launch
        if self.model.node_count > fused.MAX_NODES or _arch_in_use() != "cpu":
            return False
        if self._contacts.on and self.control.colliders_move and (
                self.control.colliders_turn or self.colliders.rotating or "rigid" in self.colliders.owners):
            return False  # the colliders turn between substeps (or a rigid solver places its shapes): the host places them
        if self.integrator == "xpbd":
            return True
        return self.accumulate == "gather"  # (a splitting scheme's kick–drifts or a tableau's stages)

    def _fused_steps(self, t0: float, h: float, j: int, n: int) -> int:
        """Steps j … n−1 of the frame in one launch; the same times as :meth:`fixed_step`'s."""
        times = np.empty((n - j, 2), np.float64)
        for m in range(j, n):
            t_end = t0 + m * h + h
            times[m - j] = self._alpha(t_end), t_end
        x0, v0 = self.state.node_pos, self.state.node_vel
        if self._contacts.on:
            x0, v0 = self._x0, self._v0
        st = self.stepper
        if self.integrator == "xpbd":
            spr = [g for g in st.groups if isinstance(g, SpringConstraints)]  # (absent without springs)
            lam = spr[0].lam if spr else st.x_prev
            its = st.iterations if st.groups else 0
            args = (True, st.x_prev, lam, its, (), st.x_prev, (), (), st.x_prev, st.x_prev, st.x_prev)
        elif hasattr(st, "_segments"):
            segs = tuple((slot, kick, tuple(drifts)) for slot, kick, drifts in st._segments)
            args = (False, x0, x0, 0, segs, st.a, (), (), st.a, x0, x0)
        else:  # a Runge–Kutta tableau
            args = (False, x0, x0, 0, (), st.a, st._rows, st._b, st.vs, st.yx, st.yv)
        n_shapes, poses = 0, np.zeros((1, 1, 6), np.float32)
        if self._contacts.on:
            poses = np.zeros((1, 1, 6), self.colliders._np)  # (the fields' dtype: one compile)
            if self.control.colliders_move:  # placed as _post's follow would, step by step
                poses = self.colliders.poses_over(self.control, [(te - h, te) for _a, te in times])
                n_shapes = self.colliders.count
        self._bad_seen = fused.run_steps(self.model, self.state, self.fields, self._contacts, x0, v0,
                                         self._bad, self.contact_log, times, h, int(j == 0), self._move_rows(),
                                         len(self._moves), poses, n_shapes, *args, tuple(self.elements))
        self._moves = {}
        return n - j

    def fixed_step(self, t0: float, h: float, j: int, n: int) -> int:
        if self._fusable():
            return self._fused_steps(t0, h, j, n)
        t = t0 + j * h
        self._drive_pins(h, t + h)
        x0, v0 = self.state.node_pos, self.state.node_vel
        if self._contacts.on and self.model.node_count:
            copy_nodes(x0, v0, self._x0, self._v0, self.model.node_count)
            x0, v0 = self._x0, self._v0
        self.stepper.step(h)
        self._post(t + h, h, x0, v0)
        return 1

    def first_nonfinite(self):
        t = float(self._bad[None]) if self._bad_seen is None else self._bad_seen
        self._bad_seen = None
        if t >= constraints.NO_FAILURE:
            return None
        self._bad[None] = constraints.NO_FAILURE
        return t

    def attempt(self, t: float, h: float) -> float:
        return self._doubling.attempt(h, self.atol, self.rtol,
                                      before=lambda hs, end: self._drive_pins(hs, t + end * h))

    def commit(self, t: float, h: float) -> None:
        self._post(t + h, h, self._doubling.x0, self._doubling.v0)

    def rollback(self) -> None:
        self._doubling.rollback()

    def first_step(self, t: float, t_end: float) -> float:
        return min(t_end - t, SAFETY * self.stable_step())

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

    def reset(self) -> None:
        """Back to the topology's rest state at time 0 with its own pins (a reused scene)."""
        top, model = self.top, self.model
        self.set_positions(top.positions)
        self.set_velocities(np.zeros_like(top.positions))
        home = np.zeros(top.node_count, bool)
        home[top.pinned] = True
        for node in np.flatnonzero(home != model.pinned_mask):
            model.set_pinned(int(node), bool(home[node]))
        p = self._padded(top.positions)
        model.pin_start.from_numpy(p)
        model.pin_target.from_numpy(p)
        self._pins_changed()
        if self.colliders is not None:
            self.colliders.reset()
        self._bad[None] = constraints.NO_FAILURE
        self.contact_log.count[None] = 0
        self.driver.reset()
        self.time, self._frame, self.energy_log = 0.0, (0.0, 1.0), []
        self._moves, self._bad_seen = {}, None

    def pin(self, node: int, target=None) -> None:
        """Hold ``node`` at ``target`` (default: where it is now)."""
        self._moves.pop(node, None)
        pos = self.state.node_pos[node] if target is None else [float(c) for c in target]
        self.model.pin_start[node] = self.state.node_pos[node]
        self.model.pin_target[node] = pos
        self.model.set_pinned(node, True)
        self._pins_changed()

    def release(self, node: int) -> None:
        self._moves.pop(node, None)
        self.model.set_pinned(node, False)
        self._pins_changed()

    def _pins_changed(self) -> None:
        self.bounds = self._bounds()
        if self._limits is not None:
            self._limits.refresh()

    def set_pin_target(self, node: int, pos) -> None:
        """Where a pinned node should be at the end of the next ``step``: it moves there linearly
        over the frame, its velocity inferred. Pins the node if it was free."""
        self.set_pin_targets([node], [pos])

    def set_pin_targets(self, nodes, positions) -> None:
        """:meth:`set_pin_target` for many nodes at once: ``nodes`` (k,) ints, ``positions``
        (k, 3) m (a driven body's every pin each frame: 260 hair roots were ~1 ms of Python a frame
        one call at a time)."""
        nodes = np.asarray(nodes, np.int64).reshape(-1)
        pos = np.asarray(positions, np.float64).reshape(len(nodes), 3)
        for node in nodes[~self.model.pinned_mask[nodes]].tolist():
            self.pin(node)
        self._moves.update(zip(nodes.tolist(), pos.tolist()))  # written at the next step (_flush_moves)

    def apply(self, requests) -> None:
        """Pin requests from the control (:class:`~engine.control.PinRequest`), in order."""
        for r in requests:
            if r.kind == "release":
                self.release(r.node)
            elif r.kind == "move":
                self.set_pin_target(r.node, r.target)
            else:
                self.pin(r.node, r.target)

    def energy(self) -> dict:
        spring = spring_energy(self.model, self.state.node_pos) if self.model.spring_count else 0.0
        e = network_energy(self.top, self.model.pinned_mask, self.positions(), self.velocities(),
                           self.gravity[None].to_numpy(), spring)
        for g in self.elements:  # every term by its name (the same term twice: name_2, …)
            key, k = g.name, 2
            while key in e:
                key, k = f"{g.name}_{k}", k + 1
            e[key] = g.energy(self.state.node_pos)
            e["total"] += e[key]
        return dict(t=self.time, **e)

    def lines(self, kinds=(STRUCTURAL,)) -> np.ndarray:
        """(K, 2) node index pairs to draw as lines (structural springs by default)."""
        return surface_lines(self.top, kinds)

    def triangles(self) -> np.ndarray:
        """(T, 3) node indices of the render surface (cloth sheet, jelly outer faces)."""
        return self.top.triangles
