"""engine.launch.FastKernel: the same results as the usual call, bound once, and any argument it
cannot vouch for sent the usual way (which checks it)."""
import numpy as np
import pytest
import taichi as ti

from engine.runtime import ensure_init

ensure_init()

from engine.launch import FastKernel  # noqa: E402

ND_I = ti.types.ndarray(dtype=ti.i32, ndim=1)
ND_V = ti.types.ndarray(dtype=ti.types.vector(2, ti.f32), ndim=1)
ND_U = ti.types.ndarray(dtype=ti.u32, ndim=1)


@ti.kernel
def _mix(a: ND_I, v: ND_V, out: ND_U, k: ti.i32, u: ti.u32, x: ti.f32) -> ti.f32:
    """out[i] = a[i]·k + u + ⌊v[i]·x⌋ for i < out's length; returns Σ v[i][1]·x."""
    total = ti.cast(0.0, ti.f32)
    for i in range(out.shape[0]):
        out[i] = ti.cast(a[i] * k, ti.u32) + u + ti.cast(v[i][0] * x, ti.u32)
    for i in range(out.shape[0]):
        total += v[i][1] * x
    return total


@ti.kernel
def _vec(out: ti.types.ndarray(dtype=ti.f32, ndim=1), o: ti.types.vector(3, ti.f32), s: ti.f32):
    for i in range(3):
        out[i] = o[i] * s


@ti.kernel
def _with_template(f: ti.template(), k: ti.i32):
    f[None] = k


def test_fast_calls_give_the_usual_calls_results():
    fk = FastKernel(_mix)
    a = ti.ndarray(ti.i32, 6)
    v = ti.ndarray(ti.types.vector(2, ti.f32), 6)
    a.from_numpy(np.arange(6, dtype=np.int32))
    v.from_numpy(np.arange(12, dtype=np.float32).reshape(6, 2))
    for k, u, x in ((2, 7, 0.5), (3, 1, 1.5), (-1, 9, 2.0), (5, 2**31 + 3, 0.25)):
        want = np.empty(6, np.uint32)
        got = np.empty(6, np.uint32)
        r_want = _mix(a, v, want, k, u, x)
        r_got = fk(a, v, got, k, u, x)
        assert fk._bound is not None  # bound at the first call: the rest took the fast path
        assert np.array_equal(got, want) and r_got == r_want, (k, u, x)
    assert np.array_equal(got, np.arange(6) * 5 + 2**31 + 3 + np.floor(np.arange(0, 12, 2) * 0.25))


def test_a_float_vector_argument_is_set_entry_by_entry():
    fk = FastKernel(_vec)
    for o, s in (((1.0, 2.0, 3.0), 2.0), ((-0.5, 4.0, 0.25), 3.0), (np.array([7.0, 8.0, 9.0]), 0.5)):
        out = np.zeros(3, np.float32)
        fk(out, o, s)
        assert fk._bound is not None and np.array_equal(out, np.asarray(o, np.float32) * np.float32(s))
    with pytest.raises(Exception):  # two entries for three: the usual path refuses it
        fk(np.zeros(3, np.float32), (1.0, 2.0), 1.0)
    for short in ((np.zeros(3, np.float32), (1.0, 2.0, 3.0)), ()):  # refused as Taichi refuses it
        with pytest.raises(Exception, match="missing"):
            fk(*short)


def test_an_argument_the_binding_does_not_cover_goes_the_usual_way():
    fk = FastKernel(_mix)
    a = ti.ndarray(ti.i32, 4)
    a.fill(1)
    v = ti.ndarray(ti.types.vector(2, ti.f32), 4)
    v.fill(0.0)
    fk(a, v, np.zeros(4, np.uint32), 1, 0, 1.0)
    bound = fk._bound
    # a numpy array of another dtype: not bound, so the usual call checks it (and refuses it)
    with pytest.raises(Exception, match="(?i)dtype|type"):
        fk(a, v, np.zeros(4, np.float64), 1, 0, 1.0)
    # a strided view: the usual path, which refuses it, never a write across its gaps
    base = np.zeros(8, np.uint32)
    fk._bound = bound
    with pytest.raises(ValueError, match="contiguous"):
        fk(a, v, base[::2], 3, 0, 1.0)
    assert not base.any()


def test_a_kernel_with_template_arguments_always_takes_the_usual_path():
    f = ti.field(ti.i32, ())
    fk = FastKernel(_with_template)
    for k in (4, 5):
        fk(f, k)
        assert f[None] == k
    assert fk._kinds is None and fk._primal is _with_template._primal
