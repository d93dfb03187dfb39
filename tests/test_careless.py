"""Issue 20: careless users. Each case works, or fails in one line naming the method, argument,
flag or config key and the value, and a refused call changes nothing."""
import os

import numpy as np
import pytest

from helpers import one_line as _one_line

from engine import checks


# -- render(out=...) ---------------------------------------------------------------------------------
def test_render_out_refuses_read_only_arrays(tmp_path):
    ro = np.zeros((36, 64, 4), np.uint8)
    ro.flags.writeable = False
    over_bytes = np.frombuffer(bytes(36 * 64 * 4), np.uint8).reshape(36, 64, 4)
    path = tmp_path / "img.raw"
    path.write_bytes(bytes(36 * 64 * 4))
    mm = np.memmap(path, np.uint8, mode="r", shape=(36, 64, 4))
    for a in (ro, over_bytes, mm):
        with pytest.raises(ValueError) as e:
            checks.image_array("render: out", a, 64, 36)
        text = _one_line(e)
        assert text.startswith("render: out") and "read-only" in text and "writeable" in text, text
    checks.image_array("render: out", np.zeros((36, 64, 4), np.uint8), 64, 36)  # a writeable one is fine


def test_render_out_names_the_property_that_failed():
    base = np.zeros((36, 128, 4), np.uint8)
    cases = [(base[:, ::2], "C-contiguous"), (np.zeros((36, 64, 3), np.uint8), "shape"),
             (np.zeros((36, 64, 4), np.float32), "dtype"), (np.zeros((64, 36, 4), np.uint8), "shape")]
    for a, prop in cases:
        with pytest.raises(ValueError) as e:
            checks.image_array("render: out", a, 64, 36)
        text = _one_line(e)
        assert text.startswith("render: out: " + ("the array is not" if prop == "C-contiguous" else prop)), text
        assert prop in text, text


def test_render_into_a_read_only_array_changes_nothing():
    from engine.api import SceneBuilder

    s = (SceneBuilder(seed=1, fps=60).render(width=32, height=32)
         .emitter(name="e", rate=200.0, lifetime=1.0).build())
    s.step(1 / 60)
    buf = bytearray(32 * 32 * 4)
    ro = np.frombuffer(bytes(buf), np.uint8).reshape(32, 32, 4)
    before = ro.tobytes()
    with pytest.raises(ValueError, match=r"^render: out: .*read-only"):
        s.render(32, 32, out=ro)
    assert ro.tobytes() == before
    ok = np.empty((32, 32, 4), np.uint8)
    assert s.render(32, 32, out=ok) is not None
    s.close()


# -- a burst shares the pool with the stream ----------------------------------------------------------
def _stream_and_burst(render=False):
    from engine.api import SceneBuilder

    return (SceneBuilder(fps=60, seed=1).render(width=32, height=32)
            .emitter(name="sparks", rate=400.0, lifetime=1.2, lifetime_randomness=0.5, speed=(1.0, 2.0))
            .build(render=render))


def test_a_burst_does_not_starve_the_stream_while_the_segment_has_free_slots():
    """The README's game example: after burst(200) every birth takes a free slot of the emitter's
    segment; a particle is dropped only when the segment is full (before: the ring's head waited
    on long-lived burst particles and ~300 births were dropped with ~300 slots free)."""
    s = _stream_and_burst()
    ps = s.scene.particles
    em, size = ps.emitters, ps.layout.sizes[0]
    stream_born = 0
    for i in range(200):
        if i == 60:
            s.burst("sparks", 200)
        free = size - int(ps.state.particle_alive.to_numpy()[:size].sum())
        e0, d0 = int(em.emitted_counts()[0]), s.dropped()
        s.step(1 / 120)
        born, dropped = int(em.emitted_counts()[0]) - e0, s.dropped() - d0
        assert born == min(born + dropped, free), (i, born, dropped, free)
        if i > 60:
            stream_born += born
    assert stream_born > 0.9 * 400 * 139 / 120 * 0.6, stream_born
    s.close()



