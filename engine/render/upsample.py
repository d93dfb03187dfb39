"""The reduced layer's upsample to full resolution (Cantlay 2007): which tiles read it, its rows
interpolated along x, and the bilinear or bilateral sample a pixel takes of it.

Bilinear where the reduced depths under a pixel agree; bilateral (depth-aware) where they differ by
more than 10 % of the pixel's depth: each of the four nearest texels weighs bilinear ×
1 / (10⁻³ + |z_texel − z| / z), so smoke does not bleed across the edge of a nearer surface. Which
of a tile's pixels need the bilateral weights (``tile_edge_rows``) depends on depths alone, so
the composite keeps it per tile (engine.render.composite).

The reduced level is stored after the full one in the same flat arrays: texel (x, y) at
LO + y·Wl + x, LO = W·H; the coarse level (half the reduced scale) after it, at LC + y·Wc + x.
The coarse level reaches the picture through the reduced one: ``co_sample`` upsamples its sums
(not a resolved layer) to a reduced texel, the same bilinear or bilateral rule one level down.
"""
# (no `from __future__ import annotations`: Taichi reads kernel annotations at definition)

import taichi as ti

from .sprites import TILE

vec4 = ti.types.vector(4, ti.f32)
# pixel arrays are flat, (H·W,) in row-major order, indexed y·W + x: a 2-D ndarray recomputes
# its strides at every access (measured 1.2–1.7× slower in these loops than a flat index)
ND_V4 = ti.types.ndarray(dtype=vec4, ndim=1)
ND_I1 = ti.types.ndarray(dtype=ti.i32, ndim=1)
ND_F = ti.types.ndarray(dtype=ti.f32, ndim=1)


@ti.func
def lo_quad(px, py, s, Wl, Hl):
    """The four reduced texels around full-resolution pixel (px, py): rows ja, jb, columns
    xa, xb (clamped to the level) and the bilinear fractions (fx, fy)."""
    v = (py + 0.5) * s - 0.5
    j0 = ti.cast(ti.floor(v), ti.i32)
    fy = v - j0
    ja, jb = ti.min(ti.max(j0, 0), Hl - 1), ti.min(ti.max(j0 + 1, 0), Hl - 1)
    u = (px + 0.5) * s - 0.5
    i0 = ti.cast(ti.floor(u), ti.i32)
    fx = u - i0
    xa, xb = ti.min(ti.max(i0, 0), Wl - 1), ti.min(ti.max(i0 + 1, 0), Wl - 1)
    return ja, jb, xa, xb, fx, fy


@ti.func
def co_corner(x, y, Wc, Hc):
    """``lo_quad(x, y, 0.5, Wc, Hc)`` by integer operations, the same values: at half scale
    u = (x + ½)/2 − ½ = x/2 − ¼ is exact in f32, so its floor is (x − 1) >> 1 and its fraction ¾
    for an even x, ¼ for an odd one. Every reduced texel under a drawn coarse tile takes it (the
    float floors and conversions were ~0.2 ms of the reduced level's 3.5 ms in flames.toml at
    1280×720, its splat launched alone on a captured frame)."""
    i0, j0 = (x - 1) >> 1, (y - 1) >> 1
    fx = ti.select(x & 1 == 0, 0.75, 0.25)
    fy = ti.select(y & 1 == 0, 0.75, 0.25)
    ja, jb = ti.min(ti.max(j0, 0), Hc - 1), ti.min(ti.max(j0 + 1, 0), Hc - 1)
    xa, xb = ti.min(ti.max(i0, 0), Wc - 1), ti.min(ti.max(i0 + 1, 0), Wc - 1)
    return ja, jb, xa, xb, fx, fy


@ti.func
def quad_is_edge(z00, z10, z01, z11, z):
    """Whether the four texels' depths differ by more than 10 % of the pixel's depth z (then
    the upsample is bilateral at this pixel)."""
    return ti.max(z00, z10, z01, z11) - ti.min(z00, z10, z01, z11) > 0.1 * z


