"""The engine from a game loop: build, step, steer, read back, listen for contacts, render.

    from engine.api import ParticleScene, FixedTimestep

    scene = ParticleScene.from_file("configs/campfire.toml", contacts=True)
    clock = FixedTimestep(1 / 120)
    while running:
        clock.advance(scene, frame_seconds)          # same simulation at 30 Hz or 144 Hz
        scene.move_collider("log", player_position)  # velocity inferred: it pushes particles
        for hit in scene.contacts(min_speed=2.0).rows(): play_sound(hit)
        image = scene.render(320, 180)               # (H, W, 4) uint8 RGBA to blit

Everything here writes the scene's :class:`~engine.control.Control` (this frame's inputs) or reads
back; fields and kernels were built by :class:`~engine.scene.Scene`. Adding or removing emitters,
colliders or bodies rebuilds the scene between frames (kernels are compiled for a fixed set of
features) and carries live particles, emitter clocks, inputs and soft bodies over by name.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from .config import load_config
from .render.camera import Camera
from .scene import Scene


@dataclass
class Contacts:
    """Particle–collider contacts of the last ``step`` (sorted by time, then pool slot).

    ``collider`` (K,) int index into the scene's colliders, ``position`` (K, 3) m, ``normal``
    (K, 3) unit, ``speed`` (K,) impact speed along the normal m/s, ``time`` (K,) s."""

    collider: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    speed: np.ndarray
    time: np.ndarray
    dropped: int = 0  # contacts beyond the buffer

    def __len__(self):
        return len(self.speed)

    def rows(self):
        for k in range(len(self)):
            yield dict(collider=int(self.collider[k]), position=self.position[k],
                       normal=self.normal[k], speed=float(self.speed[k]), time=float(self.time[k]))


class FixedTimestep:
    """Fixed-timestep accumulator ("Fix Your Timestep!", Fiedler 2004): the game hands in real
    frame times of any length, the simulation always advances in steps of ``dt``. ``alpha`` is the
    fraction of a step left over, for interpolating what is drawn."""

    def __init__(self, dt: float = 1 / 120, max_steps: int = 16):
        if not dt > 0:
            raise ValueError(f"dt: must be positive, got {dt}")
        self.dt, self.max_steps = float(dt), int(max_steps)
        self.accumulator = 0.0
        self.alpha = 0.0

    def advance(self, scene, frame_time: float) -> int:
        """Run as many whole steps as the accumulated time allows (at most ``max_steps``, so a
        stall does not spiral); returns how many ran."""
        self.accumulator += max(0.0, float(frame_time))
        n = 0
        # a tolerance of 1e-9 s keeps 1/144 + ... sums that land on a step from losing one to rounding
        while self.accumulator >= self.dt - 1e-9 and n < self.max_steps:
            scene.step(self.dt)
            self.accumulator -= self.dt
            n += 1
        if n == self.max_steps:
            self.accumulator = min(self.accumulator, self.dt)
        self.accumulator = max(self.accumulator, 0.0)
        self.alpha = self.accumulator / self.dt
        return n


class ParticleScene:
    """A scene driven from Python. Build with :meth:`from_file`, :meth:`from_dict` or
    :class:`SceneBuilder`. Several can live in one process; ``engine.runtime.init`` is called
    once for all of them (or skipped when the host initialised Taichi itself)."""

    def __init__(self, config, contacts: bool | int = False, render: bool = True):
        self._data = copy.deepcopy(config) if isinstance(config, dict) else None
        self.cfg = load_config(config) if not hasattr(config, "model_dump") else config
        self._contacts = (65536 if contacts is True else int(contacts or 0))
        self._render = render
        self.scene = Scene(self.cfg, render=render, contacts=self._contacts)
        self._last_contacts = None

    @classmethod
    def from_file(cls, path, **kw) -> "ParticleScene":
        from .config import read_toml

        data = read_toml(path)
        data.setdefault("name", str(path).rsplit("/", 1)[-1].removesuffix(".toml"))
        return cls(data, **kw)

    @classmethod
    def from_dict(cls, data: dict, **kw) -> "ParticleScene":
        return cls(data, **kw)

    # -- time -------------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return self.scene.t

    def step(self, dt: float) -> None:
        """Advance by dt seconds (any length), sub-stepping with the configured integrator."""
        if not dt > 0:
            raise ValueError(f"dt: must be positive, got {dt}")
        self.scene.advance(dt)
        self._last_contacts = None

    def live_count(self) -> int:
        """Live particles now (one read-back per step, only when asked)."""
        return self.scene.live_count()

    # -- control ----------------------------------------------------------------------------------
    def _emitter(self, name) -> int:
        names = [e.name for e in self.cfg.emitters]
        if name not in names:
            raise KeyError(f"emitter: no emitter named {name!r} (names: {names})")
        return names.index(name)

    def move_emitter(self, name: str, position, over: float | None = None) -> None:
        """Move emitter ``name`` to ``position`` by the end of the next step of length ``over``
        (default: one frame at the config's fps); its velocity is inferred from the motion."""
        e = self._emitter(name)
        self.scene.control.move_emitter(e, self.time, self.time + (over or self.scene.frame_dt), position)

    def set_rate(self, name: str, rate: float) -> None:
        """Particles per second (the pool keeps its size: beyond it particles are counted dropped)."""
        if not rate >= 0:
            raise ValueError(f"rate: must be >= 0, got {rate}")
        self.scene.control.set_rate(self._emitter(name), rate)

    def set_emitting(self, name: str, on: bool) -> None:
        """Start or stop an emitter's continuous emission (bursts from code still work)."""
        self.scene.control.set_emitting(self._emitter(name), on)

    def burst(self, name: str, count: int, position=None) -> None:
        """Emit ``count`` particles from ``name`` at the start of the next step; with ``position``
        the emitter is first placed there (a jump, not a motion: nothing is inherited)."""
        e, ctl = self._emitter(name), self.scene.control
        if position is not None:
            ctl.place_emitter(e, self.time, position)
        ctl.burst(e, count)

    def move_collider(self, name: str, position, over: float | None = None) -> None:
        """Move collider ``name`` (a plane's point or a sphere's centre) to ``position`` by the end
        of the next step; its velocity is inferred, so it pushes particles and soft bodies."""
        k = self.scene.colliders.index(name)
        self.scene.control.move_collider(k, self.time, self.time + (over or self.scene.frame_dt), position)

    def set_wind(self, wind) -> None:
        """Air velocity (m/s) seen by drag."""
        self.scene.control.set_wind(wind)

    def set_gravity(self, g) -> None:
        """Gravity (m/s²) for particles and soft bodies."""
        self.scene.control.set_gravity(g)

    def _body(self, name):
        for b in self.scene.bodies:
            if b.cfg.name == name:
                return b
        raise KeyError(f"body: no body named {name!r} (names: {[b.cfg.name for b in self.scene.bodies]})")

    def pin(self, body: str, node: int, target=None) -> None:
        """Hold a node of a soft body at ``target`` (default: where it is), from the next step."""
        self.scene.control.pin(self._body(body).index, node, target)

    def move_pin(self, body: str, node: int, target) -> None:
        """Drag a pinned node to ``target`` over the next step (a hand holding the cloth)."""
        self.scene.control.move_pin(self._body(body).index, node, target)

    def release(self, body: str, node: int) -> None:
        self.scene.control.release(self._body(body).index, node)

    # -- read-back --------------------------------------------------------------------------------
    def particles(self) -> dict:
        """Live particles as NumPy arrays (copies; Taichi fields are not shared memory on every
        backend): ``position`` (N, 3), ``velocity`` (N, 3), ``age`` (N,), ``life`` (N,),
        ``emitter`` (N,) index, ``color`` (N, 3) linear RGB from the emitter's ramp."""
        out = self.scene.live_particles()
        out["color"] = self._colors(out["emitter"], np.clip(out["age"] / out["life"], 0, 1))
        return out

    def _colors(self, emitter, t):
        col = np.zeros((len(t), 3), np.float32)
        for e, em in enumerate(self.cfg.emitters):
            sel = emitter == e
            if sel.any():
                stops = np.asarray(em.color, np.float64)
                for c in range(3):
                    col[sel, c] = np.interp(t[sel], stops[:, 0], stops[:, 1 + c])
        return col

    def body_positions(self, name: str) -> np.ndarray:
        return self._body(name).positions()

    def energy(self) -> dict:
        """Per soft body: kinetic, gravitational and spring energy (J)."""
        return {b.cfg.name or f"body{k}": b.system.energy() for k, b in enumerate(self.scene.bodies)}

    def contacts(self, min_speed: float = 0.0) -> Contacts:
        """Contacts of the last ``step`` with impact speed >= ``min_speed`` (needs contacts=True)."""
        if not self._contacts:
            raise RuntimeError("contacts: build the scene with contacts=True to record them")
        if self._last_contacts is None:
            p = self.scene.particles
            if p is None:
                empty = np.zeros(0)
                self._last_contacts = Contacts(empty.astype(np.int32), np.zeros((0, 3)), np.zeros((0, 3)),
                                               empty, empty)
            else:
                (collider, pos, normal, speed, time, _slot), dropped = p.contacts()
                self._last_contacts = Contacts(collider, pos, normal, speed, time, dropped=dropped)
        c = self._last_contacts
        m = c.speed >= min_speed
        return Contacts(c.collider[m], c.position[m], c.normal[m], c.speed[m], c.time[m], c.dropped)

    def render(self, width: int | None = None, height: int | None = None, camera: Camera | None = None,
               show_colliders: bool | None = None, *, out: np.ndarray | None = None,
               transparent: bool = False, bgra: bool = False) -> np.ndarray:
        """(H, W, 4) uint8 RGBA image of the current state, any size, any camera (a new size or
        camera compiles nothing). ``out``: a C-contiguous (H, W, 4) uint8 array to draw into
        (no allocation per frame). Opaque, unless ``transparent``: premultiplied RGBA with alpha 0
        where nothing is drawn, to composite over the game's own frame with the blend
        (ONE, ONE_MINUS_SRC_ALPHA) — additive light carries alpha 0, so it adds. ``bgra``: bytes
        in B, G, R, A order, as SDL/pygame and X11 surfaces take them."""
        return self.scene.render(width, height, camera, show_colliders, out=out, transparent=transparent,
                                 bgra=bgra)

    # -- changing what the scene holds (rebuilds between frames) -----------------------------------
    def _data_now(self) -> dict:
        return self._data if self._data is not None else self.cfg.model_dump(exclude_none=True)

    def _rebuild(self, data: dict) -> None:
        new_cfg = load_config(data)
        self.scene = Scene(new_cfg, render=self._render, contacts=self._contacts, previous=self.scene)
        self.cfg, self._data = new_cfg, data

    def _add(self, key: str, item: dict) -> None:
        data = self._data_now()
        data.setdefault(key, []).append(dict(item))
        self._rebuild(data)

    def _remove(self, key: str, name: str) -> None:
        data = self._data_now()
        data[key] = [x for x in data.get(key, []) if x.get("name") != name]
        self._rebuild(data)

    def add_emitter(self, emitter: dict) -> None:
        self._add("emitters", emitter)

    def remove_emitter(self, name: str) -> None:
        self._emitter(name)  # a clear KeyError for an unknown name
        self._remove("emitters", name)

    def add_collider(self, collider: dict) -> None:
        self._add("colliders", collider)

    def remove_collider(self, name: str) -> None:
        self.scene.colliders.index(name)
        self._remove("colliders", name)

    def add_body(self, body: dict) -> None:
        self._add("bodies", body)

    def remove_body(self, name: str) -> None:
        self._body(name)
        self._remove("bodies", name)


class SceneBuilder:
    """Build a scene in code: ``SceneBuilder(fps=60).emitter(rate=200, effect="sparks")
    .collider(type="plane").body(type="cloth", ...).build(contacts=True)``. Keys are the config's
    keys and are validated the same way (unknown keys are errors naming the nearest one)."""

    def __init__(self, **scene_keys):
        self.data = dict(scene_keys)

    def _table(self, key, **values):
        self.data[key] = {**self.data.get(key, {}), **values}
        return self

    def camera(self, **kw):
        return self._table("camera", **kw)

    def solver(self, **kw):
        return self._table("solver", **kw)

    def forces(self, **kw):
        return self._table("forces", **kw)

    def render(self, **kw):
        return self._table("render", **kw)

    def emitter(self, **kw):
        self.data.setdefault("emitters", []).append(kw)
        return self

    def collider(self, **kw):
        self.data.setdefault("colliders", []).append(kw)
        return self

    def body(self, **kw):
        self.data.setdefault("bodies", []).append(kw)
        return self

    def build(self, **kw) -> ParticleScene:
        return ParticleScene(copy.deepcopy(self.data), **kw)
