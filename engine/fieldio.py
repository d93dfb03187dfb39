"""Many small fields written in one launch.

``field.from_numpy`` compiles (or loads from the offline cache) one kernel per field it writes:
a scene's per-emitter parameters were 12 such kernels and its counters 5 more, 11–17 ms each to
load on a warm start (timed at their first launch: ~0.2 s of sparks' start). A
:class:`ColumnWriter` writes a fixed list of fields, all of one scalar type, from one array of
rows (n, C) — a scalar field one column, a vector field as many as it has components — in one
kernel: one compile for the list. A :class:`WriterGroup` makes several writers' writes (of any of
the three types) one launch of one kernel: a scene's colliders' fixed numbers and first
orientations and its particles' emitter parameters, counters and force parameters were six kernels
to load at each start, 12-16 ms each.
"""
# (no __future__ annotations: Taichi reads the kernels' annotations)

import contextlib

import numpy as np
import taichi as ti
from taichi.lang.matrix import MatrixField

from .launch import data_oriented


@data_oriented
class ColumnWriter:
    """Writes rows (n, C) into ``fields`` (shape (≥ n,), all of dtype ``dtype`` — f32, f64 or i32 —
    in order: column
    ``offsets[c]`` onward is field c's, ``widths[c]`` columns wide; 0 for a scalar field)."""

    def __init__(self, fields, dtype=ti.f32, group=None):
        """``group``: a :class:`WriterGroup` whose one kernel makes this writer's writes."""
        self.fields = tuple(fields)
        self.widths = tuple(f.n if isinstance(f, MatrixField) else 0 for f in self.fields)
        offsets, at = [], 0
        for w in self.widths:
            offsets.append(at)
            at += max(w, 1)
        self.offsets, self.columns = tuple(offsets), at
        self._np = {ti.i32: np.int32, ti.f64: np.float64}.get(dtype, np.float32)
        self.group = group
        if group is not None:
            group._add(self)

    def write(self, *arrays) -> None:
        """One array per field, in order, each (n,) or (n, width), n the same for all; values
        are cast to the fields' type as ``from_numpy`` would."""
        n = len(arrays[0])
        rows = np.empty((n, self.columns), self._np)
        for c, a in enumerate(arrays):
            rows[:, self.offsets[c]: self.offsets[c] + max(self.widths[c], 1)] = \
                np.asarray(a).reshape(n, max(self.widths[c], 1))
        self._put(rows)

    def zero(self, n: int) -> None:
        """Set the first n entries of every field to zero."""
        self._put(np.zeros((n, self.columns), self._np))

    def _put(self, rows) -> None:
        if self.group is not None:
            self.group._put(self, rows)
        else:
            _write_rows(self, rows.reshape(-1), len(rows))


@data_oriented
class WriterGroup:
    """One kernel for several :class:`ColumnWriter` (those built with ``group=`` this group, all
    before its first launch: the kernel is compiled for them). A writer's write launches that
    kernel for its rows alone; inside :meth:`held`, the writes are kept and made in one launch as
    the outermost block ends (none if it raises; an inner block that raises inside an outer one
    that goes on leaves its writes to the outer one). A second write to one writer inside a block
    replaces the first whole, its rows past the second's included (the engine's writers always
    write all their rows)."""

    def __init__(self):
        self.writers, self._held, self._holding, self._launched = [], {}, 0, False

    def _add(self, writer) -> None:
        if self._launched:
            raise RuntimeError("WriterGroup: a writer added after the group's kernel was compiled")
        writer.slot = len(self.writers)  # (its place in the group's kernel)
        self.writers.append(writer)

    @contextlib.contextmanager
    def held(self):
        self._holding += 1
        try:
            yield self
        except BaseException:
            if self._holding == 1:
                self._held.clear()
            raise
        finally:
            self._holding -= 1
        if self._holding == 0 and self._held:
            parts, self._held = self._held, {}
            self._launch(parts)

    def _put(self, writer, rows) -> None:
        if self._holding:
            self._held[writer.slot] = rows
        else:
            self._launch({writer.slot: rows})

    def _launch(self, parts) -> None:
        if not self._launched:
            self._launched = True
            self.writers = tuple(self.writers)
            self.kinds = tuple(_KINDS[w._np] for w in self.writers)
        flat = {k: [] for k in _KINDS.values()}
        at = dict.fromkeys(_KINDS.values(), 0)
        starts, counts = np.zeros(len(self.writers), np.int32), np.zeros(len(self.writers), np.int32)
        for g, rows in sorted(parts.items()):
            k = self.kinds[g]
            starts[g], counts[g] = at[k], len(rows)
            flat[k].append(rows.reshape(-1))
            at[k] += rows.size
        arrays = [np.concatenate(flat[k]) if flat[k] else np.zeros(1, t) for t, k in _KINDS.items()]
        _write_groups(self, *arrays, starts, counts)


_KINDS = {np.float32: 0, np.int32: 1, np.float64: 2}


@ti.func
def _rows_from(W: ti.template(), flat: ti.template(), start, n):
    """Writer W's n rows, row-major in ``flat`` from ``start`` (``ColumnWriter.write``'s rows)."""
    for e in range(n):
        base = start + e * W.columns
        for c in ti.static(range(len(W.fields))):
            if ti.static(W.widths[c] == 0):
                W.fields[c][e] = flat[base + W.offsets[c]]
            else:
                for k in ti.static(range(W.widths[c])):
                    W.fields[c][e][k] = flat[base + W.offsets[c] + k]


@ti.kernel
def _write_rows(W: ti.template(), flat: ti.types.ndarray(ndim=1), n: ti.i32):
    """Writer W's n rows, row-major in ``flat`` (a writer of no group)."""
    _rows_from(W, flat, 0, n)


@ti.kernel
def _write_groups(G: ti.template(), f32: ti.types.ndarray(dtype=ti.f32, ndim=1),
                  i32: ti.types.ndarray(dtype=ti.i32, ndim=1), f64: ti.types.ndarray(dtype=ti.f64, ndim=1),
                  starts: ti.types.ndarray(dtype=ti.i32, ndim=1), counts: ti.types.ndarray(dtype=ti.i32, ndim=1)):
    """Every writer g of group G with counts[g] > 0: its rows from the flat array of its type."""
    for g in ti.static(range(len(G.writers))):
        if ti.static(G.kinds[g] == 0):
            _rows_from(G.writers[g], f32, starts[g], counts[g])
        elif ti.static(G.kinds[g] == 1):
            _rows_from(G.writers[g], i32, starts[g], counts[g])
        else:
            _rows_from(G.writers[g], f64, starts[g], counts[g])
