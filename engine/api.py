"""The engine from a game loop: build, step, steer, read back, listen for contacts, render.

    from engine.api import ParticleScene, FixedTimestep

    scene = ParticleScene.from_file("configs/campfire.toml", contacts=True)
    clock = FixedTimestep(1 / 120)
    while running:
        clock.advance(scene, frame_seconds)          # same simulation at 30 Hz or 144 Hz
        scene.move_collider("log", player_position)  # velocity inferred: it pushes particles
        for hit in scene.contacts(min_speed=2.0).rows(): play_sound(hit)
        image = scene.render(320, 180)               # (H, W, 4) uint8 RGBA to blit

Everything here is Control (this frame's inputs) or read-back; fields and kernels were built by
:class:`~engine.scene.Scene`. Adding or removing emitters, colliders or bodies rebuilds the scene
between frames (kernels are compiled for a fixed set of features) and carries live particles,
emitter clocks and soft bodies over by name.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from .config import load_config
from .particles.pool import PARTICLE_FIELDS
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
        p = self.scene.particles
        if p is not None and self._contacts:
            p.integrator.contact_count[None] = 0
        self.scene.advance(dt)
        if p is not None:
            self.scene.stats.alive = p.count_alive()
        self._last_contacts = None

    # -- control ----------------------------------------------------------------------------------
    def _emitter(self, name) -> int:
        names = [e.name for e in self.cfg.emitters]
        if name not in names:
            raise KeyError(f"emitter: no emitter named {name!r} (names: {names})")
        return names.index(name)

    def move_emitter(self, name: str, position, over: float | None = None) -> None:
        """Move emitter ``name`` to ``position`` by the end of the next step of length ``over``
        (default: one frame at the config's fps); its velocity is inferred from the motion."""
        em = self.scene.particles.emitters
        dt = over or self.scene.frame_dt
        em.set_target(self._emitter(name), self.time, self.time + dt, position)

    def set_rate(self, name: str, rate: float) -> None:
        """Particles per second (the pool keeps its size: beyond it particles are counted dropped)."""
        if not rate >= 0:
            raise ValueError(f"rate: must be >= 0, got {rate}")
        self.scene.particles.emitters.clocks[self._emitter(name)].rate = float(rate)

    def set_emitting(self, name: str, on: bool) -> None:
        """Start or stop an emitter's continuous emission (bursts from code still work)."""
        self.scene.particles.emitters.clocks[self._emitter(name)].enabled = bool(on)

    def burst(self, name: str, count: int, position=None) -> None:
        """Emit ``count`` particles from ``name`` at the start of the next step; with ``position``
        the emitter is first placed there (a jump, not a motion: nothing is inherited)."""
        em, e = self.scene.particles.emitters, self._emitter(name)
        if position is not None:
            em.runtime_paths[e] = [(self.time, tuple(float(c) for c in position))]
        em.burst(e, int(count))

    def move_collider(self, name: str, position, over: float | None = None) -> None:
        """Move collider ``name`` (a plane's point or a sphere's centre) to ``position`` by the end
        of the next step; its velocity is inferred, so it pushes particles and soft bodies."""
        dt = over or self.scene.frame_dt
        k = self.scene.colliders.index(name)
        self.scene.colliders.set_target(k, self.time, self.time + dt, position)
        if self.scene.particles is not None:
            self.scene.particles.moving_colliders = True
        for body in self.scene.bodies:
            if body.colliders is not None:
                body.colliders.set_target(k, self.time, self.time + dt, position)
                body.system.move_colliders = True

    def set_wind(self, wind) -> None:
        """Air velocity (m/s) seen by drag."""
        self.scene.particles.forces.force_wind[None] = [float(c) for c in wind]

    def set_gravity(self, g) -> None:
        p = self.scene.particles
        if p is not None:
            p.forces.force_gravity[None] = [float(c) for c in g]
        for body in self.scene.bodies:
            body.system.model.gravity[None] = [float(c) for c in g]

    def _body(self, name):
        for b in self.scene.bodies:
            if b.cfg.name == name:
                return b
        raise KeyError(f"body: no body named {name!r} (names: {[b.cfg.name for b in self.scene.bodies]})")

    def pin(self, body: str, node: int, target=None) -> None:
        """Hold a node of a soft body at ``target`` (default: where it is)."""
        self._body(body).system.pin(int(node), target)

    def move_pin(self, body: str, node: int, target) -> None:
        """Drag a pinned node to ``target`` over the next step (a hand holding the cloth)."""
        self._body(body).system.set_pin_target(int(node), target)

    def release(self, body: str, node: int) -> None:
        self._body(body).system.release(int(node))

    # -- read-back --------------------------------------------------------------------------------
    def particles(self) -> dict:
        """Live particles as NumPy arrays (copies; Taichi fields are not shared memory on every
        backend): ``position`` (N, 3), ``velocity`` (N, 3), ``age`` (N,), ``life`` (N,),
        ``emitter`` (N,) index, ``color`` (N, 3) linear RGB from the emitter's ramp."""
        p = self.scene.particles
        if p is None:
            z = np.zeros((0, 3), np.float32)
            return dict(position=z, velocity=z, age=np.zeros(0), life=np.zeros(0),
                        emitter=np.zeros(0, np.int32), color=z)
        S, cap = p.state, p.layout.capacity
        alive = S.particle_alive.to_numpy()[:cap] != 0
        age = S.particle_age.to_numpy()[:cap]
        m = alive & (age >= 0)
        life = S.particle_life.to_numpy()[:cap][m]
        emitter = S.particle_emitter.to_numpy()[:cap][m]
        out = dict(position=S.particle_pos.to_numpy()[:cap][m], velocity=S.particle_vel.to_numpy()[:cap][m],
                   age=age[m], life=life, emitter=emitter)
        out["color"] = self._colors(emitter, np.clip(age[m] / life, 0, 1))
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
        p = self.scene.particles
        if not self._contacts:
            raise RuntimeError("contacts: build the scene with contacts=True to record them")
        if self._last_contacts is None:
            I = p.integrator
            n = int(I.contact_count[None])
            k = min(n, I.max_contacts)
            slot = I.contact_slot.to_numpy()[:k]
            tt = I.contact_time.to_numpy()[:k]
            order = np.lexsort((slot, tt))  # deterministic, whatever order threads wrote them in
            self._last_contacts = Contacts(I.contact_collider.to_numpy()[:k][order],
                                           I.contact_pos.to_numpy()[:k][order],
                                           I.contact_normal.to_numpy()[:k][order],
                                           I.contact_speed.to_numpy()[:k][order], tt[order],
                                           dropped=max(0, n - k))
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
        old = self.scene
        new_cfg = load_config(data)
        keep = {b.cfg.name: b for b in old.bodies if b.cfg.name}
        bodies = [keep.get(b.name) if b.name and keep.get(b.name) is not None
                  and keep[b.name].cfg == b else None for b in new_cfg.bodies]
        scene = Scene(new_cfg, render=self._render, contacts=self._contacts, bodies=bodies)
        scene.t, scene.frame, scene.stats = old.t, old.frame, old.stats
        if old.particles is not None and scene.particles is not None:
            _carry_particles(old.particles, scene.particles)
        self.scene, self.cfg, self._data = scene, new_cfg, data

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


def _carry_particles(old, new) -> None:
    """Copy each named emitter's ring (particles, head, serial, clock) into the rebuilt pool."""
    fields = PARTICLE_FIELDS
    src = {f: getattr(old.state, f).to_numpy() for f in fields}
    dst = {f: getattr(new.state, f).to_numpy() for f in fields}
    old_names = [c.name for c in old.emitters.configs]
    for e_new, c in enumerate(new.emitters.configs):
        if not c.name or c.name not in old_names:
            continue
        e_old = old_names.index(c.name)
        a, n_old = old.layout.starts[e_old], old.layout.sizes[e_old]
        b, n_new = new.layout.starts[e_new], new.layout.sizes[e_new]
        n = min(n_old, n_new)
        for f in fields:
            dst[f][b:b + n] = src[f][a:a + n]
        dst["particle_emitter"][b:b + n] = e_new
        new.emitters.clocks[e_new] = copy.copy(old.emitters.clocks[e_old])
        new.emitters.emitter_head[e_new] = int(old.emitters.emitter_head[e_old]) % n_new
        new.emitters.emitter_serial[e_new] = int(old.emitters.emitter_serial[e_old])
    for f in fields:
        getattr(new.state, f).from_numpy(dst[f])


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
