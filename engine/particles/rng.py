"""Counter-based random numbers: a pure function of (seed, stream, counter), so a particle's
randomness depends on which particle it is, not on thread timing or slot order.

PCG's output permutation as an integer hash (O'Neill 2014; Jarzynski & Olano, "Hash Functions for
GPU Rendering", JCGT 2020, recommend it for quality per cost).

Both are plain Python functions called inside kernels (``engine.quick_ops.inline``), not
``ti.func``: Taichi runs a plain function at compile time on its arguments' expressions, so the
calls build the hash's operations directly, where a ``ti.func`` is parsed and its AST transformed
again at each call site at every start (spawn's 10 draws and curl noise's lattice hashes: ~30 ms
of sparks' warm start). The operations are integer ones and the last an exact scaling (a 24-bit
integer to f32, times 2^-24), so the values do not depend on how the IR around them is shaped:
the same bits as the ``ti.func`` (tests/test_particles.py: the bits of a NumPy version of the
hash). Their intermediate values go through local variables (``quick_ops.local``) as the
``ti.func``'s did: built as plain expressions, a value used twice was built twice when the kernel
was lowered, and the hash nests three deep (spawn took 18.5 s to compile cold instead of 0.25 s).
"""
import taichi as ti
from taichi.lang.expr import Expr

from ..quick_ops import inline, local as _local


def _u32(c: int):
    """A u32 constant, as the front end builds ``ti.u32(c)`` written in a kernel (a data type
    called from Python, as it would be in a plain function, refuses)."""
    return Expr(c, dtype=ti.u32)


@inline
def pcg_hash(v):
    """u32 hash of ``v`` (cast to u32); Taichi scope only."""
    state = _local(ti.cast(v, ti.u32) * _u32(747796405) + _u32(2891336453))
    word = _local(((state >> ((state >> _u32(28)) + _u32(4))) ^ state) * _u32(277803737))
    return (word >> _u32(22)) ^ word


@inline
def rand01(seed, stream, counter, k):
    """Uniform in [0, 1) from 24 hash bits; ``k`` picks one of several numbers per draw.
    Taichi scope only."""
    h = _local(pcg_hash(ti.cast(seed, ti.u32) ^ pcg_hash(ti.cast(stream, ti.u32) * _u32(16) + ti.cast(k, ti.u32)
                                                          ^ pcg_hash(ti.cast(counter, ti.u32)))))
    return ti.cast(h >> _u32(8), ti.f32) * (1.0 / 16777216.0)
