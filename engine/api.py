"""The engine from a game loop: build, step, steer, read back, listen for contacts, render.

    from engine.api import ParticleScene, FixedTimestep

    scene = ParticleScene.from_file("configs/campfire.toml", contacts=True, interpolate=True)
    clock = FixedTimestep(1 / 120)
    while running:
        clock.advance(scene, frame_seconds)          # same simulation at 30 Hz or 144 Hz
        scene.move_collider("log", player_position)  # velocity inferred: it pushes particles
        for hit in scene.contacts(min_speed=2.0).rows(): play_sound(hit["name"])
        image = scene.render(320, 180, transparent=True, alpha=clock.alpha)  # premultiplied RGBA

Everything here checks its arguments first (:mod:`engine.checks`: ``TypeError``, ``ValueError``
or ``KeyError`` in one line naming the argument and the value; a refused call changes nothing),
then writes the scene's :class:`~engine.control.Control` (this frame's inputs) or reads back.
Fields and kernels were built by :class:`~engine.scene.Scene`; a discarded scene (``close()`` or
garbage) is kept for the next scene of the same config (:mod:`engine.reuse`), so a level restart
compiles nothing. Adding or removing emitters, colliders or bodies rebuilds the scene between
frames and carries live particles, emitter clocks, inputs and soft bodies over by name
(:mod:`engine.api_edit`).
"""
from __future__ import annotations

import copy
import math
import weakref

import numpy as np

from . import checks, reuse, runtime
from .budget import fit, hold, particle_budget, release, set_particle_budget
from .api_edit import SceneEdits, _load, _shallow
from .api_potential import PotentialAPI
from .api_rigid import RigidAPI
from .api_soft import SoftBodyAPI
from .builder import ConfigBuilder
from .checks import COORD, MAX_CONTACTS, MAX_DT, MAX_STEPS_PER_CALL, boolean, integer, number, vector
from .particles.capacity import MAX_POOL
from .clock import FixedTimestep
from .config import ConfigError, config_data
from .contacts import Contacts
from .ode.driver import substeps
from .render.camera import Camera
from .scene import Scene

SPARE_EMITTERS = 4  # emitters add_emitter can write in place (rows beyond the config's)
SPARE_SLOTS = 16_384  # pool slots for them (about 1.5 MB; dead slots cost a check per step)

__all__ = ["ParticleScene", "SceneBuilder", "FixedTimestep", "Camera", "Contacts", "set_particle_budget",
           "particle_budget"]


def _discard(key, scene, token, program) -> None:
    """A ParticleScene went away: its slots return to the budget, its scene to the pool."""
    release(token)
    reuse.give_back(key, scene, program)


