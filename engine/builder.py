"""Scene configs built in code: the config's keys as keyword arguments (the game API's
:class:`~engine.api.SceneBuilder` adds ``build()``; this module knows no scene, so the two do not
import each other)."""
from __future__ import annotations

from .checks import plain


class ConfigBuilder:
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
