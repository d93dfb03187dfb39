"""The stop check (a signal's flag) is polled between steps, so a frame of many steps stops
mid-way instead of running to its end."""
import pytest

from engine import runtime
from engine.config import load_config
from engine.scene import Scene
from helpers import scene_dict


@pytest.mark.parametrize("adaptive", [False, True])
def test_a_long_frame_stops_between_steps(adaptive):
    cfg = load_config(scene_dict(solver__h=1e-4, solver__adaptive=adaptive, solver__tolerance=1e-6,
                                 forces__gravity=[0.0, -9.81, 0.0], forces__drag=2.0))
    scene = Scene(cfg, render=False)
    polls = []

    def stop_after_ten():
        polls.append(1)
        return len(polls) > 10

    runtime.set_stop_check(stop_after_ten)
    try:
        with pytest.raises(runtime.Interrupted):
            scene.advance_frame()  # 1/30 s at h = 1e-4: hundreds of steps without the check
    finally:
        runtime.set_stop_check(None)
    assert len(polls) == 11 and scene.stats.steps <= 10
