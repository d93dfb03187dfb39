"""The budget's memory estimate against the Taichi fields and ndarrays a real scene allocates once
it has drawn a frame: the estimate is read off the definitions by hand (particles_tools/budget.py), so
a pool, renderer or spring network that grows must fail here rather than let the budget go stale."""
import math

import pytest
import taichi as ti

from engine.config import load_config
from engine.scene import Scene
from particles_tools import budget

_BYTES = {ti.f32: 4, ti.i32: 4, ti.u32: 4, ti.u8: 1, ti.i8: 1, ti.f64: 8, ti.i64: 8, ti.u64: 8,
          ti.f16: 2, ti.i16: 2, ti.u16: 2}


def field_bytes(root) -> int:
    """Bytes of every distinct Taichi field and ndarray reachable from ``root`` through
    attributes, lists, tuples and dicts."""
    from taichi.lang._ndarray import Ndarray
    from taichi.lang.field import Field

    seen, total, todo = set(), 0, [root]
    while todo:
        obj = todo.pop()
        if id(obj) in seen or obj is None or isinstance(obj, (str, bytes, int, float, type)):
            continue
        seen.add(id(obj))
        if isinstance(obj, Field):
            cells = math.prod(obj.shape) if obj.shape else 1
            width = getattr(obj, "n", 1) * (getattr(obj, "m", 1) or 1)
            total += cells * width * _BYTES[obj.dtype]
        elif isinstance(obj, Ndarray):
            total += obj.to_numpy().nbytes
        elif isinstance(obj, dict):
            todo += list(obj.values())
        elif isinstance(obj, (list, tuple, set)):
            todo += list(obj)
        elif hasattr(obj, "__dict__") and type(obj).__module__.startswith("engine"):
            todo += list(vars(obj).values())
    return total


@pytest.mark.slow
@pytest.mark.parametrize("case", ["particles", "cloth"])
def test_memory_estimate_matches_the_fields_a_scene_allocates(case):
    if case == "particles":  # ~60k slots, sub-emitter events and adaptive candidates allocated
        cfg = load_config({
            "fps": 30, "frames": 1, "render": {"width": 320, "height": 180},
            "solver": {"integrator": "rk4", "adaptive": True},
            "emitters": [{"name": "a", "rate": 20000.0, "lifetime": 2.0,
                          "sub_emitters": [{"emitter": "b", "event": "death"}]},
                         {"name": "b", "rate": 0.0, "lifetime": 0.5}]})
    else:
        cfg = load_config({"fps": 30, "frames": 1, "render": {"width": 320, "height": 180},
                           "bodies": [{"type": "cloth", "resolution": [64, 64],
                                       "integrator": "rk4", "damping": 0.01}]})
    scene = Scene(cfg)
    scene.render()  # the image-sized arrays are allocated at the first frame of a size
    actual = field_bytes(scene)
    est = budget.estimate(cfg, 320, 180, frames_in_flight=0)
    assert est.parts["frames in flight"] == 0
    # the estimate may round up (spring counts are bounds) but not miss a large share
    assert 0.85 * actual <= est.memory <= 1.6 * actual, (actual, est.parts)


def test_parse_bytes():
    assert budget.parse_bytes("4GB") == 4 << 30
    assert budget.parse_bytes("1.5m") == 3 << 19
    assert budget.parse_bytes("123") == 123
    for bad in ("", "GB", "-1GB", "4XB", "0", "1e3"):
        with pytest.raises(ValueError):
            budget.parse_bytes(bad)
