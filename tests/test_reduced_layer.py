"""The reduced-resolution layer (and the coarse one under it): which resolution sprites go to,
how close the layers stay to full resolution, the coarse sums mixed in only where drawn, resets
when the particles are gone, frames of small sprites that skip the layer, and the full level's
row masks (the upsample into the picture: tests/test_upsample.py)."""
import numpy as np
import pytest

from helpers import drawn_scene, other_schedule

from engine.api import ParticleScene
from engine.render.resolution import particle_scale


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
    layer in the composite (per tile its ``k`` argument 0: built without the layer's code; per
    pixel its ``has_lo`` argument 0; nor, per pixel, interpolate its rows:
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
    at = [a.name for a in composite.kernel._primal.arguments].index("k" if schedule == "tiles" else "has_lo")
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
