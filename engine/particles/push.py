"""Two-way coupling: particles of ``two_way`` emitters push the rigid bodies they hit back.

A contact's response (engine.colliders: restitution and friction on the velocity relative to the
surface point) changes a particle's velocity by Δv; by Newton's third law the body receives the
impulse J = −m Δv at the contact point p (m: the emitter's ``mass`` per particle, kg), and the
angular impulse (p − c) × J about its centre c (Baraff's notes: ΔP = J, ΔL = r × J).

Determinism (the Coupling board's rule: no float atomics into the state). Each particle slot
keeps its own record over one coupling step — the body it pushed, Σ Δv and Σ (p − c) × Δv, f32,
with c the body's centre where the table had it at that contact — written by the one thread that
steps that slot. After the particles' advance the records are summed on the host in slot order
in float64 (:meth:`Pusher.impulses`): the same bytes for any thread count.

One body per slot and coupling step: a particle that touches a second body within the same
coupling step (a frame, unless some system asks for shorter ones) gives that body nothing — its
later contacts with the first body still count. Rare for a spray, and never a push in a wrong
direction; the momentum given away is then not conserved exactly.

The record is compiled only where some emitter is ``two_way``: the colliders' ``pusher`` is
None otherwise and the particle step is the same code as before.
"""
import numpy as np
import taichi as ti

from ..launch import data_oriented


@data_oriented
class Pusher:
    """Per-slot push records (shape (capacity,)): ``push_body`` (i32, the rigid body's index, −1:
    none yet), ``push_dv`` (f32 (3,), m/s: Σ Δv of the slot's particle over its contacts with that
    body), ``push_moment`` (f32 (3,), m²/s: Σ (p − c) × Δv, c the body's centre at each contact).
    ``body_of`` (i32, shape (table count,)): the body owning each shape of the table (−1: a
    config's collider). ``masses``: kg per particle of each emitter row (0: not ``two_way``)."""

    def __init__(self, capacity: int, colliders, masses):
        n = max(1, int(capacity))
        self.capacity = int(capacity)
        self.push_body = ti.field(ti.i32, shape=n)
        self.push_dv = ti.Vector.field(3, ti.f32, shape=n)
        self.push_moment = ti.Vector.field(3, ti.f32, shape=n)
        self.body_of = ti.field(ti.i32, shape=max(1, colliders.count))
        owners = np.full(max(1, colliders.count), -1, np.int32)
        for k, s in enumerate(colliders.specs):
            if s.owner == "rigid":
                owners[k] = s.owner_index
        self.body_of.from_numpy(owners)
        self.masses = np.asarray(masses, np.float64)
        self.clear()

    @ti.func
    def add(self, i, body, r, dv):
        """Slot i's particle changed velocity by dv (m/s) at the offset r (m) from ``body``'s
        centre. Slot i is written by its own thread only (no atomics)."""
        if i >= 0:
            b = self.push_body[i]
            if b < 0:
                self.push_body[i] = body
                b = body
            if b == body:
                self.push_dv[i] += dv
                self.push_moment[i] += r.cross(dv)

    def clear(self) -> None:
        """Empty every record (the start of a coupling step; a reset)."""
        self.push_body.fill(-1)
        self.push_dv.fill(0.0)
        self.push_moment.fill(0.0)

    def impulses(self, emitter_of, bodies: int):
        """(J, L): float64 (bodies, 3) — the impulse (N·s) and angular impulse about each body's
        centre (N·m·s) the records give, J = −Σ m Δv, L = −Σ m (p − c) × Δv over the slots in
        slot order (np.add.at adds in index order: the same sums for any thread count).
        ``emitter_of``: (capacity,) each slot's emitter row. None when nothing was pushed."""
        cap = self.capacity
        b = self.push_body.to_numpy()[:cap]
        m = self.masses[np.asarray(emitter_of)[:cap]] if cap else np.zeros(0)
        hit = (b >= 0) & (m > 0)
        if not hit.any():
            return None
        w = -m[hit][:, None]
        J = np.zeros((bodies, 3))
        L = np.zeros((bodies, 3))
        np.add.at(J, b[hit], w * self.push_dv.to_numpy()[:cap][hit].astype(np.float64))
        np.add.at(L, b[hit], w * self.push_moment.to_numpy()[:cap][hit].astype(np.float64))
        return J, L
