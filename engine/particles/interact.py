"""Particles that interact: position-based constraints and pair forces inside the pool's step.

After the integrator's step (forces, colliders) the pool's step calls :meth:`Interactions.step`
(Lie splitting: first order in h for the coupling, whatever the integrator's own order):

- the deterministic neighbour grid (:class:`~engine.geometry.grid.HashGrid`) is rebuilt from the
  live, born slots of emitters with a grid kind;
- ``iterations`` Jacobi sweeps of position constraints (Müller et al. 2007, position based
  dynamics; Jacobi because each particle gathers its own correction from its neighbours' positions
  of the previous sweep: no float atomics, the same bytes for any thread count). Every pair's
  correction is exactly antisymmetric in IEEE arithmetic (a − b = −(b − a), products of negated
  pairs are exact), so momentum is conserved up to the rounding of each particle's sum;
  - ``granular``: contact at 2·radius with position-based friction (Macklin et al. 2014, "Unified
    particle physics", §6.1: static friction removes the relative tangential displacement while it
    is below μ·penetration, kinetic friction scales it to μ·penetration) and optional cohesion (a
    pull back to touching for pairs a little apart);
  - ``fluid``: position-based fluids (Macklin & Müller 2013): the density constraint
    C_i = ρ_i/ρ₀ − 1 (eq. 1, clamped at 0 so a free surface is not pulled inward), λ_i (eq. 11 with
    the relaxation ε), Δp_i (eq. 14) with the artificial pressure s_corr (eq. 13, k = 0.1, Δq = 0.2h,
    n = 4); rest spacing s = 2·radius, kernel support h = 2s, m = 1 and ρ₀ the kernel sum over a cubic
    lattice of spacing s, so a lattice at spacing s is exactly at rest density (the terms:
  :mod:`engine.particles.fluid`);
  - ``repel``: one soft push apart of pairs closer than 2·radius (a fraction REPEL of the overlap);
- the velocities take the corrections, v += Δx/h (the PBD velocity update v = (x* − x)/h);
- fluid: XSPH viscosity (eq. 17), vorticity confinement (eqs. 15–16) and a surface-tension term
  (the cohesion kernel of Akinci et al. 2013, "Versatile surface tension and adhesion for SPH");
- ``gravity``: a kick v += h·a(x) with softened pair attraction a_i = G m Σ_j r_ij/(|r_ij|² + ε²)^{3/2},
  over all pairs (a per-i gather; ``method = "direct"``, or "auto" up to AUTO_DIRECT gravity
  slots) or by a particle–mesh approximation on the host (``"mesh"``, or "auto" beyond) (:mod:`engine.particles.pm`: cloud-in-cell on a 32³ grid, isolated
  FFT convolution; momentum kept to rounding, forces smoothed over about a cell);
- every member is projected onto the colliders again (after the constraint solve), so every kind
  still collides with them.
"""
import math

import numpy as np
import taichi as ti

from .. import runtime
from ..geometry.grid import HashGrid, NeighbourLists
from ..launch import data_oriented, fast_method
from . import pm
from .fluid import FLUID_EPS, S_CORR_DQ, S_CORR_K, FluidTerms, lattice_constants, poly6
from .pm import AUTO_DIRECT

