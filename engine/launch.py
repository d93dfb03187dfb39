"""A hot kernel launched without Taichi's per-call Python (the CPU backend).

Taichi 1.7 spends ~15 µs of Python per ndarray argument and ~6 µs per scalar at every call: it
derives the template key from every argument (``TaichiCallableTemplateMapper.extract``), then sets
each through a chain of type tests (``Kernel.launch_kernel``). The renderer's kernels take 10–30
arguments each, several times a frame: a 28-argument kernel cost ~300 µs a call here against
~15 µs for the launch itself (a micro-benchmark, 2,000 calls).

:class:`FastKernel` calls the kernel the usual way once — which checks the arguments, compiles,
and binds the compiled instance — and afterwards sets the arguments straight into a launch
context by their annotated kind, then launches the same compiled code (same bytes). It only
takes kernels whose arguments are all ndarrays, scalars and float vectors (no ``ti.template()``:
their key is the objects themselves), and only on the CPU backend (a GPU's numpy arguments need
the copies the usual path makes). A numpy argument's dtype and rank are part of the binding: a
call with different ones goes the usual way (which checks them) and binds again. The callers
are the engine's own: each ndarray is one the renderer allocated with the annotated type.
"""
from __future__ import annotations

import numpy as np

_ND, _INT, _UINT, _FLOAT, _VEC = range(5)


class FastKernel:
    """``FastKernel(kernel)(*args)``: the kernel's result, as ``kernel(*args)``."""

    def __init__(self, kernel):
        from taichi.lang.util import cook_dtype
        from taichi.types.utils import is_signed
        from taichi.lang.matrix import VectorType
        from taichi.types import ndarray_type, primitive_types

        self.kernel = kernel
        self._kinds = None
        prim = getattr(kernel, "_primal", None)
        kinds = []
        for arg in getattr(prim, "arguments", None) or ():
            an = arg.annotation
            if isinstance(an, ndarray_type.NdarrayType):
                kinds.append(_ND)
            elif id(an) in primitive_types.integer_type_ids:
                kinds.append(_INT if is_signed(cook_dtype(an)) else _UINT)
            elif id(an) in primitive_types.real_type_ids:
                kinds.append(_FLOAT)
            elif isinstance(an, VectorType) and an.dtype in primitive_types.real_types:
                kinds.append((_VEC, an.n))  # a float vector: its n entries, as the usual path sets them
            else:
                return  # a template, vector or struct argument: always the usual path
        ret = prim.return_type
        if ret is not None and len(ret) != 1:
            return
        self._prim, self._ret = prim, (ret[0] if ret else None)
        self._kinds = tuple(kinds)
        self._nd = tuple(i for i, k in enumerate(kinds) if k == _ND)
        self._bound = None  # (program, numpy signature, compiled kernel, compiled data)

    def __getattr__(self, name):  # the kernel's own attributes (``_primal``, …), for tests and tools
        if name == "kernel":
            raise AttributeError(name)
        return getattr(self.kernel, name)

    def _signature(self, args):
        return tuple((a.dtype, a.ndim) if isinstance(a, np.ndarray) else None for a in (args[i] for i in self._nd))

    def __call__(self, *args):
        if self._kinds is None:
            return self.kernel(*args)
        from taichi.lang import impl

        if len(args) != len(self._kinds):
            return self.kernel(*args)  # (the usual path refuses it, naming the count)
        prog = impl.get_runtime().prog
        sig = self._signature(args)
        b = self._bound
        if b is None or b[0] is not prog or b[1] != sig:
            return self._bind(prog, sig, args)
        ctx = b[2].make_launch_context()
        for i, (kind, v) in enumerate(zip(self._kinds, args)):
            if kind == _ND:
                if isinstance(v, np.ndarray):
                    if not v.flags.c_contiguous:
                        return self.kernel(*args)  # (the usual path copies it, or refuses it)
                    ctx.set_arg_external_array_with_shape((i,), int(v.ctypes.data), v.nbytes, v.shape, 0)
                else:
                    ctx.set_arg_ndarray((i,), v.arr)
            elif kind == _INT:
                ctx.set_arg_int((i,), int(v))
            elif kind == _UINT:
                ctx.set_arg_uint((i,), int(v))
            elif kind == _FLOAT:
                ctx.set_arg_float((i,), float(v))
            else:
                if len(v) != kind[1]:
                    return self.kernel(*args)  # (the usual path refuses it)
                for j in range(kind[1]):
                    ctx.set_struct_arg_float((i, j), float(v[j]))
        prog.launch_kernel(b[3], ctx)
        if self._ret is None:
            return None
        prog.synchronize()
        return self._prim.construct_kernel_ret(ctx, self._ret, (0,))

    def _bind(self, prog, sig, args):
        """The usual call (checks, compiles), then the compiled instance kept for the next."""
        from .runtime import _arch_in_use

        out = self.kernel(*args)
        self._bound = None
        if _arch_in_use() == "cpu" and not self._prim.has_print:  # (a print needs the usual sync)
            cpp = self._prim.compiled_kernels[self._prim.ensure_compiled(*args)]
            self._bound = (prog, sig, cpp, prog.compile_kernel(prog.config(), prog.get_device_caps(), cpp))
        return out


def fast(kernel) -> FastKernel:
    return FastKernel(kernel)
