"""The reduced-resolution layer (and the coarse one under it): rows interpolated only where the
composite reads them, the upsample bilinear or bilateral by cached per-pixel masks, the coarse
sums mixed in only where drawn, empty rows shown as the background, resets when the particles
are gone, and how close the layers stay to full resolution."""
import numpy as np
import pytest

from helpers import drawn_scene, other_schedule

from engine.api import ParticleScene
from engine.render.resolution import particle_scale


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
    ``reduced_row`` unrolls them) equal the bilinear upsample's x half bit for bit, and equal each
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


@pytest.mark.slow
def test_reduced_layer_stays_close_to_full_resolution():
    """Smoke drawn into the ¼-resolution layer and upsampled looks like smoke drawn at full
    resolution: small differences, spread thin, no shift in overall brightness."""
    full = drawn_scene("configs/smoke.toml", frames=40, size=(320, 180), particle_resolution=1)
    quarter = drawn_scene("configs/smoke.toml", frames=40, size=(320, 180), particle_resolution=0.25)
    a = full.render()[..., :3].astype(float)
    b = quarter.render()[..., :3].astype(float)
    assert quarter.renderer.targets(320, 180).has_lo and not full.renderer.targets(320, 180).has_lo
    diff = np.abs(a - b)
    assert a.std() > 3 and diff.mean() < 1.5 and np.percentile(diff, 99) < 16, (diff.mean(), np.percentile(diff, 99))
    assert abs(a.mean() - b.mean()) < 1.0


def test_auto_resolution_follows_the_image_height():
    assert particle_scale("auto", 180) == 1.0
    assert particle_scale("auto", 360) == 0.5
    assert particle_scale("auto", 720) == 0.25
    assert particle_scale(0.5, 4000) == 0.5 and particle_scale(1, 4000) == 1.0


def _small_scene(schedule, emitters):
    """A 320×180 scene of these emitters seen from 4 m, its reduced layer at ¼, drawn with this
    schedule ("tiles" or "pixels")."""
    s = ParticleScene.from_dict({
        "name": "small", "fps": 60, "frames": 60,
        "camera": {"position": [0.0, 1.0, 4.0], "look_at": [0.0, 1.0, 0.0]},
        "render": {"width": 320, "height": 180, "particle_resolution": 0.25}, "emitters": emitters})
    if schedule == "pixels":
        s.scene.renderer = other_schedule(s.scene, "pixels")
    return s


def _levels(s):
    """The levels (0 full, 1 reduced, 2 coarse) of the sprites the scene's last frame drew."""
    info = s.scene.renderer.records.spr_info.to_numpy()
    return set(np.unique(info[info[:, 0] != 0, 2]).tolist())


@pytest.mark.parametrize("schedule, size, level", [("tiles", 0.6, 1), pytest.param("pixels", 0.6, 1, marks=pytest.mark.slow),
                                                   pytest.param("tiles", 2.0, 2, marks=pytest.mark.slow),
                                                   ("pixels", 2.0, 2)])
def test_once_every_particle_is_gone_the_frame_is_the_background_again(schedule, size, level):
    """A frame with nothing to draw skips the splat only once no reduced or coarse tile is left
    drawn from the last one: the first empty frame after smoke in the reduced layer (0.6 m puffs,
    16 px) or the coarse one (2 m puffs, 54 px) resets it, and it and every later one equal the
    background alone (the frame before anything was born)."""
    s = _small_scene(schedule, [{"name": "puff", "position": [0.0, 1.0, 0.0], "speed": [0.0, 0.2],
                                 "bursts": [{"time": 0.0, "count": 40}], "lifetime": 0.2, "blend": "alpha",
                                 "size": [[0.0, size]], "alpha": [[0.0, 0.8]]}])
    background = s.render().copy()
    s.step(1 / 60)
    drawn = s.render().copy()
    t = s.scene.renderer.targets(320, 180)
    assert t.has_lo and not t.lo_clear and np.abs(drawn.astype(int) - background).sum() > 1000
    assert _levels(s) == {level}
    for _ in range(30):  # past every particle's lifetime
        s.step(1 / 60)
    assert s.particles()["position"].shape[0] == 0
    for _ in range(3):  # the first empty frame splats (resetting the reduced tiles), the others skip
        assert np.array_equal(s.render(), background)
    assert t.lo_clear
    s.close()


