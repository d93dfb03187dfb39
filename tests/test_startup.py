"""Start-up: what a warm start rests on.

* ``particles run`` leaves the kernels it compiled in Taichi's offline cache (engine.runtime's
  exit hook: without it the process ended without Taichi's teardown, wrote nothing, and every
  run started cold — 11 s for sparks' first frame instead of ~3);
* a scene's build-time parameters are written by few kernels (engine.fieldio: each kernel is one
  more to load at every start), with the values ``from_numpy`` would write.

Taichi's quickened front end (engine.front_end) is tested in tests/test_front_end.py.
"""
import os
import subprocess
import sys

import numpy as np
import pytest
import taichi as ti

from helpers import ROOT


def _cache_files(folder):
    return sorted(f for f in os.listdir(folder) if f.endswith(".tic"))


@pytest.mark.slow
def test_run_leaves_its_kernels_in_the_offline_cache(tmp_path):
    cache = tmp_path / "ticache"
    cache.mkdir()
    env = dict(os.environ, PARTICLES_TI_CACHE=str(cache), TI_SKIP_VERSION_CHECK="ON")
    cmd = [sys.executable, "-m", "engine", "run", os.path.join(ROOT, "configs", "sparks.toml"),
           "--frames", "1", "--out", str(tmp_path / "out"), "--overwrite", "--quiet"]
    first = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr
    kept = _cache_files(cache)
    assert len(kept) > 20  # sparks' step and render kernels (54 on Taichi 1.7.4)
    again = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    assert _cache_files(cache) == kept  # the second run compiled nothing new: every kernel hit


def test_column_writer_writes_what_from_numpy_writes():
    from engine.fieldio import ColumnWriter

    rng = np.random.default_rng(3)
    a, b = ti.field(ti.f32, shape=7), ti.Vector.field(3, ti.f32, shape=7)
    c, d = ti.field(ti.f32, shape=7), ti.field(ti.i32, shape=7)
    va, vb, vc = rng.normal(size=7), rng.normal(size=(7, 3)), rng.normal(size=7)
    vd = rng.integers(-5, 5, size=7)
    ColumnWriter([a, b, c]).write(va, vb, vc)
    ColumnWriter([d], ti.i32).write(vd)
    ref_a, ref_b = ti.field(ti.f32, shape=7), ti.Vector.field(3, ti.f32, shape=7)
    ref_a.from_numpy(va.astype(np.float32))
    ref_b.from_numpy(vb.astype(np.float32))
    assert np.array_equal(a.to_numpy(), ref_a.to_numpy())
    assert np.array_equal(b.to_numpy(), ref_b.to_numpy())
    assert np.array_equal(c.to_numpy(), vc.astype(np.float32))
    assert np.array_equal(d.to_numpy(), vd.astype(np.int32))
    e, f = ti.field(ti.f64, shape=7), ti.Vector.field(3, ti.f64, shape=7)  # f64: no rounding to f32
    ve, vf = rng.normal(size=7) / 3.0, rng.normal(size=(7, 3)) / 3.0
    ColumnWriter([e, f], ti.f64).write(ve, vf)
    assert np.array_equal(e.to_numpy(), ve) and np.array_equal(f.to_numpy(), vf)
    w = ColumnWriter([a, b])
    w.zero(4)  # the first 4 rows of each, the rest kept
    assert not a.to_numpy()[:4].any() and not b.to_numpy()[:4].any()
    assert np.array_equal(a.to_numpy()[4:], ref_a.to_numpy()[4:])
    assert np.array_equal(b.to_numpy()[4:], ref_b.to_numpy()[4:])


