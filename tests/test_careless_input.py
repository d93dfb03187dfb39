"""Careless users (issue 20) of the scene's inputs: names, the timestep and step(), huge numbers,
long keyframe paths, deep data, soft bodies' keys. Each case works, or fails in one line naming the
method, argument, flag or config key and the value, and a refused call changes nothing."""

import numpy as np
import pytest

from helpers import one_line as _one_line

from engine import checks


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
