"""Contacts as an event queue: records kept on the device between two drains, read in one go.

A step's kernels append a record per contact (pool slot or node, collider, position, normal,
impact speed, time) at an atomic counter; nothing is read back per step. The counter is reset
only when the records are drained (:func:`drain`), so a game that reads contacts once per frame
sees every contact of every step since its last read, however many fixed steps ran; contacts
beyond the buffer are counted (``dropped``), never written over earlier ones. The drained rows
are sorted by (time, slot): the order threads wrote them in does not show.

A contact names both parties, each by kind, index and name (warp.sim's ``rigid_contact_shape0/1``
pairs name both shapes the same way): party a is what moved into the surface — a ``"particle"``
(index: its pool slot; name: its emitter's, recorded with the contact, so a slot reused later
does not rename it) or a soft body's ``"node"`` (index: the node; name: the body's) — and party b
the shape it met in the scene's shape table — a ``"collider"`` of the config or a ``"rigid"``
body's shape (index: the collider's, or the rigid body's; name: the shape's).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import taichi as ti

from .launch import data_oriented


@dataclass
class Contacts:
    """Contacts drained by ``ParticleScene.contacts()`` (sorted by time, then slot).

    ``collider`` (K,) int index into the scene's shape table, ``position`` (K, 3) m, ``normal``
    (K, 3) unit, ``speed`` (K,) impact speed along the normal m/s, ``time`` (K,) s, ``slot`` (K,)
    pool slot (particles) or node index (a soft body's); ``names`` the shapes' names by index;
    ``dropped``: contacts since the previous drain that did not fit the buffer.

    Both parties (module docstring): ``group`` (K,) int the emitter of each particle (0 for a soft
    body's nodes), ``kind`` party a's kind ("particle" or "node"), ``group_names`` the names
    ``group`` indexes (the emitters', or the body's), ``shapes`` per shape of the table its
    (kind, index): ("collider", k) or ("rigid", body index). Read them per row as ``a_kind``,
    ``a_index``, ``a_name``, ``b_kind``, ``b_index``, ``b_name`` (or :meth:`rows`)."""

    collider: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    speed: np.ndarray
    time: np.ndarray
    slot: np.ndarray
    names: tuple = ()
    dropped: int = 0
    group: np.ndarray = None
    kind: str = "particle"
    group_names: tuple = ()
    shapes: tuple = ()

    def __post_init__(self):
        if self.group is None:
            self.group = np.zeros(len(self.slot), np.int32)

    @classmethod
    def empty(cls, names=(), dropped: int = 0, **parties) -> "Contacts":
        z = np.zeros(0, np.float32)
        return cls(np.zeros(0, np.int32), np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32), z, z,
                   np.zeros(0, np.int32), tuple(names), dropped, **parties)

    def __len__(self):
        return len(self.speed)

    @property
    def collider_name(self) -> np.ndarray:
        """(K,) the name of each row's collider ("" for an unnamed one)."""
        lookup = np.array(list(self.names) or [""], dtype=object)
        return lookup[self.collider] if len(self) else np.zeros(0, object)

    # -- both parties ---------------------------------------------------------------------------
    @property
    def a_kind(self) -> np.ndarray:
        """(K,) party a's kind: "particle" or "node"."""
        return np.full(len(self), self.kind, dtype=object)

    @property
    def a_index(self) -> np.ndarray:
        """(K,) party a's index: the particle's pool slot or the node's index (``slot``)."""
        return self.slot

    @property
    def a_name(self) -> np.ndarray:
        """(K,) party a's name: the particle's emitter's, or the soft body's ("" when unnamed)."""
        lookup = np.array(list(self.group_names) or [""], dtype=object)
        return lookup[np.clip(self.group, 0, len(lookup) - 1)] if len(self) else np.zeros(0, object)

    def _shape(self, j: int) -> np.ndarray:
        table = list(self.shapes) or [("collider", k) for k in range(max(1, len(self.names)))]
        col = np.array([s[j] for s in table], dtype=object)
        return col[self.collider] if len(self) else np.zeros(0, object)

    @property
    def b_kind(self) -> np.ndarray:
        """(K,) party b's kind: "collider" or "rigid"."""
        return self._shape(0)

    @property
    def b_index(self) -> np.ndarray:
        """(K,) party b's index: the collider's (``collider``) or the rigid body's."""
        return self._shape(1).astype(np.int64) if len(self) else np.zeros(0, np.int64)

    @property
    def b_name(self) -> np.ndarray:
        """(K,) party b's name (``collider_name``)."""
        return self.collider_name

    def where(self, mask) -> "Contacts":
        """The rows where ``mask`` holds (``dropped`` kept)."""
        return Contacts(self.collider[mask], self.position[mask], self.normal[mask], self.speed[mask],
                        self.time[mask], self.slot[mask], self.names, self.dropped, self.group[mask],
                        self.kind, self.group_names, self.shapes)

    def rows(self):
        """One dict per contact: collider (index), name, position, normal, speed, time, slot, and
        both parties: a_kind, a_index, a_name, b_kind, b_index, b_name."""
        names, a_name, b_kind, b_index = self.collider_name, self.a_name, self.b_kind, self.b_index
        for k in range(len(self)):
            yield dict(collider=int(self.collider[k]), name=str(names[k]), position=self.position[k],
                       normal=self.normal[k], speed=float(self.speed[k]), time=float(self.time[k]),
                       slot=int(self.slot[k]), a_kind=self.kind, a_index=int(self.slot[k]),
                       a_name=str(a_name[k]), b_kind=str(b_kind[k]), b_index=int(b_index[k]),
                       b_name=str(names[k]))


def drain(count, slot, collider, pos, normal, speed, time, capacity: int, names=(), group=None,
          **parties) -> Contacts:
    """Read the records in the fields (``count`` a 0-d i32 field, the others shape (capacity,)),
    sorted by (time, slot), and reset the counter: the next drain starts empty. ``group``: the
    records' party-a groups (a field like ``slot``; None: all 0); ``parties``: ``kind``,
    ``group_names``, ``shapes`` (:class:`Contacts`)."""
    n = int(count[None])
    if n == 0:
        return Contacts.empty(names, **parties)
    k = min(n, capacity)
    sl = slot.to_numpy()[:k]
    tt = time.to_numpy()[:k]
    order = np.lexsort((sl, tt))  # deterministic, whatever order threads wrote them in
    cols = [f.to_numpy()[:k][order] for f in (collider, pos, normal, speed)]
    grp = group.to_numpy()[:k][order] if group is not None else None
    count[None] = 0
    return Contacts(*cols, tt[order], sl[order], tuple(names), max(0, n - k), grp, **parties)


@data_oriented
class ContactBuffer:
    """Device-side contact records, for a particle pool (its integrator's ``contact_log``) and a
    soft body's nodes alike: ``capacity`` rows; ``enabled`` False when nothing records."""

    def __init__(self, capacity: int, kind: str = "particle"):
        """``kind``: what the records' party a is ("particle" or "node")."""
        self.capacity = int(capacity)
        self.enabled = self.capacity > 0
        self.kind = kind
        n = max(1, self.capacity)
        self.count = ti.field(ti.i32, shape=())
        self.slot = ti.field(ti.i32, shape=n)
        self.group = ti.field(ti.i32, shape=n)  # party a's group: a particle's emitter
        self.collider = ti.field(ti.i32, shape=n)
        self.pos = ti.Vector.field(3, ti.f32, shape=n)
        self.normal = ti.Vector.field(3, ti.f32, shape=n)
        self.speed = ti.field(ti.f32, shape=n)
        self.time = ti.field(ti.f32, shape=n)

    @ti.func
    def record(self, i, which, x, nrm, spd, t, group):
        """A contact of party a ``i`` (slot or node; ``group`` its emitter, or 0) with shape
        ``which`` at x (normal, impact speed, time). Integer atomics only: a row's place depends
        on thread timing, its content does not, and the drain sorts."""
        c = ti.atomic_add(self.count[None], 1)
        if c < self.capacity:
            self.slot[c], self.collider[c], self.pos[c] = i, which, ti.cast(x, ti.f32)
            self.normal[c], self.speed[c], self.time[c] = nrm, spd, ti.cast(t, ti.f32)
            self.group[c] = group

    def drain(self, names=(), group_names=(), shapes=()) -> Contacts:
        """Every record since the last drain (:class:`Contacts`); ``names``, ``shapes``: the shape
        table's names and (kind, index) pairs; ``group_names``: the names of party a's groups."""
        parties = dict(kind=self.kind, group_names=tuple(group_names), shapes=tuple(shapes))
        if not self.enabled:
            return Contacts.empty(names, **parties)
        return drain(self.count, self.slot, self.collider, self.pos, self.normal, self.speed, self.time,
                     self.capacity, names, self.group, **parties)
