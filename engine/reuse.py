"""Built scenes kept for reuse: a level restart or a second copy of an effect costs no compile.

Taichi specialises a kernel for the fields it is given (``ti.template()``), so a scene built anew
compiles every kernel again even when an identical scene was built before (2–7 s on 2 cores with
the offline cache warm), and the compiled code and fields of a discarded scene stay allocated:
freeing a field means destroying its SNode tree, and ``SNodeTree.destroy()`` drops every compiled
kernel of the process (taichi/_snode/snode_tree.py: ``clear_compiled_functions``), so every other
live scene would compile again. A discarded scene is therefore kept here, by the key of its
config and build options, and the next scene with that key takes it and resets it
(:meth:`engine.scene.Scene.reset`): the same fields, the same compiled kernels, the same render
targets. Memory stays flat over any number of restarts of one level.

Several copies at once need several scenes: :func:`prepare` builds (and warms up) spares on a
loading screen. ``engine.runtime.reset()`` forgets them all (their fields die with the program).
"""
from __future__ import annotations

import json

from . import runtime

_idle: dict = {}  # key -> [Scene, ...]
counts = {"built": 0, "reused": 0}
_program = [0]  # which Taichi program the scenes belong to (engine.runtime.reset starts another)


def program() -> int:
    """The current program's number: a scene built under another is dead."""
    return _program[0]


def key_for(cfg, **options) -> str:
    """What decides a scene's fields and kernels: the whole validated config and the options."""
    return json.dumps([cfg.model_dump(mode="json"), sorted(options.items())], sort_keys=True)


def take(key: str):
    """An idle scene with this key (not yet reset), or None."""
    scenes = _idle.get(key)
    if scenes:
        counts["reused"] += 1
        return scenes.pop()
    return None


def give_back(key: str, scene, built_in: int) -> None:
    """Keep ``scene`` (built under program ``built_in``) for the next scene of its key; one of an
    earlier program is dropped (its fields died with it)."""
    if built_in == _program[0]:
        _idle.setdefault(key, []).append(scene)


def idle(key: str | None = None) -> int:
    """Idle scenes kept (with ``key``, or in all)."""
    return len(_idle.get(key, ())) if key is not None else sum(len(v) for v in _idle.values())


def forget() -> None:
    _idle.clear()
    _program[0] += 1


runtime.on_reset(forget)