@ti.func
def lo_sample(px, py, z, lo: ti.template(), rows: ti.template(), depth_lo: ti.template(), LO, W,
              Wl, Hl, s, edge):
    """The reduced layer at full-resolution pixel (px, py) of depth z, bilinear: a vertical
    lerp between two rows already interpolated along x (``lo_rows``). In a tile where the
    reduced depths differ by more than 10 % (``edge``: a silhouette, not a receding floor) and
    at this pixel too, bilateral instead: each of the four texels weighs bilinear ×
    1 / (10⁻³ + |z_texel − z| / z), so smoke does not bleed across the edge of a nearer surface."""
    ja, jb, xa, xb, fx, fy = lo_quad(px, py, s, Wl, Hl)
    out = (1.0 - fy) * rows[ja * W + px] + fy * rows[jb * W + px]
    if edge != 0:
        ra, rb = LO + ja * Wl, LO + jb * Wl
        z00, z10 = depth_lo[ra + xa], depth_lo[ra + xb]
        z01, z11 = depth_lo[rb + xa], depth_lo[rb + xb]
        if quad_is_edge(z00, z10, z01, z11, z):
            iz = 1.0 / z
            w00 = (1.0 - fx) * (1.0 - fy) / (1e-3 + ti.abs(z00 - z) * iz)
            w10 = fx * (1.0 - fy) / (1e-3 + ti.abs(z10 - z) * iz)
            w01 = (1.0 - fx) * fy / (1e-3 + ti.abs(z01 - z) * iz)
            w11 = fx * fy / (1e-3 + ti.abs(z11 - z) * iz)
            out = (w00 * lo[ra + xa] + w10 * lo[ra + xb] + w01 * lo[rb + xa]
                   + w11 * lo[rb + xb]) / (w00 + w10 + w01 + w11)
    return out


