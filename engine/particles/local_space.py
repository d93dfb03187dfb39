"""Local-space emitters (``space = "local"``): live particles move with their emitter, as Unity's
and Godot's local simulation space does for translation — a jet on a moving ship stays a jet.

The particles are simulated in the world as any others (forces and colliders see world
positions); after each step the emitter's displacement is added to its ring: over a step of
length ``span`` the emitter moved by ``d`` (linearly: control paths are linear within a step), so
a particle of age a carries ``d · min(1, a / span)`` — one born during the step only the part of
the motion after its birth — plus any jump the emitter made between steps (``jump``, for particles
older than the step). One launch per moving local emitter per step; none while it stands still.
"""
import taichi as ti


@ti.kernel
def carry(S: ti.template(), start: ti.i32, size: ti.i32, d: ti.types.vector(3, ti.f32),
          jump: ti.types.vector(3, ti.f32), span: ti.f32):
    for j in range(size):
        i = start + j
        if S.particle_alive[i] != 0 and S.particle_age[i] >= 0.0:
            a = S.particle_age[i]
            f = 1.0
            if span > 0.0:
                f = ti.min(1.0, a / span)
            shift = f * d
            if a > span * 1.001:  # born before this step (the ones born at its start have age = span)
                shift += jump
            S.particle_pos[i] += shift
