"""The fixed-timestep clock a game loop drives a scene with."""
from __future__ import annotations

from .checks import integer, number


class FixedTimestep:
    """Fixed-timestep accumulator ("Fix Your Timestep!", Fiedler 2004): the game hands in real
    frame times of any length, the simulation always advances in steps of ``dt``. ``alpha`` is the
    fraction of a step left over: ``scene.render(alpha=clock.alpha)`` draws between the last two
    steps (a scene built with ``interpolate=True``)."""

    def __init__(self, dt: float = 1 / 120, max_steps: int = 16):
        self.dt = number("FixedTimestep: dt", dt, 0.0, 1.0, lo_open=True)
        self.max_steps = integer("FixedTimestep: max_steps", max_steps, 1, 100_000)
        self.accumulator = 0.0
        self.alpha = 0.0

    def advance(self, scene, frame_time: float) -> int:
        """Run as many whole steps as the accumulated time allows (at most ``max_steps``, so a
        stall does not spiral); returns how many ran."""
        self.accumulator += number("FixedTimestep.advance: frame_time", frame_time, 0.0)
        n = 0
        # a tolerance of 1e-9 s keeps 1/144 + ... sums that land on a step from losing one to rounding
        while self.accumulator >= self.dt - 1e-9 and n < self.max_steps:
            scene.step(self.dt)
            self.accumulator -= self.dt
            n += 1
        if n == self.max_steps:
            self.accumulator = min(self.accumulator, self.dt)
        self.accumulator = max(self.accumulator, 0.0)
        self.alpha = min(1.0, self.accumulator / self.dt)
        return n