@ti.func
def co_quad(x, y, z, depth: ti.template(), LC, Wc, Hc):
    """Where reduced texel (x, y) of depth z reads the coarse level: its four nearest coarse
    texels (indices) and their weights — bilinear, or where their depths differ by more than 10 %
    of z (``quad_is_edge``) bilateral as in ``lo_sample``, normalised."""
    ja, jb, xa, xb, fx, fy = co_corner(x, y, Wc, Hc)
    ra, rb = LC + ja * Wc, LC + jb * Wc
    k = ti.Vector([ra + xa, ra + xb, rb + xa, rb + xb])
    w = ti.Vector([(1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy])
    zq = ti.Vector([depth[k[0]], depth[k[1]], depth[k[2]], depth[k[3]]])
    if quad_is_edge(zq[0], zq[1], zq[2], zq[3], z):
        w = w / (1e-3 + ti.abs(zq - z) / z)
        w = w / w.sum()
    return k, w


@ti.func
def co_mix(acc: ti.template(), k, w):
    """The coarse level's sums ``acc`` (accA or accB) at the quad (k, w) of ``co_quad``: what a
    sprite drawn there adds, read as if it had been drawn at the reduced level."""
    return w[0] * acc[k[0]] + w[1] * acc[k[1]] + w[2] * acc[k[2]] + w[3] * acc[k[3]]


@ti.func
def tile_edge_rows(px0, py0, px1, py1, dep: ti.template(), LO, W, Wl, Hl, s,
                   edge_rows: ti.template(), at):
    """Where ``lo_sample`` goes bilateral in the tile: ``edge_rows[at + y − py0]`` gets, for each
    pixel row y, a mask with bit x − px0 set where ``quad_is_edge`` holds at pixel (x, y) — none
    unless ``lo_edge`` (the tile's test) holds — and the return is whether any bit is set. Where
    a bit is clear the upsample is bilinear, the value the hoisted bilinear path gives. A
    receding floor passes the tile's test (its depth grows by more than 10 % over a tile's
    footprint beyond a few metres) and fails the pixel's (over two texels it grows by less)."""
    e = lo_edge(px0, py0, px1, py1, dep, LO, Wl, Hl, s)
    any_edge = 0
    for y in range(py0, py1 + 1):
        mask = 0
        if e != 0:
            for x in range(px0, px1 + 1):
                ja, jb, xa, xb, fx, fy = lo_quad(x, y, s, Wl, Hl)
                ra, rb = LO + ja * Wl, LO + jb * Wl
                if quad_is_edge(dep[ra + xa], dep[ra + xb], dep[rb + xa], dep[rb + xb],
                                dep[y * W + x]):
                    mask |= 1 << (x - px0)
        edge_rows[at + y - py0] = mask
        any_edge |= mask
    return ti.select(any_edge != 0, 1, 0)


@ti.func
def footprint(px0, py0, px1, py1, s, Wl, Hl):
    """The texels [lx0, lx1] × [ly0, ly1] of a level at scale s (Wl × Hl texels) that the
    bilinear upsample (``lo_quad``) reads for the pixels [px0, px1] × [py0, py1]."""
    lx0 = ti.max(0, ti.cast(ti.floor((px0 + 0.5) * s - 0.5), ti.i32))
    lx1 = ti.min(Wl - 1, ti.cast(ti.floor((px1 + 0.5) * s - 0.5), ti.i32) + 1)
    ly0 = ti.max(0, ti.cast(ti.floor((py0 + 0.5) * s - 0.5), ti.i32))
    ly1 = ti.min(Hl - 1, ti.cast(ti.floor((py1 + 0.5) * s - 0.5), ti.i32) + 1)
    return lx0, lx1, ly0, ly1


@ti.func
def lo_edge(px0, py0, px1, py1, depth_lo: ti.template(), LO, Wl, Hl, s):
    """Whether the reduced depths a tile's upsample reads differ by more than 10 % (then the
    bilateral weights are needed; elsewhere bilinear is the same and cheaper)."""
    lx0, lx1, ly0, ly1 = footprint(px0, py0, px1, py1, s, Wl, Hl)
    lo_z, hi_z = 1e30, 0.0
    for ly in range(ly0, ly1 + 1):
        for k in range(LO + ly * Wl + lx0, LO + ly * Wl + lx1 + 1):
            lo_z = ti.min(lo_z, depth_lo[k])
            hi_z = ti.max(hi_z, depth_lo[k])
    return ti.select(hi_z - lo_z > 0.1 * lo_z, 1, 0)


@ti.func
def lo_near(px0, py0, px1, py1, touched_lo: ti.template(), Wl, Hl, TXl, s):
    """Whether any reduced-layer tile the upsample reads for this tile holds sprites."""
    lx0, lx1, ly0, ly1 = footprint(px0, py0, px1, py1, s, Wl, Hl)
    near = 0
    for ly in range(ly0 // TILE, ly1 // TILE + 1):
        for lx in range(lx0 // TILE, lx1 // TILE + 1):
            near |= touched_lo[ly * TXl + lx]
    return near


@ti.func
def _row_needed(j, touched_lo: ti.template(), TXl, TYl, R):
    """Whether reduced row j lies within R rows of a reduced tile drawn this frame."""
    need = 0
    for tr in range(ti.max(0, j - R) // TILE, ti.min(TYl - 1, (j + R) // TILE) + 1):
        for tx in range(TXl):
            need |= touched_lo[tr * TXl + tx]
    return need


@ti.func
def _row_texel(lo: ti.template(), j, x, LO, Wl, s):
    """Reduced row j interpolated along x at full-resolution column x (bilinear's x half)."""
    u = (x + 0.5) * s - 0.5
    i0 = ti.cast(ti.floor(u), ti.i32)
    fx = u - i0
    xa, xb = ti.min(ti.max(i0, 0), Wl - 1), ti.min(ti.max(i0 + 1, 0), Wl - 1)
    return (1.0 - fx) * lo[LO + j * Wl + xa] + fx * lo[LO + j * Wl + xb]


@ti.func
def is_empty_layer(v):
    """Whether a texel (vec4) is the empty layer (0, 0, 0, 1) exactly: no light, transmittance 1
    (a resolved reduced texel, or a coarse texel's sums A)."""
    return v[0] == 0.0 and v[1] == 0.0 and v[2] == 0.0 and v[3] == 1.0


@ti.kernel
def lo_rows(lo: ND_V4, rows: ND_V4, row_empty: ND_I1, W: ti.i32, H: ti.i32, Wl: ti.i32, Hl: ti.i32,
            s: ti.f32, touched_lo: ND_I1, TXl: ti.i32, TYl: ti.i32, R: ti.i32, per_pixel: ti.template(),
            k: ti.template()):
    """The reduced layer's rows interpolated along x at every full-resolution column:
    rows[j·W + x] (the first half of a separable bilinear upsample; the composite does the
    vertical half with two loads per pixel instead of four) — only the rows the composite
    can read: it reads row j for a tile whose footprint (rows ``lo_near`` spans, fewer than
    R = TILE·s + 3) holds a reduced tile drawn this frame, so row j is needed only when a
    drawn reduced tile lies within R rows of it (the rest are left as they were, unread).

    ``per_pixel`` (the GPU's schedule): one thread a texel, each testing its row (a few dozen
    cached loads), since a thread a row leaves a GPU with ~Hl threads (180 at 1280×720: 1.75 ms
    on an H200, one launch of debris). Else one thread a row (the CPU's), walking the row's
    texels: ``k`` = 1/s (2 or 4) columns a texel pair. Both write the same values.

    The CPU's also marks, per needed row j and full-resolution tile column tx,
    ``row_empty[j·TX + tx]`` (TX = ceil(W / TILE)): whether every texel pair the row's values
    there are drawn from is the empty layer (0, 0, 0, 1) exactly. Then so is each of those values,
    and each vertical lerp of two such rows (the weights are multiples of 1/8 at s = 1/2 or 1/4,
    so (1 − f) + f = 1 exactly), and the composite's pixel there is the packed background's bit
    for bit (c·1 + 0): ``composite_tiles`` copies it (42–54 % of the rows of the tiles under
    smoke that hold no sprite of their own, in explosion, debris and campfire at 1280×720). The
    GPU's composite does not read it."""
    LO = W * H
    if ti.static(per_pixel):
        for j, x in ti.ndrange(Hl, W):
            if _row_needed(j, touched_lo, TXl, TYl, R) != 0:
                rows[j * W + x] = _row_texel(lo, j, x, LO, Wl, s)
    else:
        # s = 1/k: column x = k·i + k/2 + m (m < k) lies between texels i and i + 1 at
        # fx = (m + ½)/k, the value _row_texel computes there (exact in f32 for k = 2, 4):
        # two loads serve k columns, with no per-column index arithmetic (k odd: other fx)
        ti.static_assert(k % 2 == 0, "lo_rows: the reduced layer's scale must be 1/2 or 1/4")
        ti.static_assert(TILE & (TILE - 1) == 0)
        TX = (W + TILE - 1) // TILE
        for j in range(Hl):
            if _row_needed(j, touched_lo, TXl, TYl, R) != 0:
                run = 1  # every pair so far in this tile column empty
                for i in range(-1, (W + k) // k):
                    a = lo[LO + j * Wl + ti.min(ti.max(i, 0), Wl - 1)]
                    b = lo[LO + j * Wl + ti.min(ti.max(i + 1, 0), Wl - 1)]
                    both = ti.select(is_empty_layer(a) and is_empty_layer(b), 1, 0)
                    for m in ti.static(range(k)):
                        x = k * i + k // 2 + m
                        if 0 <= x < W:
                            fx = ti.static((m + 0.5) / k)
                            rows[j * W + x] = (1.0 - fx) * a + fx * b
                            run &= both
                            if x & (TILE - 1) == TILE - 1 or x == W - 1:  # a tile column's last
                                row_empty[j * TX + x // TILE] = run
                                run = 1
