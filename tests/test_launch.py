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


@ti.kernel
def _tuple_template(fs: ti.template(), k: ti.i32, x: ti.f32):
    for i in ti.static(range(len(fs))):
        fs[i][None] = k * (i + 1) + ti.cast(x, ti.i32)


@ti.data_oriented
class _Holder:
    def __init__(self, n):
        self.n = n
        self.f = ti.field(ti.i32, ())


@ti.kernel
def _with_object(h: ti.template(), k: ti.i32):
    h.f[None] = k * h.n


def test_template_arguments_bind_to_the_objects_themselves():
    """A binding holds for its template objects only: another object, a dead one's recycled id,
    another plain value each bind anew, and every call writes where the usual call would."""
    import gc

    fk = FastKernel(_with_template)
    a, b = ti.field(ti.i32, ()), ti.field(ti.i32, ())
    for k in (4, 5, 6):
        fk(a, k)
        fk(b, -k)
        assert (a[None], b[None]) == (k, -k)
    assert len(fk._bound) == 2  # one binding each, both kept
    fo = FastKernel(_with_object)
    for n in range(1, 9):  # objects made and dropped: an id may come back, the binding must not
        h = _Holder(n)
        fo(h, 2)
        assert h.f[None] == 2 * n, n  # (a stale binding writes the dead object's field)
        del h
        gc.collect()
    # the case for certain: a binding made for one object found under another's id (as when a
    # dead object's id comes back) is not trusted: the new object is written, the old one not
    old, new = _Holder(2), _Holder(5)
    fo(old, 2)
    fo._bound[(id(new),)] = fo._bound.pop((id(old),))
    fo(new, 3)
    assert (old.f[None], new.f[None]) == (4, 15)
    ft = FastKernel(_tuple_template)
    fs = (ti.field(ti.i32, ()), ti.field(ti.i32, ()))
    for k in (1, 2):
        ft(fs, k, 0.5)
        assert [f[None] for f in fs] == [k, 2 * k]
    assert len(ft._bound) == 1
    h1, h2 = _Holder(3), _Holder(5)
    for k in (2, 3):
        fo(h1, k)
        fo(h2, k)
        assert (h1.f[None], h2.f[None]) == (3 * k, 5 * k)
    # a binding keeps no template object alive (a dropped scene's fields go back to engine.reuse)
    import weakref

    r = weakref.ref(h2)
    del h2
    gc.collect()
    assert r() is None


def test_a_kernel_with_an_argument_it_cannot_set_takes_the_usual_path():
    @ti.kernel
    def ivec(out: ti.types.ndarray(dtype=ti.i32, ndim=1), v: ti.types.vector(2, ti.i32)):
        out[0] = v[0] + v[1]

    out = np.zeros(1, np.int32)
    fk = FastKernel(ivec)
    fk(out, (2, 3))
    assert fk._kinds is None and out[0] == 5


