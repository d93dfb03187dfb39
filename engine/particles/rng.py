"""Counter-based random numbers: a pure function of (seed, stream, counter), so a particle's
randomness depends on which particle it is, not on thread timing or slot order.

PCG's output permutation as an integer hash (O'Neill 2014; Jarzynski & Olano, "Hash Functions for
GPU Rendering", JCGT 2020, recommend it for quality per cost).
"""
import taichi as ti


@ti.func
def pcg_hash(v):
    state = ti.cast(v, ti.u32) * ti.u32(747796405) + ti.u32(2891336453)
    word = ((state >> ((state >> ti.u32(28)) + ti.u32(4))) ^ state) * ti.u32(277803737)
    return (word >> ti.u32(22)) ^ word


@ti.func
def rand01(seed, stream, counter, k):
    """Uniform in [0, 1) from 24 hash bits; ``k`` picks one of several numbers per draw."""
    h = pcg_hash(ti.cast(seed, ti.u32) ^ pcg_hash(ti.cast(stream, ti.u32) * ti.u32(16) + ti.cast(k, ti.u32)
                                                   ^ pcg_hash(ti.cast(counter, ti.u32))))
    return ti.cast(h >> ti.u32(8), ti.f32) * (1.0 / 16777216.0)