def _puffs(width, height):
    """Big alpha puffs (coarse level), small ones (reduced) and an additive glow (coarse)."""
    return {
        "name": "puffs", "fps": 60, "frames": 60, "seed": 3,
        "camera": {"position": [0.0, 1.0, 4.0], "look_at": [0.0, 1.0, 0.0]},
        "render": {"width": width, "height": height, "particle_resolution": 0.25},
        "emitters": [
            {"name": "big", "position": [0.0, 1.0, 0.0], "speed": [0.2, 0.8], "rate": 60.0, "lifetime": 1.0,
             "blend": "alpha", "size": [[0.0, 1.5], [1.0, 2.5]], "alpha": [[0.0, 0.5]],
             "color": [[0.0, 0.8, 0.8, 0.9]]},
            {"name": "small", "position": [0.5, 1.0, 0.0], "speed": [0.2, 0.8], "rate": 60.0, "lifetime": 1.0,
             "blend": "alpha", "size": [[0.0, 0.4]], "alpha": [[0.0, 0.7]], "color": [[0.0, 0.3, 0.5, 0.9]]},
            {"name": "glow", "position": [-0.5, 1.0, 0.0], "speed": [0.2, 0.8], "rate": 30.0, "lifetime": 1.0,
             "blend": "additive", "size": [[0.0, 2.0]], "alpha": [[0.0, 0.3]], "color": [[0.0, 1.0, 0.5, 0.1]]}]}


def test_coarse_level_draws_what_the_reduced_level_would(monkeypatch):
    """Big sprites (radius ≥ 4 coarse texels) go to the coarse level at half the reduced scale,
    whose sums the reduced level adds before it resolves (light and OIT sums add, transmittances
    multiply): the picture is the one the reduced level alone draws but for the coarser sampling
    (measured at 8 px texels: mean 0.95 of 255, 99th percentile 23; with the coarse OIT sums left
    out, mean 6.3, or its transmittance, 5.3), and both schedules draw the same image."""
    import engine.render.renderer as renderer_module

    s = ParticleScene.from_dict(_puffs(320, 180))
    for _ in range(40):
        s.step(1 / 60)
    coarse = s.render().copy()
    assert _levels(s) == {1, 2} and coarse[..., :3].std() > 20
    pixels = other_schedule(s.scene, "pixels").render(s.scene.camera, 320, 180)
    assert np.abs(coarse.astype(int) - pixels.astype(int)).max() <= 1
    monkeypatch.setattr(renderer_module, "CO_MIN_TEXELS", 1e9)  # every big sprite at the reduced level
    reduced = s.render()
    assert _levels(s) == {1}
    d = np.abs(coarse.astype(int) - reduced.astype(int))[..., :3]
    assert d.mean() < 1.5 and np.percentile(d, 99) < 32, (d.mean(), np.percentile(d, 99))
    s.close()


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
                             1, 1.0, 0.9, 0, 4)
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


