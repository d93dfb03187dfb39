"""A hot kernel launched without Taichi's per-call Python (the CPU and CUDA backends).

Taichi 1.7 spends ~15 µs of Python per ndarray argument and ~6 µs per scalar at every call: it
derives the template key from every argument (``TaichiCallableTemplateMapper.extract``), then sets
each through a chain of type tests (``Kernel.launch_kernel``). The renderer's kernels take 10–30
arguments each, several times a frame: a 28-argument kernel cost ~300 µs a call here against
~15 µs for the launch itself (a micro-benchmark, 2,000 calls).

:class:`FastKernel` calls the kernel the usual way once — which checks the arguments, compiles,
and binds the compiled instance — and afterwards sets the arguments straight into a launch
context by their annotated kind, then launches the same compiled code (same bytes). It takes
kernels whose arguments are ndarrays, scalars, float vectors and ``ti.template()`` objects, on
the CPU and CUDA backends (Taichi's LLVM backends). On CUDA a numpy argument is a host pointer
either way: Taichi's C++ launcher copies it to the device before the launch and back after it,
for the usual call and this one alike (Taichi 1.7's Python path adds nothing for a contiguous
numpy array). Vulkan and Metal keep the usual path (not measured here). A numpy argument's
dtype and rank are part of the binding: a call with different ones goes the usual way (which
checks them) and binds again.

Template arguments are compiled in, not passed: a binding holds for the very objects it was made
with. It keeps each as a weak reference, as Taichi's own template key does (a strong one would
keep a dropped scene's fields alive, which engine.reuse hands to the next scene), or, for a
number, a bool or a string, its type and value; a tuple item by item. A call whose template
arguments are not a binding's (another object, or one that died and whose id came back) goes the
usual way and binds them; anything else (a list, an object without weak references) always goes
the usual way. At most ``MAX_BINDINGS`` bindings a kernel (then they start over): a kernel
called for several systems keeps one each. The callers are the engine's own: each ndarray is
one the engine allocated with the annotated type.
"""
from __future__ import annotations

import contextlib
import weakref

import numpy as np

_ND, _INT, _UINT, _FLOAT, _VEC, _TPL = range(6)
MAX_BINDINGS = 16
BINDING_ARCHES = ("cpu", "cuda")  # where a kernel binds (engine.runtime._arch_in_use names)
_PLAIN = (int, float, bool, str)


def _pin(v):
    """(key, check) of a template argument: the key hashes it (by identity for an object), the
    check tells whether a later argument is the same one (a weak reference for an object); None
    when it cannot be pinned (then the kernel takes the usual path for it)."""
    if type(v) in _PLAIN:
        return (type(v), v), ("v", type(v), v)
    if type(v) is tuple:
        items = [_pin(x) for x in v]
        if any(it is None for it in items):
            return None
        return tuple(k for k, _ in items), ("t", tuple(c for _, c in items))
    try:
        return id(v), ("w", weakref.ref(v))
    except TypeError:
        return None


def _same(check, v) -> bool:
    """Whether ``v`` is the template argument ``check`` (from :func:`_pin`) was made for."""
    if check[0] == "w":
        return check[1]() is v
    if check[0] == "v":
        return type(v) is check[1] and v == check[2]
    return type(v) is tuple and len(v) == len(check[1]) and all(_same(c, x) for c, x in zip(check[1], v))


