"""Whole-pool operations outside the step: emptying a pool (a reused scene) and keeping the
positions of the last step (drawing between two steps). Module-level kernels over a
:class:`~engine.particles.pool.ParticleState` (a template argument).
"""
# (no `from __future__ import annotations`: Taichi reads kernel annotations at definition)
import taichi as ti


@ti.kernel
def clear(S: ti.template()):
    """Every slot empty, as a newly allocated pool is (a scene reused for a restart)."""
    for i in range(S.capacity):
        S.particle_pos[i] = ti.Vector([0.0, 0.0, 0.0])
        S.particle_vel[i] = ti.Vector([0.0, 0.0, 0.0])
        S.particle_age[i] = 0.0
        S.particle_life[i] = 0.0
        S.particle_alive[i] = 0
        S.particle_emitter[i] = 0
        S.particle_rand[i] = 0.0


@ti.kernel
def save_positions(S: ti.template()):
    """``particle_prev_pos`` = where each born particle is now; NaN for the others (a particle
    born during the coming step is drawn where it is, not interpolated from a stale slot)."""
    nan = ti.math.nan
    for i in range(S.capacity):
        p = ti.Vector([nan, nan, nan])
        if S.particle_alive[i] != 0 and S.particle_age[i] >= 0.0:
            p = S.particle_pos[i]
        S.particle_prev_pos[i] = p
