"""Soft bodies in the off-screen renderer: shaded triangles (cloth, jelly) and lines (chains,
hair), z-buffered against the background and occluding the particles drawn after them.

Both loops are serialised: a z-buffer written from several threads races (which triangle wins a
pixel would depend on timing), and the same config must give the same frame. Triangles are
smooth-shaded with per-vertex normals (area-weighted, computed in NumPy), lit two-sided by one
directional light plus ambient, and interpolated perspective-correctly (through 1/z).
"""
import numpy as np
import taichi as ti

vec3 = ti.types.vector(3, ti.f32)
NEAR = 0.05
DEPTH_BIAS = 0.01  # m


class MeshLayer:
    def __init__(self, bodies, renderer):
        self.bodies = list(bodies)
        nv = [len(b.topology.positions) for b in self.bodies]
        self.offsets = np.cumsum([0] + nv[:-1]).astype(np.int64)
        self.nv = int(sum(nv))
        tris = [b.triangles + o for b, o in zip(self.bodies, self.offsets) if len(b.triangles)]
        lines = [b.lines + o for b, o in zip(self.bodies, self.offsets) if len(b.lines)]
        self.tris = np.concatenate(tris).astype(np.int32) if tris else np.zeros((0, 3), np.int32)
        self.lines = np.concatenate(lines).astype(np.int32) if lines else np.zeros((0, 2), np.int32)
        self.mesh_pos = ti.Vector.field(3, ti.f32, shape=max(1, self.nv))
        self.mesh_nrm = ti.Vector.field(3, ti.f32, shape=max(1, self.nv))
        self.mesh_col = ti.Vector.field(3, ti.f32, shape=max(1, self.nv))
        cols = np.concatenate([np.tile(np.asarray(b.cfg.color, np.float32), (n, 1))
                               for b, n in zip(self.bodies, nv)]) if self.nv else np.zeros((1, 3), np.float32)
        self.mesh_col.from_numpy(np.ascontiguousarray(cols.reshape(-1, 3)[: max(1, self.nv)]))
        self.tri_count, self.line_count = len(self.tris), len(self.lines)
        if self.tri_count:
            self.tri_idx = ti.Vector.field(3, ti.i32, shape=self.tri_count)
            self.tri_idx.from_numpy(self.tris)
        if self.line_count:
            self.line_idx = ti.Vector.field(2, ti.i32, shape=self.line_count)
            self.line_idx.from_numpy(self.lines)
        self._build(renderer)

    def update(self) -> None:
        """Copy the bodies' node positions in and recompute vertex normals."""
        if not self.nv:
            return
        pos = np.concatenate([b.positions().astype(np.float64) for b in self.bodies])
        self.mesh_pos.from_numpy(pos.astype(np.float32))
        if self.tri_count:
            t = self.tris
            fn = np.cross(pos[t[:, 1]] - pos[t[:, 0]], pos[t[:, 2]] - pos[t[:, 0]])  # area-weighted
            n = np.zeros_like(pos)
            for k in range(3):
                np.add.at(n, t[:, k], fn)
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
            self.mesh_nrm.from_numpy(n.astype(np.float32))

    def _build(self, R):
        W, H = R.W, R.H
        bg, depth = R.bg, R.depth
        P, N, C = self.mesh_pos, self.mesh_nrm, self.mesh_col
        tri_count, line_count = self.tri_count, self.line_count
        tri_idx = self.tri_idx if tri_count else None
        line_idx = self.line_idx if line_count else None

        @ti.func
        def project(p, o, f, r, u, th):
            d = p - o
            z = d.dot(f)
            s = 0.5 * H / (ti.max(z, NEAR) * th)
            return ti.Vector([d.dot(r) * s + 0.5 * W, 0.5 * H - d.dot(u) * s, z])

        @ti.kernel
        def draw_triangles(o: vec3, f: vec3, r: vec3, u: vec3, th: ti.f32):
            ldir = ti.Vector([0.4, 0.8, 0.3]).normalized()
            ti.loop_config(serialize=True)
            for t in range(tri_count):
                ia, ib, ic = tri_idx[t][0], tri_idx[t][1], tri_idx[t][2]
                a = project(P[ia], o, f, r, u, th)
                b = project(P[ib], o, f, r, u, th)
                c = project(P[ic], o, f, r, u, th)
                area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
                if a[2] > NEAR and b[2] > NEAR and c[2] > NEAR and ti.abs(area) > 1e-9:
                    x0 = ti.max(0, ti.cast(ti.floor(ti.min(a[0], b[0], c[0])), ti.i32))
                    x1 = ti.min(W - 1, ti.cast(ti.floor(ti.max(a[0], b[0], c[0])), ti.i32))
                    y0 = ti.max(0, ti.cast(ti.floor(ti.min(a[1], b[1], c[1])), ti.i32))
                    y1 = ti.min(H - 1, ti.cast(ti.floor(ti.max(a[1], b[1], c[1])), ti.i32))
                    for py in range(y0, y1 + 1):
                        for px in range(x0, x1 + 1):
                            sx, sy = px + 0.5, py + 0.5
                            w0 = ((c[0] - b[0]) * (sy - b[1]) - (c[1] - b[1]) * (sx - b[0])) / area
                            w1 = ((a[0] - c[0]) * (sy - c[1]) - (a[1] - c[1]) * (sx - c[0])) / area
                            w2 = 1.0 - w0 - w1
                            if w0 >= 0 and w1 >= 0 and w2 >= 0:
                                iz = w0 / a[2] + w1 / b[2] + w2 / c[2]  # 1/z is linear on screen
                                z = 1.0 / iz
                                # 1 cm of depth bias: cloth resting on the ground would z-fight it
                                if z - DEPTH_BIAS < depth[py, px]:
                                    depth[py, px] = z - DEPTH_BIAS
                                    n = ((w0 / a[2]) * N[ia] + (w1 / b[2]) * N[ib] + (w2 / c[2]) * N[ic]) * z
                                    col = ((w0 / a[2]) * C[ia] + (w1 / b[2]) * C[ib] + (w2 / c[2]) * C[ic]) * z
                                    n = n.normalized()
                                    view = (o - (P[ia] * w0 + P[ib] * w1 + P[ic] * w2)).normalized()
                                    if n.dot(view) < 0:  # two-sided: shade the side we see
                                        n = -n
                                    diff = ti.max(0.0, n.dot(ldir))
                                    hv = (ldir + view).normalized()
                                    spec = ti.pow(ti.max(0.0, n.dot(hv)), 24.0)
                                    bg[py, px] = col * (0.18 + 0.7 * diff) * 0.35 + 0.04 * spec

        @ti.kernel
        def draw_lines(o: vec3, f: vec3, r: vec3, u: vec3, th: ti.f32):
            ti.loop_config(serialize=True)
            for k in range(line_count):
                ia, ib = line_idx[k][0], line_idx[k][1]
                a = project(P[ia], o, f, r, u, th)
                b = project(P[ib], o, f, r, u, th)
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
                                if 0 <= X < W and 0 <= Y < H and q[2] < depth[Y, X] + 0.02:
                                    w = (tx if dx else 1.0 - tx) * (ty if dy else 1.0 - ty)
                                    a_ = ti.min(1.0, 1.6 * w)
                                    bg[Y, X] = bg[Y, X] * (1.0 - a_) + col * a_

        self._tris, self._lines = draw_triangles, draw_lines

    def draw(self, args) -> None:
        if self.tri_count:
            self._tris(*args)
        if self.line_count:
            self._lines(*args)