@ti.data_oriented
class _Counter:
    def __init__(self, n):
        self.v = ti.field(ti.i32, n)

    @ti.kernel
    def add(self, k: ti.i32, out: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        for i in self.v:
            self.v[i] += k * (i + 1)
            out[i] = self.v[i]


def test_a_data_oriented_method_launches_fast_with_its_owner_first():
    from engine.launch import fast_method

    fm = fast_method(_Counter, "add")
    c1, c2 = _Counter(3), _Counter(4)
    for k in (1, 2):
        o1, o2 = np.zeros(3, np.int32), np.zeros(4, np.int32)
        fm(c1, k, o1)
        fm(c2, k, o2)
    assert o1.tolist() == [3, 6, 9] and o2.tolist() == [3, 6, 9, 12] and len(fm._bound) == 2
    with pytest.raises(Exception, match="missing"):  # refused as obj.add(1) is refused
        fm(c1, 1)
    assert c1.v.to_numpy().tolist() == [3, 6, 9]  # (a refused call changed nothing)


@ti.kernel
def _lean_sum(out: ti.types.ndarray(dtype=ti.f32, ndim=1), s: ti.f32):
    for i in range(out.shape[0]):
        out[i] = (i * s + s) * (i * s + s)  # the same expression twice: what the CSE pass merges


def test_a_lean_kernel_compiles_without_the_cse_pass_and_leaves_the_setting_as_it_was(monkeypatch):
    """``lean``: every compile of the kernel (the usual call, and the binding's compile of the same
    kernel) runs with Taichi's opt_level at 0, and the setting is back after it, a refused call
    included; later calls take the binding; the results are the plain kernel's."""
    from taichi.lang import impl, kernel_impl

    seen = []
    usual_launch = kernel_impl.Kernel.launch_kernel

    def spy(self, *args, **kwargs):
        seen.append(impl.current_cfg().opt_level)
        return usual_launch(self, *args, **kwargs)

    monkeypatch.setattr(kernel_impl.Kernel, "launch_kernel", spy)
    before = impl.current_cfg().opt_level
    assert before > 0  # (engine.runtime.init keeps Taichi's default)
    lean, plain = FastKernel(_lean_sum, lean=True), FastKernel(_lean_sum)
    for s in (0.5, 1.25, -3.0):
        got, want = np.empty(5, np.float32), np.empty(5, np.float32)
        lean(got, s)
        assert impl.current_cfg().opt_level == before
        plain(want, s)
        assert np.array_equal(got, want), s
    assert seen == [0, before]  # one usual call each: the rest took their bindings
    with pytest.raises(Exception):
        lean(np.empty(5, np.float64), 1.0)  # another dtype: refused by the usual path, in the switch
    assert impl.current_cfg().opt_level == before


@pytest.mark.parametrize("arch, binds", [("cpu", True), ("cuda", True), ("vulkan", False), ("metal", False)])
def test_kernels_bind_on_the_llvm_backends_only(monkeypatch, arch, binds):
    """CPU and CUDA launch bound kernels (on CUDA Taichi's C++ launcher makes a numpy argument's
    host-device copies for either path); Vulkan and Metal keep the usual call. The results are
    the usual call's either way (the arch is pretended here: the kernel runs on this CPU)."""
    from engine import runtime

    monkeypatch.setattr(runtime, "_arch_in_use", lambda: arch)
    fk = FastKernel(_mix)
    a = ti.ndarray(ti.i32, 5)
    a.from_numpy(np.arange(5, dtype=np.int32))
    v = ti.ndarray(ti.types.vector(2, ti.f32), 5)
    v.fill(1.5)
    for k in (2, 3):
        want, got = np.empty(5, np.uint32), np.empty(5, np.uint32)
        assert _mix(a, v, want, k, 1, 2.0) == fk(a, v, got, k, 1, 2.0)
        assert np.array_equal(got, want)
    assert bool(fk._bound) is binds


def test_data_oriented_reads_attributes_the_plain_way_and_still_binds_kernel_methods():
    """engine.launch.data_oriented: a class without kernel methods gets Python's own attribute
    look-up (not Taichi's per-read function) and is still a kernel's template argument; in a class
    with a kernel method only that name goes through Taichi's look-up, which binds it (a call
    writes the object's field), while a property and plain attributes read as usual."""
    from engine.launch import data_oriented

    @data_oriented
    class Plain:
        def __init__(self):
            self.n = 3
            self.f = ti.field(ti.i32, ())

    @data_oriented
    class WithKernel:
        def __init__(self):
            self.n = 5
            self.f = ti.field(ti.i32, ())

        @property
        def twice(self):
            return 2 * self.n

        @ti.kernel
        def fill(self, k: ti.i32):
            self.f[None] = k * self.n

    p, w = Plain(), WithKernel()
    assert Plain.__getattribute__ is object.__getattribute__
    _with_object(p, 7)
    assert p.f[None] == 21
    assert WithKernel.__getattribute__ is not object.__getattribute__
    w.fill(4)
    assert w.f[None] == 20 and w.twice == 10 and w.n == 5
    assert type(w.fill).__name__ != "method"  # (Taichi's binding, not a plain bound function)


def test_data_oriented_binds_static_kernels_and_a_subclass_s_own():
    """Kernels the class body does not hold as plain methods still go through Taichi's look-up:
    a static kernel, and a kernel an undecorated subclass adds (to a base with kernels and to
    one without), whose other attributes read the plain way."""
    from engine.launch import data_oriented

    @data_oriented
    class Static:
        @staticmethod
        @ti.kernel
        def twice(x: ti.i32) -> ti.i32:
            return 2 * x

    @data_oriented
    class Bare:
        def __init__(self):
            self.f = ti.field(ti.i32, ())

    class Grown(Bare):
        @ti.kernel
        def fill(self, k: ti.i32):
            self.f[None] = k + 1

    @data_oriented
    class WithKernel:
        def __init__(self):
            self.f = ti.field(ti.i32, ())

        @ti.kernel
        def fill(self, k: ti.i32):
            self.f[None] = k

    class More(WithKernel):
        @ti.kernel
        def more(self, k: ti.i32):
            self.f[None] = 3 * k

    assert Static().twice(4) == 8
    g = Grown()
    g.fill(6)
    assert g.f[None] == 7 and Bare.__getattribute__ is object.__getattribute__
    m = More()
    m.more(5)
    assert m.f[None] == 15
    m.fill(2)
    assert m.f[None] == 2
