"""Many small fields written in one launch.

``field.from_numpy`` compiles (or loads from the offline cache) one kernel per field it writes:
a scene's per-emitter parameters were 12 such kernels and its counters 5 more, 11–17 ms each to
load on a warm start (timed at their first launch: ~0.2 s of sparks' start). A
:class:`ColumnWriter` writes a fixed list of fields, all of one scalar type, from one array of
rows (n, C) — a scalar field one column, a vector field as many as it has components — in one
kernel: one compile for the list.
"""
# (no __future__ annotations: Taichi reads the kernels' annotations)

import numpy as np
import taichi as ti
from taichi.lang.matrix import MatrixField


@ti.data_oriented
class ColumnWriter:
    """Writes rows (n, C) into ``fields`` (shape (≥ n,), all of dtype ``dtype`` — f32, f64 or i32 —
    in order: column
    ``offsets[c]`` onward is field c's, ``widths[c]`` columns wide; 0 for a scalar field)."""

    def __init__(self, fields, dtype=ti.f32):
        self.fields = tuple(fields)
        self.widths = tuple(f.n if isinstance(f, MatrixField) else 0 for f in self.fields)
        offsets, at = [], 0
        for w in self.widths:
            offsets.append(at)
            at += max(w, 1)
        self.offsets, self.columns = tuple(offsets), at
        self._np = {ti.i32: np.int32, ti.f64: np.float64}.get(dtype, np.float32)

    def write(self, *arrays) -> None:
        """One array per field, in order, each (n,) or (n, width), n the same for all; values
        are cast to the fields' type as ``from_numpy`` would."""
        n = len(arrays[0])
        rows = np.empty((n, self.columns), self._np)
        for c, a in enumerate(arrays):
            rows[:, self.offsets[c]: self.offsets[c] + max(self.widths[c], 1)] = \
                np.asarray(a).reshape(n, max(self.widths[c], 1))
        _write_rows(self, rows)

    def zero(self, n: int) -> None:
        """Set the first n entries of every field to zero."""
        _write_rows(self, np.zeros((n, self.columns), self._np))


@ti.kernel
def _write_rows(W: ti.template(), rows: ti.types.ndarray(ndim=2)):
    for e in range(rows.shape[0]):
        for c in ti.static(range(len(W.fields))):
            if ti.static(W.widths[c] == 0):
                W.fields[c][e] = rows[e, W.offsets[c]]
            else:
                for k in ti.static(range(W.widths[c])):
                    W.fields[c][e][k] = rows[e, W.offsets[c] + k]
