"""Element groups: one energy term evaluated over a soft body's elements, for the explicit methods
(forces), XPBD (a constraint group) and the energy diagnostic, all from engine.forces.terms.

Determinism (PHYSICS.md, "Energy-based models"): each element writes its k gradient slots
``fe[e, s]`` (one writer per slot, no atomics); each node then sums its slots in a fixed order (a
CSR list of flat slots e·k + s, increasing), as the spring gather does. So the forces are
bit-identical for any thread count. The XPBD projection sweeps a greedy colouring of the elements
(engine.geometry.colouring): no two elements of a colour share a node.

Kinds (``KINDS``; k nodes per element; the stiffness given to the group and its unit):

* ``bending`` (4: hinge a, b, wings c, d; k N·m per hinge): ψ = ½ k (θ − θ₀)²
* ``area`` (3; K N/m): ψ = ½ (K/A₀)(A − A₀)²
* ``volume`` (4: a tetrahedron; K Pa): ψ = ½ (K/V₀)(V − V₀)²
* ``elastic`` (4: a tetrahedron; a material (model, μ, λ) and Kelvin–Voigt η Pa·s): ψ = V₀ Ψ(F).
  Its XPBD form is the energy itself as a constraint, C = √(2ψ) with α = 1 (ψ = ½ C²/α; Bender,
  Koschier, Charrier & Weber 2014, "Position-based simulation of continuum materials", §4), with
  ∇C = ∇ψ / C.

User energies (Taichi autodiff over per-element copies) are :mod:`engine.forces.user`.
"""

import numpy as np
import taichi as ti

from ..geometry.colouring import greedy_colors, schedule, serial_sweep
from . import terms
from ..launch import data_oriented

KINDS = {"bending": 4, "area": 3, "volume": 4, "elastic": 4}
_KIND_ID = {"bending": 0, "area": 1, "volume": 2, "elastic": 3}


def node_slots(n_nodes: int, elems: np.ndarray):
    """CSR (offset (N+1,), slot (E·k,)) listing, per node, the flat slots e·k + s where it appears,
    increasing: the fixed order of the per-node sum."""
    flat = np.asarray(elems, np.int64).ravel()
    order = np.argsort(flat, kind="stable")  # stable: slots of a node stay increasing
    offset = np.zeros(n_nodes + 1, np.int64)
    np.cumsum(np.bincount(flat, minlength=n_nodes), out=offset[1:])
    return offset.astype(np.int32), order.astype(np.int32)


@ti.func
def _term(g: ti.template(), X: ti.template(), e):
    """(C or ψ, gradients as a 4-column matrix, ok) of element e: C for the constraint kinds,
    ψ for ``elastic``; column s is the gradient on node slot s (unused columns zero)."""
    dt = g.dtype
    nd = g.nodes[e]
    G = ti.Matrix.zero(dt, 3, 4)
    val = ti.cast(0, dt)
    ok = 1
    if ti.static(g.kind == "bending"):
        th, ga, gb, gc, gd, good = terms.dihedral_angle(dt, X[nd[0]], X[nd[1]], X[nd[2]], X[nd[3]])
        val = terms.wrap_angle(th - g.rest[e])
        G = ti.Matrix.cols([ga, gb, gc, gd])
        ok = good
    elif ti.static(g.kind == "area"):
        A, ga, gb, gc = terms.triangle_area(dt, X[nd[0]], X[nd[1]], X[nd[2]])
        val = A - g.rest[e]
        G = ti.Matrix.cols([ga, gb, gc, ti.Vector.zero(dt, 3)])
    elif ti.static(g.kind == "volume"):
        V, ga, gb, gc, gd = terms.tet_volume(dt, X[nd[0]], X[nd[1]], X[nd[2]], X[nd[3]])
        val = V - g.rest[e]
        G = ti.Matrix.cols([ga, gb, gc, gd])
    else:
        psi, ga, gb, gc, gd = terms.tet_elastic(dt, g.model, X[nd[0]], X[nd[1]], X[nd[2]], X[nd[3]],
                                                g.B[e], g.rest[e], g.mat[0], g.mat[1])
        val = psi
        G = ti.Matrix.cols([ga, gb, gc, gd])
    return val, G, ok