def _children():
    from engine.api import SceneBuilder

    return (SceneBuilder(fps=60, seed=4)
            .emitter(name="p", rate=200.0, lifetime=0.1, speed=(0.5, 1.0),
                     sub_emitters=[{"event": "death", "emitter": "c", "count": 1}])
            .emitter(name="c", rate=0.0, emitting=False, lifetime=1.0, lifetime_randomness=0.9,
                     speed=(0.1, 0.2), capacity=160)
            .build(render=False))


def test_sub_emitter_children_take_free_slots_too():
    """Children whose ring slot holds a long-lived child take a free slot of their segment: none
    is dropped while the segment has room (before: 117 of 779 dropped with the segment at most
    109 of 160 full)."""
    s = _children()
    ps = s.scene.particles
    start, size = ps.layout.starts[1], ps.layout.sizes[1]
    most = 0
    for _ in range(240):
        s.step(1 / 60)
        most = max(most, int(ps.state.particle_alive.to_numpy()[start:start + size].sum()))
    assert most < size
    assert ps.emitters.dropped_counts().tolist() == [0, 0]
    assert ps.emitters.emitted_counts()[1] > 700
    s.close()

SLOT_PROBE = """
import hashlib, sys
sys.path[:0] = [".", "tests"]
from engine import runtime
runtime.init("cpu", threads=int(sys.argv[1]))
from test_careless import _children, _stream_and_burst
s = _stream_and_burst()
for i in range(150):
    if i in (30, 60):
        s.burst("sparks", 200)
    s.step(1 / 120)
c = _children()
for i in range(120):
    c.step(1 / 60)
h = hashlib.sha256()
for f in ("particle_pos", "particle_vel", "particle_age", "particle_alive", "particle_emitter"):
    h.update(getattr(c.scene.particles.state, f).to_numpy().tobytes())
print(h.hexdigest(), c.dropped(), *c.scene.particles.emitters.emitted_counts())
S = s.scene.particles.state
h = hashlib.sha256()
for f in ("particle_pos", "particle_vel", "particle_age", "particle_alive", "particle_emitter"):
    h.update(getattr(S, f).to_numpy().tobytes())
print(h.hexdigest(), s.dropped(), *s.scene.particles.emitters.emitted_counts())
"""


@pytest.mark.slow
def test_births_moved_to_free_slots_are_the_same_bytes_for_any_thread_count(tmp_path):
    import subprocess
    import sys

    script = tmp_path / "probe.py"
    script.write_text(SLOT_PROBE)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    runs = [subprocess.run([sys.executable, str(script), str(n)], cwd=root, capture_output=True, text=True)
            for n in (1, 2, 2)]
    assert all(r.returncode == 0 for r in runs), [r.stderr[-1500:] for r in runs]
    out = [r.stdout.split() for r in runs]
    assert out[0] == out[1] == out[2], out


# -- names ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("bad", [" ", "\t", "a\nb", "nul\x00", " lead", "trail ", "\x7f"])
def test_emitter_names_must_be_printable_and_not_blank(bad):
    from engine.config import ConfigError, load_config

    with pytest.raises(ConfigError) as e:
        load_config({"emitters": [{"name": "ok", "rate": 1.0}, {"name": bad, "rate": 1.0}]})
    assert len(e.value.problems) == 1, e.value.problems
    line = e.value.problems[0]
    assert line.startswith("emitters[1].name: ") and "\n" not in line, line
    for kind in ("colliders", "bodies"):
        item = {"name": bad, "type": "plane"} if kind == "colliders" else {"name": bad, "type": "chain"}
        with pytest.raises(ConfigError, match=rf"{kind}\[0\]\.name"):
            load_config({"emitters": [{"rate": 1.0}], kind: [item]})


def test_an_empty_name_reaches_nothing():
    from engine.config import ConfigError, load_config

    load_config({"emitters": [{"rate": 1.0}, {"name": "", "rate": 1.0}]})  # unnamed: allowed
    with pytest.raises(ConfigError, match=r"emitters\[0\]\.sub_emitters\[0\]\.emitter: '' is not allowed"):
        load_config({"emitters": [{"name": "a", "rate": 1.0, "sub_emitters": [{"emitter": ""}]}, {"rate": 1.0}]})
    with pytest.raises(KeyError, match="burst: name: no emitter named ''"):
        checks.name("burst: name", "", ["", "sparks"], "emitter")