KINDS = {"granular": 1, "fluid": 2, "gravity": 3, "repel": 4}
GRID_KINDS = ("granular", "fluid", "repel")
COHESION_RANGE = 0.1  # cohesion pulls pairs up to 2r·(1 + 0.1) apart back toward touching
GRANULAR_RELAX = 0.5  # Jacobi relaxation: a fixed factor (not 1/contact count: that breaks momentum)
# the speed a granular grain may leave a solve with (when above its speed before): a fraction of 2r/h: overlaps a step starts with
# (grains born into one another, a fast stream landing) are resolved without flinging grains out —
# a bound in the spirit of Macklin et al. 2014's pre-stabilisation (§4.4); resting piles never reach it
GRANULAR_MAX_SPEED = 0.1
REPEL = 0.25  # fraction of a repel overlap removed per step (soft)
GRAIN_SKIN = 0.6  # the neighbour lists' skin (a fraction of a cell) without fluid members
@data_oriented
class Interactions(FluidTerms):
    """The interactions of one scene's pool (built once; kernels compiled for the kinds present).

    ``configs``: the emitter configs (their ``interact`` tables; emitters of one kind share one
    table, the schema checks it); ``rows``: emitter rows allocated. Per-slot fields (capacity):
    ``slot_kind`` (i32, 0: none), ``member`` (i32: in the grid), ``x_pre``/``v_pre`` (vec3 f32: at
    the step's end before the solve, m and m/s), ``corr`` (vec3 f32: the solve's total Δx, m),
    ``delta`` (a sweep's Jacobi Δx); fluid adds ``lam`` (f32), ``omega`` (vec3, 1/s), ``vbuf``."""

    def __init__(self, state, configs, rows: int, colliders, sizes=None, starts=None):
        self.state, self.cap = state, max(1, state.capacity)
        self.colliders = colliders
        self.has_colliders = colliders is not None and colliders.count > 0
        self.params = {}
        kinds = np.zeros(max(1, rows), np.int32)
        for e, c in enumerate(configs):
            if c.interact is not None:
                kinds[e] = KINDS[c.interact.kind]
                self.params.setdefault(c.interact.kind, c.interact)
        self.emitter_kind = ti.field(ti.i32, shape=len(kinds))
        self.emitter_kind.from_numpy(kinds)
        # the slots the interacting emitters' rings span (rings are consecutive ranges in emitter
        # order; emitters added later never interact: engine.particles.system): every per-slot
        # loop runs over [lo, hi) only — a game's pool keeps spare slots (water: 2,508 of 18,892)
        self.lo, self.hi = 0, self.cap
        if sizes and starts:  # (the pool's PoolLayout: ring e is [starts[e], starts[e] + sizes[e]))
            on = [e for e in range(len(sizes)) if kinds[e] != 0]
            if on:
                self.lo, self.hi = int(starts[min(on)]), int(starts[max(on)] + sizes[max(on)])
        self.granular, self.fluid = "granular" in self.params, "fluid" in self.params
        self.gravity, self.repel = "gravity" in self.params, "repel" in self.params
        n = self.cap
        self.slot_kind = ti.field(ti.i32, shape=n)
        self.member = ti.field(ti.i32, shape=n)
        self.x_pre, self.v_pre = ti.Vector.field(3, ti.f32, shape=n), ti.Vector.field(3, ti.f32, shape=n)
        self.corr, self.delta = ti.Vector.field(3, ti.f32, shape=n), ti.Vector.field(3, ti.f32, shape=n)
        self.press = ti.field(ti.f32, shape=n)  # how far the colliders pushed back during the solve, m
        self.iterations = max([int(p.iterations) for k, p in self.params.items() if k != "gravity"] or [0])
        cell = 0.0
        self.g_coh, self.f_vort, self.f_tension = 0.0, 0.0, 0.0  # (compile-time switches below)
        if self.granular:
            p = self.params["granular"]
            self.g_d = 2.0 * p.radius
            self.g_mu, self.g_coh = float(p.friction), float(p.cohesion)
            self.g_reach = self.g_d * (1.0 + COHESION_RANGE) if self.g_coh > 0 else self.g_d
            cell = max(cell, self.g_reach)
        if self.fluid:
            p = self.params["fluid"]
            self.f_s = 2.0 * p.radius
            self.f_h = 2.0 * self.f_s
            self.f_rho0, g0 = lattice_constants(self.f_s, self.f_h)
            self.f_eps = FLUID_EPS * g0
            self.f_scorr = S_CORR_K / g0  # s_corr as a density error of k (scale-free, see module doc)
            self.f_wdq = poly6(S_CORR_DQ * self.f_h, self.f_h)
            self.f_visc, self.f_vort, self.f_tension = float(p.viscosity), float(p.vorticity), float(p.surface_tension)
            h = self.f_h
            self.f_cmax = 32.0 / (math.pi * h ** 9) * (h / 2) ** 6  # Akinci's C at its peak r = h/2
            self.lam = ti.field(ti.f32, shape=n)
            self.omega = ti.Vector.field(3, ti.f32, shape=n)
            self.vbuf = ti.Vector.field(3, ti.f32, shape=n)
            cell = max(cell, self.f_h)
        if self.repel:
            self.r_d = 2.0 * self.params["repel"].radius
            cell = max(cell, self.r_d)
        self.mesh = False  # gravity by particle–mesh (method "mesh", or "auto" past AUTO_DIRECT slots)
        if self.gravity:
            p = self.params["gravity"]
            self.gm = float(p.G) * float(p.mass)
            self.eps2 = float(p.softening) ** 2
            slots = sum(int(n) for e, n in enumerate(sizes) if kinds[e] == KINDS["gravity"]) if sizes else n
            self.mesh = p.method == "mesh" or (p.method == "auto" and slots > AUTO_DIRECT)
            if self.mesh:
                self.g_acc = ti.Vector.field(3, ti.f32, shape=n)  # the mesh's accelerations, m/s²
            else:  # the pair sum reads the gravity slots' positions packed in slot order, one
                # array per axis (SoA): the inner loop then vectorizes on plain 8-wide loads
                # instead of de-interleaving x, y, z (same sums, same bytes; galaxy's 9 M pairs a
                # step 11-13 -> 6.4-7.4 ms in a micro-benchmark)
                self.g_pos = ti.Vector.field(3, ti.f32, shape=n, layout=ti.Layout.SOA)
                self.g_count = ti.field(ti.i32, shape=())
        self.grid = HashGrid(n, cell, self.lo, self.hi) if cell > 0 else None
        # each member's neighbours listed once a step and reused by every gather while they hold
        # (engine.geometry.grid.NeighbourLists: every visitor here cuts off within the cell)
        # The skin: grains and repelled points (about a dozen neighbours within 1.2 cells) take a
        # wide one — a pour moves grains past a tenth of a cell within a step's sweeps and relisted
        # about 3 times a step; at 0.6 sand's listing + sweeps fell 7.8 → 6.2 ms a frame (profile,
        # 40 frames) — a fluid (~58 within 1.2 cells) the narrow one: at 0.4 its lists overflow
        # NEIGHBOURS and its sweeps tripled
        skin = NeighbourLists.SKIN if self.fluid else GRAIN_SKIN
        self.lists = NeighbourLists(self.grid, state.particle_pos, skin) if self.grid is not None else None
        self.listed = self.lists is not None  # (a compile-time switch)
        # on the CPU the sweeps and the velocity pass do not test ``stale`` themselves: it is read
        # here before each (a 5 µs read; kernels there run in order on this thread anyway) and a
        # kernel lists them again only when set — the listing's three loops in every sweep, empty
        # ~88 % of the time, cost a pool hand-off each (engine.runtime.one_thread). A GPU keeps the
        # test on the device: a read there waits for every kernel before it
        self.relist_on_host = self.listed and runtime._arch_in_use() == "cpu"  # (compile-time)

    # -- per-step entry --------------------------------------------------------------------------
    def step(self, h: float) -> None:
        """Interact over the step of h just taken (positions and velocities at its end)."""
        # (a kernel a stage: the grid, the lists and, on a GPU, the test for stale lists live in
        # them, so a step takes 2 + iterations launches and reads nothing back; it took
        # 5 + 2·iterations, one more a relisting, iterations + 1 of them reads of ``stale``. On the
        # CPU the test is such a read again, ``relist_on_host``: one more launch a relisting)
        # (each launched without Taichi's per-call Python: engine.launch; sand's 24 a frame)
        if self.grid is not None:
            self._launch("begin")
        else:
            self._launch("prepare")
        if self.mesh:
            self._mesh_gravity()
        for _ in range(self.iterations if self.grid is not None else 0):
            self._launch("sweep", h)
        self._launch("finish", h)

    def _launch(self, name: str, *args) -> None:
        """Stage ``name`` (``run_stage``), or a callable set on the instance under that name, run
        in its place (a test's hook: it wraps ``run_stage``, which on the CPU lists the neighbours
        again first when they are stale; the kernel alone does not)."""
        own = self.__dict__.get(name)
        if own is not None:
            own(*args)
        else:
            self.run_stage(name, *args)

    def run_stage(self, name: str, *args) -> None:
        """Kernel ``name`` on the fast launch; a sweep or the velocity pass first lists the
        neighbours again when they are stale (``relist_on_host``: tested here, on the CPU)."""
        if self.relist_on_host and name in ("sweep", "finish") and self.lists.stale[None]:
            _FAST["relist_all"](self)
        _FAST[name](self, *args)

    def _mesh_gravity(self) -> None:
        """The gravity slots' accelerations by particle–mesh (engine.particles.pm), at the step's
        end positions, into ``g_acc`` (the finish kernel's kick reads them)."""
        kind = self.slot_kind.to_numpy()
        on = np.flatnonzero(kind == KINDS["gravity"])
        acc = np.zeros((self.cap, 3), np.float32)
        if len(on) > 1:
            p = self.params["gravity"]
            x = self.state.particle_pos.to_numpy()[on]
            acc[on] = pm.pm_accelerations(x, float(p.G), float(p.mass), float(p.softening)).astype(np.float32)
        self.g_acc.from_numpy(acc)

    def stats(self) -> dict:
        if self.grid is None:
            return {}
        return dict(self.grid.stats(), unlisted=int(self.lists.unlisted[None]))

    def relist(self) -> None:
        """List each member's neighbours of its own kind (at the positions now)."""
        self.lists.build(self.member, self.slot_kind)

    # -- kernels ---------------------------------------------------------------------------------
    @ti.kernel
    def relist_all(self):
        """Every member's neighbours listed again (at the positions now)."""
        self.lists.relist(self.member, self.slot_kind, False)

    @ti.kernel
    def prepare(self):
        """Each slot's kind and membership; the step's end (x_pre, v_pre); no correction yet."""
        self._prepare()

    @ti.kernel
    def begin(self):
        """``prepare``, the grid rebuilt from the members and their neighbours listed."""
        self._prepare()
        self.grid.rebuild(self.state.particle_pos, self.member)
        self.lists.relist(self.member, self.slot_kind, False)

    @ti.func
    def _prepare(self):
        S = self.state
        for i in range(self.lo, self.hi):
            k = 0
            if S.particle_alive[i] != 0 and S.particle_age[i] > 0.0:
                k = self.emitter_kind[S.particle_emitter[i]]
            self.slot_kind[i] = k
            self.member[i] = 1 if (k == 1 or k == 2 or k == 4) else 0
            self.x_pre[i] = S.particle_pos[i]
            self.v_pre[i] = S.particle_vel[i]
            self.corr[i] = ti.Vector([0.0, 0.0, 0.0])
            self.press[i] = 0.0

    @ti.func
    def _granular(self, i, h):
        S = self.state
        xi = S.particle_pos[i]
        di = h * S.particle_vel[i] + self.corr[i]  # i's displacement over the step so far
        dx = ti.Vector([0.0, 0.0, 0.0])
        self.lists.visit(i, self.slot_kind, 1, self._granular_pair, (xi, di, h, dx))
        return GRANULAR_RELAX * dx

    @ti.func
    def _granular_pair(self, j, xi, di, h, dx: ti.template()):
        """Grain j's contact with the grain at xi (displaced by di over the step), added into dx."""
        S = self.state
        D, reach2 = self.g_d, self.g_reach * self.g_reach
        r = xi - S.particle_pos[j]
        d2 = r.dot(r)
        if 0.0 < d2 < reach2:
            d = ti.sqrt(d2)
            nrm = r / d
            if d < D:
                pen = D - d
                dx += 0.5 * pen * nrm
                rel = di - (h * S.particle_vel[j] + self.corr[j])
                t = rel - rel.dot(nrm) * nrm
                tl = t.norm()
                # static below μ·pen: all of t removed; kinetic: scaled to μ·pen
                dx -= 0.5 * t * ti.min(self.g_mu * pen / ti.max(tl, 1e-12), 1.0)
            elif ti.static(self.g_coh > 0):
                dx -= 0.5 * self.g_coh * (d - D) * nrm

    @ti.func
    def _repel(self, i):
        xi = self.state.particle_pos[i]
        dx = ti.Vector([0.0, 0.0, 0.0])
        self.lists.visit(i, self.slot_kind, 4, self._repel_pair, (xi, dx))
        return dx

    @ti.func
    def _repel_pair(self, j, xi, dx: ti.template()):
        r = xi - self.state.particle_pos[j]
        d2 = r.dot(r)
        if 0.0 < d2 < self.r_d * self.r_d:
            d = ti.sqrt(d2)
            dx += 0.5 * REPEL * (self.r_d - d) / d * r

    @ti.kernel
    def sweep(self, h: ti.f32):
        """One Jacobi sweep: every member's Δx from its neighbours' positions, then applied
        (after listing them again if a member has moved too far since: ``lists.stale``; on the
        CPU ``run_stage`` does that first, ``relist_on_host``)."""
        S = self.state
        if ti.static(not self.relist_on_host):
            self.lists.relist(self.member, self.slot_kind, True)
        if ti.static(self.fluid):
            for i in range(self.lo, self.hi):
                if self.slot_kind[i] == 2:
                    self.lam[i] = self._fluid_lambda(i)
        for i in range(self.lo, self.hi):
            k = self.slot_kind[i]
            dx = ti.Vector([0.0, 0.0, 0.0])
            if ti.static(self.granular):
                if k == 1:
                    dx = self._granular(i, h)
            if ti.static(self.fluid):
                if k == 2:
                    dx = self._fluid_delta(i)
            if ti.static(self.repel):
                if k == 4:
                    dx = self._repel(i)
            self.delta[i] = dx
        for i in range(self.lo, self.hi):
            if self.member[i] != 0:
                x = S.particle_pos[i] + self.delta[i]
                if ti.static(self.has_colliders):
                    # the colliders are constraints of every sweep too (else a grain pushed into the
                    # ground by those above would only be put back after the solve, overlapping them)
                    zero = ti.Vector([0.0, 0.0, 0.0])
                    nx, _v, n_in, _k, _w, _n, _s = self.colliders.project(x, zero, self.x_pre[i], zero, h)
                    if n_in > 0:
                        self.press[i] += (nx - x).norm()
                        x = nx
                S.particle_pos[i] = x
                self.corr[i] = x - self.x_pre[i]
                self.lists.moved(i, x)

    @ti.func
    def _gravity(self, i):
        """a_i = G m Σ_j (x_j − x_i) / (|x_j − x_i|² + ε²)^{3/2} over every other gravity slot (m/s²),
        in slot order over the packed positions (``_pack_gravity``): no branch in the loop, and i's
        own term is exactly zero (r = 0, ε > 0), so it needs no test either."""
        xi = self.state.particle_pos[i]
        a = ti.Vector([0.0, 0.0, 0.0])
        for k in range(self.g_count[None]):
            r = self.g_pos[k] - xi
            d2 = r.dot(r) + self.eps2
            a += r / (d2 * ti.sqrt(d2))
        return self.gm * a

    @ti.func
    def _pack_gravity(self):
        """The gravity slots' positions into ``g_pos[0:g_count]`` in slot order (one serial pass)."""
        self.g_count[None] = 0
        ti.loop_config(serialize=True)
        for j in range(self.lo, self.hi):
            if self.slot_kind[j] == 3:
                self.g_pos[self.g_count[None]] = self.state.particle_pos[j]
                self.g_count[None] += 1

    @ti.kernel
    def finish(self, h: ti.f32):
        """Velocities from the corrections, the fluid's velocity terms, gravity's kick, then every
        member projected onto the colliders (x_pre, v_pre: the step's end before the solve)."""
        S = self.state
        if ti.static(self.listed and not self.relist_on_host):  # (the velocity gathers read the
            self.lists.relist(self.member, self.slot_kind, True)  # lists: fresh ones)
        for i in range(self.lo, self.hi):
            if self.member[i] != 0:
                v = S.particle_vel[i] + self.corr[i] / h
                if ti.static(self.granular):
                    if self.slot_kind[i] == 1:  # a solve may stop a grain, not fling it past the bound
                        top = ti.max(S.particle_vel[i].norm(), GRANULAR_MAX_SPEED * self.g_d / h)
                        s = v.norm()
                        if s > top:
                            v *= top / s
                S.particle_vel[i] = v
        if ti.static(self.f_vort > 0):
            for i in range(self.lo, self.hi):
                if self.slot_kind[i] == 2:
                    self.omega[i] = self._vorticity(i)
        if ti.static(self.fluid):
            for i in range(self.lo, self.hi):
                if self.slot_kind[i] == 2:
                    self.vbuf[i] = self._fluid_velocity(i, h)
        if ti.static(self.gravity and not self.mesh):
            self._pack_gravity()
            for i in range(self.lo, self.hi):
                if self.slot_kind[i] == 3:
                    self.delta[i] = S.particle_vel[i] + h * self._gravity(i)
        if ti.static(self.mesh):
            for i in range(self.lo, self.hi):
                if self.slot_kind[i] == 3:
                    self.delta[i] = S.particle_vel[i] + h * self.g_acc[i]
        for i in range(self.lo, self.hi):
            k = self.slot_kind[i]
            if k != 0:
                v = S.particle_vel[i]
                if ti.static(self.fluid):
                    if k == 2:
                        v = self.vbuf[i]
                if ti.static(self.gravity):
                    if k == 3:
                        v = self.delta[i]
                x = S.particle_pos[i]
                if ti.static(self.has_colliders):
                    nx, nv, n_in, kill, _w, nrm, _s = self.colliders.project(x, v, self.x_pre[i], self.v_pre[i], h)
                    x, v = nx, nv
                    if ti.static(self.granular):
                        if k == 1 and n_in > 0:
                            # grain–collider friction at the position level (Macklin et al. 2014,
                            # eq. 24 against a static shape): the colliders' push back in the sweeps
                            # is the normal load (press); its tangential part is held (static) or cut by μ·load
                            c = self.corr[i]
                            t = c - c.dot(nrm) * nrm
                            tl = t.norm()
                            cut = t * ti.min(self.g_mu * self.press[i] / ti.max(tl, 1e-12), 1.0)
                            x -= cut
                            v -= cut / h
                    if kill != 0:
                        S.particle_alive[i] = 0
                S.particle_pos[i] = x
                S.particle_vel[i] = v


_FAST = {name: fast_method(Interactions, name) for name in ("begin", "prepare", "sweep", "finish", "relist_all")}
