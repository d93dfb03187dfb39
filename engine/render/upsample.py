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
def lo_bilateral(px, py, z, lo: ti.template(), depth_lo: ti.template(), LO, Wl, Hl, s):
    """The reduced layer at full-resolution pixel (px, py) of depth z, bilateral (where
    ``quad_is_edge`` holds there): each of the four nearest texels weighs bilinear ×
    1 / (10⁻³ + |z_texel − z| / z), so smoke does not bleed across the edge of a nearer surface."""
    ja, jb, xa, xb, fx, fy = lo_quad(px, py, s, Wl, Hl)
    ra, rb = LO + ja * Wl, LO + jb * Wl
    z00, z10 = depth_lo[ra + xa], depth_lo[ra + xb]
    z01, z11 = depth_lo[rb + xa], depth_lo[rb + xb]
    return bilateral_mix(fx, fy, z, z00, z10, z01, z11, lo[ra + xa], lo[ra + xb], lo[rb + xa], lo[rb + xb])


@ti.func
def bilateral_mix(fx, fy, z, z00, z10, z01, z11, t00, t10, t01, t11):
    """The four texels t (vec4) of depths z.. around a pixel of depth z at fractions (fx, fy),
    each weighing bilinear × 1 / (10⁻³ + |z_texel − z| / z), normalised (``lo_bilateral``; the
    composite's whole rows take it too, with their loads hoisted)."""
    iz = 1.0 / z
    w00 = (1.0 - fx) * (1.0 - fy) / (1e-3 + ti.abs(z00 - z) * iz)
    w10 = fx * (1.0 - fy) / (1e-3 + ti.abs(z10 - z) * iz)
    w01 = (1.0 - fx) * fy / (1e-3 + ti.abs(z01 - z) * iz)
    w11 = fx * fy / (1e-3 + ti.abs(z11 - z) * iz)
    return (w00 * t00 + w10 * t10 + w01 * t01 + w11 * t11) / (w00 + w10 + w01 + w11)


@ti.func
def lo_sample(px, py, z, lo: ti.template(), rows: ti.template(), depth_lo: ti.template(), LO, W,
              Wl, Hl, s, edge):
    """The reduced layer at full-resolution pixel (px, py) of depth z (the per-pixel schedule's),
    bilinear: a vertical lerp between two rows already interpolated along x (``lo_rows``). In a
    tile where the reduced depths differ by more than 10 % (``edge``: a silhouette, not a
    receding floor) and at this pixel too, bilateral instead (``lo_bilateral``)."""
    ja, jb, xa, xb, fx, fy = lo_quad(px, py, s, Wl, Hl)
    out = (1.0 - fy) * rows[ja * W + px] + fy * rows[jb * W + px]
    if edge != 0:
        ra, rb = LO + ja * Wl, LO + jb * Wl
        if quad_is_edge(depth_lo[ra + xa], depth_lo[ra + xb], depth_lo[rb + xa], depth_lo[rb + xb], z):
            out = lo_bilateral(px, py, z, lo, depth_lo, LO, Wl, Hl, s)
    return out


def row_place(dx: int, k: int):
    """Where pixel px0 + dx of a row (px0 a multiple of TILE, the reduced scale 1/k) reads the
    reduced row along x: (n, fx), texels i0 + n and i0 + n + 1 (i0 = px0/k − 1) at fraction fx,
    as ``row_lerp`` (Python, for unrolled rows: column x = k·i + k/2 + m lies between texels i
    and i + 1 at fx = (m + ½)/k)."""
    q = dx - k // 2
    return q // k + 1, (q % k + 0.5) / k


@ti.func
def lo_row(y, k: ti.template()):
    """The upper reduced row (unclamped) that full-resolution row y reads at scale 1/k:
    floor((y + ½)/k − ½), ``lo_quad``'s j0, in integers."""
    return (2 * y + 1 - k) // (2 * k)


@ti.func
def row_lerp(lo: ti.template(), r, x, Wl, k: ti.template()):
    """Reduced row r (``lo`` index of its first texel) interpolated along x at full-resolution
    column x, scale 1/k (k = 2 or 4): ``lo_quad``'s x half by integers — x = k·i + k/2 + m lies
    between texels i and i + 1 at fx = (m + ½)/k, exact in f32, the value the float form gives."""
    ti.static_assert(k == 2 or k == 4, "the reduced layer's scale must be 1/2 or 1/4")
    q = x - k // 2
    i = q // k
    fx = (ti.cast(q - i * k, ti.f32) + 0.5) * ti.static(1.0 / k)
    return (1.0 - fx) * lo[r + ti.min(ti.max(i, 0), Wl - 1)] + fx * lo[r + ti.min(ti.max(i + 1, 0), Wl - 1)]


@ti.func
def rows_lerp(lo: ti.template(), ra, rb, x, fy, Wl, k: ti.template()):
    """Reduced rows ra, rb (``row_lerp`` each) at column x, then between them at fraction fy:
    the bilinear upsample at a pixel of column x."""
    return (1.0 - fy) * row_lerp(lo, ra, x, Wl, k) + fy * row_lerp(lo, rb, x, Wl, k)


@ti.func
def empty_rows(lo: ti.template(), j0, j1, px0, px1, LO, Wl, k: ti.template()):
    """A mask, bit j − j0 for reduced rows j0..j1: whether every texel that ``row_lerp`` reads
    for the columns px0..px1 in row j is the empty layer (0, 0, 0, 1) exactly. Then so is each
    value interpolated there, and each vertical lerp of two such rows (the weights are multiples
    of 1/8, so (1 − f) + f = 1 exactly): the composite's pixel there is the packed background's
    bit for bit (c·1 + 0)."""
    xa = ti.max((px0 - k // 2) // k, 0)
    xb = ti.min((px1 - k // 2) // k + 1, Wl - 1)
    mask = 0
    for j in range(j0, j1 + 1):
        i, last = LO + j * Wl + xa, LO + j * Wl + xb
        while i <= last:  # (to the first texel that is not empty: under smoke, the first one)
            if not is_empty_layer(lo[i]):
                break
            i += 1
        mask |= ti.select(i > last, 1, 0) << (j - j0)
    return mask


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
    """Where the upsample goes bilateral in the tile (``lo_sample``'s test; the CPU's composite
    takes these bits as they are, without testing the pixel again): ``edge_rows[at + y − py0]`` gets, for each
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
def lo_rows(lo: ND_V4, rows: ND_V4, W: ti.i32, H: ti.i32, Wl: ti.i32, Hl: ti.i32, s: ti.f32,
            touched_lo: ND_I1, TXl: ti.i32, TYl: ti.i32, R: ti.i32):
    """The per-pixel schedule's (a GPU's): the reduced layer's rows interpolated along x at every
    full-resolution column, rows[j·W + x] (the first half of a separable bilinear upsample;
    ``composite_pixels`` does the vertical half with two loads per pixel instead of four), one
    thread a texel — only the rows the composite can read: it reads row j for a tile whose
    footprint (rows ``lo_near`` spans, fewer than R = TILE·s + 3) holds a reduced tile drawn this
    frame, so row j is needed only when a drawn reduced tile lies within R rows of it (the rest
    are left as they were, unread). The CPU's composite reads the texels themselves
    (``row_lerp``): writing these rows (3.7 MB at 1280×720, s = ¼) and reading them back cost
    more than interpolating each row in the composite."""
    LO = W * H
    for j, x in ti.ndrange(Hl, W):
        if _row_needed(j, touched_lo, TXl, TYl, R) != 0:
            rows[j * W + x] = _row_texel(lo, j, x, LO, Wl, s)
