"""The game API's calls that change what a scene holds between frames (a mixin of
:class:`engine.api.ParticleScene`): add or remove an emitter, a collider or a soft body. An
emitter the built scene can take is written into its spare rows and slots (nothing compiles);
anything else rebuilds the scene around the new config data (a compile), carrying live particles
and attached potentials over. Every argument is checked first: one line naming it and the value,
and a refused call changes nothing."""
from __future__ import annotations

import copy

from . import checks
from .config import ConfigError, load_config


def _load(where: str, data: dict):
    try:
        return load_config(data)
    except ConfigError as e:
        raise ValueError(f"{where}: {'; '.join(e.problems)}") from None


def _shallow(where: str, data) -> None:
    """Refuse data nested deeper than a config can be (before deepcopy or the checks recurse
    into it: a 100,000-deep dict is one line, not a RecursionError)."""
    from .config.load import MAX_DEPTH, check_depth

    try:
        check_depth(data)
    except ConfigError:
        raise ValueError(f"{where}: dicts and lists nested more than {MAX_DEPTH} levels deep are not allowed "
                         f"(a config needs 5)") from None


class SceneEdits:
    """Needs ``self._live(where)``, ``self._install``, ``self._data``, ``self.cfg``, ``self.scene``,
    ``self._potentials``/``self._attach`` (engine.api_potential) and the lookups ``_emitter``,
    ``_collider``, ``_body``."""

    def _rebuild(self, where: str, data: dict) -> None:
        old = self._live(where)
        self._install(data, where, previous=old)
        # potentials carry over (compiled again for the new pool); one whose named emitters are
        # all gone goes with them
        known, kept = {e.name for e in self.cfg.emitters}, []
        for fn, p, chosen, name in self._potentials:
            if chosen is not None:
                chosen = tuple(n for n in chosen if n in known)
                if not chosen:
                    continue
            kept.append((fn, p, chosen, name))
        self._potentials = kept
        if self.scene.particles is not None:
            for spec in kept:
                self._attach(where, self.scene, spec)

    def _with(self, where: str, key: str, item) -> dict:
        """A copy of the scene's config data with ``item`` (a dict of config keys, checked to be
        one and not too deep) appended to the list ``key``."""
        if not isinstance(item, dict):
            raise TypeError(f"{where}: {checks.show(item)} is not a dict of config keys")
        _shallow(f"{where}: {key[:-1] if key != 'bodies' else 'body'}", item)
        data = copy.deepcopy(self._data)
        data.setdefault(key, []).append(checks.plain(copy.deepcopy(item)))
        return data

    def _add(self, where: str, key: str, item) -> None:
        self._rebuild(where, self._with(where, key, item))

    def _remove(self, where: str, key: str, name: str) -> None:
        data = copy.deepcopy(self._data)
        data[key] = [x for x in data.get(key, []) if x.get("name") != name]
        self._rebuild(where, data)

    def add_emitter(self, emitter: dict) -> None:
        """Add an emitter (a dict of config keys) between frames. One whose needs the scene
        already compiled (its blend mode and force terms; no sub-emitters) and that fits the
        spare rows and slots is written into them: nothing compiles. Otherwise the scene is
        rebuilt around it (a compile), carrying live particles over."""
        s = self._live("add_emitter")
        data = self._with("add_emitter", "emitters", emitter)
        cfg = _load("add_emitter", data)
        self.last_add = s.why_not_add(cfg)  # None: added in place
        if self.last_add is None:
            s.add_emitters(cfg)
            self.cfg, self._data = cfg, data
        else:
            self._rebuild("add_emitter", data)

    def remove_emitter(self, name: str) -> None:
        self._live("remove_emitter")
        self._remove("remove_emitter", "emitters", self.cfg.emitters[self._emitter("remove_emitter", name)].name)

    def add_collider(self, collider: dict) -> None:
        self._add("add_collider", "colliders", collider)

    def remove_collider(self, name: str) -> None:
        self._live("remove_collider")
        self._remove("remove_collider", "colliders", self.cfg.colliders[self._collider("remove_collider", name)].name)

    def add_body(self, body: dict) -> None:
        self._add("add_body", "bodies", body)

    def remove_body(self, name: str) -> None:
        self._remove("remove_body", "bodies", self._body("remove_body", name).cfg.name)
