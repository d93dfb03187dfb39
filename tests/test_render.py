"""The renderer: two schedules, one image; determinism; sizes, cameras and overlays without
recompiling; what the output array holds. (The reduced and coarse layers, their upsample and
the composite's skips: ``test_reduced_layer.py`` and ``test_upsample.py``.)"""
import numpy as np
import pytest

from helpers import drawn_scene, on_thread_counts, other_schedule

from engine.api import ParticleScene
from engine.render.renderer import MAX_SIZES_KEPT


@pytest.mark.parametrize("path, res", [("configs/sparks.toml", 1),
                                       pytest.param("configs/dust.toml", 0.5, marks=pytest.mark.slow),
                                       pytest.param("configs/campfire.toml", 0.25, marks=pytest.mark.slow),
                                       pytest.param("configs/debris.toml", 0.25, marks=pytest.mark.slow)])
def test_per_pixel_schedule_draws_the_per_tile_image(path, res):
    """The GPU's schedule (a thread per pixel, registers) and the CPU's (a thread per tile,
    sprite-major) add the same sprites to each pixel in the same order: the same image but for
    compiler rounding (fast math may fuse differently in the two kernels)."""
    s = drawn_scene(path, size=(192, 108), particle_resolution=res)
    tiles = s.render()
    pixels = other_schedule(s, "pixels").render(s.camera, 192, 108)
    diff = np.abs(tiles.astype(int) - pixels.astype(int))
    assert tiles[..., :3].std() > 3  # something was drawn
    assert diff.max() <= 1 and (diff > 0).mean() < 2e-3, (diff.max(), (diff > 0).mean())
    if res != 1:
        assert s.renderer.targets(192, 108).has_lo


_PROBE = """
import hashlib, sys
from engine import runtime
runtime.init("cpu", threads=int(sys.argv[1]))
from engine.config import load_config
from engine.scene import Scene
s = Scene(load_config("configs/campfire.toml", {"render.particle_resolution": 0.5}), width=200, height=120)
h = hashlib.sha256()
for _ in range(12):
    s.advance_frame()
    h.update(s.render().tobytes())
print(h.hexdigest())
"""


@pytest.mark.slow
def test_frames_are_byte_identical_across_thread_counts():
    out = on_thread_counts(_PROBE, timeout=300)
    assert out[0][-1] == out[1][-1], out


def _compiled(renderer):
    """How many kernel instances the renderer's kernels have compiled so far."""
    kernels = [renderer._background, *renderer._k.values()]
    if renderer.has_particles:
        kernels += [renderer._sprites, renderer._tally, renderer._scatter]
    return sum(len(k._primal.compiled_kernels) for k in kernels)


def test_a_second_scene_compiles_no_composite_kernel():
    """The splat and composite kernels take every array as an argument: built once per Taichi
    program and blend modes, a second scene (a rebuilt one, another level) shares them."""
    cfg = {"name": "dots", "fps": 60, "frames": 4, "render": {"width": 96, "height": 54},
           "emitters": [{"rate": 200.0, "speed": [0.5, 1.0], "lifetime": 1.0, "blend": "alpha"}]}
    a = ParticleScene.from_dict(cfg)
    a.step(1 / 60)
    a.render()
    kernels = a.scene.renderer._k
    before = sum(len(k._primal.compiled_kernels) for k in kernels.values())
    b = ParticleScene.from_dict(cfg)
    b.step(1 / 60)
    b.render()
    assert b.scene.renderer._k is kernels
    assert sum(len(k._primal.compiled_kernels) for k in kernels.values()) == before
    a.close()
    b.close()


@pytest.mark.slow  # (default run kept under 5 minutes cold: CI runs it with the slow tests)
def test_new_sizes_cameras_and_overlays_compile_nothing():
    s = drawn_scene("configs/sparks.toml", frames=5, size=(128, 72))
    r = s.renderer
    s.render()
    s.render(transparent=True)
    before = _compiled(r)
    for w, h in ((200, 100), (64, 200), (131, 77)):
        img = s.render(w, h, transparent=(w == 64))
        assert img.shape == (h, w, 4) and img[..., :3].max() > 0
    moved = s.camera.__class__((0.3, 1.8, 5.0), s.camera.look_at, s.camera.fov)
    s.render(camera=moved)
    assert _compiled(r) == before
    # buffers of the least recently used sizes are dropped, and a dropped size comes back with the
    # same image and no compile
    first = s.render(200, 100)
    for w, h in ((96, 54), (112, 63), (144, 81), (160, 90)):
        s.render(w, h)
    assert len(r._targets) <= MAX_SIZES_KEPT and (200, 100) not in {k[:2] for k in r._targets}
    assert np.array_equal(s.render(200, 100), first) and _compiled(r) == before


