"""The layers of the code, read from the imports (AST, nothing is imported or run).

Rules (README, "How the code is laid out"):
- the core never imports the tools (``particles_tools``);
- ``engine.ode`` imports nothing of particles, springs, scene, config, render, api, control,
  colliders or bodies;
- the config package's import closure holds no Taichi (validating a file needs no compiler);
- only ``engine.ode`` reads method coefficients (tableaus, splittings, a method's ``scheme``,
  stability polynomials): everyone else sees a method's name, order and cost;
- only the driver (``engine.ode.driver``) calls the step-size controller;
- physics rooms (particles, soft bodies, rigid bodies: :data:`PHYSICS_ROOMS`) never import one
  another: the scene (``engine.scene``) joins them; the shared rooms below them (ode, geometry,
  forces, xpbd, the System protocol, colliders, contacts) import no physics room;
- the renderer imports no physics room and not the scene: it draws what systems hand it;
- no import circle anywhere in the first-party packages (a module-level import cycle between two
  modules; imports inside functions count too, since they are still a circle of knowledge).
Each rule is also checked against a planted violation, so a checker that sees nothing fails.
"""
import ast
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def module_name(path):
    rel = os.path.relpath(path, ROOT)[:-3].replace(os.sep, ".")
    return rel[: -len(".__init__")] if rel.endswith(".__init__") else rel


def is_package(path):
    return os.path.basename(path) == "__init__.py"


def attributes_of(source):
    """Every attribute name read or called in ``source`` (``x.scheme``, ``ctrl.propose(...)``)."""
    return {node.attr for node in ast.walk(ast.parse(source)) if isinstance(node, ast.Attribute)}


def imports_of(source, name, package):
    """Absolute module names imported by ``source`` (module ``name``; ``package`` True for an
    ``__init__``), relative imports resolved, ``from X import y`` also yielding ``X.y``."""
    out = set()
    base = name.split(".") if package else name.split(".")[:-1]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parent = base[: len(base) - (node.level - 1)]
                mod = ".".join(parent + ([node.module] if node.module else []))
            else:
                mod = node.module
            out.add(mod)
            out.update(f"{mod}.{a.name}" for a in node.names)
    return out


def sources(extra=None):
    """{module: (source, is_package)} for every module of engine/ and effects/; ``extra`` adds or
    replaces sources for planted violations."""
    out = {}
    for top in ("engine", "effects", "particles_tools"):
        for dp, _, files in os.walk(os.path.join(ROOT, top)):
            for f in files:
                if f.endswith(".py"):
                    p = os.path.join(dp, f)
                    with open(p, encoding="utf-8") as fh:
                        out[module_name(p)] = (fh.read(), is_package(p))
    out.update(extra or {})
    return out


def graph(extra=None):
    """{module: imported module names} (see :func:`sources` for ``extra``)."""
    return {name: imports_of(src, name, pkg) for name, (src, pkg) in sources(extra).items()}


def closure(g, start):
    """Every module reachable from ``start`` by imports (third-party names included as leaves).
    Importing a.b.c runs a/__init__ and a/b/__init__ first, so parents count too."""
    seen, todo = set(), [start]
    while todo:
        m = todo.pop()
        if m in seen:
            continue
        seen.add(m)
        parts = m.split(".")
        todo += [".".join(parts[:k]) for k in range(1, len(parts))]
        todo += list(g.get(m, ()))
    return seen


def in_pkg(mod, pkg):
    return mod == pkg or mod.startswith(pkg + ".")


COEFFICIENT_MODULES = ("engine.ode.tableau", "engine.ode.splitting")
COEFFICIENT_NAMES = {"TABLEAUS", "SPLITTINGS", "ButcherTableau", "Splitting", "EULER", "MIDPOINT", "RK4",
                     "SYMPLECTIC_EULER", "VERLET"}
