"""User energies: a Python ``ti.func`` energy of an element's k nodes, forces by Taichi autodiff,
computed deterministically (PHYSICS.md, "Energy-based models").

Taichi's reverse mode turns every global read into a float atomic add into the adjoint, so a
kernel reading shared vertices sums their gradients in thread order (not byte-identical). Here the
kernel that is differentiated reads only **per-element copies** ``xe[e]`` (3 × k, gathered from
the node positions first): each copy's adjoint has one writer, the element's own thread. The
per-node force is then the fixed-order CSR sum of the slots (as every element group does). The
energy function sees its element only — ``energy(x, p)`` with ``x`` the 3 × k matrix of node
positions (columns, m) and ``p`` the element's parameter vector — so it cannot read neighbours
(the loops of run-time length Taichi's autodiff mishandles have nowhere to come from); it must be
a ``ti.func`` (anything else is refused with a message).

Kernels are built once per group (per energy function), never per frame. A group is an XPBD
constraint group too (C = √(2ψ), α = 1, as for the solids' materials) and reports its energy by
name. The stiffness guard cannot see a user energy's stiffness: choose ``substeps`` yourself.
"""
import numpy as np
import taichi as ti

from ..geometry.colouring import greedy_colors, schedule
from ..runtime import cfg_optimized
from .elements import node_slots


def fields_read(fn, seen=None) -> list:
    """The Taichi fields and ndarrays a ``ti.func`` reaches through its globals and closure
    (and those of the ``ti.func`` s it calls), as "name" or "name.attr": an energy or potential
    that reads one sees state other than its element's x and p (a neighbour's position, a
    height map) — Taichi's autodiff gives no gradient through an index, so its forces would be
    silently wrong. Empty for a function that reads only its arguments and constants."""
    import inspect

    from taichi.lang._ndarray import Ndarray
    from taichi.lang.field import Field

    seen = set() if seen is None else seen
    py = inspect.unwrap(fn)
    code = getattr(py, "__code__", None)
    if code is None or code in seen:
        return []
    seen.add(code)
    scope = dict(getattr(py, "__globals__", {}))
    if py.__closure__:
        scope.update({n: c.cell_contents for n, c in zip(code.co_freevars, py.__closure__)
                      if _filled(c)})
    names = set(code.co_names) | set(code.co_freevars)
    found = []
    for n in sorted(names):
        if n not in scope:
            continue
        v = scope[n]
        if isinstance(v, (Field, Ndarray)):
            found.append(n)
        elif getattr(v, "_is_taichi_function", False):
            found += fields_read(v, seen)
        elif not inspect.ismodule(v):
            found += [f"{n}.{a}" for a in sorted(names) if isinstance(getattr(v, a, None), (Field, Ndarray))]
    return found


def _filled(cell) -> bool:
    try:
        cell.cell_contents
    except ValueError:  # a closure cell not yet assigned
        return False
    return True


def check_reads(key: str, fn) -> None:
    """Refuse a ``ti.func`` that reads Taichi fields (:func:`fields_read`) in one line naming
    them; ``key``: how the message names the argument ("energy", "add_potential: potential")."""
    found = fields_read(fn)
    if found:
        import inspect

        name = getattr(inspect.unwrap(fn), "__name__", "?")
        raise ValueError(f"{key}: {name} reads the Taichi field(s) {', '.join(found)}: it may read only its "
                         f"arguments (x, p) and constants — a field read inside gets no gradient through its "
                         f"index (silently wrong forces); pass what it needs in params")


def central_difference_forces(energy, field, X, eps: float) -> np.ndarray:
    """(N, 3) −∂E/∂x by central differences: ``energy(field)`` → E (J) of the positions written
    into ``field`` (N vec3, f64), each coordinate of ``X`` (N, 3) moved by ±``eps`` m in turn (a
    reference for gradient checks; ``field`` is left at the last probe)."""
    X = np.asarray(X, np.float64)
    fd = np.zeros_like(X)
    for i in range(len(X)):
        for c in range(3):
            p = X.copy()
            p[i, c] += eps
            field.from_numpy(p)
            ep = energy(field)
            p[i, c] -= 2 * eps
            field.from_numpy(p)
            fd[i, c] = -(ep - energy(field)) / (2 * eps)
    return fd