@pytest.mark.slow
def test_background_is_redrawn_when_camera_or_colliders_move():
    s = drawn_scene("configs/sparks.toml", frames=5)
    first = s.render()
    assert np.array_equal(s.render(), first)  # kept background
    moved = s.camera.__class__((0.3, 1.8, 5.0), s.camera.look_at, s.camera.fov)
    assert not np.array_equal(s.render(camera=moved), first)
    assert np.array_equal(s.render(), first)
    pos = s.colliders.collider_point.to_numpy()[: s.colliders.count]
    s.colliders.move_to(s.t + 0.1, pos + np.array([0.0, 0.3, 0.0], np.float32))
    cached = s.render()
    assert not np.array_equal(cached, first)
    s.renderer.targets(s.width, s.height).bg_key = None  # force a full redraw
    assert np.array_equal(cached, s.render())  # the move had been noticed


@pytest.mark.slow  # (hair's compile: 10 s)
def test_a_moving_collider_redraws_only_where_it_was_and_is():
    """hair: the head (a sphere collider on a path) moves every frame over a ground plane, with a
    soft body drawn into the frame's own copy of the background. The kept background redrawn in
    the moved sphere's screen rectangles gives the bytes a whole redraw gives, frame after frame."""
    s = drawn_scene("configs/hair.toml", frames=0, size=(160, 90), particle_resolution=0.5)
    R = s.renderer
    rects = []
    draw = R._background
    R._background = lambda *a: (rects.append(a[-4:]), draw(*a))[1]
    t = R.targets(s.width, s.height)
    for k in range(12):
        s.advance_frame()
        img = s.render()
        if k % 4 == 3:
            t.bg_key = None  # a whole redraw
            assert np.array_equal(s.render(), img), k
    assert rects[0] == (0, 0, 160, 90)
    part = [r for r in rects[1:] if r != (0, 0, 160, 90)]
    assert len(part) == 11  # (each frame but the first; the forced whole redraws aside)
    assert all(0 < (x1 - x0) * (y1 - y0) < 0.5 * 160 * 90 for x0, y0, x1, y1 in part), part
    # the packed background holds two pixels an element: some rectangles cut a pair at an edge
    assert any(x0 % 2 or x1 % 2 for x0, _, x1, _ in part), part


@pytest.mark.slow
def test_pair_list_grows_without_changing_the_image():
    s = drawn_scene("configs/sparks.toml", frames=15)
    ref = s.render()
    t = s.renderer.targets(s.width, s.height)
    t.grow_pairs(16)
    assert np.array_equal(s.render(), ref)
    assert t.pair_capacity >= s.renderer.last_pairs > 16


def test_transparent_overlay_is_premultiplied_with_alpha_zero_where_nothing_is_drawn():
    s = ParticleScene.from_dict({  # additive sparks and alpha smoke, nothing else to compile
        "seed": 1, "fps": 30, "frames": 1, "camera": {"position": [0.0, 1.0, 5.0], "look_at": [0.0, 1.0, 0.0]},
        "emitters": [{"effect": "sparks", "rate": 300.0, "position": [0.3, 1.0, 0.0]},
                     {"effect": "smoke", "rate": 60.0, "position": [-0.4, 0.8, 0.0]}]})
    for _ in range(20):
        s.step(1 / 30)
    opaque = s.render(160, 90)
    over = s.render(160, 90, transparent=True)
    assert np.all(opaque[..., 3] == 255)
    empty = np.all(over[..., :3] == 0, axis=-1)
    assert empty.mean() > 0.3 and np.all(over[empty, 3] == 0)  # background left out
    assert np.all(over[..., :3] <= np.maximum(over[..., 3:], over[..., :3]).max())
    lit = over[..., :3].max(-1) > 40
    assert lit.any() and (over[lit, 3] < 255).any()  # additive light adds (alpha below 1)


@pytest.mark.slow
def test_render_into_a_given_array_and_refuse_a_wrong_one():
    """Every pixel of ``out`` is written, whatever it held (the untouched tiles too: on the CPU
    the frame starts as one copy of the packed background, which the composite then skips)."""
    s = drawn_scene("configs/sparks.toml", frames=5, size=(96, 54))
    out = np.full((54, 96, 4), 0xAB, np.uint8)
    got = s.render(out=out)
    assert got is out and out[..., :3].max() > 0 and np.array_equal(out, s.render(out=np.zeros_like(out)))
    assert isinstance(s.renderer.targets(96, 54).bg_packed, np.ndarray)  # (the host copy was taken)
    for bad in (np.zeros((54, 96, 3), np.uint8), np.zeros((54, 96, 4), np.float32),
                np.zeros((96, 54, 4), np.uint8), np.zeros((54, 192, 4), np.uint8)[:, ::2]):
        with pytest.raises(ValueError, match="out"):
            s.render(out=bad)


