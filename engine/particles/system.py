"""The particle half of a scene: pool, emitters, forces and integrator, stepped to frame times.

Built once from a validated config (every field is allocated and every kernel compiled for the
scene's features before the first step). The steps are chosen by the ODE core's
:class:`~engine.ode.driver.Driver` — equal fixed substeps landing exactly on each target, or step
doubling with the one controller — and this class implements its protocol: a step emits what is
due, moves the colliders to the control's positions, launches the fused step kernel and the
sub-emitter passes. Nothing is read back per step: the non-finite check once per ``advance``, the
live count when asked.
"""
from __future__ import annotations

import copy

import numpy as np

from ..contacts import Contacts
from ..fieldio import WriterGroup
from ..system import SystemBase
from ..ode.driver import Driver, SimulationDiverged, StepPolicy
from ..ode.methods import METHODS
from . import integrate
from .emitters import Emitters
from .forces import Forces
from .integrate import NO_FAILURE, ParticleIntegrator
from .pool import PARTICLE_FIELDS, ParticleState, PoolLayout, pool_sizes
from .slots import clear as clear_pool
from .slots import save_positions

H_MAX_FACTOR = 64  # an adaptive step may grow to 64 × the configured h
MAX_RUN = 32  # fixed steps fused into one launch at most (a stop request waits for at most this many)
EVENT_TOL = 0.01  # an adaptive step locates impacts to 1% of atol from the surface (fixed: to rounding)


