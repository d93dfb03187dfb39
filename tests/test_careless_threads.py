"""Careless users (issue 20) of the engine across threads and after a reset: refused in one line,
changing nothing."""
import os

import pytest

from helpers import one_line as _one_line


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