class ParticleScene(SceneEdits, RigidAPI, SoftBodyAPI, PotentialAPI):
    """A scene driven from Python. Build with :meth:`from_file`, :meth:`from_dict` or
    :class:`SceneBuilder`. Several can live in one process; ``engine.runtime.init`` is called
    once for all of them (or skipped when the host initialised Taichi itself).

    ``contacts``: True (65,536) or the number of contact records kept between two
    :meth:`contacts` calls; ``render``: build the renderer; ``interpolate``: keep last-step
    positions for ``render(alpha=)``; ``max_dt``: the longest ``step(dt)`` allowed (s);
    ``spare_emitters``, ``spare_slots``: room for emitters added by :meth:`add_emitter` without
    compiling (parameter rows and pool slots beyond the config's)."""

    def __init__(self, config, contacts: bool | int = False, render: bool = True, *,
                 interpolate: bool = False, max_dt: float = MAX_DT, spare_emitters: int = SPARE_EMITTERS,
                 spare_slots: int = SPARE_SLOTS):
        where = type(self).__name__
        runtime.check_thread(where)
        self._spare = (integer(f"{where}: spare_emitters", spare_emitters, 0, 64),
                       integer(f"{where}: spare_slots", spare_slots, 0, MAX_POOL))
        self._contacts = (65536 if contacts is True else
                          0 if contacts is False else integer(f"{where}: contacts", contacts, 0, MAX_CONTACTS))
        self._render = boolean(f"{where}: render", render)
        self._interpolate = boolean(f"{where}: interpolate", interpolate)
        self.max_dt = number(f"{where}: max_dt", max_dt, 0.0, 60.0, lo_open=True)
        if isinstance(config, dict):
            _shallow(f"{where}: config", config)
            data = checks.plain(copy.deepcopy(config))
        elif hasattr(config, "model_dump"):
            data = config_data(config)
        else:
            raise TypeError(f"{where}: config: {checks.show(config)} is not a config dict or a validated config")
        self._finalizer, self._token, self.scene = None, None, None
        self._potentials = []  # (function, params, emitter names or None, name), in the order added
        self.last_add = None  # why the last add_emitter rebuilt the scene (None: added in place)
        self._install(data, where)

    def _install(self, data: dict, where: str, previous=None) -> None:
        """Validate ``data`` (under the particle budget) and make it this object's scene: an
        idle one of the same key reset, else a new build (carrying ``previous`` over). Refused
        (a bad config, the budget), nothing changes."""
        cfg = _load(where, data)
        release(self._token)  # this scene's own slots do not count against its rebuild
        try:
            data, cfg, self.budget_scale, spare = fit(data, cfg, lambda d: _load(where, d), self._spare)
            opts = dict(render=self._render, contacts=self._contacts, interpolate=self._interpolate,
                        spare=spare)
            key = reuse.key_for(cfg, **opts)
            scene = reuse.take(key) if previous is None else None
            if scene is not None:
                scene.reset()
                if scene.particles is not None:  # a reused scene acts with this object's potentials only
                    scene.particles.clear_potentials()
            else:
                scene = Scene(cfg, previous=previous, **opts)
                reuse.counts["built"] += 1
                if previous is None:
                    scene.reset()  # compiles the reset launches now, not at the first restart
        except BaseException:
            if previous is not None:
                hold(self._token, previous.capacity)
            raise
        if self._finalizer is not None:
            self._finalizer.detach()  # the scene it replaces was carried over: not reusable
        self.scene, self.cfg, self._data, self._key = scene, cfg, data, key
        self._program = reuse.program()
        self._token = object()
        hold(self._token, scene.capacity)
        self._finalizer = weakref.finalize(self, _discard, key, scene, self._token, reuse.program())

    @classmethod
    def from_file(cls, path, **kw) -> "ParticleScene":
        from .config import read_toml

        try:
            data = read_toml(path)
        except ConfigError as e:
            raise ValueError(f"from_file: {'; '.join(e.problems)}") from None
        data.setdefault("name", str(path).rsplit("/", 1)[-1].removesuffix(".toml"))
        return cls(data, **kw)

    @classmethod
    def from_dict(cls, data: dict, **kw) -> "ParticleScene":
        return cls(data, **kw)

    @classmethod
    def prepare(cls, config, copies: int = 1, sizes=(), **kw) -> None:
        """Build ``copies`` scenes of ``config`` now, warmed up (:meth:`warm_up`), and keep them
        idle: the next ``copies`` scenes of this config (and options) start without compiling.
        For a loading screen; a path, a dict or a validated config."""
        n = integer("prepare: copies", copies, 1, 64)
        made = [cls.from_file(config, **kw) if isinstance(config, str) else cls(config, **kw) for _ in range(n)]
        for s in made:
            s.warm_up(sizes)
        for s in made:
            s.close()

    def warm_up(self, sizes=()) -> None:
        """Compile now what the game will call later — a step with a burst from every emitter and
        moving colliders, read-backs, contact drains, a render at each (width, height) of
        ``sizes`` — then return to t = 0 as built. Pays the compile cost on a loading screen."""
        s = self._live("warm_up")
        sizes = [checks.image_size("warm_up: sizes", w, h, (s.width, s.height)) for w, h in sizes]
        s.warm_up(sizes)

    def close(self) -> None:
        """Discard the scene now: its fields and compiled kernels wait for the next scene of the
        same config (engine.reuse), its slots go back to the particle budget."""
        if self._finalizer is not None:
            self._finalizer()
        self.scene = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _live(self, where: str) -> Scene:
        runtime.check_thread(where)
        if self.scene is None:
            raise RuntimeError(f"{where}: this scene was closed")
        if self._program != reuse.program():
            raise RuntimeError(f"{where}: this scene was built before engine.runtime.reset(), which freed its "
                               f"fields and kernels: build it again")
        return self.scene

    # -- time -------------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return self._live("time").t

    def step(self, dt: float) -> None:
        """Advance by dt seconds (0 < dt <= max_dt), sub-stepping with the configured integrator."""
        s = self._live("step")
        number("step: dt", dt, 0.0, lo_open=True)
        if dt > self.max_dt:
            raise ValueError(f"step: dt: {dt!r} s is longer than max_dt = {self.max_dt:g} s: step in pieces "
                             f"(FixedTimestep does) or build the scene with a larger max_dt")
        sol = self.cfg.solver
        if not sol.adaptive and s.particles is not None and substeps(dt, sol.h) > MAX_STEPS_PER_CALL:
            raise ValueError(f"step: dt: {dt!r} s is {substeps(dt, sol.h):,} steps of solver.h = {sol.h:g} s; "
                             f"at most {MAX_STEPS_PER_CALL:,} per call")
        if self._interpolate:
            s.save_positions()
        s.advance(float(dt))

    def live_count(self) -> int:
        """Live particles now (one read-back per step, only when asked)."""
        return self._live("live_count").live_count()

    def dropped(self) -> int:
        """Particles that found no free pool slot so far (a budget or a capacity too small)."""
        return self._live("dropped").dropped()

    # -- control ----------------------------------------------------------------------------------
    def _emitter(self, where: str, name) -> int:
        names = [e.name for e in self.cfg.emitters]
        return names.index(checks.name(f"{where}: name", name, names, "emitter"))

    def _collider(self, where: str, name) -> int:
        names = [c.name for c in self.cfg.colliders]
        return names.index(checks.name(f"{where}: name", name, names, "collider"))

    def _over(self, where: str, over, s: Scene) -> float:
        return s.frame_dt if over is None else number(f"{where}: over", over, 0.0, self.max_dt, lo_open=True)

    def move_emitter(self, name: str, position, over: float | None = None) -> None:
        """Move emitter ``name`` to ``position`` by the end of the next step of length ``over``
        (default: one frame at the config's fps); its velocity is inferred from the motion."""
        s = self._live("move_emitter")
        e, p = self._emitter("move_emitter", name), vector("move_emitter: position", position)
        s.control.move_emitter(e, s.t, s.t + self._over("move_emitter", over, s), p)

    def set_rate(self, name: str, rate: float) -> None:
        """Particles per second (the pool keeps its size: beyond it particles are counted dropped)."""
        s = self._live("set_rate")
        e, r = self._emitter("set_rate", name), number("set_rate: rate", rate, 0.0, 1e8)
        s.control.set_rate(e, r)

    def set_emitting(self, name: str, on: bool) -> None:
        """Start or stop an emitter's continuous emission (bursts from code still work)."""
        s = self._live("set_emitting")
        e, on = self._emitter("set_emitting", name), boolean("set_emitting: on", on)
        s.control.set_emitting(e, on)

    def burst(self, name: str, count: int, position=None) -> None:
        """Emit ``count`` particles from ``name`` at the start of the next step — at ``position``
        if given, without moving the emitter (a spark shower where a bullet hits)."""
        s = self._live("burst")
        e = self._emitter("burst", name)
        ring = s.emitter_capacity(e)
        n = integer("burst: count", count, 0, ring)
        p = None if position is None else vector("burst: position", position)
        if n:
            s.control.burst(e, n, p)

    def move_collider(self, name: str, position, over: float | None = None) -> None:
        """Move collider ``name`` (a plane's point or a sphere's centre) to ``position`` by the end
        of the next step; its velocity is inferred, so it pushes particles and soft bodies."""
        s = self._live("move_collider")
        k, p = self._collider("move_collider", name), vector("move_collider: position", position)
        s.control.move_collider(k, s.t, s.t + self._over("move_collider", over, s), p)

    def set_collider_pose(self, name: str, position, orientation=None, velocity=None, angular_velocity=None,
                          over: float | None = None) -> None:
        """Place collider ``name`` at ``position`` (m) with ``orientation`` ([w, x, y, z], None: as
        it turns now) by the end of the next step of length ``over`` (default: one frame).
        ``velocity`` (m/s) and ``angular_velocity`` (rad/s, world): its motion over that step
        (None: inferred from the move; a spin kept after it), which the surface point's velocity
        v + ω × r hands to what it hits. Spinning needs a collider built to rotate (its config's
        ``angular_velocity`` or ``rotates = true``); others are turned without a spin."""
        where = "set_collider_pose"
        s = self._live(where)
        k = self._collider(where, name)
        p = vector(f"{where}: position", position)
        q = None if orientation is None else vector(f"{where}: orientation", orientation, 4)
        if q is not None and math.fsum(c * c for c in q) < 1e-12:
            raise ValueError(f"{where}: orientation {checks.show(orientation)} is not allowed: a quaternion "
                             f"[w, x, y, z] must not be zero")
        v = None if velocity is None else vector(f"{where}: velocity", velocity)
        w = None if angular_velocity is None else vector(f"{where}: angular_velocity", angular_velocity, bound=1e4)
        if not s.colliders.specs[k].spins:
            if w is not None and any(w):
                raise ValueError(f"{where}: angular_velocity {checks.show(angular_velocity)} is not allowed: "
                                 f"collider {name!r} was built without rotation (give it an angular_velocity "
                                 f"or rotates = true in its config)")
            w = (0.0, 0.0, 0.0)  # turned without a spin: a shape that cannot spin is placed, not swept
        s.control.set_collider_pose(k, s.t, s.t + self._over(where, over, s), p, q, v, w)

    def set_wind(self, wind) -> None:
        """Air velocity (m/s) seen by drag."""
        self._live("set_wind").control.set_wind(vector("set_wind: wind", wind))

    def set_gravity(self, g) -> None:
        """Gravity (m/s²) for particles and soft bodies."""
        self._live("set_gravity").control.set_gravity(vector("set_gravity: g", g))

    # -- read-back --------------------------------------------------------------------------------
    def particles(self) -> dict:
        """Live particles as NumPy arrays (copies; Taichi fields are not shared memory on every
        backend): ``position`` (N, 3), ``velocity`` (N, 3), ``age`` (N,), ``life`` (N,),
        ``emitter`` (N,) index, ``color`` (N, 3) linear RGB from the emitter's ramp."""
        out = self._live("particles").live_particles()
        out["color"] = self._colors(out["emitter"], np.clip(out["age"] / np.maximum(out["life"], 1e-30), 0, 1))
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

    def contacts(self, min_speed: float = 0.0, body: str | None = None) -> Contacts:
        """Every contact since the previous call (the queue drains), however many steps ran,
        with impact speed >= ``min_speed`` (slower ones are drained too): particle contacts, or
        the nodes of soft body ``body`` (built with ``contacts = true`` in its config). Needs
        the scene built with contacts; ``dropped`` counts those past the buffer."""
        s = self._live("contacts")
        v = number("contacts: min_speed", min_speed, 0.0, COORD)
        b = None if body is None else self._body("contacts", body)
        if not self._contacts:
            raise RuntimeError("contacts: build the scene with contacts=True to record them")
        names, shapes = s.colliders.names, s.colliders.parties  # the one shape table's
        if b is not None:
            if not b.cfg.contacts:
                raise RuntimeError(f"contacts: body {body!r} does not record contacts: set contacts = true "
                                   f"in its config")
            c = b.contacts(names, shapes)
        else:
            c = (s.particles.contacts(names, shapes) if s.particles is not None
                 else Contacts.empty(names, shapes=shapes))
        return c.where(c.speed >= v) if v > 0 else c

    def render(self, width: int | None = None, height: int | None = None, camera: Camera | None = None,
               show_colliders: bool | None = None, *, out: np.ndarray | None = None,
               transparent: bool = False, bgra: bool = False, alpha: float | None = None) -> np.ndarray:
        """(H, W, 4) uint8 RGBA image of the current state, any size (16 to 16,384 a side, at most
        4 GiB of render memory), any camera: neither compiles anything. ``out``: a C-contiguous
        (H, W, 4) uint8 array to draw into (no allocation per frame). Opaque, unless
        ``transparent``: premultiplied RGBA, alpha 0 where nothing is drawn, to composite over the
        game's frame with the blend (ONE, ONE_MINUS_SRC_ALPHA) — additive light carries alpha 0,
        so it adds. ``bgra``: bytes in B, G, R, A order, as SDL/pygame and X11 surfaces take them.
        ``alpha``: draw particles between their positions before and after the last step
        (``FixedTimestep.alpha``; a scene built with ``interpolate=True``)."""
        s = self._live("render")
        w, h = checks.image_size("render", width, height, (s.width, s.height))
        cam = None if camera is None else checks.camera("render: camera", camera, Camera)
        show = None if show_colliders is None else boolean("render: show_colliders", show_colliders)
        flags = [boolean(f"render: {k}", v) for k, v in (("transparent", transparent), ("bgra", bgra))]
        if out is not None:
            checks.image_array("render: out", out, w, h)
        if alpha is not None:
            alpha = number("render: alpha", alpha, 0.0, 1.0)
            if not self._interpolate:
                raise ValueError("render: alpha: the scene keeps no last-step positions: build it with "
                                 "interpolate=True")
        if s.renderer is None:
            raise RuntimeError("render: this scene was built with render=False")
        return s.render(w, h, cam, show, out=out, transparent=flags[0], bgra=flags[1], alpha=alpha)


class SceneBuilder(ConfigBuilder):
    __doc__ = ConfigBuilder.__doc__

    def build(self, **kw):
        """A :class:`ParticleScene` (its keyword arguments: contacts, render, interpolate, max_dt)."""
        return ParticleScene(copy.deepcopy(self.data), **kw)