class FastKernel:
    """``FastKernel(kernel)(*args)``: the kernel's result, as ``kernel(*args)``."""

    def __init__(self, kernel, usual=None, lean=False):
        from taichi.lang.util import cook_dtype
        from taichi.types.utils import is_signed
        from taichi.lang.matrix import VectorType
        from taichi.types import ndarray_type, primitive_types, template

        self.kernel = kernel
        usual = usual if usual is not None else kernel  # the usual call, Taichi's checks and all
        self._compiling = contextlib.nullcontext
        if lean:  # every compile of this kernel without Taichi's whole-kernel CSE (engine.runtime)
            from .runtime import without_kernel_cse as compiling

            def usual(*args, _usual=usual):
                with compiling():
                    return _usual(*args)

            self._compiling = compiling
        self._usual = usual
        self._kinds = None
        prim = getattr(kernel, "_primal", None)
        kinds = []
        for arg in getattr(prim, "arguments", None) or ():
            an = arg.annotation
            if isinstance(an, template) or an is template:
                kinds.append(_TPL)
            elif isinstance(an, ndarray_type.NdarrayType):
                kinds.append(_ND)
            elif id(an) in primitive_types.integer_type_ids:
                kinds.append(_INT if is_signed(cook_dtype(an)) else _UINT)
            elif id(an) in primitive_types.real_type_ids:
                kinds.append(_FLOAT)
            elif isinstance(an, VectorType) and an.dtype in primitive_types.real_types:
                kinds.append((_VEC, an.n))  # a float vector: its n entries, as the usual path sets them
            else:
                return  # an int vector, matrix or struct argument: always the usual path
        ret = prim.return_type
        if ret is not None and len(ret) != 1:
            return
        self._prim, self._ret = prim, (ret[0] if ret else None)
        self._kinds = tuple(kinds)
        self._nd = tuple(i for i, k in enumerate(kinds) if k == _ND)
        self._tpl = tuple(i for i, k in enumerate(kinds) if k == _TPL)
        # the launch context's slot of each passed argument (templates take none), and its kind
        self._slots = tuple((i, i - sum(1 for j in self._tpl if j < i), k) for i, k in enumerate(kinds)
                            if k != _TPL)
        # template key -> (program, numpy signature, template checks, compiled kernel, compiled data)
        self._bound = {}
        _register(self)

    def __getattr__(self, name):  # the kernel's own attributes (``_primal``, …), for tests and tools
        if name == "kernel":
            raise AttributeError(name)
        return getattr(self.kernel, name)

    def _signature(self, args):
        return tuple((a.dtype, a.ndim) if isinstance(a, np.ndarray) else None for a in (args[i] for i in self._nd))

    def __call__(self, *args):
        if self._kinds is None:
            return self._usual(*args)
        from taichi.lang import impl

        if len(args) != len(self._kinds):
            return self._usual(*args)  # (the usual path refuses it, naming the count)
        prog = impl.get_runtime().prog
        sig = self._signature(args)
        pins = None
        if self._tpl:
            pins = [_pin(args[i]) for i in self._tpl]
            if any(p is None for p in pins):
                return self._usual(*args)  # (an argument it cannot pin: Taichi's own key decides)
            key = tuple(k for k, _ in pins)
        else:
            key = ()
        b = self._bound.get(key)
        if (b is None or b[0] is not prog or b[1] != sig
                or not all(_same(c, args[i]) for c, i in zip(b[2], self._tpl))):
            return self._bind(prog, sig, args, key, pins)
        ctx = b[3].make_launch_context()
        for i, slot, kind in self._slots:
            v = args[i]
            if kind == _ND:
                if isinstance(v, np.ndarray):
                    if not v.flags.c_contiguous:
                        return self._usual(*args)  # (the usual path copies it, or refuses it)
                    ctx.set_arg_external_array_with_shape((slot,), int(v.ctypes.data), v.nbytes, v.shape, 0)
                else:
                    ctx.set_arg_ndarray((slot,), v.arr)
            elif kind == _INT:
                ctx.set_arg_int((slot,), int(v))
            elif kind == _UINT:
                ctx.set_arg_uint((slot,), int(v))
            elif kind == _FLOAT:
                ctx.set_arg_float((slot,), float(v))
            else:
                if len(v) != kind[1]:
                    return self._usual(*args)  # (the usual path refuses it)
                for j in range(kind[1]):
                    ctx.set_struct_arg_float((slot, j), float(v[j]))
        prog.launch_kernel(b[4], ctx)
        if self._ret is None:
            return None
        prog.synchronize()
        return self._prim.construct_kernel_ret(ctx, self._ret, (0,))

    def _bind(self, prog, sig, args, key, pins):
        """The usual call (checks, compiles), then the compiled instance kept for the next call
        with these template arguments."""
        from .runtime import _arch_in_use

        out = self._usual(*args)
        self._bound.pop(key, None)
        if _arch_in_use() in BINDING_ARCHES and not self._prim.has_print:  # (a print needs the usual sync)
            if len(self._bound) >= MAX_BINDINGS:
                self._bound.clear()
            cpp = self._prim.compiled_kernels[self._prim.ensure_compiled(*args)]
            checks = tuple(c for _, c in pins) if pins else ()
            with self._compiling():  # (the compile above, found again: the same config)
                data = prog.compile_kernel(prog.config(), prog.get_device_caps(), cpp)
            self._bound[key] = (prog, sig, checks, cpp, data)
        return out


