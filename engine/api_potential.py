"""The game API's external potentials on particles (a mixin of :class:`engine.api.ParticleScene`):
a user's U(x, p), its forces −∇U by Taichi autodiff (engine.particles.potential), kept across the
scene's rebuilds, and the energy read back. Arguments are checked first (one line naming the
argument and the value; a refused call, a potential Taichi cannot compile included, changes
nothing)."""
from __future__ import annotations

from typing import TYPE_CHECKING

from . import checks

if TYPE_CHECKING:  # pragma: no cover
    from .scene import Scene


class PotentialAPI:
    """Potentials from code. Needs ``self._live(where)``, ``self.cfg`` and ``self._potentials``
    (the specs kept for rebuilds)."""

    def add_potential(self, potential, params=None, emitters=None, name: str = "potential") -> None:
        """Let an external potential U(x, p) act on particles: ``potential`` a ``@ti.func`` of x
        (a 3-vector, m) and p (the vector of ``params``: a 1-D sequence of 1 to 16 finite floats,
        default [0.0]) returning U in J/kg, so a particle accelerates by a = −∇U(x) (a well, a
        terrain); ``emitters``: the names of the emitters whose particles it acts on (a name or a
        list; None: all, those added later included); ``name`` labels it in :meth:`potential_energy`.

        Forces by Taichi autodiff, deterministic (engine.particles.potential): one gradient per
        half kick, v −= (h/2)∇U before and after each particle step (Strang splitting: second
        order, symplectic with the symplectic inner methods; with rk4 or step doubling the
        potential's part stays second order, and an adaptive step is capped at ``solver.h``).
        Costs two gradient evaluations (three launches each) a step, and fixed steps are no longer
        fused into runs. Its kernels compile here; a potential Taichi cannot compile is refused
        (ValueError), as is a gradient that turns non-finite at a particle (the step raises
        SimulationDiverged naming it). Kept across rebuilds (add_emitter, add_collider…; each
        compiles it again) until the scene is closed."""
        where = "add_potential"
        s = self._live(where)
        from .particles.potential import check_function, check_params

        check_function(where, potential)
        p = check_params(where, params)
        known = [e.name for e in self.cfg.emitters]
        if emitters is None:
            chosen = None
        else:
            items = [emitters] if isinstance(emitters, str) else emitters
            if not isinstance(items, (list, tuple)) or not items:
                raise ValueError(f"{where}: emitters: {checks.show(emitters)} is not an emitter name or a "
                                 f"non-empty list of them")
            chosen = tuple(dict.fromkeys(checks.name(f"{where}: emitters", e, known, "emitter") for e in items))
        taken = [q[3] for q in self._potentials]
        if not isinstance(name, str) or not name or name in taken:
            raise ValueError(f"{where}: name: {checks.show(name)} is not allowed: a non-empty str no other "
                             f"potential has (taken: {', '.join(map(repr, taken)) or 'none'})")
        if s.particles is None or not s.particles.layout.capacity:
            raise ValueError(f"{where}: the scene has no particles (no emitters) to act on")
        spec = (potential, p, chosen, name)
        self._attach(where, s, spec)
        self._potentials.append(spec)

    def _attach(self, where: str, s: Scene, spec) -> None:
        """Compile potential ``spec`` (function, params, emitter names or None, name) into scene
        ``s``'s particles; a compile error is one ValueError line and nothing is added."""
        import taichi as ti

        potential, p, chosen, name = spec
        names = [e.name for e in self.cfg.emitters]
        rows = None if chosen is None else [names.index(n) for n in chosen]
        try:
            s.particles.add_potential(potential, p, rows, name)
        except (ti.TaichiCompilationError, RuntimeError) as e:  # (type errors: RuntimeError from C++)
            first = next((ln.strip() for ln in str(e).splitlines() if ln.strip()), type(e).__name__)
            raise ValueError(f"{where}: potential: Taichi could not compile "
                             f"{getattr(potential, '__name__', 'it')}(x, p) -> scalar: {first}") from None

    def potential_energy(self) -> dict:
        """{name: Σ U(x_i)} over the born particles each potential acts on (J/kg: particles have
        unit mass); {} without potentials. One kernel pair and a read-back per potential."""
        s = self._live("potential_energy")
        return s.particles.energy() if s.particles is not None else {}
