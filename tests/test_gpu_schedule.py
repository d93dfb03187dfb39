"""No kernel launched per frame runs serialised: on a GPU a serialised kernel (or a top-level
loop over one index) is one thread, however many the device has.

Two checks: every kernel in the core's source is read (fast; the serial kernels allowed are the
ODE driver's fixed-step loop, which integrates one small state through time and is never part of
a frame, and the rigid XPBD solver's Gauss-Seidel passes over contacts and joints), and (slow) every shipped config is stepped and rendered while kernel launches are
recorded, and each launched kernel's source is read."""
import ast
import glob
import inspect
import os
import textwrap

import pytest
from taichi.lang import kernel_impl

from engine.api import ParticleScene

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIGS = sorted(glob.glob(os.path.join(ROOT, "configs", "*.toml")))


def serial_parts(source: str):
    """Why a kernel's source runs serially: a ``loop_config(serialize=True)`` or a top-level
    ``for`` over ``range(1)`` (a common way to force one thread); empty if neither."""
    tree = ast.parse(textwrap.dedent(source))
    fn = next(n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef))
    found = []
    for node in ast.walk(fn):
        if isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "loop_config":
            for kw in node.keywords:
                if kw.arg == "serialize" and getattr(kw.value, "value", False) is True:
                    found.append("loop_config(serialize=True)")
    for stmt in fn.body:
        if isinstance(stmt, ast.For) and isinstance(stmt.iter, ast.Call) \
                and getattr(stmt.iter.func, "id", "") == "range":
            args = [getattr(a, "value", None) for a in stmt.iter.args]
            if args in ([1], [0, 1]):
                found.append("top-level loop over a single index")
    return found


def launched_per_frame(path, frames=2):
    """The kernels (Python functions) launched while stepping and rendering ``frames`` frames,
    after one warm-up frame (which may run one-time set-up kernels)."""
    scene = ParticleScene.from_file(path)
    scene.step(1 / 60)
    scene.render(160, 90)
    from engine.launch import FastKernel

    seen = {}
    original, original_fast = kernel_impl.Kernel.__call__, FastKernel.__call__

    def record(self, *args, **kwargs):
        seen[self.func.__qualname__] = self.func
        return original(self, *args, **kwargs)

    def record_fast(self, *args, **kwargs):  # (engine.launch: launches that skip Kernel.__call__)
        func = self.kernel._primal.func
        seen[func.__qualname__] = func
        return original_fast(self, *args, **kwargs)

    kernel_impl.Kernel.__call__, FastKernel.__call__ = record, record_fast
    try:
        for _ in range(frames):
            scene.step(1 / 60)
            scene.render(160, 90)
    finally:
        kernel_impl.Kernel.__call__, FastKernel.__call__ = original, original_fast
    return seen


def test_the_checker_sees_planted_serial_kernels():
    planted = '''
def k(n: int):
    ti.loop_config(serialize=True)
    for i in range(n):
        pass
    for _ in range(1):
        pass
'''
    assert serial_parts(planted) == ["loop_config(serialize=True)", "top-level loop over a single index"]
    assert serial_parts("def k(n: int):\n    for i in range(n):\n        x = 1\n") == []