class ParticleSystem(SystemBase):
    """The particle pool as a system of the scene (engine.system): ``kind`` particles."""

    kind = "particles"
    name = "particles"

    def __init__(self, cfg, colliders, control, stats, contacts: int = 0, interpolate: bool = False,
                 spare=(0, 0), writes=None):
        """``spare``: (emitter rows, pool slots) allocated beyond the config's, so emitters can be
        added between frames without new fields or compiles (:meth:`add_emitters`). ``writes``:
        the :class:`~engine.fieldio.WriterGroup` to write the parameters with (a scene's, shared
        with its colliders: one kernel for both); none: one of its own."""
        self.cfg = self._built = cfg
        sol = cfg.solver
        self.method, self.adaptive, self.stats = sol.integrator, sol.adaptive, stats
        self.label = f"integrator {self.method}"
        self.control = control
        self.layout = PoolLayout.for_emitters(cfg.emitters, 1.0 / cfg.fps, spare[1])
        rows = len(cfg.emitters) + int(spare[0])
        events = any(e.sub_emitters for e in cfg.emitters)
        self.state = ParticleState(self.layout.capacity, self.adaptive, events, interpolate)
        # the emitters' and forces' per-emitter parameters and counters: one kernel writes them
        # all, once at the build and again as emitters are added or the scene reset
        self.writes = writes if writes is not None else WriterGroup()
        with self.writes.held():
            self.emitters = Emitters(cfg.emitters, self.layout, cfg.seed, control.emitters, self.state, rows,
                                     self.writes)
            self.forces = Forces(cfg.forces, cfg.emitters, self.state, self.emitters.emitter_drag, control, rows,
                                 self.writes)
        self.colliders = colliders
        # two-way coupling (engine.particles.push): per-slot push records, compiled into the
        # step only where some emitter is two_way (the table's pusher is None otherwise)
        self.pusher = None
        if any(e.two_way for e in cfg.emitters) and colliders is not None and colliders.count:
            from .push import Pusher

            self.pusher = Pusher(self.layout.capacity, colliders, self._masses(cfg.emitters, rows))
        if colliders is not None:
            colliders.pusher = self.pusher
        self.integrator = ParticleIntegrator(self.state, self.forces.make_accel(), colliders,
                                             self.method, self.adaptive, sol.extrapolate,
                                             events=self.emitters.uses_events, contacts=contacts,
                                             impacts=sol.impacts, quadratic=self.forces.names == ["gravity"],
                                             lanes=not self.forces.use_turbulence)
        # a scene without interact imports, allocates and compiles none of it; with it, an adaptive
        # step never grows past the configured h (the constraint solve's stability is set there)
        self.interact = None
        if any(e.interact is not None for e in cfg.emitters) and self.layout.capacity:
            from .interact import Interactions

            self.interact = Interactions(self.state, cfg.emitters, rows, colliders, sizes=self.layout.sizes,
                                         starts=self.layout.starts)
        self.order = METHODS[self.method].order
        atol = sol.atol if sol.atol is not None else sol.tolerance
        self.atol, self.rtol = atol, sol.tolerance
        self.tol_g = EVENT_TOL * atol  # impacts located to this distance from the surface (m)
        self.driver = Driver(self, StepPolicy(
            h=sol.h, adaptive=self.adaptive, rtol=sol.tolerance, atol=atol,
            h_max=(1 if self.interact is not None else H_MAX_FACTOR) * sol.h,
            max_steps=sol.max_steps_per_frame,
            max_steps_hint="raise solver.tolerance or solver.max_steps_per_frame"), stats)
        self._alive = None  # the live count, read back when first asked after an advance
        self._held = None  # ((t0, h, step), plan): births due at a step a fused run stopped before
        # external potentials (engine.particles.potential), added from the API; none: nothing of
        # them is allocated or compiled and every step is launched exactly as before
        self.potentials: list = []
        self._h_max = self.driver.policy.h_max
        self._vel_kept = None  # velocities before an adaptive attempt's first kick (rollback)

    def advance(self, t0: float, t1: float) -> None:
        """Advance from t0 to exactly t1 (the System protocol, engine.scene.system). Contact
        records accumulate until :meth:`contacts` drains them."""
        self._alive = None
        if not self.potentials:
            self.driver.advance(t0, t1)
            return
        try:
            self.driver.advance(t0, t1)
        except SimulationDiverged as e:
            bad = [(t, p.name) for p in self.potentials if (t := p.failed_at()) is not None]
            if not bad:
                raise
            t, name = min(bad)
            raise SimulationDiverged(self.label, self.method, e.h, t,
                                     f"potential {name!r} (add_potential) has a non-finite gradient at a "
                                     f"particle's position (the particle was removed)") from None

    # -- two-way coupling (engine.particles.push) ---------------------------------------------------
    @staticmethod
    def _masses(emitters, rows: int) -> np.ndarray:
        """kg per particle of each emitter row: its ``mass`` where it is two_way, else 0."""
        m = np.zeros(max(1, rows))
        for e, em in enumerate(emitters):
            m[e] = em.mass if em.two_way else 0.0
        return m

    def receive(self, coupling) -> None:
        """Start the coupling step's push records empty (two-way coupling only)."""
        if self.pusher is not None:
            self.pusher.clear()

    def publish(self, coupling) -> None:
        """The impulses this coupling step's particles gave the rigid bodies, summed in slot
        order (:meth:`~engine.particles.push.Pusher.impulses`), put on the board for the next
        coupling step as ``rigid_impulses``: (J, L) float64 (bodies, 3), N·s and N·m·s about each
        body's centre. The rigid bodies advanced first this step (rule 1), so they take it at
        the start of the next one: a one-step lag."""
        if self.pusher is None or not self.layout.capacity:
            return
        got = self.pusher.impulses(self.state.particle_emitter.to_numpy(), len(self.cfg.rigid_bodies))
        if got is not None:
            coupling.put_later(self.name, "rigid_impulses", got)

    # -- the driver's protocol (engine.ode.driver) -----------------------------------------------
    def _move_colliders(self, t: float, t_end: float) -> bool:
        """Put moving colliders where the control says they are at t_end, moving since t (the
        step's start); whether any moves (the one shape table: soft bodies place it at their own
        steps' times the same way)."""
        return self.colliders.follow(self.control, t, t_end)

    def fixed_step(self, t0: float, h: float, j: int, n: int) -> int:
        """Step j of h from t0 (step m starts at t0 + m·h); then, while nothing has to happen
        between steps — no births due, colliders still, no sub-emitters — the following steps in
        the same launch (at most MAX_RUN). Births due at the step a run stops before are held for
        the next call, so the emitters' clocks advance exactly as step by step."""
        t = t0 + j * h
        held, self._held = self._held, None
        self.emitters.spawn(held[1] if held is not None and held[0] == (t0, h, j) else self.emitters.plan(t, h))
        k = 1
        # (with a potential every step is its own launch between two half kicks: no fused runs)
        if not self._move_colliders(t, t + h) and not self.emitters.uses_events and self.interact is None \
                and not self.potentials:
            while j + k < min(n, j + MAX_RUN):
                due = self.emitters.plan(t0 + (j + k) * h, h)
                if due is not None:
                    self._held = ((t0, h, j + k), due)
                    break
                k += 1
        if self.layout.capacity:
            self._kick(t, h, second=False)
            if k == 1:
                integrate.step_fixed(self.integrator, t, h)
            else:
                integrate.step_fixed_run(self.integrator, t0, h, j, k)
            if self.interact is not None:  # (k == 1: interacting particles take no fused runs)
                self.interact.step(h)
            self._kick(t + h, h, second=True)
        self.emitters.emit_children()
        self.emitters.carry_local(t, t0 + (j + k) * h)
        return k

    def warm_steps(self, t: float, h: float) -> None:
        """Compile both launches :meth:`fixed_step` takes, a single step and a fused run of them:
        which ones a warm-up's own steps take depends on when its births fall (a burst, then
        none due: one run), and a game's first steps would compile the other. One step of h at t
        each (the caller resets); nothing where runs are never fused (step doubling, events,
        interactions, potentials: a step a launch, compiled by any step)."""
        if self.layout.capacity and not self.adaptive and not self.emitters.uses_events \
                and self.interact is None and not self.potentials:
            integrate.step_fixed(self.integrator, t, h)
            integrate.step_fixed_run(self.integrator, t, h, 0, 1)

    def attempt(self, t: float, h: float) -> float:
        self.emitters.emit(t, h)  # newborns wait (negative age) if the attempt is retried shorter
        self._move_colliders(t, t + h)
        if not self.layout.capacity:
            return 0.0
        if self.potentials:  # the first half kick goes into the velocities: kept to undo it
            from .potential import _save

            _save(self.state.particle_vel, self._vel_kept, self.layout.capacity)
            self._kick(t, h, second=False)
        return float(integrate.attempt(self.integrator, t, h, self.atol, self.rtol, self.tol_g))

    def commit(self, t: float, h: float) -> None:
        if self.layout.capacity:
            integrate.commit(self.integrator, t, h)
            if self.interact is not None:
                self.interact.step(h)
            self._kick(t + h, h, second=True)
        self.emitters.emit_children()
        self.emitters.carry_local(t, t + h)

    def rollback(self) -> None:
        # the trial sits in cand_pos / cand_vel until committed; a rejected attempt's first half
        # kick is undone (the retry kicks again with its own h)
        if self.potentials and self.layout.capacity:
            from .potential import _save

            _save(self._vel_kept, self.state.particle_vel, self.layout.capacity)

    # -- external potentials (engine.particles.potential) -----------------------------------------
    def _kick(self, t: float, h: float, second: bool) -> None:
        """Each potential's half kick, the step's first or ``second`` (engine.particles.potential:
        imported, with the autodiff and element code it uses, only by a scene that has one)."""
        if self.potentials:
            from .potential import POST, PRE

            for p in self.potentials:  # in the order added: a fixed order of additions
                p.half_kick(t, h, POST if second else PRE)

    def add_potential(self, potential, params, emitter_rows, name: str) -> None:
        """Act on the particles of ``emitter_rows`` (indices; None: every row, spare ones too)
        with ``potential`` (a checked ``ti.func``) and ``params`` (checked (P,) floats). Its
        kernels are compiled here; one Taichi cannot compile raises and nothing is added."""
        from .potential import ParticlePotential, _save

        rows = np.ones(self.emitters.count, np.int32)
        if emitter_rows is not None:
            rows[:] = 0
            rows[list(emitter_rows)] = 1
        if self.adaptive and self._vel_kept is None:
            import taichi as ti

            self._vel_kept = ti.Vector.field(3, ti.f32, max(1, self.layout.capacity))
            _save(self.state.particle_vel, self._vel_kept, 0)  # compiled now, not at the first step
        pot = ParticlePotential(potential, params, rows, self.state, self.integrator.nonfinite_t, name)
        pot.compile()
        self.potentials.append(pot)
        # step doubling estimates the inner step's error only, not the splitting's: an adaptive
        # step never grows past the configured h while a potential acts (as with interactions)
        self.driver.policy.h_max = min(self._h_max, self.cfg.solver.h)

    def clear_potentials(self) -> None:
        """Drop every potential (their fields stay allocated, unused): steps as built."""
        self.potentials = []
        self.driver.policy.h_max = self._h_max

    def energy(self) -> dict:
        """{potential name: Σ U(x_i) over the particles it acts on (J/kg, unit masses)}; {}
        without potentials."""
        return {p.name: p.energy() for p in self.potentials}

    def first_nonfinite(self):
        f = self.integrator.nonfinite_t
        bad = float(f[None])
        if bad >= NO_FAILURE:
            return None
        f[None] = NO_FAILURE
        return bad

    # -- emitters added between frames ----------------------------------------------------------
    def why_not_add(self, cfg):
        """Why ``cfg`` (this scene's config with emitters appended) cannot take its new emitters
        in place, or None: they need spare rows and slots, the compiled force terms and no
        sub-emitter links."""
        n, new = len(self.cfg.emitters), cfg.emitters[len(self.cfg.emitters):]
        if cfg.model_copy(update={"emitters": list(self.cfg.emitters)}) != self.cfg:
            return "the config changed elsewhere"
        if len(cfg.emitters) > self.emitters.count:
            return f"no spare emitter row ({self.emitters.count - n} spare)"
        need = sum(pool_sizes(cfg.emitters, 1.0 / cfg.fps)[n:])
        if need > self.layout.spare:
            return f"its pool needs {need:,} slots, {self.layout.spare:,} spare"
        if any(e.sub_emitters for e in new):
            return "it has sub-emitters"
        if any(e.two_way for e in new) and self.pusher is None:
            return "it pushes rigid bodies (two_way) and the scene was built without two-way coupling"
        if any(e.interact is not None for e in new):
            return "it interacts (the interactions are built with the scene)"
        if not self.forces.covers(cfg.forces, cfg.emitters):
            return "it needs a force term the scene did not compile"
        return None

    def add_emitters(self, cfg) -> None:
        """Take the emitters ``cfg`` appends (checked by :meth:`why_not_add`; their inputs already
        in the control): rings from the spare slots, parameters into spare rows. Writes fields
        only: nothing is allocated or compiled."""
        for size in pool_sizes(cfg.emitters, 1.0 / cfg.fps)[len(self.cfg.emitters):]:
            self.layout.take(size)
        with self.writes.held():
            self.emitters.set_configs(cfg.emitters)
            self.forces.set_emitters(cfg.emitters)
        if self.pusher is not None:
            self.pusher.masses = self._masses(cfg.emitters, self.emitters.count)
        self.cfg = cfg

    def reset(self) -> None:
        """Back to the state the build left (an empty pool at t = 0, the built emitters only),
        keeping every field and compiled kernel: a scene reused for a level restart."""
        with self.writes.held():  # (parameters and zeroed counters: one launch)
            if self.cfg is not self._built:
                self.layout.drop_after(len(self._built.emitters))
                self.emitters.set_configs(self._built.emitters)
                self.forces.set_emitters(self._built.emitters)
                if self.pusher is not None:
                    self.pusher.masses = self._masses(self._built.emitters, self.emitters.count)
                self.cfg = self._built
            self.emitters.reset()
        if self.pusher is not None:
            self.pusher.clear()
        clear_pool(self.state)
        I = self.integrator
        I.nonfinite_t[None] = NO_FAILURE
        I.contact_log.count[None] = 0
        I.hits[None] = 0
        for p in self.potentials:  # (kept: the API drops them from a scene it takes for reuse)
            p.bad_t[None] = 1e30
        self.driver.reset()
        self._alive, self._held = None, None

    def save_positions(self) -> None:
        """Keep where the particles are (``particle_prev_pos``) before a game step, for drawing
        between the last two steps."""
        if self.state.interpolate and self.layout.capacity:
            save_positions(self.state)

    # -- read-back ----------------------------------------------------------------------------------
    def count_alive(self) -> int:
        """Live slots (particles not yet born this step included): one read-back per advance."""
        if self._alive is None:
            self._alive = int(integrate.count_alive(self.state.particle_alive, self.layout.capacity,
                                                    self.emitters.dropped, 0))
        return self._alive

    def ring_size(self, e: int) -> int:
        """Slots of emitter ``e``'s ring (pool layout)."""
        return int(self.layout.sizes[e])

    def dropped(self) -> int:
        """Births dropped so far (a ring full of live particles), all emitters together."""
        E = self.emitters
        return int(integrate.count_alive(self.state.particle_alive, 0, E.dropped, len(E.configs)))

    def contacts(self, names=(), shapes=()):
        """Every contact recorded since the previous call (:class:`~engine.contacts.Contacts`,
        sorted by time then pool slot; ``dropped``: those that did not fit the buffer); drains.
        ``names``, ``shapes``: the shape table's (default: this system's table's); each row names
        the particle's emitter."""
        I = self.integrator
        if not names and not shapes and self.colliders is not None:
            names, shapes = self.colliders.names, self.colliders.parties
        emitters = tuple(e.name for e in self.cfg.emitters)
        if not I.record:
            return Contacts.empty(names, kind="particle", group_names=emitters, shapes=shapes)
        return I.contact_log.drain(names, emitters, shapes)

    def carry_from(self, old: "ParticleSystem") -> None:
        """Copy each named emitter's ring (particles, head, serial, clock) from ``old`` (the same
        scene before a rebuild) into this pool."""
        src = {f: getattr(old.state, f).to_numpy() for f in PARTICLE_FIELDS}
        dst = {f: getattr(self.state, f).to_numpy() for f in PARTICLE_FIELDS}
        old_names = [c.name for c in old.emitters.configs]
        for e_new, c in enumerate(self.emitters.configs):
            if not c.name or c.name not in old_names:
                continue
            e_old = old_names.index(c.name)
            a, n_old = old.layout.starts[e_old], old.layout.sizes[e_old]
            b, n_new = self.layout.starts[e_new], self.layout.sizes[e_new]
            n = min(n_old, n_new)
            for f in PARTICLE_FIELDS:
                dst[f][b:b + n] = src[f][a:a + n]
            dst["particle_emitter"][b:b + n] = e_new
            self.emitters.clocks[e_new] = copy.copy(old.emitters.clocks[e_old])
            self.emitters.emitter_head[e_new] = int(old.emitters.emitter_head[e_old]) % n_new
            self.emitters.emitter_serial[e_new] = int(old.emitters.emitter_serial[e_old])
        for f in PARTICLE_FIELDS:
            getattr(self.state, f).from_numpy(dst[f])

