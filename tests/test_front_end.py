"""Taichi's front end, quickened (engine.front_end, engine.quick_ops): every replacement gives
the same text, lines or bits as Taichi's own — source positions (what a kernel's compile error
shows), the text wrapper and fill, the class check, the vector reductions — and what is kept
between starts (source texts and lines) comes back only while its file's text is the same.
"""
import ast
import inspect
import os
import textwrap

import numpy as np
import pytest
import taichi as ti

from engine import front_end, runtime

from helpers import ROOT


def test_memoised_source_positions_are_taichis_text():
    from taichi.lang.ast import ast_transformer_utils as atu

    memo = atu.ASTTransformerContext.get_pos_info
    assert getattr(memo, "memoized", False)  # installed by runtime.init

    def bad(a):
        b = a + 1
        for i in range(3):
            if b > i:
                b = b * 2 + a.imag
        return b

    src, start = inspect.getsourcelines(bad)

    class Ctx:  # what get_pos_info reads of Taichi's context
        file, lineno_offset, indent = __file__, start - 1, 4
        src = [line.rstrip("\n") for line in inspect.getsourcelines(bad)[0]]
        func = type("F", (), {"func": bad})()

    ctx = Ctx()
    nodes = [n for n in ast.walk(ast.parse(textwrap.dedent("".join(src))))
             if isinstance(n, (ast.stmt, ast.expr))]
    assert len(nodes) > 15
    for n in nodes:
        want = memo.original(ctx, n)
        assert "line" in want and "^" in want
        assert memo(ctx, n) == want
        assert memo(ctx, n) == want  # the kept text, the second time


def test_a_kernel_error_still_points_at_its_line():
    x = ti.field(ti.f32, shape=4)

    @ti.kernel
    def broken():
        for i in x:
            x[i] = x[i] + ti.not_defined_anywhere()

    with pytest.raises(Exception) as e:
        broken()
    text = str(e.value)
    assert "not_defined_anywhere" in text
    assert "^" in text  # the caret line under the node
    runtime.check_thread("test")  # the program is still ours and usable


def test_quick_wrapper_wraps_as_textwrap_does():
    """engine.front_end's TextWrapper for Taichi's source-position text: the same lines as
    textwrap's for real source lines (some past 80 columns), caret lines, blanks and tabs."""
    from engine.front_end import _QuickWrapper

    quick, ref = _QuickWrapper(width=80), textwrap.TextWrapper(width=80)
    lines = []
    for name in ("engine/render/composite.py", "engine/runtime.py", "engine/particles/integrate.py"):
        with open(os.path.join(ROOT, name), encoding="utf-8") as f:
            lines += f.read().splitlines()
    assert sum(len(s) > 80 for s in lines) > 10 and sum(len(s) <= 80 for s in lines) > 100
    carets = [" " * k + "^" * m + " " * t for k in (0, 3, 8, 60) for m in (0, 1, 17, 40) for t in (0, 5)]
    odd = ["", " ", "    ", "\t", "\tx = 1", "x = 1\t", "a  b  ", "x" * 80, "x" * 81, "x " * 40,
           " " * 79 + "^", " " * 81, "é" * 80, "a\u00a0b", "a\nb", "x = 1\n", "   \n", "\n",
           "x" * 79 + "\n", "x" * 80 + "\n", "a \n\n"]
    for s in lines + carets + odd:
        assert quick.wrap(s) == ref.wrap(s), repr(s)
        assert quick.wrap(s) == ref.wrap(s), repr(s)  # a kept long line, the second time


def test_quick_fill_fills_as_textwrap_does():
    """engine.front_end's textwrap.fill for Taichi's source parsing: the same text as textwrap's
    for every line of real source files as inspect.getsourcelines gives them (with their
    newline), and for blanks, tabs and lines past the width."""
    from taichi.lang import kernel_impl

    from engine.front_end import _quick_fill

    assert kernel_impl.textwrap.fill is _quick_fill  # installed at import
    assert kernel_impl.textwrap.dedent is textwrap.dedent
    lines = []
    for name in ("engine/render/composite.py", "engine/runtime.py", "engine/particles/integrate.py"):
        with open(os.path.join(ROOT, name), encoding="utf-8") as f:
            lines += f.readlines()
    assert sum(s.endswith("\n") for s in lines) > 100
    odd = ["", "\n", "   \n", "\t\n", "\tx = 1\n", "x = 1   \n", "x\n\n", "x" * 40 + "\n", "x" * 41,
           "é \n", "a\u00a0b\n", "  a\r\n"]
    for s in lines + odd:
        assert _quick_fill(s, tabsize=4, width=9999) == textwrap.fill(s, tabsize=4, width=9999), repr(s)
    for s in odd:  # a narrow width: wrapped as textwrap wraps
        assert _quick_fill(s, width=40) == textwrap.fill(s, width=40), repr(s)


