"""The layers of the code, read from the imports (AST, nothing is imported or run).

Rules (README, "How the code is laid out"):
- the core never imports the tools (``engine.tools``);
- ``engine.ode`` imports nothing of particles, springs, scene, config, render or api;
- the config package's import closure holds no Taichi (validating a file needs no compiler).
Each rule is also checked against a planted violation, so a checker that sees nothing fails.
"""
import ast
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def module_name(path):
    rel = os.path.relpath(path, ROOT)[:-3].replace(os.sep, ".")
    return rel[: -len(".__init__")] if rel.endswith(".__init__") else rel


def is_package(path):
    return os.path.basename(path) == "__init__.py"


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


def graph(extra=None):
    """{module: imported module names} for every module of engine/ and effects/; ``extra`` adds
    or replaces sources ({module name: (source, is_package)}) for planted violations."""
    g = {}
    for top in ("engine", "effects"):
        for dp, _, files in os.walk(os.path.join(ROOT, top)):
            for f in files:
                if f.endswith(".py"):
                    p = os.path.join(dp, f)
                    with open(p, encoding="utf-8") as fh:
                        g[module_name(p)] = imports_of(fh.read(), module_name(p), is_package(p))
    for name, (src, pkg) in (extra or {}).items():
        g[name] = imports_of(src, name, pkg)
    return g


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


def violations(g):
    bad = []
    for m, deps in g.items():
        if in_pkg(m, "engine") and not in_pkg(m, "engine.tools") and m != "engine.__main__":
            bad += [f"{m} imports {d} (the core never imports the tools)"
                    for d in deps if in_pkg(d, "engine.tools")]
        if in_pkg(m, "engine.ode"):
            for layer in ("engine.particles", "engine.springs", "engine.scene", "engine.config",
                          "engine.render", "engine.api", "engine.bodies"):
                bad += [f"{m} imports {d} (engine.ode stands alone)" for d in deps if in_pkg(d, layer)]
    taichi = sorted(d for d in closure(g, "engine.config") if in_pkg(d, "taichi"))
    if taichi:
        bad.append(f"engine.config's import closure holds {taichi[0]} (validation needs no Taichi)")
    return bad


def test_layers_hold():
    assert violations(graph()) == []


@pytest.mark.parametrize("name, source, pkg, rule", [
    ("engine.scene", "from .tools import cli\n", False, "never imports the tools"),
    ("engine.render.raster", "from ..tools.bench import common\n", False, "never imports the tools"),
    ("engine.ode.solve", "from ..particles.pool import ParticleState\n", False, "stands alone"),
    ("engine.ode.solve", "import engine.scene\n", False, "stands alone"),
    ("engine.config.load", "from ..particles import pool\n", False, "no Taichi"),
])
def test_planted_violation_is_caught(name, source, pkg, rule):
    """The checker is not blind: each rule fails on a violation planted in a real module."""
    bad = violations(graph({name: (source, pkg)}))
    assert any(rule in b for b in bad), bad
