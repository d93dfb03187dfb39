"""Issue 20: careless users. Each case works, or fails in one line naming the method, argument,
flag or config key and the value, and a refused call changes nothing."""
import mmap
import os

import numpy as np
import pytest

from engine import checks


def _one_line(e):
    text = str(e.value)
    assert "\n" not in text and len(text) < 400, text
    return text


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
