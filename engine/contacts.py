"""Contacts as an event queue: records kept on the device between two drains, read in one go.

A step's kernels append a record per contact (pool slot or node, collider, position, normal,
impact speed, time) at an atomic counter; nothing is read back per step. The counter is reset
only when the records are drained (:func:`drain`), so a game that reads contacts once per frame
sees every contact of every step since its last read, however many fixed steps ran; contacts
beyond the buffer are counted (``dropped``), never written over earlier ones. The drained rows
are sorted by (time, slot): the order threads wrote them in does not show.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import taichi as ti


@dataclass
class Contacts:
    """Contacts drained by ``ParticleScene.contacts()`` (sorted by time, then slot).

    ``collider`` (K,) int index into the scene's colliders, ``position`` (K, 3) m, ``normal``
    (K, 3) unit, ``speed`` (K,) impact speed along the normal m/s, ``time`` (K,) s, ``slot`` (K,)
    pool slot (particles) or node index (a soft body's); ``names`` the colliders' names by index;
    ``dropped``: contacts since the previous drain that did not fit the buffer."""

    collider: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    speed: np.ndarray
    time: np.ndarray
    slot: np.ndarray
    names: tuple = ()
    dropped: int = 0

    @classmethod
    def empty(cls, names=(), dropped: int = 0) -> "Contacts":
        z = np.zeros(0, np.float32)
        return cls(np.zeros(0, np.int32), np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32), z, z,
                   np.zeros(0, np.int32), tuple(names), dropped)

    def __len__(self):
        return len(self.speed)

    @property
    def collider_name(self) -> np.ndarray:
        """(K,) the name of each row's collider ("" for an unnamed one)."""
        lookup = np.array(list(self.names) or [""], dtype=object)
        return lookup[self.collider] if len(self) else np.zeros(0, object)

    def where(self, mask) -> "Contacts":
        """The rows where ``mask`` holds (``dropped`` kept)."""
        return Contacts(self.collider[mask], self.position[mask], self.normal[mask], self.speed[mask],
                        self.time[mask], self.slot[mask], self.names, self.dropped)

    def rows(self):
        """One dict per contact: collider (index), name, position, normal, speed, time, slot."""
        names = self.collider_name
        for k in range(len(self)):
            yield dict(collider=int(self.collider[k]), name=str(names[k]), position=self.position[k],
                       normal=self.normal[k], speed=float(self.speed[k]), time=float(self.time[k]),
                       slot=int(self.slot[k]))


def drain(count, slot, collider, pos, normal, speed, time, capacity: int, names=()) -> Contacts:
    """Read the records in the fields (``count`` a 0-d i32 field, the others shape (capacity,)),
    sorted by (time, slot), and reset the counter: the next drain starts empty."""
    n = int(count[None])
    if n == 0:
        return Contacts.empty(names)
    k = min(n, capacity)
    sl = slot.to_numpy()[:k]
    tt = time.to_numpy()[:k]
    order = np.lexsort((sl, tt))  # deterministic, whatever order threads wrote them in
    cols = [f.to_numpy()[:k][order] for f in (collider, pos, normal, speed)]
    count[None] = 0
    return Contacts(*cols, tt[order], sl[order], tuple(names), max(0, n - k))


@ti.data_oriented
class ContactBuffer:
    """Device-side contact records, for a particle pool (its integrator's ``contact_log``) and a
    soft body's nodes alike: ``capacity`` rows; ``enabled`` False when nothing records."""

    def __init__(self, capacity: int):
        self.capacity = int(capacity)
        self.enabled = self.capacity > 0
        n = max(1, self.capacity)
        self.count = ti.field(ti.i32, shape=())
        self.slot = ti.field(ti.i32, shape=n)
        self.collider = ti.field(ti.i32, shape=n)
        self.pos = ti.Vector.field(3, ti.f32, shape=n)
        self.normal = ti.Vector.field(3, ti.f32, shape=n)
        self.speed = ti.field(ti.f32, shape=n)
        self.time = ti.field(ti.f32, shape=n)

    @ti.func
    def record(self, i, which, x, nrm, spd, t):
        c = ti.atomic_add(self.count[None], 1)
        if c < self.capacity:
            self.slot[c], self.collider[c], self.pos[c] = i, which, ti.cast(x, ti.f32)
            self.normal[c], self.speed[c], self.time[c] = nrm, spd, ti.cast(t, ti.f32)

    def drain(self, names=()) -> Contacts:
        if not self.enabled:
            return Contacts.empty(names)
        return drain(self.count, self.slot, self.collider, self.pos, self.normal, self.speed, self.time,
                     self.capacity, names)
