"""Meshes in the renderer (what systems' ``drawables()`` give: soft bodies, rigid shapes): shaded
triangles (cloth, jelly, rigid bodies) and lines (chains, hair), depth-
tested against the background and hiding the particles behind them. Parallel and deterministic:

* **Triangles** through a visibility buffer: every triangle, in parallel, rasterises its
  bounding box and keeps, per pixel, the minimum of the 64-bit key (depth bits << 32 | triangle),
  an integer ``atomic_min`` — the nearest triangle wins, ties go to the lower index, whatever the
  thread order (a float z-buffer written from several threads would race). A second pass shades
  each covered pixel from its winning triangle: smooth normals (area-weighted, gathered per vertex)
  interpolated perspective-correctly through 1/z, one directional light, two-sided.
* **Lines** (1 px, bilinear coverage a per sample) add their optical depth −log(1 − a) and their
  colour weighted by it into fixed-point integers: integer sums are exact in any order, and
  T = exp(−Σ) is what drawing them one over another gives for lines of one colour. The four i32
  sums of a pixel travel as two i64 (``pack2``), so a sample makes two atomic adds, not four.

Only tiles a body touches (this frame or the last) are rewritten: the rest of the frame's
background and depth stay as the background pass left them.
"""
# (no `from __future__ import annotations`: Taichi reads kernel annotations at definition)

import numpy as np
import taichi as ti

from .. import runtime
from ..launch import fast
from ..spread import TASK, item, rounds, tasks
from .sprites import TILE
from .upsample import ND_F, ND_I1, ND_V4  # pixel arrays: flat, y·W + x

vec3 = ti.types.vector(3, ti.f32)
ND_I64 = ti.types.ndarray(dtype=ti.i64, ndim=1)
ND_L2 = ti.types.ndarray(dtype=ti.types.vector(2, ti.i64), ndim=1)
NEAR = 0.05
DEPTH_BIAS = 0.01  # m: cloth resting on the ground would z-fight it
EMPTY = (1 << 63) - 1  # no triangle at this pixel
FIXED = 65536.0  # fixed-point scale of the line sums
SERIAL_VERTICES = 65536  # host vertices copied in on the launching thread, at most (CPU)


@ti.kernel
def _copy_in(dst: ti.template(), rows: ti.types.ndarray(dtype=ti.f32, ndim=2), serial: ti.template()):
    """rows (n, 3) f32 into the vec3 field ``dst`` (what ``from_numpy`` writes)."""
    ti.loop_config(serialize=serial)
    for i in range(rows.shape[0]):
        for c in ti.static(range(3)):
            dst[i][c] = rows[i, c]


_copy_in = fast(_copy_in)  # (engine.launch: without Taichi's per-call Python)