# kernels allowed to be serial, by qualified name, with why (none of them runs in a frame)
ALLOWED = {"_Kernels.__init__.<locals>.run_fixed": "engine.ode.solve: one ODE state stepped in time",
           # engine.rigid.kernel: XPBD's contacts and joints, Gauss-Seidel in a fixed order (each
           # correction sees the ones before it: the deterministic alternative to float atomics);
           # rigid bodies are few and their f64 state lives on the CPU
           "_build.<locals>.joints": "rigid XPBD joints, Gauss-Seidel, then the coupled ones' direct solve",
           # fixed-order f64 energy sums: diagnostics read when asked (scene.energy()), not a frame's work
           "spring_energy": "soft-body spring energy, serial f64 sum in spring order",
           "_energy": "energy terms of an element group, serial f64 sum in element order",
           "UserEnergy._build.<locals>.total": "a user energy's total, serial f64 sum in element order",
           # per frame, but short: level 2 of the grid's prefix scan over block totals (T/1024 adds)
           # and the births moved to free slots, one thread per emitter in plan order (only when a
           # ring's head meets live particles); on a GPU these want the binning's chunked scan
           "HashGrid.rebuild": "neighbour grid: level-2 scan of the block totals on one thread",
           "Interactions._pack_gravity": "direct pair gravity: the gravity slots' positions packed in "
                                         "slot order on one thread (one pass before the N² gather)",
           "spawn_children": "sub-emitter children moved to free slots in rank order, one thread",
           "_build.<locals>.finish": "rigid XPBD: a substep's end and the next one's start, Gauss-Seidel",
           "_build.<locals>.whole": "rigid XPBD: a small scene's whole step on one thread",
           "run_steps": "engine.springs.fused: a small spring network's frame on the CPU backend only "
                        "(SpringSystem._fusable checks the arch; a GPU keeps the parallel per-phase "
                        "launches): one thread beats 4-16 launches a substep there",
           "_project": "engine.xpbd.constraints and engine.forces.elements: a small XPBD group's sweep "
                       "on the CPU backend only (engine.geometry.colouring.serial_sweep checks the arch; "
                       "a GPU keeps a parallel loop a colour): one thread beats a pool wake-up a colour"}
# of those, the ones a frame may launch on the CPU (the slow check below records on the CPU)
CPU_FRAME = {"run_steps", "_project"}


def test_small_xpbd_groups_are_serial_on_the_cpu_only(monkeypatch):
    from engine import runtime
    from engine.geometry.colouring import SERIAL_MAX, serial_sweep

    assert serial_sweep(100) and serial_sweep(SERIAL_MAX) and not serial_sweep(SERIAL_MAX + 1)
    # the small loops run on one thread ask engine.runtime.one_thread (spawns, links, the grid,
    # the rigid copies, the poses, the mesh copy; the binning's scan-block loops the arch itself):
    # loops the source checks below cannot see, their serialize= a flag; true on the CPU only
    assert runtime.one_thread(100, 4096) and not runtime.one_thread(4097, 4096)
    monkeypatch.setattr(runtime, "_arch_in_use", lambda: "cuda")
    assert not serial_sweep(100) and not runtime.one_thread(1, 4096)


def kernels_in_source(root):
    """(module path, qualified name, source) of every @ti.kernel and @ti.func function under
    ``root`` (a func's top-level loops are its caller's top-level loops when it is called at a
    kernel's top level, as the fused stages call theirs)."""
    out = []
    for path in glob.glob(os.path.join(root, "**", "*.py"), recursive=True):
        with open(path, encoding="utf-8") as fh:
            src = fh.read()
        tree = ast.parse(src)
        stack = [(tree, "")]
        while stack:
            node, prefix = stack.pop()
            for child in ast.iter_child_nodes(node):
                if isinstance(child, (ast.FunctionDef, ast.ClassDef)):
                    q = f"{prefix}{child.name}"
                    if isinstance(child, ast.FunctionDef) and any(
                            getattr(d, "attr", getattr(d, "id", "")) in ("kernel", "func")
                            for d in child.decorator_list):
                        out.append((path, q, ast.get_source_segment(src, child)))
                    inner = f"{q}.<locals>." if isinstance(child, ast.FunctionDef) else f"{q}."
                    stack.append((child, inner))
                else:
                    stack.append((child, prefix))
    return out


def test_no_kernel_in_the_core_is_serialised():
    core = [k for k in kernels_in_source(os.path.join(ROOT, "engine"))
            if os.sep + "tools" + os.sep not in k[0]]
    assert len(core) > 20  # the scan found the kernels
    bad = {q: why for _, q, src in core if (why := serial_parts(src)) and q not in ALLOWED}
    assert bad == {}, bad
    assert set(ALLOWED) <= {q for _, q, _ in core}  # the allow-list names kernels that exist


@pytest.mark.slow
@pytest.mark.parametrize("path", CONFIGS, ids=[os.path.basename(p)[:-5] for p in CONFIGS])
def test_no_kernel_launched_per_frame_is_serialised(path):
    seen = launched_per_frame(path)
    assert seen, "no kernels recorded"
    bad = {name: why for name, fn in seen.items()
           if (why := serial_parts(inspect.getsource(fn))) and name not in ALLOWED}
    assert bad == {}, bad
