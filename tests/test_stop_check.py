"""The stop check (a signal's flag) is polled between steps, so a frame of many steps stops
mid-way instead of running to its end: once per attempted step, or per run of fixed steps fused
into one launch (at most engine.particles.system.MAX_RUN of them)."""
import pytest

from engine import runtime
from engine.config import load_config
from engine.particles.system import MAX_RUN
from engine.scene import Scene
from helpers import scene_dict


def stop_after(n, scene):
    polls = []

    def check():
        polls.append(1)
        return len(polls) > n

    runtime.set_stop_check(check)
    try:
        with pytest.raises(runtime.Interrupted):
            scene.advance_frame()  # 1/30 s at h = 1e-4: hundreds of steps without the check
    finally:
        runtime.set_stop_check(None)
    return len(polls)


@pytest.mark.parametrize("adaptive", [False, True])
def test_a_long_frame_stops_between_steps(adaptive):
    # births in every step (1e5/s at h = 1e-4): nothing to fuse, one poll per step
    cfg = load_config(scene_dict(solver__h=1e-4, solver__adaptive=adaptive, solver__tolerance=1e-6,
                                 forces__gravity=[0.0, -9.81, 0.0], forces__drag=2.0,
                                 emitters=[{"rate": 1e5, "lifetime": 0.05, "speed": [1.0, 1.0]}]))
    scene = Scene(cfg, render=False)
    assert stop_after(10, scene) == 11
    assert scene.stats.steps + scene.stats.rejected == 10


def test_fused_fixed_steps_stop_between_runs():
    # one burst, then nothing due: runs of MAX_RUN steps per launch, one poll per run
    cfg = load_config(scene_dict(solver__h=1e-4, forces__gravity=[0.0, -9.81, 0.0],
                                 emitters=[{"rate": 0.0, "lifetime": 10.0, "bursts": [{"count": 100}]}]))
    scene = Scene(cfg, render=False)
    assert stop_after(3, scene) == 4
    assert scene.stats.steps == 3 * MAX_RUN < 334  # the frame has 334 steps