_ALL = weakref.WeakSet()  # every FastKernel with bindings to drop when the program is reset
_HOOKED = []


def _register(fk) -> None:
    if not _HOOKED:
        from .runtime import on_reset

        on_reset(_forget_all)
        _HOOKED.append(True)
    _ALL.add(fk)


def _forget_all() -> None:
    """engine.runtime.reset: drop every binding (each holds the old program's compiled code)."""
    for fk in list(_ALL):
        fk._bound = {}


def fast(kernel, lean: bool = False) -> FastKernel:
    """``lean``: compiled without Taichi's whole-kernel CSE (engine.runtime.without_kernel_cse)."""
    return FastKernel(kernel, lean=lean)


def fast_method(cls, name: str) -> FastKernel:
    """A data-oriented class's kernel method as a FastKernel called with the owner first:
    ``fast_method(C, "step")(obj, h)`` is ``obj.step(h)`` (the owner is the kernel's ``self``
    template argument, bound by a weak reference)."""
    return FastKernel(getattr(cls, name), usual=lambda owner, *args: getattr(owner, name)(*args))


def _kernel_names(cls) -> frozenset:
    """The names under which ``cls`` (its MRO) holds a Taichi kernel: a method, a static or class
    method's function, or a property's getter."""
    names = set()
    for klass in cls.__mro__:
        for name, v in vars(klass).items():
            if any(hasattr(f, "_is_wrapped_kernel") for f in (v, getattr(v, "__func__", None),
                                                               getattr(v, "fget", None)) if f is not None):
                names.add(name)
    return frozenset(names)


def _plain_lookup(cls) -> None:
    """``cls`` (already through ``ti.data_oriented``) reads its kernel names through Taichi's
    look-up and everything else through Python's own."""
    kernels = _kernel_names(cls)
    if not kernels:
        cls.__getattribute__ = object.__getattribute__
        return
    taichi_lookup, plain = cls.__getattribute__, object.__getattribute__

    def __getattribute__(self, item):
        return taichi_lookup(self, item) if item in kernels else plain(self, item)

    cls.__getattribute__ = __getattribute__


def data_oriented(cls):
    """``ti.data_oriented`` with Python's own attribute look-up for everything but kernels.

    Taichi's decorator sends every attribute read of the object through a Python function that
    binds kernel methods (``kernel_impl.data_oriented``'s ``_getattr``): 430 ns a read of
    ``Colliders.count`` here against 28 ns, and the host reads a scene's objects a few hundred
    times a frame (debris' colliders: 242 reads a frame, crates' 196). A class without kernels
    gets the plain look-up back; one with them (methods, static or class methods, property
    getters) goes through Taichi's only for those names, which binds them as Taichi does. So does
    every subclass, decorated or not (a subclass may add kernels). Kernels still take the object
    as a template: Taichi's compiler reads its fields and funcs with getattr (the same values
    through either look-up)."""
    import taichi as ti

    cls = ti.data_oriented(cls)
    _plain_lookup(cls)
    base_init_subclass = cls.__dict__.get("__init_subclass__")

    def __init_subclass__(sub, **kwargs):
        if base_init_subclass is not None:
            base_init_subclass.__func__(sub, **kwargs)
        else:
            super(cls, sub).__init_subclass__(**kwargs)
        _plain_lookup(ti.data_oriented(sub))

    cls.__init_subclass__ = classmethod(__init_subclass__)
    return cls