@ti.kernel
def _gather(g: ti.template(), w: ti.template(), A: ti.template(), j: ti.i32):
    """fe = −∂ψ/∂xe per slot (one writer each), then A[j, i] += w_i Σ its slots in order."""
    for e in range(g.count):
        for s in ti.static(range(g.arity)):
            g.fe[e * g.arity + s] = -ti.Vector([g.xe.grad[e][0, s], g.xe.grad[e][1, s], g.xe.grad[e][2, s]])
    for i in range(g.n_nodes):
        f = ti.Vector.zero(g.dtype, 3)
        for q in range(g.slot_offset[i], g.slot_offset[i + 1]):
            f += g.fe[g.slot[q]]
        A[j, i] = A[j, i] + w[i] * f


@ti.kernel
def _clear(g: ti.template()):
    for e in range(g.count):
        g.mult[e] = 0


class UserEnergy:
    """``energy``: a ``ti.func`` (x: 3 × k matrix, p: vector of P) → ψ (J); ``nodes``: (E, k) node
    indices; ``params``: (E, P) per-element parameters (or None: P = 1, zeros); ``dtype`` of the
    system (f64 for gradient checks). ``name`` labels its energy."""

    def __init__(self, energy, nodes, n_nodes: int, params=None, dtype=ti.f32, name: str = "user"):
        if not getattr(energy, "_is_taichi_function", False):
            raise ValueError(f"energy: must be a @ti.func of (x, p), got {type(energy).__name__}")
        check_reads("energy", energy)
        nodes = np.asarray(nodes, np.int64)
        if nodes.ndim != 2 or nodes.shape[1] < 1 or nodes.shape[1] > 8:
            raise ValueError(f"nodes: expected an (E, k) array with 1 <= k <= 8, got shape {nodes.shape}")
        if len(nodes) and (nodes.min() < 0 or nodes.max() >= n_nodes):
            raise ValueError(f"nodes: index out of range (the body has {n_nodes} nodes)")
        self.kind, self.name, self.dtype = "user", name, dtype
        self.count, self.arity, self.n_nodes = len(nodes), nodes.shape[1], n_nodes
        params = np.zeros((len(nodes), 1)) if params is None else np.asarray(params, np.float64).reshape(len(nodes), -1)
        E, N, k, P = max(1, self.count), max(1, n_nodes), self.arity, params.shape[1]
        npd = np.float64 if dtype == ti.f64 else np.float32
        self.nodes = ti.Vector.field(k, ti.i32, E)
        buf = np.zeros((E, k), np.int32)
        buf[: self.count] = nodes
        self.nodes.from_numpy(buf)
        self.p = ti.Vector.field(P, dtype, E)
        pb = np.zeros((E, P))
        pb[: self.count] = params
        self.p.from_numpy(pb.astype(npd))
        self.xe = ti.Matrix.field(3, k, dtype, E, needs_grad=True)  # per-element copies
        self.psi = ti.field(dtype, E, needs_grad=True)
        self.fe = ti.Vector.field(3, dtype, E * k)
        self.mult = ti.field(dtype, E)
        off, slot = node_slots(n_nodes, nodes)
        self.slot_offset = ti.field(ti.i32, N + 1)
        self.slot = ti.field(ti.i32, max(1, len(slot)))
        self.slot_offset.from_numpy(np.concatenate([off, np.full(N + 1 - len(off), off[-1], np.int32)]))
        self.slot.from_numpy(np.concatenate([slot, np.zeros(max(1, len(slot)) - len(slot), np.int32)]))
        colors, nc = greedy_colors(n_nodes, nodes)
        order, self.color_ranges = schedule(colors, nc)
        self.color_elem = ti.field(ti.i32, E)
        self.color_elem.from_numpy(np.concatenate([order, np.zeros(E - len(order), np.int64)]).astype(np.int32))
        self._build(energy)

    def _build(self, energy):
        g, k, dt = self, self.arity, self.dtype

        @ti.kernel
        def copy_in(X: ti.template()):
            for e in range(g.count):
                nd = g.nodes[e]
                for s in ti.static(range(k)):
                    for c in ti.static(range(3)):
                        g.xe[e][c, s] = X[nd[s]][c]

        @ti.kernel
        def element_energy():  # differentiated: reads only xe[e] and p[e] (one writer per adjoint)
            for e in range(g.count):
                g.psi[e] = energy(g.xe[e], g.p[e])

        @ti.kernel
        def total() -> ti.f64:
            s = ti.cast(0, ti.f64)
            ti.loop_config(serialize=True)
            for e in range(g.count):
                s += ti.cast(g.psi[e], ti.f64)
            return s

        @ti.kernel
        def project(X: ti.template(), w: ti.template(), h: ti.f64, lo: ti.i32, hi: ti.i32):
            """One colour [lo, hi): a launch per colour (a user energy may be long to compile)."""
            hh = ti.cast(h, dt)
            for q in range(lo, hi):
                e = g.color_elem[q]
                nd = g.nodes[e]
                C = ti.sqrt(2 * ti.max(g.psi[e], 0))
                den = ti.cast(0, dt)
                for s in ti.static(range(k)):
                    for cc in ti.static(range(3)):
                        den += w[nd[s]] * (g.xe.grad[e][cc, s] / ti.max(C, 1e-30)) ** 2
                at = 1 / (hh * hh)
                if C > 1e-12 and den > 0:
                    dlam = (-C - at * g.mult[e]) / (den + at)
                    g.mult[e] += dlam
                    for s in ti.static(range(k)):
                        X[nd[s]] += w[nd[s]] * dlam / C * ti.Vector(
                            [g.xe.grad[e][0, s], g.xe.grad[e][1, s], g.xe.grad[e][2, s]])

        self._copy_in, self._element_energy, self._total, self._project = copy_in, element_energy, total, project

    def _grad(self, X) -> None:
        """ψ per element and ∂ψ/∂xe (autodiff, each adjoint slot written by its element only)."""
        self._copy_in(X)
        self.xe.grad.fill(0)
        self.psi.grad.fill(1)
        self._element_energy()
        with cfg_optimized():  # (an adjoint compiles right only with Taichi's CFG passes: engine.runtime)
            self._element_energy.grad()

    # -- the element-group protocol (engine.forces.elements.ElementGroup) ---------------------------
    def node_bounds(self):
        return np.zeros(self.n_nodes), np.zeros(self.n_nodes)

    def add_forces(self, X, V, w, A, j: int) -> None:
        if self.count:
            self._grad(X)
            _gather(self, w, A, j)

    def clear(self) -> None:
        _clear(self)

    def project(self, X, x_prev, w, h: float) -> None:
        # Jacobi within a colour would be wrong for shared nodes: the gradient is refreshed once
        # per sweep (per iteration), then every colour projects in order with it.
        self._grad(X)
        for lo, hi in self.color_ranges:
            self._project(X, w, h, lo, hi)

    def energy(self, X) -> float:
        if not self.count:
            return 0.0
        self._copy_in(X)
        self._element_energy()
        return float(self._total())

    def forces(self, X) -> np.ndarray:
        """(N, 3) −∇ψ (N) at X, float64, for tests and gradient checks."""
        self._grad(X)
        fe = -self.xe.grad.to_numpy()[: self.count].astype(np.float64).reshape(self.count, 3, self.arity)
        nodes = self.nodes.to_numpy()[: self.count]
        out = np.zeros((self.n_nodes, 3))
        for s in range(self.arity):
            for c in range(3):
                out[:, c] += np.bincount(nodes[:, s], fe[:, c, s], self.n_nodes)
        return out

    def check_gradient(self, X, eps: float = 1e-6) -> float:
        """Largest relative difference between the autodiff forces and central differences of the
        energy at X (an (N, 3) array): gradient checks only mean something in f64."""
        if self.dtype != ti.f64:
            raise ValueError("check_gradient: gradient checks need dtype=ti.f64 (f32 central differences "
                             "carry ~1e-3 relative error, so a wrong gradient would pass)")
        X = np.asarray(X, np.float64)
        field = ti.Vector.field(3, ti.f64, max(1, self.n_nodes))
        field.from_numpy(X)
        f = self.forces(field)
        fd = central_difference_forces(self.energy, field, X, eps)
        return float(np.max(np.abs(f - fd)) / max(1e-300, np.max(np.abs(fd))))
