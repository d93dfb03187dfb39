"""The fixed-timestep clock a game loop drives a scene with."""
from __future__ import annotations

from .checks import integer, number

MIN_DT = 1e-6  # s: a shorter step is a typo (and below the accumulator's rounding tolerance)


class FixedTimestep:
    """Fixed-timestep accumulator ("Fix Your Timestep!", Fiedler 2004): the game hands in real
    frame times of any length, the simulation always advances in steps of ``dt``. ``alpha`` is the
    fraction of a step left over: ``scene.render(alpha=clock.alpha)`` draws between the last two
    steps (a scene built with ``interpolate=True``)."""

    def __init__(self, dt: float = 1 / 120, max_steps: int = 16):
        self.dt = number("FixedTimestep: dt", dt, MIN_DT, 1.0)
        self.max_steps = integer("FixedTimestep: max_steps", max_steps, 1, 100_000)
        self.accumulator = 0.0
        self.alpha = 0.0

    def advance(self, scene, frame_time: float) -> int:
        """Run as many whole steps as the accumulated time allows (at most ``max_steps``, so a
        stall does not spiral); returns how many ran. A step that raises drops the accumulated
        time (the error propagates): the next call does not run a burst of catch-up steps."""
        self.accumulator += number("FixedTimestep.advance: frame_time", frame_time, 0.0)
        n = 0
        # a tolerance of 1e-9 s keeps 1/144 + ... sums that land on a step from losing one to rounding
        while self.accumulator >= self.dt - 1e-9 and n < self.max_steps:
            try:
                scene.step(self.dt)
            except BaseException:
                # the time this call was handed is given up: the next call starts from its own
                # frame time, not a backlog that would run max_steps steps at once
                self.accumulator, self.alpha = 0.0, 0.0
                raise
            self.accumulator -= self.dt
            n += 1
        if n == self.max_steps:
            self.accumulator = min(self.accumulator, self.dt)
        self.accumulator = max(self.accumulator, 0.0)
        self.alpha = min(1.0, self.accumulator / self.dt)
        return n