def test_look_force_and_collider_parameters_written_in_one_launch_each():
    """The sprites' per-emitter look (engine.render.sprites.Look: ramps, additive, streak, size
    randomness), the forces' per-emitter parameters and the colliders' fixed numbers, each written
    by one kernel: the values ``from_numpy`` of the configs' numbers would give, spare rows zero."""
    from engine.api import ParticleScene
    from engine.render.sprites import LOOK_SAMPLES

    data = {"forces": {"turbulence": {"strength": 2.0}}, "emitters": [
        {"name": "a", "rate": 10.0, "blend": "additive", "streak": 0.02, "size_randomness": 0.3,
         "color": [[0.0, 1.0, 0.5, 0.25], [1.0, 0.2, 0.3, 0.4]], "alpha": [[0.0, 0.9], [1.0, 0.1]],
         "size": [[0.0, 0.05]], "gravity_scale": 0.5, "buoyancy": 2.0, "cooling": 3.0},
        {"name": "b", "rate": 10.0, "blend": "alpha", "size_randomness": 0.7, "gravity_scale": -1.25,
         "turbulence": 0.8}],
        "colliders": [{"type": "plane", "restitution": 0.3, "friction": 0.2},
                      {"type": "sphere", "center": [1.0, 2.0, 3.0], "radius": 0.5, "restitution": 0.7}]}
    s = ParticleScene.from_dict(data, render=True)
    C = s.scene.colliders  # (radius, restitution, friction and the first positions: one launch)
    assert np.array_equal(C.collider_point.to_numpy(), np.float32([[0, 0, 0], [1, 2, 3]]))
    assert np.array_equal(C.collider_radius.to_numpy(), np.float32([1.0, 0.5]))  # (a plane: the default 1)
    assert np.array_equal(C.collider_restitution.to_numpy(), np.float32([0.3, 0.7]))
    assert C.collider_friction.to_numpy()[0] == np.float32(0.2)
    look = s.scene.renderer.look
    assert look.emitter_additive.to_numpy()[:2].tolist() == [1, 0]
    assert np.array_equal(look.emitter_streak.to_numpy()[:2], np.float32([0.02, 0.0]))
    assert np.array_equal(look.emitter_size_rand.to_numpy()[:2], np.float32([0.3, 0.7]))
    table = look.look_table.to_numpy()
    t = np.linspace(0.0, 1.0, LOOK_SAMPLES + 1)
    assert np.array_equal(table[0, :, 0], np.interp(t, [0.0, 1.0], [1.0, 0.2]).astype(np.float32))
    assert np.array_equal(table[0, :, 3], np.interp(t, [0.0, 1.0], [0.9, 0.1]).astype(np.float32))
    assert np.array_equal(table[0, :, 4], np.float32(np.full(LOOK_SAMPLES + 1, 0.05)))
    assert not table[2:].any() and not look.emitter_streak.to_numpy()[2:].any()  # spare rows
    F = s.scene.particles.forces
    assert np.array_equal(F.emitter_gravity_scale.to_numpy()[:2], np.float32([0.5, -1.25]))
    assert np.array_equal(F.emitter_buoyancy.to_numpy()[:2], np.float32([2.0, 0.0]))
    assert np.array_equal(F.emitter_inv_cooling.to_numpy()[:1], np.float32([1.0 / 3.0]))
    assert np.array_equal(F.emitter_turbulence.to_numpy()[:2], np.float32([1.0, 0.8]))  # (default 1)
    s.close()


def test_writer_group_writes_every_writer_in_one_kernel():
    """engine.fieldio.WriterGroup: writes held in a block land together, each writer's rows as
    ``from_numpy`` would write them (f32, i32 and f64, scalar and vector fields); a write outside a
    block writes that writer's rows alone; a block that raises writes nothing; the group's writers
    are fixed once its kernel is built."""
    from engine.fieldio import ColumnWriter, WriterGroup

    rng = np.random.default_rng(5)
    a, b = ti.field(ti.f32, shape=6), ti.Vector.field(3, ti.f32, shape=6)
    c, d = ti.field(ti.i32, shape=6), ti.Vector.field(2, ti.f64, shape=6)
    e = ti.field(ti.f32, shape=6)
    g = WriterGroup()
    wab, wc = ColumnWriter([a, b], group=g), ColumnWriter([c], ti.i32, g)
    wd, we = ColumnWriter([d], ti.f64, g), ColumnWriter([e], group=g)
    va, vb = rng.normal(size=4), rng.normal(size=(4, 3))
    vc, vd, ve = rng.integers(-9, 9, size=5), rng.normal(size=(6, 2)) / 3.0, rng.normal(size=6)
    with g.held():
        wab.write(va, vb)
        wc.write(vc)
        wd.write(vd)
        we.write(ve)
        assert not a.to_numpy().any() and not d.to_numpy().any()  # held: nothing written yet
    assert np.array_equal(a.to_numpy()[:4], va.astype(np.float32)) and not a.to_numpy()[4:].any()
    assert np.array_equal(b.to_numpy()[:4], vb.astype(np.float32))
    assert np.array_equal(c.to_numpy()[:5], vc.astype(np.int32))
    assert np.array_equal(d.to_numpy(), vd)  # f64: no rounding through f32
    assert np.array_equal(e.to_numpy(), ve.astype(np.float32))
    wc.zero(2)  # outside a block: that writer's rows alone
    assert c.to_numpy()[:2].tolist() == [0, 0] and np.array_equal(c.to_numpy()[2:5], vc[2:].astype(np.int32))
    assert np.array_equal(a.to_numpy()[:4], va.astype(np.float32))
    with pytest.raises(ZeroDivisionError):
        with g.held():
            we.zero(6)
            1 / 0
    assert np.array_equal(e.to_numpy(), ve.astype(np.float32))  # the block raised: nothing written
    with pytest.raises(RuntimeError, match="after the group's kernel"):
        ColumnWriter([ti.field(ti.f32, shape=2)], group=g)