def test_class_check_agrees_with_taichis():
    """engine.front_end's test of whether a kernel is being defined in a class body answers as
    Taichi's own at each frame level, in a data-oriented class, a plain class and a function."""
    from taichi.lang import kernel_impl

    ours = kernel_impl._inside_class
    assert ours is front_end._inside_class  # installed by runtime.init
    taichis = ours.taichis
    seen = []

    def probe(fn):  # called as a decorator is: the defining frame is 2 up from ours / Taichi's
        levels = []
        for k in (1, 2, 3):  # (a loop, not a comprehension: that would be a frame of its own)
            levels.append((ours(k), taichis(k)))
        seen.append(levels)
        return fn

    @ti.data_oriented
    class Oriented:
        @probe
        def f(self):
            pass

    class Plain(object):
        @probe
        def g(self):
            pass

    def outer():
        @probe
        def h():
            pass

    outer()
    assert len(seen) == 3
    for levels in seen:
        for got, want in levels:
            assert got == want
    assert any(got for levels in seen for got, _ in levels)  # a class body was recognised


@pytest.mark.parametrize("dtype", [ti.f32, ti.f64])
def test_quick_vector_ops_give_taichis_bits(dtype):
    """engine.quick_ops' dot, sum, norm_sqr, norm, cross and normalized (a vector's methods in a
    kernel) against Taichi's own functions in the same kernel: the same bits for 4,000 random
    vectors in f32 and f64, magnitudes 1e-3 to 1e3, and a matrix's sum and norm. A different
    formula shows in the last bits (normalized as v / |v|: 1.7 % of the values differ); the
    order of a sum's terms does not, as Taichi compiles with fast math (reassociation allowed)."""
    from taichi.lang import matrix_ops

    assert all(getattr(getattr(matrix_ops, n), "quick", False) for n in
               ("sum", "norm_sqr", "norm", "dot", "cross", "normalized"))  # installed by runtime
    orig = matrix_ops.quick_originals
    o_dot, o_sum, o_nsq, o_norm = orig["dot"], orig["sum"], orig["norm_sqr"], orig["norm"]
    o_cross, o_unit = orig["cross"], orig["normalized"]
    n = 4000
    rng = np.random.default_rng(11)
    npdt = np.float32 if dtype == ti.f32 else np.float64
    a = (rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-3, 3, size=(n, 1))).astype(npdt)
    b = (rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-3, 3, size=(n, 1))).astype(npdt)
    out = np.zeros((n, 2, 12), npdt)

    @ti.kernel
    def both(a: ti.types.ndarray(), b: ti.types.ndarray(), out: ti.types.ndarray()):
        for i in range(a.shape[0]):
            x = ti.Vector([a[i, 0], a[i, 1], a[i, 2]], dt=dtype)
            y = ti.Vector([b[i, 0], b[i, 1], b[i, 2]], dt=dtype)
            m = ti.Matrix([[x[0], y[1]], [x[2], y[0]]], dt=dtype)
            c, u = x.cross(y), (x - y).normalized()
            q = [x.dot(y), x.sum(), x.norm_sqr(), (x + y).norm(), m.sum(), m.norm(), c[0], c[1], c[2],
                 u[0], u[1], u[2]]
            c0, u0 = o_cross(x, y), o_unit(x - y)
            r = [o_dot(x, y), o_sum(x), o_nsq(x), o_norm(x + y), o_sum(m), o_norm(m), c0[0], c0[1],
                 c0[2], u0[0], u0[1], u0[2]]
            for k in ti.static(range(12)):
                out[i, 0, k] = q[k]
                out[i, 1, k] = r[k]

    both(a, b, out)
    assert np.isfinite(out).all() and np.abs(out[:, 0]).max() > 1.0
    np.testing.assert_array_equal(out[:, 0].view(np.uint8), out[:, 1].view(np.uint8))
    # and the values are what they say (so neither side is trivially wrong)
    np.testing.assert_allclose(out[:, 0, 0], (a.astype(float) * b).sum(1), rtol=1e-3, atol=1e-3)
    np.testing.assert_allclose(out[:, 0, 6:9], np.cross(a.astype(float), b), rtol=1e-3, atol=1e-2)


def test_quick_vector_ops_leave_other_calls_to_taichi():
    """What the quick ops do not cover goes to Taichi's own: Python scope, and a call Taichi
    refuses (a dot of a vector with a matrix) is refused with Taichi's message."""
    v = ti.Vector([1.0, 2.0, 2.0])
    assert v.dot(ti.Vector([3.0, 0.0, 1.0])) == 5.0 and v.norm() == 3.0 and v.sum() == 5.0

    @ti.kernel
    def wrong() -> ti.f32:
        x = ti.Vector([1.0, 2.0])
        m = ti.Matrix([[1.0, 0.0], [0.0, 1.0]])
        return x.dot(m)

    with pytest.raises(Exception) as e:
        wrong()
    assert "rhs for dot is not a vector" in str(e.value)
    runtime.check_thread("test")