COEFFICIENT_ATTRIBUTES = {"scheme", "stability_polynomial"}
CONTROLLER_NAMES = {"StepDoublingController", "propose"}


def imported_name(dep, pkg="engine.ode"):
    """``y`` for a ``from engine.ode[.sub] import y`` entry, else None."""
    return dep.rsplit(".", 1)[1] if in_pkg(dep, pkg) and dep != pkg else None


# a room is a tuple of packages/modules; engine.bodies (config → spring network) is the soft-body room's
PHYSICS_ROOMS = {"particles": ("engine.particles",), "soft bodies": ("engine.springs", "engine.softbody", "engine.bodies"),
                 "rigid bodies": ("engine.rigid",)}
SHARED_ROOMS = ("engine.ode", "engine.geometry", "engine.forces", "engine.xpbd", "engine.system",
                "engine.colliders", "engine.contacts")
FIRST_PARTY = ("engine", "effects", "particles_tools")


def room_of(mod):
    return next((r for r, pkgs in PHYSICS_ROOMS.items() if any(in_pkg(mod, p) for p in pkgs)), None)


def cycles(g):
    """Import circles among first-party modules: one line per strongly connected component of
    more than one module (Tarjan, iterative), its members sorted."""
    nodes = [m for m in g if any(in_pkg(m, p) for p in FIRST_PARTY)]
    # importing a submodule runs its parent packages first: that edge is no circle of knowledge
    edges = {m: sorted({d for d in g[m] if d in g and d != m and not in_pkg(m, d)}) for m in nodes}
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]
    for root in nodes:
        if root in index:
            continue
        work = [(root, 0)]
        while work:
            v, i = work.pop()
            if i == 0:
                index[v] = low[v] = counter[0]
                counter[0] += 1
                stack.append(v)
                on.add(v)
            nbrs = edges.get(v, [])
            if i < len(nbrs):
                work.append((v, i + 1))
                w = nbrs[i]
                if w not in index:
                    work.append((w, 0))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            if work:
                u = work[-1][0]
                low[u] = min(low[u], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def violations(g, src=None):
    """Every broken rule, one line each; ``src`` ({module: (source, is_package)}) adds the
    rules that read attribute names, not only imports."""
    bad = []
    for m, deps in g.items():
        if in_pkg(m, "engine") and not in_pkg(m, "particles_tools") and m != "engine.__main__":
            bad += [f"{m} imports {d} (the core never imports the tools)"
                    for d in deps if in_pkg(d, "particles_tools")]
        if in_pkg(m, "engine.ode"):
            for layer in ("engine.particles", "engine.springs", "engine.scene", "engine.config",
                          "engine.render", "engine.api", "engine.bodies", "engine.control",
                          "engine.colliders"):
                bad += [f"{m} imports {d} (engine.ode stands alone)" for d in deps if in_pkg(d, layer)]
            continue
        bad += [f"{m} imports {d} (only engine.ode reads tableau coefficients)" for d in deps
                if any(in_pkg(d, c) for c in COEFFICIENT_MODULES) or imported_name(d) in COEFFICIENT_NAMES]
        bad += [f"{m} imports {d} (only the driver calls the controller)" for d in deps
                if in_pkg(d, "engine.ode.controller") or imported_name(d) in CONTROLLER_NAMES]
    for m, (text, _pkg) in (src or {}).items():
        if in_pkg(m, "engine.ode"):
            continue
        used = attributes_of(text)
        bad += [f"{m} reads .{a} (only engine.ode reads tableau coefficients)"
                for a in sorted(used & COEFFICIENT_ATTRIBUTES)]
        bad += [f"{m} calls .{a}() (only the driver calls the controller)"
                for a in sorted(used & CONTROLLER_NAMES)]
    for m, deps in g.items():
        room = room_of(m)
        if room is not None:
            bad += [f"{m} imports {d} (physics rooms never import one another: the scene joins them)"
                    for d in deps if room_of(d) not in (None, room)]
        if any(in_pkg(m, r) for r in SHARED_ROOMS):
            bad += [f"{m} imports {d} (a shared room imports no physics room)"
                    for d in deps if room_of(d) is not None or in_pkg(d, "engine.scene")]
        if in_pkg(m, "engine.render"):
            bad += [f"{m} imports {d} (the renderer imports no physics room)"
                    for d in deps if room_of(d) is not None or in_pkg(d, "engine.scene")]
    bad += [f"import circle: {' -> '.join(c)}" for c in cycles(g)]
    taichi = sorted(d for d in closure(g, "engine.config") if in_pkg(d, "taichi"))
    if taichi:
        bad.append(f"engine.config's import closure holds {taichi[0]} (validation needs no Taichi)")
    return bad


_BASE = {}


def check(extra=None):
    """Every broken rule in the tree, with ``extra`` planted (the tree is read and parsed once)."""
    if not _BASE:
        src = sources()
        _BASE.update(src=src, graph={n: imports_of(t, n, p) for n, (t, p) in src.items()})
    src = dict(_BASE["src"], **(extra or {}))
    g = dict(_BASE["graph"], **{n: imports_of(t, n, p) for n, (t, p) in (extra or {}).items()})
    return violations(g, src)


def test_layers_hold():
    assert check() == []


def test_config_imports_no_taichi_when_run():
    """The closure above reads imports; this runs one (engine.ode loads its Taichi parts lazily)."""
    code = "import sys, engine.config; print(sorted(m for m in sys.modules if m.startswith('taichi'))[:1])"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


@pytest.mark.parametrize("name, source, pkg, rule", [
    ("engine.scene", "from particles_tools import cli\n", False, "never imports the tools"),
    ("engine.render.raster", "import particles_tools.bench.common\n", False, "never imports the tools"),
    ("engine.ode.ivp", "from ..particles.pool import ParticleState\n", False, "stands alone"),
    ("engine.ode.ivp", "import engine.scene\n", False, "stands alone"),
    ("engine.ode.driver", "from ..control import Control\n", False, "stands alone"),
    ("engine.config.load", "from ..particles import pool\n", False, "no Taichi"),
    ("engine.config.schema", "from ..ode.steppers import make_step\n", False, "no Taichi"),
    ("engine.springs.system", "from ..ode.tableau import TABLEAUS\n", False, "tableau coefficients"),
    ("engine.springs.stability", "from ..ode import RK4\n", False, "tableau coefficients"),
    ("engine.particles.system", "b = METHODS[name].scheme.b\n", False, "tableau coefficients"),
    ("particles_tools.bench.step", "g = TAB.stability_polynomial()\n", False, "tableau coefficients"),
    ("engine.particles.system", "from ..ode.controller import StepDoublingController\n", False,
     "only the driver calls the controller"),
    ("engine.springs.system", "from ..ode import StepDoublingController\n", False,
     "only the driver calls the controller"),
    ("engine.springs.system", "ok, h = self.ctrl.propose(h, err)\n", False,
     "only the driver calls the controller"),
    ("engine.springs.system", "from ..particles.pool import ParticleState\n", False,
     "physics rooms never import one another"),
    ("engine.particles.system", "from ..bodies import SoftBody\n", False,
     "physics rooms never import one another"),
    ("engine.colliders", "from .particles import pool\n", False, "a shared room imports no physics room"),
    ("engine.render.mesh", "from ..springs.topology import cloth\n", False,
     "the renderer imports no physics room"),
    ("engine.render.renderer", "from ..scene import Scene\n", False, "the renderer imports no physics room"),
    ("engine.control", "from .scene import Scene\n", False, "import circle"),
])
def test_planted_violation_is_caught(name, source, pkg, rule):
    """The checker is not blind: each rule fails on a violation planted in a real module."""
    bad = check({name: (source, pkg)})
    assert any(rule in b for b in bad), bad