def test_scene_parameters_and_counters_in_one_launch():
    """A scene's colliders' fixed numbers and its particle system's emitter parameters (f32 and
    i32), counters and force parameters are written by one launch of one kernel at the build; the
    same kernel writes the particles' again when emitters are added."""
    from engine import fieldio
    from engine.api import ParticleScene
    from engine.config import load_config
    from engine.scene import Scene
    from helpers import scene_dict

    launches = []
    real = fieldio._write_groups

    def counted(*args):
        launches.append(args[0])
        return real(*args)

    data = {"emitters": [{"name": "a", "rate": 10.0, "shape": "sphere", "radius": 0.25, "gravity_scale": 0.5}],
            "colliders": [{"type": "plane", "restitution": 0.3}]}
    fieldio._write_groups = counted
    try:
        built = Scene(load_config(scene_dict(**data)), render=False)  # the build: one launch
        assert len(launches) == 1 and len(launches[0].writers) == 5
        assert built.colliders.collider_restitution.to_numpy()[0] == np.float32(0.3)
        assert built.particles.emitters.emitter_radius.to_numpy()[0] == np.float32(0.25)
        launches.clear()
        s = ParticleScene.from_dict(data, render=False, spare_emitters=1)  # (builds, then resets)
        assert len(launches) == 2 and launches[1] is launches[0]
        P = s.scene.particles
        assert P.emitters.emitter_radius.to_numpy()[0] == np.float32(0.25)
        assert P.forces.emitter_gravity_scale.to_numpy()[0] == np.float32(0.5)
        s.add_emitter({"name": "b", "rate": 5.0, "gravity_scale": -2.0})
        assert len(launches) == 3 and launches[2] is launches[0]
        assert P.forces.emitter_gravity_scale.to_numpy()[:2].tolist() == [0.5, -2.0]
        s.close()
    finally:
        fieldio._write_groups = real


@pytest.mark.parametrize("dtype", [ti.f32, ti.f64])
def test_colliders_first_orientations_written_with_their_fixed_numbers(dtype):
    """The shapes' first orientations (a tilted plane's normal, a turned box's axes, a spinning
    capsule's ω) are written with their fixed numbers in one launch, the pose kernel left
    unloaded: the values the pose kernel itself writes from the same rows."""
    from engine.colliders import ColliderSpec, Colliders

    q = np.array([0.9, 0.1, -0.3, 0.2])
    q = tuple(q / np.linalg.norm(q))
    specs = [ColliderSpec("plane", normal=(0.2, 1.0, -0.1), restitution=0.1),
             ColliderSpec("box", point=(1.0, 0.5, 0.0), half_extents=(0.3, 0.2, 0.1), orientation=q),
             ColliderSpec("capsule", point=(0.0, 1.0, 2.0), radius=0.2, half_length=0.4, orientation=q,
                          angular_velocity=(0.0, 2.0, 0.5))]
    C = Colliders(specs, dtype)
    names = ("collider_normal", "collider_axis_x", "collider_axis_z", "collider_omega", "collider_point")
    first = {n: getattr(C, n).to_numpy() for n in names}
    assert abs(np.linalg.norm(first["collider_normal"][0]) - 1.0) < 1e-6
    assert first["collider_omega"][2].tolist() == [0.0, 2.0, 0.5] and first["collider_axis_x"][1].any()
    for n in names:
        getattr(C, n).fill(0)
    C._write(turned=True)  # the pose kernel, from the rows the build left
    for n in names[:4]:
        assert np.array_equal(getattr(C, n).to_numpy(), first[n]), n