class MeshLayer:
    """Geometry of every drawable body of a scene, concatenated: ``mesh_pos``/``mesh_nrm``/``mesh_col``
    (V,) vec3 (m, unit, linear RGB), ``tri_idx`` (T,) and ``line_idx`` (L,) vertex indices."""

    def __init__(self, bodies):
        """``bodies``: anything drawn as a mesh, through its ``drawables()``: ``positions`` (a
        callable giving (V, 3) world vertices at draw time), ``triangles`` (T, 3), ``lines``
        (L, 2) and ``color`` ((3,) for all vertices or (V, 3)); optionally ``position_field``, a
        Taichi vector field (≥ V rows, f32 or f64) holding the same vertices for the body's whole
        life, which the mesh pass copies in its own launch (soft bodies' nodes)."""
        self.bodies = list(bodies)
        self.draws = [b.drawables() for b in self.bodies]
        nv = [len(d["positions"]()) for d in self.draws]
        offsets = np.cumsum([0] + nv[:-1]).astype(np.int64)
        self.nv = int(sum(nv))
        tris = [np.asarray(d["triangles"]) + o for d, o in zip(self.draws, offsets) if len(d["triangles"])]
        lines = [np.asarray(d["lines"]) + o for d, o in zip(self.draws, offsets) if len(d["lines"])]
        self.tris = np.concatenate(tris).astype(np.int32) if tris else np.zeros((0, 3), np.int32)
        self.lines = np.concatenate(lines).astype(np.int32) if lines else np.zeros((0, 2), np.int32)
        self.tri_count, self.line_count = len(self.tris), len(self.lines)
        # (field, first vertex, vertices) of the bodies whose vertices the pass copies itself, and
        # (positions, first vertex, vertices) of the others, copied in through NumPy (``update``)
        placed = [(d, int(o), k) for d, o, k in zip(self.draws, offsets, nv) if k > 0]
        self.fields = tuple((d["position_field"], o, k) for d, o, k in placed
                            if d.get("position_field") is not None)
        self.host_rows = tuple((d["positions"], o, k) for d, o, k in placed if d.get("position_field") is None)
        for f, _o, k in self.fields:  # (the pass reads rows [0, k) of it: none may be missing)
            if len(f.shape) != 1 or f.shape[0] < k:
                raise ValueError(f"drawables: position_field holds {f.shape} rows, fewer than the "
                                 f"{k} vertices its positions give")
        n = max(1, self.nv)
        self.mesh_pos = ti.Vector.field(3, ti.f32, shape=n)
        # the host's rows, kept between frames (the field bodies' rows in it stay 0: the pass
        # writes those in mesh_pos itself, after ``update``'s copy and before any read)
        self._staged = np.zeros((n, 3), np.float32) if self.host_rows else None
        # (a field's from_numpy: ~0.2 ms of Python and a parallel loop a frame; a fast-launched
        # copy, on the launching thread for a few thousand vertices on the CPU: engine.runtime.one_thread)
        self._serial = runtime.one_thread(n, SERIAL_VERTICES)
        self.mesh_nrm = ti.Vector.field(3, ti.f32, shape=n)
        self.mesh_col = ti.Vector.field(3, ti.f32, shape=n)
        cols = np.concatenate([np.broadcast_to(np.asarray(d["color"], np.float32), (k, 3))
                               for d, k in zip(self.draws, nv)]) if self.nv else np.zeros((1, 3), np.float32)
        self.mesh_col.from_numpy(np.ascontiguousarray(cols[:n], np.float32))
        self.tri_idx = ti.Vector.field(3, ti.i32, shape=max(1, self.tri_count))
        # each triangle's corners on screen this frame (x, y px; z m), as the rasteriser projected
        # them: the shading reads them back instead of projecting three vertices per pixel
        self.tri_scr = ti.Vector.field(3, ti.f32, shape=(max(1, self.tri_count), 3))
        self.line_idx = ti.Vector.field(2, ti.i32, shape=max(1, self.line_count))
        if self.tri_count:
            self.tri_idx.from_numpy(self.tris)
            # vertex → triangle adjacency (CSR), for the per-vertex normal gather
            order = np.argsort(self.tris.ravel(), kind="stable")
            self.adj_tri = ti.field(ti.i32, shape=len(order))
            self.adj_tri.from_numpy((order // 3).astype(np.int32))
            starts = np.searchsorted(self.tris.ravel()[order], np.arange(n + 1)).astype(np.int32)
            self.adj_start = ti.field(ti.i32, shape=n + 1)
            self.adj_start.from_numpy(starts)
        if self.line_count:
            self.line_idx.from_numpy(self.lines)
        self._frame = fast(_build(self))  # (engine.launch)

    @property
    def host_copy(self) -> bool:
        """Whether some body's vertices come in through NumPy (``update``)."""
        return bool(self.host_rows)

    def update(self) -> None:
        """Copy in the vertices of the bodies that give only ``positions`` (rounded to f32 by
        NumPy; ``draw`` copies the ``position_field`` ones and recomputes the vertex normals)."""
        if self.host_rows:
            for positions, first, count in self.host_rows:
                self._staged[first:first + count] = positions()
            _copy_in(self.mesh_pos, self._staged, self._serial)

    def draw(self, t, cam) -> None:
        """Rasterise into the frame targets ``t`` (engine.render.targets.FrameTargets): the
        visibility buffer and line sums, then shade the touched tiles into ``t.fbg``/``t.fdep``."""
        self._frame(t.fbg, t.fdep, t.bgc, t.depth, t.vis, t.lines, t.dirty, t.dirty_prev, *cam, t.W, t.H,
                    t.TX, t.TY, int(not t.mesh_clean))
        t.mesh_clean = True


def _build(m: MeshLayer):
    P, N, C = m.mesh_pos, m.mesh_nrm, m.mesh_col
    tri_idx, line_idx, tri_scr = m.tri_idx, m.line_idx, m.tri_scr
    tri_count, line_count, nv = m.tri_count, m.line_count, max(1, m.nv)
    adj_tri = getattr(m, "adj_tri", None)
    adj_start = getattr(m, "adj_start", None)
    fields = m.fields
    NT = tasks()  # (the loops' tasks: engine.spread)

    @ti.func
    def project(p, o, f, r, u, th, W, H):
        d = p - o
        z = d.dot(f)
        s = 0.5 * H / (ti.max(z, NEAR) * th)
        return ti.Vector([d.dot(r) * s + 0.5 * W, 0.5 * H - d.dot(u) * s, z])

    @ti.func
    def bary(a, b, c, sx, sy):
        area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        w0 = ((c[0] - b[0]) * (sy - b[1]) - (c[1] - b[1]) * (sx - b[0])) / area
        w1 = ((a[0] - c[0]) * (sy - c[1]) - (a[1] - c[1]) * (sx - c[0])) / area
        return w0, w1, 1.0 - w0 - w1

    @ti.func
    def normals():
        for v in range(nv):
            n = ti.Vector([0.0, 0.0, 0.0])
            for j in range(adj_start[v], adj_start[v + 1]):
                t = tri_idx[adj_tri[j]]
                n += (P[t[1]] - P[t[0]]).cross(P[t[2]] - P[t[0]])  # area-weighted
            N[v] = n / ti.max(n.norm(), 1e-12)

    @ti.func
    def clear(vis: ti.template(), lines: ti.template(), dirty: ti.template(), dirty_prev: ti.template(),
              H, W, TX, T, whole):
        """Empty the visibility and line buffers where the last frame wrote them (the tiles it
        marked dirty: nothing writes them elsewhere), or everywhere (``whole``: new buffers);
        those tiles become ``dirty_prev``, rewritten (restored) this frame too."""
        for sl in range(NT * TASK):  # (spread over the CPU's tasks: engine.spread)
            for rr in range(rounds(T, NT)):
                t = item(sl, rr, NT)
                if t < T:
                    if whole != 0 or dirty[t] != 0:
                        px0, py0 = (t % TX) * TILE, (t // TX) * TILE
                        for py in range(py0, ti.min(H, py0 + TILE)):
                            for k in range(py * W + px0, py * W + ti.min(W, px0 + TILE)):
                                # (each buffer only where something reads it: a scene of lines alone
                                # never reads the visibility buffer, one of triangles alone the sums)
                                if ti.static(tri_count > 0):
                                    vis[k] = ti.i64(EMPTY)
                                if ti.static(line_count > 0):
                                    lines[k] = ti.Vector([0, 0], dt=ti.i64)
                    dirty_prev[t] = dirty[t]
                    dirty[t] = 0

    @ti.func
    def tris(vis: ti.template(), dirty: ti.template(), o, f, r, u, th, W, H, TX):
        for sl in range(NT * TASK):  # (spread: a triangle's pixels vary, and a few hundred were one task)
            for rr in range(rounds(tri_count, NT)):
                t = item(sl, rr, NT)
                if t < tri_count:
                    i = tri_idx[t]
                    a = project(P[i[0]], o, f, r, u, th, W, H)
                    b = project(P[i[1]], o, f, r, u, th, W, H)
                    c = project(P[i[2]], o, f, r, u, th, W, H)
                    area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
                    tri_scr[t, 0], tri_scr[t, 1], tri_scr[t, 2] = a, b, c
                    if a[2] > NEAR and b[2] > NEAR and c[2] > NEAR and ti.abs(area) > 1e-9:
                        x0 = ti.max(0, ti.cast(ti.floor(ti.min(a[0], b[0], c[0])), ti.i32))
                        x1 = ti.min(W - 1, ti.cast(ti.floor(ti.max(a[0], b[0], c[0])), ti.i32))
                        y0 = ti.max(0, ti.cast(ti.floor(ti.min(a[1], b[1], c[1])), ti.i32))
                        y1 = ti.min(H - 1, ti.cast(ti.floor(ti.max(a[1], b[1], c[1])), ti.i32))
                        for py in range(y0, y1 + 1):
                            for px in range(x0, x1 + 1):
                                w0, w1, w2 = bary(a, b, c, px + 0.5, py + 0.5)
                                if w0 >= 0 and w1 >= 0 and w2 >= 0:
                                    z = 1.0 / (w0 / a[2] + w1 / b[2] + w2 / c[2])  # 1/z is linear on screen
                                    key = (ti.cast(ti.bit_cast(z - DEPTH_BIAS, ti.i32), ti.i64) << 32) | ti.cast(t, ti.i64)
                                    ti.atomic_min(vis[py * W + px], key)
                                    dirty[(py // TILE) * TX + px // TILE] = 1  # same value from any thread
        # (positive floats order like their bit patterns, so the integer minimum is the nearest)

    @ti.func
    def pack2(lo, hi):
        """Two i32 sums as one i64, hi·2³² + lo: sums of such values are the two sums packed
        the same way (mod 2⁶⁴), so one 64-bit atomic add does the work of two 32-bit ones; each
        half unpacks exactly while its sum fits an i32, as the four i32 sums needed already."""
        return (ti.cast(hi, ti.i64) << 32) + ti.cast(lo, ti.i64)

    @ti.func
    def unpack4(p):
        """The four i32 sums of a pixel's two packed i64 (``pack2``)."""
        a = ti.cast(p[0], ti.i32)  # (truncation: the low half, as a signed i32)
        c = ti.cast(p[1], ti.i32)
        b = ti.cast((p[0] - ti.cast(a, ti.i64)) >> 32, ti.i32)
        d = ti.cast((p[1] - ti.cast(c, ti.i64)) >> 32, ti.i32)
        return ti.Vector([a, b, c, d])

    @ti.func
    def tri_depth(vis: ti.template(), i):
        k = vis[i]
        z = 1e30
        if k != ti.i64(EMPTY):
            z = ti.bit_cast(ti.cast(k >> 32, ti.i32), ti.f32)
        return z

    @ti.func
    def lines_k(acc: ti.template(), vis: ti.template(), depth: ti.template(), dirty: ti.template(), o, f,
                r, u, th, W, H, TX):
        for sl in range(NT * TASK):  # (spread: a line's samples vary with its length)
            for rr in range(rounds(line_count, NT)):
                k = item(sl, rr, NT)
                if k < line_count:
                    ia, ib = line_idx[k][0], line_idx[k][1]
                    a = project(P[ia], o, f, r, u, th, W, H)
                    b = project(P[ib], o, f, r, u, th, W, H)
                    if a[2] > NEAR and b[2] > NEAR:
                        length = ti.sqrt((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2)
                        n = ti.min(4096, ti.cast(length * 2.0, ti.i32) + 1)
                        col = 0.5 * (C[ia] + C[ib]) * 0.35
                        for s in range(n + 1):
                            q = a + (b - a) * (s / n)
                            fx, fy = q[0] - 0.5, q[1] - 0.5  # bilinear coverage of a 1-px line
                            ix, iy = ti.cast(ti.floor(fx), ti.i32), ti.cast(ti.floor(fy), ti.i32)
                            tx, ty = fx - ix, fy - iy
                            for dy in ti.static(range(2)):
                                for dx in ti.static(range(2)):
                                    X, Y = ix + dx, iy + dy
                                    if 0 <= X < W and 0 <= Y < H:
                                        zt = 1e30
                                        if ti.static(tri_count > 0):
                                            zt = tri_depth(vis, Y * W + X)
                                        if q[2] < ti.min(depth[Y * W + X], zt) + 0.02:
                                            w = (tx if dx else 1.0 - tx) * (ty if dy else 1.0 - ty)
                                            tau = -ti.log(1.0 - ti.min(0.999, 1.6 * w))
                                            v = ti.cast(ti.Vector([tau, tau * col[0], tau * col[1],
                                                                   tau * col[2]]) * FIXED, ti.i32)
                                            # integers: exact in any order
                                            ti.atomic_add(acc[Y * W + X], ti.Vector([pack2(v[0], v[1]),
                                                                                     pack2(v[2], v[3])]))
                                            dirty[(Y // TILE) * TX + X // TILE] = 1

    @ti.func
    def shade(fbg: ti.template(), fdep: ti.template(), bgc: ti.template(), depth: ti.template(),
              vis: ti.template(), acc: ti.template(), dirty: ti.template(), dirty_prev: ti.template(), o, f,
              r, u, th, W, H, TX, TY):
        ldir = ti.Vector([0.4, 0.8, 0.3]).normalized()
        for sl in range(NT * TASK):  # (spread: the bodies' tiles lie together)
            for rr in range(rounds(TX * TY, NT)):
                t = item(sl, rr, NT)
                if t < TX * TY:
                    if dirty[t] != 0 or dirty_prev[t] != 0:
                        px0, py0 = (t % TX) * TILE, (t // TX) * TILE
                        for py in range(py0, ti.min(H, py0 + TILE)):
                            for px in range(px0, ti.min(W, px0 + TILE)):
                                k = py * W + px
                                c4 = bgc[k]
                                z = depth[k]
                                if ti.static(tri_count > 0):
                                    zt = tri_depth(vis, k)
                                    if zt < z:
                                        key = vis[k]
                                        tt = ti.cast(key - ((key >> 32) << 32), ti.i32)
                                        i = tri_idx[tt]
                                        a, b, c = tri_scr[tt, 0], tri_scr[tt, 1], tri_scr[tt, 2]
                                        w0, w1, w2 = bary(a, b, c, px + 0.5, py + 0.5)
                                        w0, w1, w2 = w0 / a[2], w1 / b[2], w2 / c[2]
                                        iz = 1.0 / (w0 + w1 + w2)
                                        n = ((w0 * N[i[0]] + w1 * N[i[1]] + w2 * N[i[2]]) * iz).normalized()
                                        col = (w0 * C[i[0]] + w1 * C[i[1]] + w2 * C[i[2]]) * iz
                                        view = (o - (P[i[0]] * w0 + P[i[1]] * w1 + P[i[2]] * w2) * iz).normalized()
                                        if n.dot(view) < 0:  # two-sided: shade the side we see
                                            n = -n
                                        diff = ti.max(0.0, n.dot(ldir))
                                        hv = (ldir + view).normalized()
                                        spec = ti.pow(ti.max(0.0, n.dot(hv)), 24.0)
                                        sc = col * (0.18 + 0.7 * diff) * 0.35 + 0.04 * spec
                                        c4 = ti.Vector([sc[0], sc[1], sc[2], 1.0])
                                        z = zt
                                if ti.static(line_count > 0):
                                    s = unpack4(acc[k])
                                    if s[0] > 0:
                                        T = ti.exp(-s[0] / FIXED)
                                        lc = ti.Vector([s[1], s[2], s[3]]) / ti.cast(s[0], ti.f32)
                                        c3 = ti.Vector([c4[0], c4[1], c4[2]]) * T + lc * (1.0 - T)
                                        c4 = ti.Vector([c3[0], c3[1], c3[2], c4[3] * T + (1.0 - T)])
                                fbg[k] = c4
                                fdep[k] = z

    @ti.kernel
    def frame(fbg: ND_V4, fdep: ND_F, bgc: ND_V4, depth: ND_F, vis: ND_I64, acc: ND_L2, dirty: ND_I1,
              dirty_prev: ND_I1, o: vec3, f: vec3, r: vec3, u: vec3, th: ti.f32, W: ti.i32, H: ti.i32,
              TX: ti.i32, TY: ti.i32, whole: ti.i32):
        """A frame's meshes in one launch: vertex normals, then the buffers cleared, the
        triangles and lines rasterised and the touched tiles shaded — each a parallel loop at
        the kernel's top level, run one after another (they were four or five launches, each
        ~0.1 ms here whatever its work; the bodies' own fields are copied in first, rounded to
        f32 as NumPy's astype rounds them)."""
        for src, first, count in ti.static(fields):
            for j in range(count):
                P[first + j] = ti.cast(src[j], ti.f32)
        if ti.static(tri_count > 0):
            normals()
        clear(vis, acc, dirty, dirty_prev, H, W, TX, TX * TY, whole)
        if ti.static(tri_count > 0):
            tris(vis, dirty, o, f, r, u, th, W, H, TX)
        if ti.static(line_count > 0):
            lines_k(acc, vis, depth, dirty, o, f, r, u, th, W, H, TX)
        shade(fbg, fdep, bgc, depth, vis, acc, dirty, dirty_prev, o, f, r, u, th, W, H, TX, TY)

    return frame