@ti.func
def element_force(g: ti.template(), X: ti.template(), V: ti.template(), e):
    """fe[e, s] = −∂ψ/∂x_s (+ damping) of element e (its k slots; no other element writes them)."""
    dt = g.dtype
    val, G, ok = _term(g, X, e)
    F = ti.Matrix.zero(dt, 3, 4)
    if ti.static(g.kind == "elastic"):
        F = -G
        if ti.static(g.eta > 0):
            nd = g.nodes[e]
            fa, fb, fc, fd = terms.tet_viscous(dt, V[nd[0]], V[nd[1]], V[nd[2]], V[nd[3]], g.B[e],
                                               g.rest[e], g.mat[2])
            F += ti.Matrix.cols([fa, fb, fc, fd])
    elif ok:
        F = -g.k[e] * val * G  # ψ = ½ k C²: −∇ψ = −k C ∇C
    for s in ti.static(range(g.arity)):
        g.fe[e * g.arity + s] = ti.Vector([F[0, s], F[1, s], F[2, s]])


@ti.func
def node_force(g: ti.template(), w: ti.template(), A: ti.template(), j, i):
    """A[j, i] += w_i Σ node i's slots, in their fixed (increasing) order."""
    f = ti.Vector.zero(g.dtype, 3)
    for q in range(g.slot_offset[i], g.slot_offset[i + 1]):
        f += g.fe[g.slot[q]]
    A[j, i] = A[j, i] + w[i] * f


@ti.kernel
def _forces(g: ti.template(), X: ti.template(), V: ti.template(), w: ti.template(), A: ti.template(),
            j: ti.i32):
    """fe per element, then A[j, i] += w_i Σ its slots in order."""
    for e in range(g.count):
        element_force(g, X, V, e)
    for i in range(g.n_nodes):
        node_force(g, w, A, j, i)


@ti.kernel
def _energy(g: ti.template(), X: ti.template()) -> ti.f64:
    """Σ ψ over the elements (J), f64, in element order (serial: deterministic)."""
    total = ti.cast(0, ti.f64)
    ti.loop_config(serialize=True)
    for e in range(g.count):
        val, G, ok = _term(g, X, e)
        if ti.static(g.kind == "elastic"):
            total += ti.cast(val, ti.f64)
        else:
            total += 0.5 * ti.cast(g.k[e], ti.f64) * ti.cast(val, ti.f64) ** 2
    return total


@ti.kernel
def _rest(g: ti.template(), X: ti.template()):
    """The rest value of each constraint kind (θ₀, A₀, V₀) from the term itself at X."""
    for e in range(g.count):
        nd = g.nodes[e]
        if ti.static(g.kind == "bending"):
            th, ga, gb, gc, gd, ok = terms.dihedral_angle(g.dtype, X[nd[0]], X[nd[1]], X[nd[2]], X[nd[3]])
            g.rest[e] = th
        elif ti.static(g.kind == "area"):
            A, ga, gb, gc = terms.triangle_area(g.dtype, X[nd[0]], X[nd[1]], X[nd[2]])
            g.rest[e] = A
        elif ti.static(g.kind == "volume"):
            V, ga, gb, gc, gd = terms.tet_volume(g.dtype, X[nd[0]], X[nd[1]], X[nd[2]], X[nd[3]])
            g.rest[e] = V


@ti.kernel
def _rest_gradients(g: ti.template(), X: ti.template()):
    """fe[e, s] = ∇_s C (or ∇_s ψ's linear part is not needed: elastic uses B) at X, for the guard."""
    for e in range(g.count):
        val, G, ok = _term(g, X, e)
        for s in ti.static(range(g.arity)):
            g.fe[e * g.arity + s] = ti.Vector([G[0, s], G[1, s], G[2, s]])


@ti.kernel
def _clear(g: ti.template()):
    for e in range(g.count):
        g.mult[e] = 0


@ti.func
def _project_one(g: ti.template(), X: ti.template(), w: ti.template(), hh, q):
    """Project the element at position q of the colour order (Macklin et al. 2016, eq. 18)."""
    dt = g.dtype
    e = g.color_elem[q]
    val, G, ok = _term(g, X, e)
    C = val
    alpha = ti.cast(1, dt)
    if ti.static(g.kind == "elastic"):  # C = √(2ψ), ∇C = ∇ψ / C, α = 1
        C = ti.sqrt(2 * ti.max(val, 0))
        if C > terms.EPS:
            G = G / C
        else:
            ok = 0
    else:
        alpha = 1 / g.k[e]
    nd = g.nodes[e]
    den = ti.cast(0, dt)
    for s in ti.static(range(g.arity)):
        gs = ti.Vector([G[0, s], G[1, s], G[2, s]])
        den += w[nd[s]] * gs.norm_sqr()
    at = alpha / (hh * hh)
    if ok and den > 0:
        dlam = (-C - at * g.mult[e]) / (den + at)
        g.mult[e] += dlam
        for s in ti.static(range(g.arity)):
            X[nd[s]] += w[nd[s]] * dlam * ti.Vector([G[0, s], G[1, s], G[2, s]])