# -- FixedTimestep and step() ---------------------------------------------------------------------------
class _Flaky:
    """A scene whose third step raises."""

    def __init__(self, fail_at=3):
        self.steps, self.fail_at = 0, fail_at

    def step(self, dt):
        self.steps += 1
        if self.steps == self.fail_at:
            raise RuntimeError("boom")


def test_fixed_timestep_after_a_raise_runs_no_burst_of_steps():
    from engine.api import FixedTimestep

    clock, scene = FixedTimestep(0.01), _Flaky()
    with pytest.raises(RuntimeError, match="boom"):
        clock.advance(scene, 0.16)  # 16 steps due; the third raises
    assert scene.steps == 3
    assert clock.advance(scene, 0.01) == 1  # one frame's worth, not the 13 left over
    assert scene.steps == 4 and 0.0 <= clock.alpha < 1.0


@pytest.mark.parametrize("dt", [1e-9, 1e-12, 5e-324, 9.99e-7])
def test_fixed_timestep_refuses_a_tiny_dt(dt):
    from engine.api import FixedTimestep

    with pytest.raises(ValueError) as e:
        FixedTimestep(dt)
    text = _one_line(e)
    assert text.startswith("FixedTimestep: dt: ") and repr(dt) in text and "1e-06" in text, text
    assert FixedTimestep(1e-6).dt == 1e-6


def test_huge_numbers_are_refused_in_one_line_naming_the_argument():
    with pytest.raises(ValueError) as e:
        checks.number("step: dt", 10**400, 0.0, lo_open=True)
    text = _one_line(e)
    assert text.startswith("step: dt: ") and "not allowed" in text, text
    with pytest.raises(ValueError, match="^step: dt: "):
        checks.number("step: dt", -10**400, 0.0, lo_open=True)


def test_step_of_a_huge_int_names_dt():
    from engine.api import SceneBuilder

    s = SceneBuilder(fps=60).emitter(name="e", rate=10.0).build(render=False)
    with pytest.raises(ValueError) as e:
        s.step(10**400)
    assert _one_line(e).startswith("step: dt: ")
    assert s.time == 0.0
    s.close()


# -- long keyframe paths -----------------------------------------------------------------------------
def _path(n, bad_at=None):
    keys = [{"time": i * 0.001, "position": [0.0, 1.0, i * 1e-6]} for i in range(n)]
    if bad_at is not None:
        keys[bad_at]["time"] = 0.0
    return keys


def test_an_out_of_order_keyframe_is_one_short_line_in_validate_and_from_dict():
    from engine.api import ParticleScene
    from engine.config import ConfigError, load_config

    data = {"emitters": [{"rate": 1.0, "path": _path(20_000, bad_at=13_337)}],
            "colliders": [{"type": "sphere", "path": _path(5_000, bad_at=7)}],
            "bodies": [{"type": "chain", "pins": [0], "pin_path": _path(10, bad_at=9)}]}
    with pytest.raises(ConfigError) as e:
        load_config(data)
    problems = e.value.problems
    assert len(problems) == 3, problems
    assert all(len(p) < 200 and "\n" not in p for p in problems), problems
    by_key = {p.split(": ", 1)[0]: p for p in problems}
    assert by_key["emitters[0].path"].startswith(
        "emitters[0].path: keyframe times must increase: keyframe 13337 has time 0,"), problems
    assert "keyframe 7 " in by_key["colliders[0].path"], problems
    assert "keyframe 9 " in by_key["bodies[0].pin_path"], problems
    with pytest.raises(ValueError) as e:
        ParticleScene.from_dict({"emitters": data["emitters"]}, render=False)
    assert len(str(e.value)) < 300 and "keyframe 13337" in str(e.value), str(e.value)[:500]
    assert e.value.__cause__ is None and e.value.__suppress_context__