@pytest.mark.parametrize("schedule", ["tiles", "pixels"])
def test_a_reduced_tile_mixes_in_the_coarse_level_only_where_it_drew_under_it(schedule):
    """A reduced tile adds the coarse level's sums only where some coarse texel its texels read
    (``co_quad``'s bilinear footprint) holds a sprite's sums, not wherever a coarse tile under it
    was drawn: a tile with no sprite of its own and nothing drawn under it is not counted as drawn
    (``touched_lo``), so the composite shows the background there; the per-pixel schedule keeps
    the same rule (bit 1 of ``touched_lo``) and draws the same image."""
    import math

    s = ParticleScene.from_dict(_puffs(640, 360))
    for _ in range(40):
        s.step(1 / 60)
    if schedule == "pixels":
        s.scene.renderer = other_schedule(s.scene, "pixels")
    img = s.render()
    t = s.scene.renderer.targets(640, 360)
    acc_a, acc_b = t.accA.to_numpy()[t.LC:t.LC + t.Wc * t.Hc], t.accB.to_numpy()[t.LC:t.LC + t.Wc * t.Hc]
    drawn = ((acc_a != (0.0, 0.0, 0.0, 1.0)).any(-1) | (acc_b != 0.0).any(-1)).reshape(t.Hc, t.Wc)
    touched_co = t.touched_co.to_numpy() != 0
    own = t.tile_count.to_numpy()[t.T0:t.T0 + t.T1] > 0
    touched = t.touched_lo.to_numpy()
    coarse_tile_under = mixed = 0
    for ty in range(t.TYl):
        for tx in range(t.TXl):
            x0, y0 = 16 * tx, 16 * ty
            x1, y1 = min(t.Wl - 1, x0 + 15), min(t.Hl - 1, y0 + 15)
            # the coarse texels co_quad reads for these reduced texels (half their scale)
            cx0 = max(0, math.floor((x0 + 0.5) / 2 - 0.5))
            cx1 = min(t.Wc - 1, math.floor((x1 + 0.5) / 2 - 0.5) + 1)
            cy0 = max(0, math.floor((y0 + 0.5) / 2 - 0.5))
            cy1 = min(t.Hc - 1, math.floor((y1 + 0.5) / 2 - 0.5) + 1)
            under = touched_co.reshape(t.TYc, t.TXc)[cy0 // 16:cy1 // 16 + 1, cx0 // 16:cx1 // 16 + 1].any()
            mix = bool(drawn[cy0:cy1 + 1, cx0:cx1 + 1].any())
            k = ty * t.TXl + tx
            assert (touched[k] != 0) == (own[k] or mix), (tx, ty)
            if schedule == "pixels":
                assert (touched[k] & 2 != 0) == mix, (tx, ty)
            coarse_tile_under += under and not mix
            mixed += mix
    assert coarse_tile_under > 0 and mixed > 0  # (the rule is exercised both ways)
    assert img[..., :3].std() > 20
    if schedule == "pixels":
        other = other_schedule(s.scene, "tiles").render(s.scene.camera, 640, 360)
        assert np.abs(other.astype(int) - img.astype(int)).max() <= 1
    s.close()


@pytest.mark.parametrize("schedule", ["tiles", "pixels"])
def test_a_frame_of_small_sprites_skips_the_reduced_rows(schedule):
    """A frame whose sprites are all at full resolution (sparks, galaxy) does not read the reduced
    layer in the composite (its ``has_lo`` argument 0; nor, per pixel, interpolate its rows:
    ``lo_rows``), since ``tally`` counts the reduced and coarse levels' pairs: the same image as
    the path that reads it, which a frame with one big sprite still takes."""
    s = _small_scene(schedule, [
        {"name": "dots", "position": [0.0, 1.0, 0.0], "speed": [0.5, 1.0],
         "bursts": [{"time": 0.0, "count": 60}], "lifetime": 5.0, "blend": "additive",
         "size": [[0.0, 0.01]], "alpha": [[0.0, 0.8]]},
        {"name": "puff", "position": [0.0, 1.0, 0.0], "start": 0.5, "bursts": [{"time": 0.5, "count": 1}],
         "lifetime": 5.0, "blend": "alpha", "size": [[0.0, 0.6]], "alpha": [[0.0, 0.5]]}])
    R = s.scene.renderer
    calls = []
    name = f"composite_{schedule}"
    composite, rows = R._k[name], R._k["lo_rows"]
    at = [a.name for a in composite.kernel._primal.arguments].index("has_lo")
    rows_calls = []

    def reading(*a):  # (this renderer's kernels only)
        if a[at]:
            calls.append(1)
        return composite(*a)

    R._k = dict(R._k, **{name: reading}, lo_rows=lambda *a: (rows_calls.append(1), rows(*a)))
    splat = R._splat

    def always_reduced(t, *a, **k):  # the path before: the reduced layer read whenever it exists
        splat(t, *a, **k)
        return int(t.has_lo)

    for _ in range(6):
        s.step(1 / 60)
    skipped = s.render().copy()
    assert _levels(s) == {0} and not calls and skipped.any() and R.last_reduced_pairs == 0
    R._splat = always_reduced
    assert np.array_equal(s.render(), skipped) and len(calls) == 1
    del R._splat
    for _ in range(30):  # the puff is born at 0.5 s: the reduced layer is read again
        s.step(1 / 60)
    drawn = s.render().copy()
    assert _levels(s) & {1, 2} and len(calls) == 2
    assert rows_calls == (calls if schedule == "pixels" else [])  # (the tiles' reads the texels)
    info, tiles = R.records.spr_info.to_numpy(), R.records.spr_tiles.to_numpy()
    on = (info[:, 0] != 0) & (info[:, 2] >= 1)  # the tile-sprite pairs of levels 1 and 2
    want = int(((tiles[on, 2] - tiles[on, 0] + 1) * (tiles[on, 3] - tiles[on, 1] + 1)).sum())
    assert R.last_reduced_pairs == want >= 1 and R.last_pairs > want
    R._splat = always_reduced
    assert np.array_equal(s.render(), drawn)
    s.close()


@pytest.mark.parametrize("config", ["configs/sparks.toml", "configs/explosion.toml", "dots"])
def test_full_rows_mark_every_row_a_sprite_drew_in(config):
    """``splat_tiles``' mask per full-level tile (``full_rows``, what the composite takes as the
    rows its sprites drew in) holds every row whose accumulators are not the empty layer — the
    streaks' and discs' rows down to a one-pixel span — and leaves some rows out (else it would
    save nothing)."""
    if config == "dots":  # sprites of 1-3 px (the splat's unrolled 2x2 block)
        api = _small_scene("tiles", [{"name": "dots", "position": [0.0, 1.0, 0.0], "speed": [0.5, 1.5],
                                      "bursts": [{"time": 0.0, "count": 400}], "lifetime": 5.0,
                                      "blend": "additive", "size": [[0.0, 0.004]], "alpha": [[0.0, 0.9]]}])
        for _ in range(20):
            api.step(1 / 60)
        s = api.scene
    else:
        s = drawn_scene(config, frames=30, size=(320, 180))
    s.render()
    t = s.renderer.targets(320, 180)
    A = t.accA.to_numpy()
    B = t.accB.to_numpy() if s.renderer.uses_alpha else np.zeros_like(A)
    counts, masks = t.tile_count.to_numpy()[:t.T0], t.full_rows.to_numpy()
    marked = unmarked = 0
    for k in np.flatnonzero(counts > 0):
        px0, py0 = (k % t.TX) * 16, (k // t.TX) * 16
        px1, py1 = min(t.W - 1, px0 + 15), min(t.H - 1, py0 + 15)
        tw, th = px1 - px0 + 1, py1 - py0 + 1
        ab = py0 * t.W + px0 * th - py0 * tw - px0  # (splat_kernels.tile_rows)
        for y in range(py0, py1 + 1):
            idx = ab + y * tw + np.arange(px0, px1 + 1)
            drawn = (A[idx] != (0.0, 0.0, 0.0, 1.0)).any() or (B[idx] != 0.0).any()
            bit = (int(masks[k]) >> (y - py0)) & 1
            assert bit or not drawn, (k, y)
            marked += bit
            unmarked += 1 - bit
    assert marked > 0 and unmarked > 0


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