@ti.func
def sweep_serial(g: ti.template(), X: ti.template(), w: ti.template(), hh):
    """Every colour in order on the calling thread (from inside a serial loop): no two elements
    of a colour share a node, so this is the per-colour sweep's result (as the springs'
    ``sweep_serial``)."""
    for q in range(g.count):
        _project_one(g, X, w, hh, q)


@ti.kernel
def _project(g: ti.template(), X: ti.template(), x_prev: ti.template(), w: ti.template(), h: ti.f64):
    """All colours in order (engine.xpbd.solver): one serial loop for a small group on the CPU
    (engine.geometry.colouring.serial_sweep), else a top-level loop a colour; one launch a sweep."""
    hh = ti.cast(h, g.dtype)
    if ti.static(serial_sweep(g.count)):  # every colour in order on this thread
        ti.loop_config(serialize=True)
        for q in range(g.count):
            _project_one(g, X, w, hh, q)
    else:
        for c in ti.static(range(len(g.color_ranges))):
            lo, hi = ti.static(g.color_ranges[c])
            for q in range(lo, hi):
                _project_one(g, X, w, hh, q)


@ti.kernel
def _project_range(g: ti.template(), X: ti.template(), w: ti.template(), h: ti.f64, lo: ti.i32, hi: ti.i32):
    """One colour [lo, hi) (a launch per colour: for the materials, whose projection is long enough
    that one unrolled copy per colour — 30 for a 6³ box — would take minutes to compile)."""
    hh = ti.cast(h, g.dtype)
    for q in range(lo, hi):
        _project_one(g, X, w, hh, q)