def test_tone_map_table_samples_aces_and_srgb():
    """The tone-map table against its closed form (ACES fit, then sRGB, 8 bits, in f64): its bins
    tile [2^-17, 8) edge to edge, each entry lies between the closed form at its bin's two edges
    (the curve rises), and read as the kernels read it (by a value's bits) it gives the closed
    form's own value for all but a few tenths of a percent of values."""
    from engine.render.tonemap import LUT_BIAS, LUT_BITS, LUT_HI, LUT_LO, tonemap, tonemap_bins, tonemap_table

    table, (lo, hi) = tonemap_table(), tonemap_bins()
    assert lo[0] == 2.0 ** -17 and hi[-1] == 8.0 and np.all(np.diff(lo) > 0)
    # the clamp's two ends read the first and the last entry, and a bin's edges stay in it
    ends = np.float32([LUT_LO, LUT_HI, np.nextafter(np.float32(LUT_LO), np.float32(1)), 1.0])
    index = (ends.view(np.uint32) >> (23 - LUT_BITS)).astype(np.int64) - LUT_BIAS
    assert list(index[:3]) == [0, len(table) - 1, 0] and lo[index[3]] == 1.0
    assert np.all(tonemap(lo) <= table) and np.all(table <= tonemap(hi))
    assert table[0] == 0 and table[-1] == 255 and np.all(np.diff(table) >= 0)
    x = np.exp(np.random.default_rng(5).uniform(np.log(1e-6), np.log(8.0), 200_000)).astype(np.float32)
    bits = np.clip(x, np.float32(LUT_LO), np.float32(LUT_HI)).view(np.uint32)
    looked_up = table[(bits >> (23 - LUT_BITS)).astype(np.int64) - LUT_BIAS]
    off = looked_up - tonemap(x)
    assert np.abs(off).max() <= 1 and np.mean(off != 0) < 0.005, np.mean(off != 0)


def test_the_kernels_tone_map_by_the_table():
    """``pack`` (through ``pack_background``: a background alone, at exposure 1 and 2) reads the
    table entry of each channel's bin — bit for bit what NumPy finds for the same f32 values —
    with below the first bin (−0, a subnormal), negatives and NaN black, from 8 on and +inf white,
    the table's two ends exactly, and alpha 255."""
    import taichi as ti

    from engine.render.composite import build_composite_kernels
    from engine.render.tonemap import LUT_BIAS, LUT_BITS, LUT_HI, LUT_LO, tonemap_table

    k = build_composite_kernels(True, True)
    rng = np.random.default_rng(11)
    special = np.float32([0.0, -1.0, np.nan, np.inf, -np.inf, 1e-30, LUT_LO, LUT_HI, 8.0, -0.0, 1e-40, 3.6])
    rgb = np.concatenate([special, np.exp(rng.uniform(np.log(1e-7), np.log(20.0), 3 * 4096 - len(special)))])
    rgb = rgb.astype(np.float32).reshape(-1, 3)
    bg = np.concatenate([rgb, np.ones((len(rgb), 1), np.float32)], axis=1)
    W, H = 64, len(bg) // 64
    arr = ti.ndarray(ti.types.vector(4, ti.f32), len(bg))
    arr.from_numpy(bg)
    table = tonemap_table()
    for exposure in (1.0, 2.0):
        packed = np.zeros(len(bg) // 2, np.uint64)
        k["pack_background"](arr, packed, W, H, 0, 0, W, H, exposure, 0)
        got = packed.view(np.uint32).view(np.uint8).reshape(-1, 4)
        with np.errstate(invalid="ignore", over="ignore"):
            x = np.nan_to_num(rgb * np.float32(exposure), nan=0.0, posinf=LUT_HI, neginf=0.0)  # (as the clamp takes them)
        bits = np.clip(x, np.float32(LUT_LO), np.float32(LUT_HI)).view(np.uint32)
        want = table[(bits >> (23 - LUT_BITS)).astype(np.int64) - LUT_BIAS]
        assert np.array_equal(got[:, :3], want) and np.all(got[:, 3] == 255), exposure
    # (exposure 2 here) 0, −1, NaN | inf, −inf, 1e-30 | 2^-16, 16, 16 | −0, 1e-40
    assert list(got[:3, :3].ravel()) == [0, 0, 0, 255, 0, 0, 0, 255, 255] and list(got[3, :2]) == [0, 0]
