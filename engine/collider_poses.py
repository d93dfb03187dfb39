"""Where the shape table's shapes are: the host's copy of their poses and the launches that write
them into the table's fields (engine.colliders).

A shape's pose is set from the scene's Control before each step (:meth:`ShapePoses.follow`), or
by a caller (:meth:`ShapePoses.move_to`): its position and the velocity over the step and,
where a shape turns, its normal, box axes and ω, in one launch (:func:`_pose_fields`) — rows the
host computes, not a ``from_numpy`` a field. The host keeps
each shape's position, orientation and ω (what :meth:`~ShapePoses.pose` reports and what the
renderer's kept background redraws around, :meth:`~ShapePoses.shown_bounds`), and reuses a
shape's orientation row while its orientation and ω are unchanged (exact: the row is a function
of them and the spec alone).
"""
# (no __future__ annotations: Taichi reads the kernels' annotations)

import numpy as np
import taichi as ti

from .geometry.shapes import BOX, CAPSULE, PLANE, SPHERE, quat_matrix_t, quat_normalize_t
from . import runtime
from .launch import fast

IDENTITY = (1.0, 0.0, 0.0, 0.0)
SERIAL_SHAPES = 4096  # shapes posed on the launching thread, at most (CPU: engine.runtime.one_thread)


@ti.kernel
def _pose_fields(point: ti.template(), vel: ti.template(), normal: ti.template(), axis_x: ti.template(),
                 axis_z: ti.template(), omega: ti.template(), rows: ti.types.ndarray(), place: ti.template(),
                 turn: ti.template(), boxes: ti.template(), spins: ti.template(), serial: ti.template()):
    """Every shape's pose from rows (n, 6 [place] + 12 [turn]) in the fields' dtype: position and
    velocity over the step (``place``: x, y, z, vx, vy, vz), then (``turn``) the normal, the box
    axes x and z (``boxes``) and ω (``spins``). One launch a step where a field's ``from_numpy``
    costs ~0.2–0.35 ms of Python each (crates' particles place 25 turning shapes a step); a
    second launch for the turning half cost ~0.14 ms more (debris: follow 5.4–5.7 → 4.7–5.0 ms
    for five a frame). ``serial``: on the launching thread (a few shapes on the CPU:
    engine.runtime.one_thread)."""
    o = ti.static(6 if place else 0)
    ti.loop_config(serialize=serial)
    for k in range(rows.shape[0]):
        for c in ti.static(range(3)):
            if ti.static(place):
                point[k][c] = rows[k, c]
                vel[k][c] = rows[k, 3 + c]
            if ti.static(turn):
                normal[k][c] = rows[k, o + c]
                if ti.static(boxes):
                    axis_x[k][c] = rows[k, o + 3 + c]
                    axis_z[k][c] = rows[k, o + 6 + c]
                if ti.static(spins):
                    omega[k][c] = rows[k, o + 9 + c]


_pose_fields = fast(_pose_fields)  # (engine.launch: without Taichi's per-call Python)