def test_kept_source_texts_come_back_until_their_file_changes(tmp_path):
    """engine.front_end.KeptTexts: Taichi's source-position texts kept from one start to the next
    come back as Taichi made them; an edit to their file drops them, even one that keeps its size
    and time; a cache file of another format or Taichi version, or not one at all, is ignored."""
    import linecache
    import marshal

    from taichi.lang.ast import ast_transformer_utils as atu

    original = atu.ASTTransformerContext.get_pos_info.original
    src_file = tmp_path / "kernels.py"
    src_file.write_text("def f(a):\n    b = a + 1\n    return b * 2\n")
    src = src_file.read_text().splitlines()

    class Ctx:
        file, lineno_offset, indent = str(src_file), 0, 0
        func = type("F", (), {"func": type("G", (), {"__name__": "f"})})()

    Ctx.src = src
    nodes = [n for n in ast.walk(ast.parse("\n".join(src))) if isinstance(n, (ast.stmt, ast.expr))]
    keys = [(Ctx.file, 0, 0, "f", type(n), n.lineno, n.end_lineno, n.col_offset, n.end_col_offset) for n in nodes]
    texts = [original(Ctx(), n) for n in nodes]
    cache = tmp_path / "cache"
    kept = front_end.KeptTexts(str(cache))
    assert kept.get(keys[0]) is None
    for k, t in zip(keys, texts):
        kept.put(k, t)
    kept.save()
    again = front_end.KeptTexts(str(cache))
    assert [again.get(k) for k in keys] == texts and all("^" in t for t in texts)
    assert not again.changed  # nothing new: nothing written at exit
    (path,) = cache.glob("*.marshal")  # one file a source file
    whole = path.read_bytes()
    header, name, digest, kept_texts = marshal.loads(whole)
    assert name == str(src_file) and len(kept_texts) == len(set(keys))
    path.write_bytes(marshal.dumps(((header[0], (0, 0, 1), header[2]), name, digest, kept_texts)))
    assert front_end.KeptTexts(str(cache)).get(keys[0]) is None  # kept by another Taichi
    path.write_bytes(whole)
    assert front_end.KeptTexts(str(cache)).get(keys[0]) == texts[0]
    st = os.stat(src_file)
    src_file.write_text("def f(a):\n    b = a + 2\n    return b * 2\n")  # the same size ...
    os.utime(src_file, ns=(st.st_atime_ns, st.st_mtime_ns))  # ... and time
    linecache.clearcache()  # (as a new process reads it)
    assert front_end.KeptTexts(str(cache)).get(keys[0]) is None
    path.write_bytes(b"not a cache file")
    assert front_end.KeptTexts(str(cache)).get(keys[0]) is None
    nowhere = front_end.KeptTexts("")  # no offline cache: nothing kept
    nowhere.put(keys[0], texts[0])
    assert nowhere.get(keys[0]) is None


def test_kept_source_lines_are_inspects(tmp_path, monkeypatch):
    """engine.front_end's getsourcelines for Taichi's front end: inspect's lines and first line
    number, kept and read back at the next start without inspect; each of two functions wrapped
    by one decorator gets its own (inspect follows ``__wrapped__``); an edited and reloaded module
    gets its new lines in the same process."""
    import importlib
    import sys as _sys

    from engine.particles import integrate, rng

    mod = tmp_path / "kept_lines_mod.py"
    mod.write_text("import functools\n\n\ndef deco(f):\n    @functools.wraps(f)\n    def w(*a):\n"
                   "        return f(*a)\n    return w\n\n\n@deco\ndef alpha(x):\n    return x + 1\n\n\n"
                   "@deco\ndef beta(x):\n    return x * 100\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    m = importlib.import_module("kept_lines_mod")
    fns = [integrate._step_one.func.func, rng.rand01, rng.pcg_hash, m.alpha, m.beta]
    first = front_end.KeptTexts(str(tmp_path / "cache"))
    monkeypatch.setattr(front_end, "KEPT_TEXTS", first)
    fresh = front_end._kept_lines(inspect.getsourcelines)
    got = [fresh(f) for f in fns]
    assert [(list(a), b) for a, b in got] == [(list(a), b) for a, b in map(inspect.getsourcelines, fns)]
    assert "x + 1" in "".join(got[3][0]) and "x * 100" in "".join(got[4][0])
    first.save()

    def no_inspect(fn):
        raise AssertionError("read back, not looked up")

    monkeypatch.setattr(front_end, "KEPT_TEXTS", front_end.KeptTexts(str(tmp_path / "cache")))
    again = front_end._kept_lines(no_inspect)
    assert [again(f) for f in fns] == got
    mod.write_text(mod.read_text().replace("x * 100", "x * 1000 - 7"))  # edited, then reloaded
    m = importlib.reload(m)
    assert "x * 1000 - 7" in "".join(fresh(m.beta)[0])
    assert fresh(m.beta) == tuple(inspect.getsourcelines(m.beta))
    _sys.modules.pop("kept_lines_mod", None)
