"""``RigidSystem``: the rigid bodies of a scene as one system (engine.system's protocol, kind
"rigid": it advances before particles and soft bodies and publishes its shapes' poses for them).

``[rigid] integrator = "xpbd"`` (default): steps of at most ``[rigid] h``; each finds its contacts
once (:mod:`.collide`, with a speculative margin of the step's motion) and takes ``substeps`` XPBD
substeps (:mod:`.xpbd`), joints included. Any of the five ODE integrators: Baraff's state on the
ODE driver (:mod:`.baraff`). Bodies at rest (``[rigid] sleep``) sleep: below ``sleep_speed`` for
``sleep_time`` they stop and hold still like fixed ones until a moving body touches them, an
impulse or a pose is set.
"""
from __future__ import annotations

import numpy as np

from ..ode.driver import DriverStats, SimulationDiverged, substeps
from ..paths import sample_path
from ..system import SystemBase
from . import broad, collide, quat
from .quat import cross
from .joints import Joints
from .model import RigidModel, RigidState
from .shapes import SPHERE
from .shapes import BOX, CODES, mesh
from .xpbd import ContactSet, XPBDSolver

SLOP = 0.005  # m: contacts are kept this far apart before touching (and a step's motion more)


class RigidSystem(SystemBase):
    kind = "rigid"

    def __init__(self, cfg, collider_specs, control, name: str = "rigid", shape_index=None):
        """``cfg``: the scene config (its ``rigid_bodies``, ``joints``, ``rigid``);
        ``collider_specs``: the scene's planes and spheres (static shapes for the bodies);
        ``control``: the scene's inputs (gravity, collider positions); ``shape_index``: {body
        index: its shape's index in the scene's shape table}, posed at every coupling step."""
        self.name, self.cfg, self.settings = name, cfg, cfg.rigid
        self.bodies_cfg = list(cfg.rigid_bodies)
        self.model = RigidModel(self.bodies_cfg)
        self.state = RigidState.from_config(self.bodies_cfg)
        self.specs = list(collider_specs)
        self.control = control
        self.shape_index = dict(shape_index or {})
        self.joints = Joints(cfg.joints, self.model, self.state) if cfg.joints else None
        self.stats = DriverStats()
        self.method = self.settings.integrator
        self.label = f"{name}: {self.method}"
        self.t = 0.0
        self.last_contacts = None
        self._pair_list = broad.PairList()  # the broad phase's pairs, kept while they hold
        self._meshes = [mesh(self.model.body_shape[i], self.model.body_radius[i], self.model.body_half[i],
                             self.model.body_half_length[i]) for i in range(self.model.count)]
        self._kin = np.flatnonzero(self.model.body_kinematic)
        if self.method == "xpbd":
            self.solver = XPBDSolver(self.model, self.state, self.joints)
            self.ode = None
        else:
            from .baraff import BaraffSystem

            self.solver = None
            self.ode = BaraffSystem(self, cfg.solver)
        self._rest = np.zeros(self.model.count)
        self.pending = []  # impulses from the API: (body, impulse, point or None)

    # -- the System protocol -------------------------------------------------------------------
    def advance(self, t0: float, t1: float) -> None:
        g = np.asarray(self.control.gravity[None].to_numpy(), np.float64)
        self._take_pending()
        if self.ode is not None:
            self.ode.advance(t0, t1, g)
        else:
            n = substeps(t1 - t0, self.settings.h)
            h = (t1 - t0) / n
            for k in range(n):
                self._xpbd_step(t0 + k * h, h, g)
        self.t = t1
        if not (np.isfinite(self.state.x).all() and np.isfinite(self.state.q).all()):
            raise SimulationDiverged(self.label, self.method, t1 - t0, t1, "non-finite state")

    def reset(self) -> None:
        self.state.__dict__.update(RigidState.from_config(self.bodies_cfg).__dict__)
        if self.solver is not None:
            self.solver.state = self.state
            self.solver.awake[:] = True
        if self.ode is not None:
            self.ode.reset()
        self._rest[:] = 0.0
        self.t, self.pending, self.last_contacts = 0.0, [], None
        self.stats.__dict__.update(DriverStats().__dict__)

    def drawables(self) -> dict:
        """Triangles of every body, moved to its pose: kind "mesh", ``positions`` a callable
        (read at draw time), ``triangles`` (T, 3), ``color`` (V, 3)."""
        offs = np.cumsum([0] + [len(v) for v, _ in self._meshes])
        tris = np.concatenate([t + o for (_, t), o in zip(self._meshes, offs)]) if self._meshes else np.zeros((0, 3), np.int32)
        cols = np.concatenate([np.tile(self.model.body_color[i], (len(v), 1)) for i, (v, _) in enumerate(self._meshes)]) \
            if self._meshes else np.zeros((0, 3))
        return dict(kind="mesh", positions=self.vertices, triangles=tris.astype(np.int32),
                    lines=np.zeros((0, 2), np.int32), color=cols.astype(np.float32))

    def vertices(self) -> np.ndarray:
        """(V, 3) float32 world vertices of every body's mesh, in body order."""
        if not self._meshes:
            return np.zeros((0, 3), np.float32)
        S = self.state
        if getattr(self, "_mesh_rows", None) is None:  # every vertex's body and local position, once
            self._mesh_rows = (np.concatenate([np.full(len(v), i) for i, (v, _) in enumerate(self._meshes)]),
                               np.concatenate([np.asarray(v, np.float64) for v, _ in self._meshes]))
        body, local = self._mesh_rows
        # all bodies in one batch (the same arithmetic per vertex as a body at a time: crates' 25
        # boxes were 13 rotate calls a frame, ~1 ms of Python under cProfile)
        return (S.x[body] + quat.rotate(S.q[body], local)).astype(np.float32)

    def energy(self) -> dict:
        S, m = self.state, self.model
        g = np.asarray(self.control.gravity[None].to_numpy(), np.float64)
        wb = quat.rotate_inv(S.q, S.w)
        dyn = m.dynamic
        kin = 0.5 * float(np.sum(m.body_mass[dyn] * np.sum(S.v[dyn] ** 2, 1)))
        rot = 0.5 * float(np.sum(m.body_inertia[dyn] * wb[dyn] ** 2))
        pot = -float(np.sum(m.body_mass[dyn] * (S.x[dyn] @ g)))
        return dict(t=self.t, kinetic=kin, rotational=rot, potential=pot, total=kin + rot + pot)

    def contacts(self, names=()):
        from ..contacts import Contacts

        return Contacts.empty(names)

    def receive(self, coupling) -> None:
        """Take the impulses particles of ``two_way`` emitters gave the bodies over the previous
        coupling step (``rigid_impulses``: (J, L) float64 (bodies, 3), N·s and N·m·s about each
        body's centre; engine.particles.push), in publishing order, before this step's advance:
        a one-step lag. Each pushed body is woken (:meth:`apply_push`)."""
        pushed = False
        for _publisher, (J, L) in coupling.get("rigid_impulses"):
            for i in np.flatnonzero(np.any(J != 0.0, axis=1) | np.any(L != 0.0, axis=1)):
                pushed |= self.apply_push(int(i), J[i], L[i], load=False)
        if pushed and self.ode is not None:
            self.ode.load()  # (once for every body pushed)

    def apply_push(self, i: int, J, L, load: bool = True) -> bool:
        """Body i takes the impulse J (N·s, at its centre) and the angular impulse L (N·m·s,
        world frame, about its centre): Δv = J/M, Δω = I_world⁻¹ L (Baraff: ΔP = J, ΔL = L);
        a fixed or path-following body takes nothing. Wakes it. Whether it moved."""
        m, S = self.model, self.state
        if not m.dynamic[i]:
            return False
        S.v[i] += np.asarray(J, np.float64) * m.body_inv_mass[i]
        S.w[i] += m.inv_inertia_world(S.q[i], i, np.asarray(L, np.float64))
        self.wake(i)
        if load and self.ode is not None:
            self.ode.load()
        return True

    def publish(self, coupling) -> None:
        """The bodies' shapes at the step's end, for particles and soft bodies (sphere, box and
        capsule poses with their velocities): :meth:`shapes`; the bodies' own shapes in the one shape
        table posed over the step."""
        shapes = self.shapes()
        coupling.put(self.name, "rigid_shapes", shapes)
        for i, k in self.shape_index.items():
            if self.model.body_shape[i] == SPHERE:
                # spheres sit in the table unrotated (their contact is the same at any
                # orientation; ω × r friction from a spinning ball is left out)
                self.control.set_collider_pose(k, coupling.t0, coupling.t1, shapes["position"][i], None,
                                               shapes["velocity"][i])
            else:  # boxes and capsules turn with the body: contacts see v + ω × r
                self.control.set_collider_pose(k, coupling.t0, coupling.t1, shapes["position"][i],
                                               shapes["orientation"][i], shapes["velocity"][i],
                                               shapes["angular_velocity"][i])

    def shapes(self) -> dict:
        """Every body's shape and pose now, as arrays in body order: ``names``, ``shape`` (codes
        of engine.rigid.shapes), ``position``, ``orientation``, ``velocity``,
        ``angular_velocity``, ``radius``, ``half_extents``, ``half_length``, ``restitution``,
        ``friction`` (copies: the board outlives the step)."""
        S, m = self.state, self.model
        return dict(names=m.names, shape=m.body_shape, position=S.x.copy(), orientation=S.q.copy(),
                    velocity=S.v.copy(), angular_velocity=S.w.copy(), radius=m.body_radius,
                    half_extents=m.body_half, half_length=m.body_half_length,
                    restitution=m.body_restitution, friction=m.body_friction)

    # -- stepping --------------------------------------------------------------------------------
    def _static_shapes(self, t):
        pos = self.control.collider_positions(t) if self.specs else np.zeros((0, 3))
        for k, s in enumerate(self.specs):
            yield k, s, pos[k]

    def find_contacts(self, t: float, h: float) -> ContactSet:
        """The contacts for a step of h from t, in a fixed order: against the scene's static
        shapes (shape by shape, then body, then point; b = −1 − the shape's index), then body
        pairs from the broad phase (pair by pair, then point)."""
        S, m = self.state, self.model
        awake = self.solver.awake if self.solver is not None else np.ones(m.count, bool)
        moving = m.dynamic & awake
        speed = np.linalg.norm(S.v, axis=1) + np.linalg.norm(S.w, axis=1) * m.body_bound
        margins = SLOP + h * speed
        R = quat.matrix(S.q)
        blocks = []  # (a, b, p_a, p_b, n, friction of b, restitution of b)
        live = np.flatnonzero(moving)
        for k, spec, p in self._static_shapes(t):
            if spec.kind == "plane":
                nrm = np.asarray(spec.normal, np.float64)
                nrm = nrm / np.linalg.norm(nrm)
                a, pa, pb = collide.plane_contacts(m, S.x, R, p, nrm, margins, live)
                n = np.broadcast_to(nrm, pa.shape)
            else:  # a sphere, box or capsule collider, posed where the control has it at t
                rows = self.static_shape_contacts(k, spec, p, t, S.x, R, margins, live)
                a = np.array([r[0] for r in rows], np.int64)
                pa, pb, n = (np.array([r[c] for r in rows], np.float64).reshape(-1, 3) for c in (1, 2, 3))
            K = len(a)
            blocks.append((a, np.full(K, -1 - k), pa, pb, n, np.full(K, float(spec.friction)),
                           np.full(K, float(spec.restitution))))
        got = self.pair_contacts(S.x, R, margins, moving)
        if got is not None:
            i, j, pa, pb, n = got
            blocks.append((i, j, pa, pb, n, m.body_friction[j], m.body_restitution[j]))
        cols = [np.concatenate([b[c] for b in blocks]) if blocks else None for c in range(7)]
        if not blocks:
            cols = [np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)),
                    np.zeros((0, 3)), np.zeros(0), np.zeros(0)]
        self._wake(cols[0], cols[1])
        return ContactSet(m, S, *cols, statics=[s.name or f"colliders[{k}]" for k, s in enumerate(self.specs)])

    def static_shape_contacts(self, k, spec, p, t, x, R, margins, bodies):
        """Contacts of ``bodies`` with the scene's sphere, box or capsule collider k (``spec``) at
        position p and its orientation at time t: (body, p_a, p_b, n) rows (engine.rigid.collide)."""
        if spec.kind == "sphere":
            return collide.sphere_collider_contacts(self.model, x, R, p, float(spec.radius), margins, bodies)
        Rk = quat.matrix(self.control.collider_orientations(t)[k][None])[0]
        geometry = (float(spec.radius), np.asarray(spec.half_extents, np.float64), float(spec.half_length))
        return collide.shape_collider_contacts(self.model, x, R, CODES[spec.kind], p, Rk, geometry, margins, bodies)

    def pair_contacts(self, x, R, margins, moving, q=None):
        """Body–body contacts of bodies at ``x`` (B, 3) turned by ``R`` (B, 3, 3) (or None: made
        from the unit quaternions ``q`` (B, 4) when some pair needs them), each grown by
        its margin (B,), for pairs with a ``moving`` body (B,) bool, jointed pairs left out: arrays
        (a, b, p_a, p_b, n) (n from b to a), in a fixed order (pair by pair from the broad phase,
        then point); None when there is none. Boxes against boxes by separating axes in one
        batch, other shape pairs one at a time (engine.rigid.collide)."""
        m = self.model
        pairs = self._pair_list.pairs(x, m.body_bound, margins)
        if len(pairs):
            keep = moving[pairs[:, 0]] | moving[pairs[:, 1]]
            if self.joints is not None:
                keep &= np.array([not self._jointed(i, j) for i, j in pairs], bool)
            pairs = pairs[keep]
        if not len(pairs):
            return None
        if R is None:
            R = quat.matrix(q)
        boxes = (m.body_shape[pairs[:, 0]] == BOX) & (m.body_shape[pairs[:, 1]] == BOX)
        bb = pairs[boxes]
        k, pa, pb, n = collide.box_box_batch(
            x[bb[:, 0]], R[bb[:, 0]], m.body_half[bb[:, 0]], x[bb[:, 1]], R[bb[:, 1]], m.body_half[bb[:, 1]],
            margins[bb[:, 0]] + margins[bb[:, 1]])
        found = [(np.flatnonzero(boxes)[k], pa, pb, n)]
        for q in np.flatnonzero(~boxes):  # other shape pairs: one at a time
            i, j = pairs[q]
            gi = (m.body_radius[i], m.body_half[i], m.body_half_length[i])
            gj = (m.body_radius[j], m.body_half[j], m.body_half_length[j])
            got = collide.pair(m.body_shape[i], m.body_shape[j], x[i], R[i], x[j], R[j], gi, gj,
                               margins[i] + margins[j])
            found += [(np.full(1, q), ca[None], cb[None], cn[None]) for ca, cb, cn in got]
        q, pa, pb, n = collide._blocks(found)
        return pairs[q, 0], pairs[q, 1], pa, pb, n

    def _jointed(self, i, j) -> bool:
        if not hasattr(self, "_joint_pairs"):
            self._joint_pairs = {(min(r["a"], r["b"]), max(r["a"], r["b"])) for r in self.joints.rows}
        return (int(i), int(j)) in self._joint_pairs

    def _wake(self, a, b) -> None:
        """An asleep body touched by a moving one faster than the sleep speed wakes up (contacts
        a–b of the step)."""
        if self.solver is None or not len(a):
            return
        aw, S, m = self.solver.awake, self.state, self.model
        if aw[m.dynamic].all():
            return
        speed = np.linalg.norm(S.v, axis=1) + np.linalg.norm(S.w, axis=1) * m.body_bound
        active = aw & m.dynamic & (speed > self.settings.sleep_speed)
        body = b >= 0
        a, b = a[body], b[body]
        for p, q in ((a, b), (b, a)):
            wake = p[~aw[p] & m.dynamic[p] & active[q]]
            aw[wake] = True
            self._rest[wake] = 0.0

    def _kinematic(self, t0, t1):
        """(positions at t0, at t1) of every body, path-following ones from their paths."""
        if not len(self._kin):
            return None
        x0, x1 = self.state.x.copy(), self.state.x.copy()
        for i in self._kin:
            x0[i] = sample_path(self.model.paths[i], t0, self.bodies_cfg[i].position)
            x1[i] = sample_path(self.model.paths[i], t1, self.bodies_cfg[i].position)
        return x0, x1

    def _xpbd_step(self, t: float, h: float, g) -> None:
        C = self.find_contacts(t, h)
        self.last_contacts = C
        n = self.settings.substeps
        hs = h / n
        self.solver.step(h, n, g, C, self._kinematic(t, t + h))
        self.stats.steps += n
        self.stats.h_min, self.stats.h_max = min(self.stats.h_min, hs), max(self.stats.h_max, hs)
        if self.settings.sleep:
            self._sleep(h)

    def _sleep(self, h: float) -> None:
        S, m, aw = self.state, self.model, self.solver.awake
        speed = np.linalg.norm(S.v, axis=1) + np.linalg.norm(S.w, axis=1) * m.body_bound
        slow = m.dynamic & aw & (speed < self.settings.sleep_speed)
        self._rest = np.where(slow, self._rest + h, 0.0)
        down = slow & (self._rest >= self.settings.sleep_time)
        if down.any():
            aw[down] = False
            S.v[down] = 0.0
            S.w[down] = 0.0

    def wake(self, i: int) -> None:
        if self.solver is not None:
            self.solver.awake[i] = True
        self._rest[i] = 0.0

    # -- driving from code (engine.api) ------------------------------------------------------------
    def carry_from(self, old: "RigidSystem") -> None:
        """Take the state of the bodies ``old`` has by the same name (a rebuild between frames)."""
        names = {n: i for i, n in enumerate(old.model.names) if n}
        for i, n in enumerate(self.model.names):
            j = names.get(n)
            if j is not None:
                for k in "xqvw":
                    getattr(self.state, k)[i] = getattr(old.state, k)[j]
        self.t = old.t
        if self.ode is not None:
            self.ode.load()

    def _take_pending(self) -> None:
        for i, J, point in self.pending:
            self.apply_impulse_now(i, J, point)
        self.pending = []

    def apply_impulse_now(self, i: int, J, point=None) -> None:
        m, S = self.model, self.state
        if not m.dynamic[i]:
            return
        J = np.asarray(J, np.float64)
        S.v[i] += J * m.body_inv_mass[i]
        if point is not None:
            r = np.asarray(point, np.float64) - S.x[i]
            S.w[i] += m.inv_inertia_world(S.q[i], i, cross(r, J))
        self._changed(i)

    def _changed(self, i: int) -> None:
        """Body i's state was set from outside the step: wake it, and reload the ODE path's Y."""
        self.wake(i)
        if self.ode is not None:
            self.ode.load()

    def set_pose(self, i: int, position=None, orientation=None) -> None:
        if position is not None:
            self.state.x[i] = position
        if orientation is not None:
            self.state.q[i] = quat.normalize(np.asarray(orientation, np.float64))
        self._changed(i)

    def set_velocity(self, i: int, velocity=None, angular_velocity=None) -> None:
        if velocity is not None:
            self.state.v[i] = velocity
        if angular_velocity is not None:
            self.state.w[i] = angular_velocity
        self._changed(i)

    def body_state(self, i: int) -> dict:
        S = self.state
        return dict(position=S.x[i].copy(), orientation=S.q[i].copy(), velocity=S.v[i].copy(),
                    angular_velocity=S.w[i].copy())