class ShapePoses:
    """The pose half of :class:`~engine.colliders.Colliders` (a mixin: the table's ``specs``,
    ``kinds``, ``spins``, fields and host arrays ``_pos``, ``_quat``, ``_omega`` are its)."""

    def _orient(self, quats, omegas) -> None:
        """Orientations (count, 4) and angular velocities (count, 3) at the current placement:
        the normals, capsule axes and box axes written to the fields. A plane left at its rest
        orientation keeps its configured normal exactly (no rotation arithmetic)."""
        if self.count == 0:
            return False
        # a shape whose orientation and ω are what they were at the last call keeps its row (resting
        # bodies published as shapes: most of a pile's, a step after step); the row is a function
        # of those inputs and the spec alone, so reusing it is exact. Per shape on Python floats
        # (engine.geometry.shapes' ``*_t``): a few shapes' arithmetic costs less so than in arrays.
        n = self.count
        Q = np.asarray(quats, np.float64).reshape(n, 4)
        W = np.asarray(omegas, np.float64).reshape(n, 3)
        qb, wb = Q.tobytes(), W.tobytes()
        keys = [qb[32 * k: 32 * k + 32] + wb[24 * k: 24 * k + 24] for k in range(n)]
        todo = [k for k in range(n) if keys[k] != self._orient_keys[k]]
        if not todo:
            return False
        Ql, Wl = Q.tolist(), W.tolist()
        for k in todo:  # (checked before anything is written: a refused call changes nothing)
            if any(Wl[k]) and not self.spins[k]:
                raise ValueError(f"angular_velocity: collider {self.specs[k].name or k!r} was built without "
                                 f"rotation (give it an angular_velocity or rotates = true); got {Wl[k]}")
        qs = {k: quat_normalize_t(*Ql[k]) for k in todo}
        rows = self._orient_rows  # normal, axis x, axis z, angular velocity
        for k in todo:
            q, w = qs[k], Wl[k]
            self._quat[k], self._omega[k] = q, w
            m = quat_matrix_t(q)  # row-major: the body's x, y, z axes are its columns
            if self.kinds[k] in (CAPSULE, BOX):
                normal = (m[1], m[4], m[7])
            else:  # a plane's normal (at its rest orientation exactly as configured)
                n0 = np.asarray(self.specs[k].normal, np.float64)
                n0 = n0 / np.linalg.norm(n0)
                normal = n0 if q == IDENTITY else np.array(m, np.float64).reshape(3, 3) @ n0
            rows[k, 0:3] = normal
            rows[k, 3:12] = (m[0], m[3], m[6], m[2], m[5], m[8], *w)
            self._orient_keys[k] = keys[k]
        return True

    def _write(self, place_rows=None, turned: bool = False) -> None:
        """Write :meth:`_pose_row`'s rows (``place_rows``) and, where ``turned``, the orientation
        rows :meth:`_orient` left, into the fields: one launch (none for nothing)."""
        parts = ([] if place_rows is None else [place_rows]) + ([self._orient_rows.astype(self._np)] if turned else [])
        if not parts:
            return
        rows = parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)
        boxes, f = BOX in self.kinds, self.collider_normal
        _pose_fields(self.collider_point, self.collider_vel, f, self.collider_axis_x if boxes else f,
                     self.collider_axis_z if boxes else f, self.collider_omega if self.rotating else f,
                     rows, place_rows is not None, turned, boxes, self.rotating,
                     runtime.one_thread(self.count, SERIAL_SHAPES))

    def reset(self) -> None:
        """Back where the specs start, at rest, at t = 0 (a reused scene)."""
        if self._moved:
            for k, s in enumerate(self.specs):
                self._pos[k] = s.position_at(0.0)
            self.collider_point.from_numpy(self._pos)
            self.collider_vel.from_numpy(np.zeros_like(self._pos))
        if self._turned or self.rotating:
            self._write(turned=self._orient([s.orientation_at(0.0) for s in self.specs],
                                            [s.angular_velocity for s in self.specs]))
        self._t, self._moved, self._turned = 0.0, False, False

    def _placed(self, positions) -> np.ndarray:
        return np.asarray(positions, np.float64).reshape(self.count, 3).astype(self._np)

    def _pose_row(self, t: float, positions, since) -> np.ndarray:
        """:meth:`move_to`'s placement on the host: positions and velocities (n, 6) in the fields'
        dtype, the host copy left there (the fields are the caller's to write)."""
        new = self._placed([s.position_at(t) for s in self.specs] if positions is None else positions)
        t0, old = (since[0], self._placed(since[1])) if since is not None else (self._t, self._pos[: self.count])
        dt = t - t0
        vel = (new - old) / dt if dt > 0 else np.zeros_like(new)
        self._pos[: self.count] = new
        self._t, self._moved = t, True
        v = np.zeros_like(self._pos)
        v[: self.count] = vel
        return np.concatenate([self._pos, v], axis=1)

    def poses_over(self, control, steps) -> np.ndarray:
        """Where ``control`` has the shapes over each step (t0, t1) of ``steps``, as :meth:`follow`
        places them, as rows (len(steps), n, 6) for a launch that runs those steps to write (a
        soft body's fused frame, engine.springs.fused); the host copy is left at the last step.
        Only for shapes that move without turning (the caller checks)."""
        # _pose_row's arithmetic step by step, without its per-call overhead (a hair frame's 12
        # steps were ~1 ms of Python): a time's positions read once (keyed by its exact value),
        # the velocity (new − old) / dt with dt as the caller's times give it (its type sets the
        # division's precision, as in _pose_row)
        at = {}

        def placed(t):
            key = float(t)
            if key not in at:
                at[key] = self._placed(control.collider_positions(t))
            return at[key]

        steps = list(steps)
        rows = np.zeros((len(steps),) + self._pos.shape[:1] + (6,), self._pos.dtype)
        rows[:, :, :3] = self._pos  # (the rows past count keep the host copy's positions)
        for k, (t0, t1) in enumerate(steps):
            new, dt = placed(t1), t1 - t0
            rows[k, : self.count, :3] = new
            if dt > 0:
                rows[k, : self.count, 3:] = (new - placed(t0)) / dt
        self._pos[: self.count] = rows[-1, : self.count, :3]
        self._t, self._moved = steps[-1][1], True
        return rows

    def move_to(self, t: float, positions=None, since=None, orientations=None, omegas=None) -> None:
        """Set the shapes' positions for time t (``positions`` (count, 3), else from their
        specs' paths). Their velocities: over the step ``since = (t0, positions at t0)`` when
        given (a step's start, so a retried shorter step infers the same motion), else from the
        motion since the last call. ``orientations`` (count, 4) [w, x, y, z] at t and ``omegas``
        (count, 3) rad/s over the step: given, or (a table with spinning shapes) from the specs."""
        if self.count == 0:
            return
        turned = False
        if orientations is not None or omegas is not None or self.rotating:
            qs = [s.orientation_at(t) for s in self.specs] if orientations is None else orientations
            ws = [s.angular_velocity for s in self.specs] if omegas is None else omegas
            turned = self._orient(qs, ws)  # first: it checks before it changes anything
            self._turned = True
        self._write(self._pose_row(t, positions, since), turned)

    def follow(self, control, t0: float, t1: float) -> bool:
        """Place the shapes where ``control`` (engine.control) has them at t1, moving since t0
        (the step's start): positions, and orientations with their angular velocities when some
        shape turns. Whether anything moves (nothing is written otherwise)."""
        if not (self.count and control.colliders_move):
            return False
        turn = self.rotating or control.colliders_turn
        self.move_to(t1, control.collider_positions(t1), since=(t0, control.collider_positions(t0)),
                     orientations=control.collider_orientations(t1) if turn else None,
                     omegas=control.collider_omegas() if turn else None)
        return True

    def pose(self, k: int) -> dict:
        """Shape k as placed now: ``position`` (3,), ``orientation`` [w, x, y, z], ``velocity``,
        ``angular_velocity`` (float64 copies of the host's values)."""
        return dict(position=self._pos[k].astype(np.float64), orientation=self._quat[k].copy(),
                    velocity=self.collider_vel[k].to_numpy().astype(np.float64),
                    angular_velocity=self._omega[k].copy())

    def shown_bounds(self) -> list:
        """Each drawn shape as placed now: (its pose as bytes, centre (3,) float64 m, bounding
        radius m; inf for a plane; radii and extents never change). What a kept background redraws
        around when some of them move (engine.render.renderer): only the screen rectangles a moved
        shape left and entered. Read from the host copy, so it costs no kernel launch; a rigid
        body's own shape is drawn by the body, not here."""
        out = []
        for k, s in enumerate(self.specs):
            if not s.visible:
                continue
            kind = self.kinds[k]
            bound = (float("inf") if kind == PLANE else float(s.radius) if kind == SPHERE
                     else float(np.linalg.norm(s.half_extents)) if kind == BOX
                     else float(s.half_length) + float(s.radius))
            out.append((self._pos[k].tobytes() + self._quat[k].tobytes(), self._pos[k].astype(np.float64), bound))
        return out
