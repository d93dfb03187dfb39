"""Scenes built in code: the config's keys as keyword arguments."""
from __future__ import annotations

import copy

from .checks import plain


class SceneBuilder:
    """Build a scene in code: ``SceneBuilder(fps=60).emitter(rate=200, effect="sparks")
    .collider(type="plane").body(type="cloth", ...).build(contacts=True)``. Keys are the config's
    keys and are validated the same way (unknown keys are errors naming the nearest one); values
    may be tuples and NumPy arrays or scalars (stored as lists and Python numbers)."""

    def __init__(self, **scene_keys):
        self.data = plain(scene_keys)

    def _table(self, key, **values):
        self.data[key] = {**self.data.get(key, {}), **plain(values)}
        return self

    def camera(self, **kw):
        return self._table("camera", **kw)

    def solver(self, **kw):
        return self._table("solver", **kw)

    def forces(self, **kw):
        return self._table("forces", **kw)

    def render(self, **kw):
        return self._table("render", **kw)

    def _item(self, key, kw):
        self.data.setdefault(key, []).append(plain(kw))
        return self

    def emitter(self, **kw):
        return self._item("emitters", kw)

    def collider(self, **kw):
        return self._item("colliders", kw)

    def body(self, **kw):
        return self._item("bodies", kw)

    def build(self, **kw):
        """A :class:`~engine.api.ParticleScene` (its keyword arguments: contacts, render,
        interpolate, max_dt)."""
        from .api import ParticleScene

        return ParticleScene(copy.deepcopy(self.data), **kw)
