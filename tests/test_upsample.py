"""The reduced layer's upsample into the full-resolution picture: the layer's rows as the
composite reads them (along x, per pixel or a whole tile row at once; per pixel for the GPU's
schedule), the bilinear or bilateral choice kept per tile and pixel row and refreshed where depths
change, rows drawn whole against the per-pixel path, rows of an empty layer shown as the packed
background, and the coarse quad by integers."""
import numpy as np
import pytest

from helpers import drawn_scene

from engine.api import ParticleScene


@pytest.mark.parametrize("k", [2, 4])
def test_reduced_rows_are_interpolated_only_where_the_composite_reads_them(k):
    """``lo_rows`` (the per-pixel schedule's), at both reduced scales (1/k): a needed row holds
    the reduced layer interpolated along x (a NumPy reference), a row no drawn reduced tile
    reaches keeps what it held."""
    import taichi as ti

    from engine.render.sprites import TILE
    from engine.render.targets import reduced_size, tiles_for
    from engine.render.upsample import lo_rows

    W, H, s = 253, 256, 1.0 / k  # (a width no multiple of k: the last texel pair is cut short)
    Wl, Hl = reduced_size(W, H, s)
    TXl, TYl = tiles_for(Wl, Hl)
    R = int(TILE * s) + 3
    rng = np.random.default_rng(5)
    lo_np = rng.random((W * H + Wl * Hl, 4), dtype=np.float32)
    layer = lo_np[W * H:].reshape(Hl, Wl, 4)  # (a view)
    touched_np = np.zeros(TXl * TYl, np.int32)
    touched_np[1 * TXl + 1] = 1  # one drawn reduced tile: reduced rows 16..31
    lo = ti.ndarray(ti.types.vector(4, ti.f32), lo_np.shape[0])
    lo.from_numpy(lo_np)
    touched = ti.ndarray(ti.i32, touched_np.shape[0])
    touched.from_numpy(touched_np)
    rows = ti.ndarray(ti.types.vector(4, ti.f32), Hl * W)
    rows.fill(-7.0)
    lo_rows(lo, rows, W, H, Wl, Hl, s, touched, TXl, TYl, R)
    got = rows.to_numpy().reshape(Hl, W, 4)
    needed = np.zeros(Hl, bool)
    needed[16 - R:31 + R + 1] = True  # the rows within R of the drawn tile's
    np.testing.assert_allclose(got[needed], _rows_along_x(layer, W, s)[needed], rtol=1e-6, atol=1e-6)
    assert (got[~needed] == -7.0).all()


def _rows_along_x(layer, W, s):
    """The reduced layer's rows (Hl, Wl, 4) interpolated along x at full-resolution columns
    0..W − 1 (``lo_quad``'s x half, in NumPy)."""
    Wl = layer.shape[1]
    u = (np.arange(W) + 0.5) * s - 0.5
    i0 = np.floor(u).astype(int)
    fx = (u - i0)[:, None]
    return (1 - fx) * layer[:, np.clip(i0, 0, Wl - 1)] + fx * layer[:, np.clip(i0 + 1, 0, Wl - 1)]


