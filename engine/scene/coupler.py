"""The coupler: steps a scene's systems together in coupling steps (engine.system's rules)."""
from __future__ import annotations

from typing import Iterator, List, Sequence, Tuple

from ..ode.driver import substeps
from ..system import Coupling, System


class Coupler:
    """Steps a scene's systems together. ``max_step`` (s): the longest coupling step when some
    system is coupled (None: the frame). Systems advance in ``coupling_order`` (rule 1), ties in the order
    given."""

    def __init__(self, systems: Sequence[System] = (), max_step=None):
        self.systems: List[System] = []
        self.max_step = max_step
        self.coupling = Coupling()
        for s in systems:
            self.add(s)

    def add(self, system: System) -> None:
        self.systems.append(system)
        self.systems.sort(key=lambda s: s.coupling_order)  # stable: ties keep the order they came in

    def remove(self, system: System) -> None:
        self.systems.remove(system)

    @property
    def coupled(self) -> bool:
        return sum(1 for s in self.systems if s.coupled) > 0 and len(self.systems) > 1

    def steps(self, t0: float, t1: float) -> Iterator[Tuple[float, float]]:
        """The coupling steps of [t0, t1]: the whole span when nothing is coupled (rule 4), else
        equal steps of at most ``max_step`` landing exactly on t1."""
        if not self.coupled or not self.max_step or t1 - t0 <= self.max_step:
            yield t0, t1
            return
        n = substeps(t1 - t0, self.max_step)
        h = (t1 - t0) / n
        for j in range(n):
            yield t0 + j * h, (t1 if j == n - 1 else t0 + (j + 1) * h)

    def advance(self, t0: float, t1: float) -> None:
        c = self.coupling
        for a, b in self.steps(t0, t1):
            c.t0, c.t1 = a, b
            c.board.clear()
            c.board.update(c.later)  # what the previous coupling step published for this one
            c.later.clear()
            for s in self.systems:
                s.receive(c)
                s.advance(a, b)
                s.publish(c)

    def clear(self) -> None:
        """Forget what the board holds for the next coupling step (a reset scene starts clean)."""
        self.coupling = Coupling()

    def reset(self) -> None:
        self.clear()
        for s in self.systems:
            s.reset()