def test_a_long_path_is_read_once_not_every_step(monkeypatch):
    from engine.config import load_config
    from engine.control import Control
    from engine.paths import Path, sample_path

    cfg = load_config({"emitters": [{"rate": 1.0, "path": _path(30_000)}]})
    ems, _ = Control.inputs_for(cfg, [])
    assert isinstance(ems[0].path, Path) and len(ems[0].path.times) == 30_000
    # counted, not timed: sampling never reads the keyframes into arrays again
    reads = []
    init = Path.__init__
    monkeypatch.setattr(Path, "__init__", lambda self, keys=(): (reads.append(len(keys)), init(self, keys))[1])
    for k in range(500):
        p = ems[0].position_at(k * 0.05)
    assert reads == []
    assert sample_path([(0.0, (0, 0, 0)), (1.0, (1, 0, 0)), (2.0, (1, 1, 0))], 0.5, (0, 0, 0)).tolist() == [0.5, 0, 0]
    assert reads == [3]  # (the counter counts: a plain list is read into a Path)
    # two keyframes (a pose set from code) are sampled without arrays, to the same bytes
    rng = np.random.default_rng(1)
    for _ in range(2000):
        t0 = float(rng.normal())
        keys = [(t0, tuple(rng.normal(size=3))), (t0 + float(abs(rng.normal())) * (rng.random() > 0.1),
                                                  list(rng.normal(size=3)))]
        t = float(rng.normal())
        assert np.array_equal(sample_path(keys, t, (9, 9, 9)), sample_path(Path(keys), t, (9, 9, 9)))
    assert p.tolist() == pytest.approx([0.0, 1.0, 499 * 0.05 * 1e-3], abs=1e-9)
    short = [(0.0, (0.0, 0.0, 0.0)), (1.0, (2.0, 0.0, 0.0))]
    assert sample_path(short, 0.25, (9, 9, 9)).tolist() == [0.5, 0.0, 0.0]
    assert sample_path(Path(short), 0.25, (9, 9, 9)).tolist() == [0.5, 0.0, 0.0]
    assert sample_path([], 0.25, (9, 9, 9)).tolist() == [9, 9, 9]


# -- deep data ------------------------------------------------------------------------------------
def _deep(n):
    d = x = {}
    for _ in range(n):
        x["a"] = {}
        x = x["a"]
    return d


def test_a_100k_deep_dict_is_one_line_not_a_recursion_error():
    from engine.api import ParticleScene

    deep = _deep(100_000)
    with pytest.raises(ValueError) as e:
        ParticleScene.from_dict(deep, render=False)
    assert _one_line(e).startswith("ParticleScene: config: ") and "32 levels" in str(e.value)
    with pytest.raises(ValueError, match="^ParticleScene: config: .*32 levels"):
        ParticleScene.from_dict({"emitters": [{"rate": 1.0, "path": [deep]}]}, render=False)
    nested_list = x = []
    for _ in range(100_000):
        x.append([])
        x = x[0]
    with pytest.raises(ValueError, match="^ParticleScene: config: .*32 levels"):
        ParticleScene.from_dict({"emitters": nested_list}, render=False)


# -- soft bodies: each type takes its own keys -----------------------------------------------------
# (bodies are a union tagged by ``type``: a key another type reads used to be accepted and ignored)
OWN_KEYS = {  # every key each type takes besides the ones all bodies take, with a value it accepts
    "chain": dict(mass=0.02, stiffness=800.0, direction=[1.0, 0.0, 0.0], length=0.5, segments=5,
                  bend_stiffness=3.0),
    "hair": dict(mass=0.02, stiffness=800.0, direction=[1.0, 0.0, 0.0], length=0.5, segments=5,
                 bend_stiffness=3.0, strands=7, roots="line", radius=0.2, cap_angle=30.0,
                 line_end=[0.5, 1.0, 0.0]),
    "cloth": dict(mass=0.02, stiffness=800.0, resolution=[5, 6], size=[0.5, 0.6], plane="xy",
                  bend_stiffness=3.0),
    "jelly": dict(mass=0.02, stiffness=800.0, resolution=[3, 4, 5], size=[0.3, 0.4, 0.5]),
    "solid": dict(resolution=[3, 4, 5], size=[0.3, 0.4, 0.5], density=500.0,
                  material={"model": "stvk", "young": 2e4, "poisson": 0.25}),
}
COMMON = dict(name="b", position=[0.0, 2.0, 0.0], damping=0.1, pins=[0], release_at=1.0, integrator="xpbd",
              substeps=2, iterations=5, max_stretch=0.1, thickness=0.01, color=[1.0, 0.5, 0.0],
              contacts=True, self_collision=True,
              pin_path=[{"time": 0.0, "position": [0.0, 0.0, 0.0]}, {"time": 1.0, "position": [0.1, 0.0, 0.0]}])