@data_oriented
class ElementGroup:
    """One term over elements. ``nodes``: (E, k) int node indices; ``positions``: (N, 3) rest
    positions (m) that define θ₀ / A₀ / V₀ / D_m; ``stiffness``: the kind's constant (see the module
    docstring); ``material``: (model name, μ, λ) for ``elastic``; ``damping``: η (Pa·s) for
    ``elastic``. Fields in ``dtype``. ``name`` labels its energy in :meth:`energy` reports."""

    def __init__(self, kind: str, nodes, positions, stiffness: float = 0.0, dtype=ti.f32, name: str = "",
                 material=None, damping: float = 0.0):
        if kind not in KINDS:
            raise ValueError(f"type: unknown energy {kind!r}; allowed: {', '.join(KINDS)}")
        k = KINDS[kind]
        nodes = np.asarray(nodes, np.int32).reshape(-1, k)
        pos = np.asarray(positions, np.float64).reshape(-1, 3)
        self.kind, self.arity, self.dtype, self.name = kind, k, dtype, name or kind
        self.count, self.n_nodes = len(nodes), len(pos)
        E, N = max(1, self.count), max(1, self.n_nodes)
        npd = np.float64 if dtype == ti.f64 else np.float32
        self.nodes = ti.Vector.field(k, ti.i32, E)
        self.rest = ti.field(dtype, E)
        self.k = ti.field(dtype, E)
        self.mult = ti.field(dtype, E)  # XPBD multipliers λ
        self.fe = ti.Vector.field(3, dtype, E * k)
        self.model, self.mu, self.lam, self.eta = 0, 0.0, 0.0, float(damping)
        if kind == "elastic":
            model, mu, lam = material
            if model not in terms.MODELS:
                raise ValueError(f"material.model: unknown value {model!r}; allowed: {', '.join(terms.MODELS)}")
            self.model = terms.MODELS.index(model)
            self.lame = (float(mu), float(lam))
            self.mu, self.lam = (terms.nh_params(mu, lam)[:2] if model == "neo_hookean" else (mu, lam))
            self.mu, self.lam = float(self.mu), float(self.lam)
            self.B = ti.Matrix.field(3, 3, dtype, E)
            # (μ, λ, η) in a field of the group's dtype: a Python float in a kernel is a constant of
            # the default f32, which would round an f64 material
            self.mat = ti.field(dtype, 3)
            self.mat.from_numpy(np.array([self.mu, self.lam, self.eta], npd))
        buf = np.zeros((E, k), np.int32)
        buf[: self.count] = nodes
        self.nodes.from_numpy(buf)
        off, slot = node_slots(self.n_nodes, nodes)
        self.slot_offset = ti.field(ti.i32, N + 1)
        self.slot = ti.field(ti.i32, max(1, len(slot)))
        self.slot_offset.from_numpy(np.concatenate([off, np.full(N + 1 - len(off), off[-1], np.int32)]))
        self.slot.from_numpy(np.concatenate([slot, np.zeros(max(1, len(slot)) - len(slot), np.int32)]))
        colors, nc = greedy_colors(self.n_nodes, nodes)
        order, self.color_ranges = schedule(colors, nc)
        self.color_elem = ti.field(ti.i32, E)
        self.color_elem.from_numpy(np.concatenate([order, np.zeros(E - len(order), np.int64)]).astype(np.int32))
        X = ti.Vector.field(3, dtype, N)
        X.from_numpy(np.concatenate([pos, np.zeros((N - len(pos), 3))]).astype(npd))
        if kind == "elastic":
            Dm = np.stack([pos[nodes[:, s]] - pos[nodes[:, 0]] for s in (1, 2, 3)], -1)  # (E, 3, 3) columns
            vol = np.linalg.det(Dm) / 6.0
            if self.count and np.min(vol) <= 0:
                raise ValueError(f"{self.name}: a tetrahedron has no positive rest volume ({np.min(vol):.3g} m³)")
            Bm = np.zeros((E, 3, 3))
            Bm[: self.count] = np.linalg.inv(Dm)
            self.B.from_numpy(Bm.astype(npd))
            rest = np.zeros(E)
            rest[: self.count] = vol
            self.rest.from_numpy(rest.astype(npd))
            self.rest_np = vol
        elif self.count:
            _rest(self, X)
            self.rest_np = self.rest.to_numpy()[: self.count].astype(np.float64)
            if kind in ("area", "volume") and np.min(self.rest_np) <= 0:
                raise ValueError(f"{self.name}: an element has no positive rest {'area' if kind == 'area' else 'volume'}")
            kk = np.full(E, float(stiffness))
            if kind in ("area", "volume"):
                kk[: self.count] = stiffness / self.rest_np  # ψ = ½ (K/A₀)(A − A₀)²
            self.k.from_numpy(kk.astype(npd))
        self._X, self._bounds = X, None  # the guard's bounds, computed when first asked for

    def _node_bounds(self, X):
        """(k_i, c_i): Gershgorin row sums of the term's Hessian at rest per node (N/m, N·s/m), for
        the stiffness guard: k |∇ᵢC| Σⱼ|∇ⱼC| (2 ks for a spring, the convention of network_bounds);
        for ``elastic`` (λ + 2μ) V₀ |gᵢ| Σⱼ|gⱼ| with gᵢ the shape-function gradients (rows of B)."""
        n = self.n_nodes
        kn, cn = np.zeros(n), np.zeros(n)
        if not self.count:
            return kn, cn
        nodes = self.nodes.to_numpy()[: self.count]
        if self.kind == "elastic":
            B = self.B.to_numpy()[: self.count].astype(np.float64)
            g = np.concatenate([-B.sum(1, keepdims=True), B], 1)  # (E, 4, 3): ∇_s of F's columns
            mu, lam = self.lame
            stiff, visc = (lam + 2 * mu) * self.rest_np, 2 * self.eta * self.rest_np
        else:
            _rest_gradients(self, X)
            g = self.fe.to_numpy()[: self.count * self.arity].reshape(self.count, self.arity, 3).astype(np.float64)
            stiff, visc = self.k.to_numpy()[: self.count].astype(np.float64), np.zeros(self.count)
        norms = np.linalg.norm(g, axis=2)  # (E, k)
        row = norms * norms.sum(1, keepdims=True)
        for s in range(self.arity):
            kn += np.bincount(nodes[:, s], stiff * row[:, s], n)
            cn += np.bincount(nodes[:, s], visc * row[:, s], n)
        return kn, cn

    def node_bounds(self):
        """(k_i, c_i) per node (see :meth:`_node_bounds`)."""
        if self._bounds is None:
            self._bounds = self._node_bounds(self._X)
        return self._bounds

    # -- the explicit methods, XPBD, the diagnostic -------------------------------------------------
    def add_forces(self, X, V, w, A, j: int) -> None:
        """A[j, i] += w_i f_i (one launch)."""
        if self.count:
            _forces(self, X, V, w, A, j)

    def clear(self) -> None:
        _clear(self)

    def project(self, X, x_prev, w, h: float) -> None:
        if self.kind == "elastic":
            for lo, hi in self.color_ranges:
                _project_range(self, X, w, h, lo, hi)
        else:
            _project(self, X, x_prev, w, h)

    def energy(self, X) -> float:
        return _energy(self, X) if self.count else 0.0
