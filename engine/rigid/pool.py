"""Pooled XPBD fields: the fields (and so the compiled step kernels) of a rigid system that is
gone serve the next system of the same shape (:class:`~engine.rigid.fields.Fields`; leased by
:class:`~engine.rigid.xpbd.XPBDSolver`)."""
import gc
import weakref
from collections import Counter

from .. import reuse, runtime
from .fields import Fields


def room(n: int) -> int:
    """Rows kept for n bodies or joints: n rounded up to a power of two, at least 4 (0 stays 0),
    so that scenes of nearly the same size share pooled fields. Rows past n are inert (no mass,
    not moving, never looped over as joints); 64 is a power of two, so a scene takes the same
    kernel path (WHOLE_MAX_BODIES) as with exact counts."""
    return 0 if n <= 0 else max(4, 1 << (n - 1).bit_length())


# The kernels are specialised to the fields they close over, so every new Fields compiles them
# anew: ~7 s cold for a box scene's whole step, 25-30 s with joints, 60-85 s with coupled joints
# (measured, 2 cores). Fields of a system that is gone are kept here, by their shape, and the next
# system of that shape takes them with their compiled kernels: a level rebuilt after an edit, or a
# test's second case, compiles nothing. Everything a step reads is loaded by its owner or written
# by the step before it is read (bodies and contacts each step; inertia, kinds, joints and plan
# when leased), so pooled fields give the same bytes as new ones (tests/test_rigid.py). Memory:
# a dropped system's fields were never freed before either (freeing a field destroys its SNode
# tree, which drops every compiled kernel of the program: engine.reuse), so the pool holds no
# more than the process did, and reuses it.
_idle: dict = {}  # key -> [Fields, ...] free
_leased: Counter = Counter()  # key -> Fields of that key held by live leases


class Lease:
    """One system's hold on a Fields (``.F``): they return to the pool when the lease is dropped
    (its owner gone or grown out of them), never while it lives."""

    def __init__(self, F: Fields):
        self.F = F
        weakref.finalize(self, _give_back, F, reuse.program())


def lease(count: int, capacity: int, nj: int, plan=None) -> Lease:
    """Fields for ``count`` bodies, ``capacity`` contacts and nj joints (``plan``: the direct
    solve's, or None), from the pool where one of that shape is free, else new (and compiled on
    first use)."""
    nd = len(plan["order"]) if plan is not None else 0
    key = (room(count), capacity, room(nj), nd, plan["size"] if nd else 0)
    if not _idle.get(key) and _leased[key]:
        gc.collect()  # a dropped system caught in a reference cycle frees its fields here
    free = _idle.get(key)
    F = free.pop() if free else Fields(*key)
    _leased[key] += 1
    F.load_plan(plan)
    return Lease(F)


def pooled(key=None) -> int:
    """Free pooled Fields (of ``key``, or all)."""
    return len(_idle.get(key, ())) if key is not None else sum(len(v) for v in _idle.values())


def _give_back(F: Fields, program: int) -> None:
    if program == reuse.program():  # fields of a reset program died with it
        _leased[F.key] -= 1
        _idle.setdefault(F.key, []).append(F)


def _forget() -> None:
    _idle.clear()
    _leased.clear()


runtime.on_reset(_forget)