@pytest.mark.parametrize("kind", sorted(OWN_KEYS))
def test_each_body_type_takes_its_own_keys_and_only_those(kind):
    from engine.config import load_config

    # energies: every type takes the key, each only the terms that apply to it (a solid: no springs)
    terms = [{"type": "volume" if kind == "solid" else "spring", "stiffness": 100.0}]
    body = dict(type=kind, **COMMON, **OWN_KEYS[kind], energies=terms)
    b = load_config({"bodies": [body]}).bodies[0]
    assert b.model_dump(include=set(body)) == body  # every key given is kept, none defaulted
    assert set(type(b).model_fields) == {"type", "energies", *COMMON, *OWN_KEYS[kind]}, "a key came or went"


@pytest.mark.parametrize("kind, key, value, owner", [
    ("cloth", "strands", 40, "hair"), ("chain", "resolution", [4, 4], "cloth, jelly or solid"),
    ("jelly", "plane", "xy", "cloth"), ("solid", "mass", 0.1, "chain, hair, cloth or jelly"),
    ("jelly", "material", {"young": 1e4}, "solid"), ("cloth", "density", 10.0, "solid"),
    ("hair", "plane", "xz", "cloth"), ("chain", "strands", 3, "hair"),
])
def test_a_key_of_another_body_type_is_one_line_naming_it(kind, key, value, owner):
    from engine.config import ConfigError, load_config

    body = dict(type=kind, **{k: v for k, v in OWN_KEYS[kind].items() if k in ("resolution", "size")})
    with pytest.raises(ConfigError) as e:
        load_config({"bodies": [dict(body, **{key: value})]})
    assert e.value.problems == [
        f"bodies[0].{key}: unknown key: {key} is a key of a {owner} body, not of a {kind} "
        f"({kind}'s own keys: {', '.join(OWN_KEYS[kind])})"], e.value.problems


def test_body_type_errors_list_the_types_and_keep_the_path_without_the_tag():
    from engine.config import ConfigError, load_config

    types = "'chain', 'hair', 'cloth', 'jelly' or 'solid'"
    cases = [
        ({"bodies": [{"type": "blob"}]}, f"bodies[0].type: 'blob' is not allowed; expected {types}"),
        ({"bodies": [{"strands": 3}]}, f"bodies[0].type: required key is missing; expected {types}"),
        ({"bodies": [{"type": "chain", "strand": 3}]},
         "bodies[0].strand: unknown key; did you mean 'strands'? It is a key of a hair body, not of a chain"),
        ({"bodies": [{"type": "chain", "lenght": 3}]}, "bodies[0].lenght: unknown key; did you mean 'length'?"),
        ({"bodies": [{"type": "cloth", "resolution": [3, 3, 3]}]},
         "bodies[0].resolution: cloth needs 2 numbers, got [3, 3, 3]"),
        ({"bodies": [{"type": "solid", "resolution": [3, 3], "size": [1.0, 1.0, 1.0]}]},
         "bodies[0].resolution: solid needs 3 numbers, got [3, 3]"),
        ({"bodies": [{"type": "jelly", "size": [1.0, 1.0, 1.0]}]}, "bodies[0].resolution: required key is missing"),
        ({"emitters": [{"rate": 1.0}], "colliders": [{"type": "box", "radius": 1.0}]},
         "colliders[0].radius: unknown key: radius is a key of a sphere or capsule collider, not of a box"),
        ({"emitters": [{"rate": 1.0}], "colliders": [{"type": "cone"}]},
         "colliders[0].type: 'cone' is not allowed; expected 'plane', 'sphere', 'box' or 'capsule'"),
    ]
    for data, line in cases:
        with pytest.raises(ConfigError) as e:
            load_config(data)
        assert len(e.value.problems) == 1 and e.value.problems[0].startswith(line), (line, e.value.problems)