@pytest.mark.parametrize("k", [2, 4])
def test_the_composite_reads_the_reduced_rows_as_the_bilinear_upsample(k):
    """What the CPU's composite reads of a reduced row at each full-resolution column: per pixel
    (``row_lerp``) and a whole tile row at once (``row_place``'s texels and fractions, as
    ``reduced_row`` and ``reduced_rows`` take them) equal the bilinear upsample's x half bit for bit, and equal each
    other, at both scales and at a width that cuts the last tile short; ``empty_rows`` marks
    exactly the rows whose texels read for a tile's columns are all the empty layer (runs set
    empty in the middle and at the right edge, one texel there made not quite empty)."""
    import taichi as ti

    from engine.render.sprites import TILE
    from engine.render.targets import reduced_size
    from engine.render.upsample import empty_rows, row_lerp, row_place

    W, H, s = 253, 64, 1.0 / k
    Wl, Hl = reduced_size(W, H, s)
    TX = -(-W // TILE)
    rng = np.random.default_rng(7)
    layer = rng.random((Hl, Wl, 4), dtype=np.float32)
    last = ((TX - 1) * TILE - k // 2) // k  # the first texel the last tile column reads
    layer[:, 20 // k:(20 // k) + 40 // k] = layer[:, last:] = (0.0, 0.0, 0.0, 1.0)
    layer[5, Wl - 1] = (0.0, 0.0, 0.0, 0.999)  # not empty: row 5's last tile column is not
    lo = ti.ndarray(ti.types.vector(4, ti.f32), Hl * Wl)
    lo.from_numpy(layer.reshape(-1, 4))
    per_pixel = ti.ndarray(ti.types.vector(4, ti.f32), Hl * W)
    whole = ti.ndarray(ti.types.vector(4, ti.f32), Hl * TX * TILE)
    flags = ti.ndarray(ti.i32, Hl * TX)

    @ti.kernel
    def read(lo: ti.types.ndarray(), per_pixel: ti.types.ndarray(), whole: ti.types.ndarray(),
             flags: ti.types.ndarray()):
        for j, tx in ti.ndrange(Hl, TX):
            px0 = tx * TILE
            px1 = ti.min(W - 1, px0 + TILE - 1)
            for x in range(px0, px1 + 1):
                per_pixel[j * W + x] = row_lerp(lo, j * Wl, x, Wl, k)
            i0 = px0 // k - 1
            for dx in ti.static(range(TILE)):
                n, fx = ti.static(row_place(dx, k))
                a = lo[j * Wl + ti.min(ti.max(i0 + n, 0), Wl - 1)]
                b = lo[j * Wl + ti.min(ti.max(i0 + n + 1, 0), Wl - 1)]
                whole[j * TX * TILE + px0 + dx] = (1.0 - fx) * a + fx * b
            flags[j * TX + tx] = empty_rows(lo, j, j, px0, px1, 0, Wl, k)

    read(lo, per_pixel, whole, flags)
    want = _rows_along_x(layer, W, s)
    got = per_pixel.to_numpy().reshape(Hl, W, 4)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(whole.to_numpy().reshape(Hl, TX * TILE, 4)[:, :W], got)
    empty = np.pad((want == (0.0, 0.0, 0.0, 1.0)).all(-1), ((0, 0), (0, TX * TILE - W)),
                   constant_values=True).reshape(Hl, TX, TILE).all(-1)
    assert empty[:, -1].sum() == Hl - 1 and not empty[5, -1] and empty[:, :-1].any(axis=1).all()
    np.testing.assert_array_equal(flags.to_numpy().reshape(Hl, TX), empty)


def _fresh_edges(s, t):
    """The image the renderer draws with every cached edge flag forgotten (recomputed); first,
    that every flag the cache held for a tile the composite reads it for is the recomputed one."""
    cached = t.edges.to_numpy()
    t.edges.fill(-1)
    img = s.render()
    fresh = t.edges.to_numpy()
    known = fresh >= 0
    assert np.array_equal(cached[known], fresh[known]), np.flatnonzero(cached[known] != fresh[known])
    return img


@pytest.mark.slow  # (default run kept under 5 minutes cold; a moving body's case runs by default)
def test_cached_edge_flags_follow_the_camera():
    """The composite caches per tile whether the reduced layer's upsample is bilateral anywhere
    in it (depths only). Smoke over a ground plane seen from a camera tilting down: the horizon,
    where the upsample is bilateral, moves, and each frame equals one drawn with the flags
    recomputed from nothing (a stale flag would leave the old horizon's tiles bilinear)."""
    s = drawn_scene("configs/flames.toml", frames=40, size=(320, 180), particle_resolution=0.25)
    t = s.renderer.targets(320, 180)
    cam = s.camera
    seen = []
    for k, y in enumerate((0.9, 0.2, -0.6)):
        s.camera = cam.__class__(cam.position, (cam.look_at[0], y, cam.look_at[2]), cam.fov)
        img = s.render()
        seen.append(t.edges.to_numpy())
        assert np.array_equal(_fresh_edges(s, t), img), k
        assert np.array_equal(t.edges.to_numpy(), seen[-1])
    # the flags changed with the view (the test is not vacuous): some tile edged in one, not another
    assert all((a == 1).any() for a in seen)
    assert any(((a == 1) & (b == 0)).any() for a, b in zip(seen, seen[1:]))


def test_cached_edge_flags_follow_a_moving_body():
    """A jelly falls through a cloud of smoke, drawn into the frame's own depth: where it drew this
    frame or the last, and next to it, the flags are recomputed — every cached flag equals the
    recomputed one and each frame the image drawn with all of them recomputed (checked to fail
    with only the drawn tiles themselves recomputed: a tile's upsample reads texels 4 px into
    its neighbours)."""
    s = ParticleScene.from_dict({
        "name": "jelly through smoke", "fps": 30, "frames": 30,
        "camera": {"position": [0.0, 1.0, 6.0], "look_at": [0.0, 1.0, 0.0]},
        "render": {"width": 320, "height": 180, "particle_resolution": 0.25},
        "emitters": [{"name": "cloud", "effect": "smoke", "shape": "sphere", "radius": 1.2,
                      "position": [0.0, 1.0, 0.0], "speed": [0.0, 0.05], "turbulence": 0.0,
                      "bursts": [{"time": 0.0, "count": 300}], "lifetime": 5.0,
                      "size": [[0.0, 0.6]], "alpha": [[0.0, 0.3]]}],
        "bodies": [{"type": "jelly", "name": "jelly", "resolution": [4, 4, 4], "size": [0.8, 0.8, 0.8],
                    "position": [-0.4, 2.6, 1.0], "mass": 0.01, "stiffness": 300.0}]})
    s.render()
    t = s.scene.renderer.targets(320, 180)
    changed = 0
    for k in range(12):
        s.step(1 / 30)
        before = t.edges.to_numpy()
        img = s.render().copy()
        changed += int(((before == 0) & (t.edges.to_numpy() == 1)).any())
        assert np.array_equal(_fresh_edges(s, t), img), k
    assert changed > 0  # the jelly made some tile's upsample bilateral on its way (not vacuous)
    s.close()


def test_whole_rows_under_the_reduced_layer_draw_what_the_per_pixel_path_draws():
    """A tile row under the reduced layer alone, drawn whole (``reduced_row``: bilinear, or
    bilateral at every pixel where the row's mask is full — the horizon's band), equals what the
    per-pixel path draws for it, which the BGRA byte order still takes: flames at 320×180 with a
    ¼ layer, the two renders with R and B swapped back, off by at most one step in a handful of
    pixels (rounding: the compiler may fuse a multiply-add differently), and rows drawn bilateral
    whole are there (not vacuous: a full mask, no sprite of the tile's own, and layer texels under
    them that are not empty; weights taken from the wrong row fail it)."""
    s = drawn_scene("configs/flames.toml", frames=40, size=(320, 180), particle_resolution=0.25)
    rgba = s.render(320, 180).astype(int)
    t = s.renderer.targets(320, 180)
    masks = t.edge_rows.to_numpy().reshape(t.T0, 16)
    edged, own = t.edges.to_numpy() == 1, t.tile_count.to_numpy()[:t.T0] > 0
    layer = t.accA.to_numpy()[t.LO:t.LO + t.Wl * t.Hl].reshape(t.Hl, t.Wl, 4)
    drawn = ~(layer == (0.0, 0.0, 0.0, 1.0)).all(-1)
    whole = 0
    for tile in np.flatnonzero(edged & ~own):
        px0, py0 = (tile % t.TX) * 16, (tile // t.TX) * 16
        for y in range(py0, min(t.H, py0 + 16)):
            j0 = int(np.floor((y + 0.5) * t.scale - 0.5))
            rows = np.clip([j0, j0 + 1], 0, t.Hl - 1)
            cols = slice(max(0, (px0 - 2) // 4), (px0 + 15 - 2) // 4 + 2)
            whole += int(masks[tile, y - py0] == 0xFFFF and drawn[rows][:, cols].any())
    assert whole >= 16, whole  # rows drawn bilateral whole, over smoke
    bgra = s.render(320, 180, bgra=True).astype(int)[..., [2, 1, 0, 3]]
    d = np.abs(rgba - bgra)
    assert d.max() <= 1 and (d > 0).mean() < 1e-3, (d.max(), (d > 0).mean())


def test_rows_drawn_together_draw_what_the_per_pixel_path_draws():
    """The rows of a tile that read the same two reduced rows bilinearly are drawn together in
    the usual byte order (``reduced_rows``), those its own sprites drew in too (the full layer over
    the reduced one): they equal what the per-pixel path draws for them, which the BGRA byte order
    takes, R and B swapped back — off by at most one step in a handful of pixels, as above
    (rounding). Not vacuous: rows of tiles without a bilateral pixel, where a sprite of the tile
    drew and the reduced texels under them are not empty, are there (a full layer left out or
    taken from another row fails it)."""
    s = drawn_scene("configs/flames.toml", frames=40, size=(320, 180), particle_resolution=0.25)
    rgba = s.render(320, 180).astype(int)
    t = s.renderer.targets(320, 180)
    plain = t.edges.to_numpy() == 0
    counts, rows = t.tile_count.to_numpy()[:t.T0], t.full_rows.to_numpy()
    layer = t.accA.to_numpy()[t.LO:t.LO + t.Wl * t.Hl].reshape(t.Hl, t.Wl, 4)
    drawn = ~(layer == (0.0, 0.0, 0.0, 1.0)).all(-1)
    both = 0
    for tile in np.flatnonzero(plain & (counts > 0)):
        px0, py0 = (tile % t.TX) * 16, (tile // t.TX) * 16
        if px0 + 16 > t.W:
            continue  # (a partial tile takes the per-pixel path in either order)
        for y in range(py0, min(t.H, py0 + 16)):
            j0 = int(np.floor((y + 0.5) * t.scale - 0.5))
            under = np.clip([j0, j0 + 1], 0, t.Hl - 1)
            cols = slice(max(0, (px0 - 2) // 4), (px0 + 15 - 2) // 4 + 2)
            both += int((rows[tile] >> (y - py0)) & 1 == 1 and drawn[under][:, cols].any())
    assert both >= 16, both  # rows with both layers, drawn together
    bgra = s.render(320, 180, bgra=True).astype(int)[..., [2, 1, 0, 3]]
    d = np.abs(rgba - bgra)
    assert d.max() <= 1 and (d > 0).mean() < 1e-3, (d.max(), (d > 0).mean())


@pytest.mark.parametrize("edge", [False, True])
def test_an_empty_reduced_row_shows_the_packed_background_only_where_no_body_drew(edge):
    """``composite_tiles`` shows a tile row whose two reduced rows are the empty layer
    (``upsample.empty_rows``) as the packed background — except in a tile a soft or rigid body
    drew in (``dirty``), whose background is the frame's own (bodies drawn in), not the packed
    one: there it composites as if not empty. A 32 × 32 image (2 × 2 tiles) at s = 1/4, the
    reduced layer empty (or, to composite it, all but empty: red 10⁻³⁰, which shows nowhere), one
    reduced tile drawn (every tile is near it), no sprite at full resolution; the packed
    background made from other colours than the frame's, so each copy shows. ``edge``: the reduced depths alternate 1 and 10 along x, so every pixel's upsample is
    bilateral (the horizon's band): an empty row is the packed background there too, and
    computed it is the frame's background exactly (the bilateral mean of empty texels is empty)."""
    import taichi as ti

    from engine.render.composite import build_composite_kernels

    k = build_composite_kernels(False, True)
    W = H = 32
    s, TX, TY = 0.25, 2, 2
    Wl = Hl = 8
    px, LO = W * H, W * H
    v4 = ti.types.vector(4, ti.f32)
    rng = np.random.default_rng(3)

    def nd(dtype, a):
        arr = ti.ndarray(dtype, a.shape[0])
        arr.from_numpy(a)
        return arr

    frame_bg = rng.random((px, 4), dtype=np.float32)
    frame_bg[:, 3] = 0.0
    other_bg = frame_bg[::-1].copy()  # what the packed background was drawn from
    packed = np.zeros(px // 2, np.uint64)
    k["pack_background"](nd(v4, other_bg), packed, W, H, 0, 0, W, H, 1.0, 0)
    dirty = np.int32([1, 0, 0, 0])  # a body drew in tile 0

    depth = np.ones(LO + Wl * Hl, np.float32)
    if edge:
        depth[LO:] = np.tile(np.float32([1.0, 10.0]), Wl * Hl // 2)

    def composite(red, only_row=None):
        texels = np.tile(np.float32([red, 0, 0, 1]), (LO + Wl * Hl + 16, 1))
        if only_row is not None:  # every reduced row empty but this one
            texels[LO:LO + Wl * Hl] = (0.0, 0.0, 0.0, 1.0)
            texels[LO + only_row * Wl:LO + (only_row + 1) * Wl, 0] = red
        acc = nd(v4, texels)
        out = np.zeros(px, np.uint32)
        edges = nd(ti.i32, np.full(TX * TY, -1, np.int32))
        k["composite_tiles"](np.zeros(TX * TY, np.int32), np.zeros(TX * TY, np.int32), acc, acc,
                             nd(v4, frame_bg), nd(ti.f32, depth), packed, out,
                             np.zeros(1, np.uint64), 0, dirty, dirty, np.int32([1]), edges,
                             np.zeros(TX * TY * 16, np.int32), 1, 1, 0, 0, TX, TY, W, H, 1, Wl, Hl, s,
                             1.0, 0.9, 0, 4)
        return out.reshape(H, W)

    marked, computed = composite(0.0), composite(1e-30)
    body = np.zeros((H, W), bool)
    body[:16, :16] = True  # tile 0
    np.testing.assert_array_equal(marked[body], computed[body])
    np.testing.assert_array_equal(marked[~body], packed.view(np.uint32).reshape(H, W)[~body])
    assert (computed[~body] != marked[~body]).mean() > 0.9  # (the copy is seen)
    own = np.zeros(px // 2, np.uint64)  # the frame's own background packed: the empty layer over it
    k["pack_background"](nd(v4, frame_bg), own, W, H, 0, 0, W, H, 1.0, 0)
    np.testing.assert_array_equal(computed, own.view(np.uint32).reshape(H, W))
    # reduced row 3 alone not empty: the pixel rows reading it (v = (y + ½)/4 − ½ between rows
    # 2 and 3 or 3 and 4: y = 10..17) are computed, the others copied (a wrong row offset in the
    # tile's empty-row bits, ``ja − jt``, moves the band)
    one = composite(1e-30, only_row=3)
    band = np.zeros((H, W), bool)
    band[10:18] = True
    np.testing.assert_array_equal(one[band | body], computed[band | body])
    np.testing.assert_array_equal(one[~band & ~body], marked[~band & ~body])


def test_coarse_corner_is_the_bilinear_quad_at_half_scale():
    """``co_corner`` (integer operations) gives exactly ``lo_quad(x, y, 0.5, ...)``'s texels and
    fractions for every reduced texel of levels of odd and even sizes, edges included."""
    import taichi as ti

    from engine.render.upsample import co_corner, lo_quad

    @ti.kernel
    def both(out: ti.types.ndarray(dtype=ti.f32, ndim=3), Wc: ti.i32, Hc: ti.i32):
        for y, x in ti.ndrange(out.shape[0], out.shape[1]):
            a = ti.Vector(lo_quad(x, y, 0.5, Wc, Hc))
            b = ti.Vector(co_corner(x, y, Wc, Hc))
            for c in ti.static(range(6)):
                out[y, x, c] = a[c]
                out[y, x, 6 + c] = b[c]

    for Wc, Hc in ((80, 45), (7, 4), (1, 1)):
        out = np.zeros((2 * Hc + 1, 2 * Wc + 1, 12), np.float32)  # (one past a level made of whole texel pairs)
        both(out, Wc, Hc)
        assert np.array_equal(out[..., :6], out[..., 6:]), (Wc, Hc)
        assert set(np.unique(out[..., 4])) == {0.25, 0.75}
