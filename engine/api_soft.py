"""The game API's soft-body calls (a mixin of :class:`engine.api.ParticleScene`): pin a node, drag
it, let it go, attach a user energy, read the nodes and the energies back. Every argument is
checked first (:mod:`engine.checks`: one line naming the argument and the value; a refused call
changes nothing), then the scene's Control is written or the body read."""
from __future__ import annotations

import numpy as np

from . import checks
from .checks import integer, vector


class SoftBodyAPI:
    """Soft bodies from code. Needs ``self._live(where)`` and ``self.scene``."""

    def _body(self, where: str, name):
        bodies = self._live(where).bodies
        names = [b.cfg.name for b in bodies]
        return bodies[names.index(checks.name(f"{where}: body", name, names, "body"))]

    def _node(self, where: str, body, node) -> int:
        return integer(f"{where}: node", node, 0, body.node_count - 1)

    def pin(self, body: str, node: int, target=None) -> None:
        """Hold a node of a soft body at ``target`` (default: where it is), from the next step."""
        b = self._body("pin", body)
        n = self._node("pin", b, node)
        t = None if target is None else vector("pin: target", target)
        self.scene.control.pin(b.index, n, t)

    def move_pin(self, body: str, node: int, target) -> None:
        """Drag a pinned node to ``target`` over the next step (a hand holding the cloth)."""
        b = self._body("move_pin", body)
        n, t = self._node("move_pin", b, node), vector("move_pin: target", target)
        self.scene.control.move_pin(b.index, n, t)

    def release(self, body: str, node: int) -> None:
        b = self._body("release", body)
        self.scene.control.release(b.index, self._node("release", b, node))

    def add_energy(self, body: str, energy, nodes, params=None, name: str = "user") -> None:
        """Attach a user energy to soft body ``body``: ``energy`` a ``@ti.func`` (x, p) → ψ (J) of
        an element's k nodes (x: 3 × k matrix of positions, m; p: its row of ``params``),
        ``nodes`` (E, k) node indices. Forces are −∇ψ by Taichi autodiff, deterministic
        (engine.forces.user); the energy is reported under ``name`` by :meth:`energy`. A k = 1
        energy over every node is an external potential U(x) (a well, a terrain). Kept until the
        scene is rebuilt (add_body, remove_body…)."""
        self._body("add_energy", body).add_energy(energy, nodes, params, name)

    def body_positions(self, name: str) -> np.ndarray:
        """(N, 3) float32 node positions of body ``name`` (m)."""
        return self._body("body_positions", name).positions()

    def energy(self) -> dict:
        """Per soft body: kinetic, gravitational and every energy term by name (spring, bending,
        area, volume, the solid's material, user energies) and their total (J). Particles'
        external potentials report in :meth:`potential_energy`."""
        return {b.cfg.name or f"body{k}": b.energy() for k, b in enumerate(self._live("energy").bodies)}