# -- interpolate=True ----------------------------------------------------------------------------
@pytest.mark.slow  # (two scene builds: ~10 s cold)
def test_interpolate_changes_no_byte_where_positions_are_equal():
    from engine.api import SceneBuilder

    def make(interp):
        return (SceneBuilder(fps=60, seed=3).render(width=96, height=64)
                .forces(gravity=(0.0, -9.81, 0.0))
                .emitter(name="e", effect="sparks", rate=300.0, position=[0.0, 1.0, 0.0])
                .emitter(name="s", effect="smoke", rate=60.0, position=[0.3, 0.5, 0.0])
                .collider(type="plane", name="ground", restitution=0.4)
                .build(interpolate=interp))

    a, b = make(False), make(True)
    for _ in range(30):
        a.step(1 / 60)
        b.step(1 / 60)
    for kw in ({}, {"transparent": True}, {"bgra": True}):
        want = a.render(**kw)
        assert np.array_equal(b.render(**kw), want), kw  # drawn where they are: no alpha
        assert np.array_equal(b.render(alpha=1.0, **kw), want), kw
    b.scene.save_positions()  # the last step's positions = the current ones: every alpha draws them
    for alpha in (0.0, 0.37, 0.5, 1.0):
        assert np.array_equal(b.render(alpha=alpha), a.render()), alpha
    a.close()
    b.close()


# -- threads --------------------------------------------------------------------------------------------
def _in_thread(fn):
    import threading

    box = {}

    def run():
        try:
            box["value"] = fn()
        except BaseException as e:  # noqa: BLE001 - handed back to the test
            box["error"] = e

    t = threading.Thread(target=run, name="loader")
    t.start()
    t.join(60)
    return box


def test_calls_from_a_second_thread_are_refused_in_one_line_and_change_nothing():
    from engine import runtime
    from engine.api import ParticleScene, SceneBuilder

    s = SceneBuilder(fps=60, seed=2).emitter(name="e", rate=300.0).build(render=False)
    s.step(1 / 60)
    before = (s.time, s.particles()["position"].tobytes(), s.live_count())
    calls = {"step": lambda: s.step(1 / 60), "burst": lambda: s.burst("e", 5),
             "particles": lambda: s.particles(), "ParticleScene": lambda: ParticleScene.from_dict(
                 {"emitters": [{"rate": 5.0}]}, render=False),
             "engine.runtime.init": lambda: runtime.init("cpu"),
             "engine.runtime.reset": lambda: runtime.reset()}
    for where, fn in calls.items():
        box = _in_thread(fn)
        err = box.get("error")
        assert isinstance(err, runtime.WrongThread), (where, box)
        text = str(err)
        assert "\n" not in text and text.startswith(f"{where}: called from thread 'loader'"), text
        assert "MainThread" in text, text
    assert (s.time, s.particles()["position"].tobytes(), s.live_count()) == before
    s.step(1 / 60)  # the owning thread goes on
    s.close()


LOADER_PROBE = """
import sys, threading
sys.path[:0] = ["."]
from engine.api import ParticleScene
box = {}
def load():
    box["scene"] = ParticleScene.from_dict({"emitters": [{"name": "e", "rate": 50.0}]}, render=False)
    box["scene"].step(1 / 60)
t = threading.Thread(target=load, name="loading")
t.start(); t.join()
try:
    box["scene"].step(1 / 60)
except RuntimeError as e:
    print("refused:", e)
"""


@pytest.mark.slow
def test_a_loading_thread_that_built_first_owns_the_engine(tmp_path):
    import subprocess
    import sys

    script = tmp_path / "probe.py"
    script.write_text(LOADER_PROBE)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    r = subprocess.run([sys.executable, str(script)], cwd=root, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.startswith("refused: step: called from thread 'MainThread', but Taichi was initialised on "
                               "thread 'loading'"), r.stdout


# -- after engine.runtime.reset() (keep last: it ends this module's program) -----------------------------
def test_zz_a_scene_used_after_runtime_reset_says_so_in_one_line():
    from engine import runtime
    from engine.api import SceneBuilder

    s = SceneBuilder(fps=60).emitter(name="e", rate=10.0).build(render=False)
    s.step(1 / 60)
    runtime.reset()
    try:
        for call in (lambda: s.step(1 / 60), lambda: s.particles(), lambda: s.render(32, 32),
                     lambda: s.burst("e", 1), lambda: s.time):
            with pytest.raises(RuntimeError) as e:
                call()
            assert "engine.runtime.reset()" in _one_line(e)
        s.close()  # closing a dead scene is harmless
    finally:
        runtime.init("cpu")
