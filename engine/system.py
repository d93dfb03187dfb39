"""The System protocol: how several kinds of physics share one scene (the coupler that steps
them together is :mod:`engine.scene.coupler`).

Every kind of physics in a scene — the particle pool, each soft body, the rigid bodies — is a
*system*. The scene knows systems only through this protocol, so a new kind joins a scene without
editing it (Newton's ``SolverCoupled`` entries and Genesis's per-kind solvers split the work the
same way; see ``../shared/ARCHITECTURE.md``). The contract, in numbered rules (scipy's
``OdeSolver`` writes its own so):

1. ``name`` (str) names the system in messages and statistics; ``kind`` is one of
   :data:`KINDS`; ``coupling_order`` (int) places it in a coupling step: lower first (``order``
   stays the Driver's: its method's order). What others read
   (kinematic shapes, rigid bodies) advances before what reads it (particles, soft bodies).
2. ``advance(t0, t1)`` steps the system from t0 to exactly t1 (t1 > t0, seconds) with its own
   Driver — fixed, adaptive or XPBD substeps inside — and lands on t1. It raises
   :class:`~engine.ode.driver.SimulationDiverged` (one line naming the system, method, h and t) on
   a non-finite state. It reads no other system's fields.
3. ``receive(coupling)`` runs before ``advance`` and ``publish(coupling)`` after it, once per
   coupling step: the :class:`Coupling` board carries what one system gives the others (shape
   poses over the step, impulses summed in a fixed order, pin targets). What a later system
   gives an earlier one (particles pushing the rigid bodies, which advanced first) is published
   with ``put_later`` and read in the next coupling step: a one-step lag. A system that neither
   gives nor takes leaves both as the defaults of :class:`SystemBase`.
4. ``coupled`` (bool): whether it needs coupling steps shorter than a frame (two systems that
   exchange data inside a frame). With nothing coupled the coupling step is the frame, so a scene
   of independent systems steps exactly as each would alone: the same bytes.
5. ``reset()`` puts it back as built (t = 0, the config's inputs), keeping fields and kernels.
6. ``drawables()`` → dict for the renderer (what to draw: arrays, callables, a field it may
   read; never the system itself).
7. ``contacts(names)`` drains its contact records (:class:`~engine.contacts.Contacts`);
   ``energy()`` → dict of named terms (J, plus ``t``); ``stats`` holds its own step counts
   (:class:`~engine.ode.driver.DriverStats`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Protocol, Tuple, runtime_checkable

KINDS = ("kinematic", "rigid", "particles", "soft_body")
ORDER = {k: i for i, k in enumerate(KINDS)}  # rule 1: what others read goes first


@runtime_checkable
class System(Protocol):
    name: str
    kind: str
    coupling_order: int
    coupled: bool

    def advance(self, t0: float, t1: float) -> None: ...

    def receive(self, coupling: "Coupling") -> None: ...

    def publish(self, coupling: "Coupling") -> None: ...

    def reset(self) -> None: ...

    def drawables(self) -> dict: ...

    def energy(self) -> dict: ...


class SystemBase:
    """Defaults for the optional parts of :class:`System`: nothing given or taken, uncoupled,
    no energy terms."""

    kind = "particles"
    coupled = False

    @property
    def coupling_order(self) -> int:
        return ORDER[self.kind]

    def receive(self, coupling: "Coupling") -> None:
        pass

    def publish(self, coupling: "Coupling") -> None:
        pass

    def drawables(self) -> dict:
        return {}

    def energy(self) -> dict:
        return {}


@dataclass
class Coupling:
    """The board systems exchange data on inside a coupling step [t0, t1]. ``board`` maps a
    (publisher name, key) pair to what it published; a reader takes what it knows by key.
    Impulses are never summed by float atomics: each contributor keeps its own record (one
    writer) and the records are reduced in a fixed order — particles' pushes on rigid bodies per
    pool slot, summed on the host in slot order in float64 (engine.particles.push) — so the sum
    does not depend on thread timing. ``later``: what :meth:`put_later` published for the next
    coupling step (the coupler moves it onto ``board`` then)."""

    t0: float = 0.0
    t1: float = 0.0
    board: Dict[Tuple[str, str], object] = field(default_factory=dict)
    # published for the next coupling step: what a later system gives an earlier one (particles'
    # pushes on rigid bodies, which advanced first); the coupler moves it onto the board then
    later: Dict[Tuple[str, str], object] = field(default_factory=dict)

    def put(self, publisher: str, key: str, value) -> None:
        self.board[(publisher, key)] = value

    def put_later(self, publisher: str, key: str, value) -> None:
        """Publish ``value`` for the next coupling step (a one-step lag: the readers of rule 1
        that go first have already advanced through this one)."""
        self.later[(publisher, key)] = value

    def get(self, key: str) -> List[Tuple[str, object]]:
        """Every (publisher, value) published under ``key``, in publishing order."""
        return [(p, v) for (p, k), v in self.board.items() if k == key]
