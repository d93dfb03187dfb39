"""Joints for the XPBD path (Müller et al. 2020 §3.3–3.4), each solved in config order every
substep, before the contacts:

* ``ball``: the anchor points of a and b coincide (a positional constraint);
* ``hinge``: ball + the hinge axes of a and b aligned (an angular constraint turning a's axis onto
  b's); ``limits`` (degrees): the angle of a about the axis relative to b, measured from t = 0,
  clamped to [min, max] by a turn about the axis;
* ``fixed``: ball + the relative orientation of t = 0 held;
* ``distance``: |p_b − p_a| kept within ``limits`` (m; default: the distance at t = 0).
``compliance`` α (m/N, rad/(N·m)): α̃ = α/h², 0 = rigid. b = "world": a point fixed in space.

The point constraints (the ball part of ball, hinge and fixed joints) of joints that share a
moving body are not solved one by one but together, by a direct solve of their linearised system
each substep (:meth:`Joints.direct_plan`, ``direct`` in :mod:`.kernel`): one Gauss–Seidel pass
cannot carry a large mass ratio along a chain (1 kg hanging from 1 g opened its joints by 1.5 m in
2 s; 64 passes a substep still by 2.5 mm), a direct solve does (Deul, Kugelstadt, Weiler, Bender
2018, "Direct Position-Based Solver for Stiff Rods", for XPBD joints in a tree; Baraff 1996,
"Linear-Time Dynamics using Lagrange Multipliers"). Angular parts and distance joints stay
Gauss–Seidel."""
from __future__ import annotations

import math

import numpy as np

from . import quat
from .quat import cross
from .elements import JOINT_CODES


def _perp(v):
    t = np.array([1.0, 0.0, 0.0]) if abs(v[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    p = cross(v, t)
    return p / np.linalg.norm(p)


class Joints:
    """The joints of a scene, built from config entries against the bodies at t = 0."""

    def __init__(self, entries, model, state):
        self.rows = []
        self._moving = np.asarray(model.dynamic, bool).copy()
        for j in entries:
            a = model.index(j.bodies[0])
            b = -1 if j.bodies[1] == "world" else model.index(j.bodies[1])
            xa, qa = state.x[a], state.q[a]
            xb, qb = (state.x[b], state.q[b]) if b >= 0 else (np.zeros(3), np.array([1.0, 0, 0, 0]))
            anchor = np.asarray(j.anchor if j.anchor is not None else (xa if b < 0 else 0.5 * (xa + xb)), np.float64)
            axis = np.asarray(j.axis, np.float64)
            axis = axis / np.linalg.norm(axis)
            perp = _perp(axis)
            row = dict(type=j.type, a=a, b=b, compliance=float(j.compliance),
                       ra=quat.rotate_inv(qa, anchor - xa),
                       rb=quat.rotate_inv(qb, anchor - xb) if b >= 0 else anchor,
                       axis_a=quat.rotate_inv(qa, axis), axis_b=quat.rotate_inv(qb, axis),
                       perp_a=quat.rotate_inv(qa, perp), perp_b=quat.rotate_inv(qb, perp),
                       q_rel=quat.mul(quat.conj(qb), qa), lam=np.zeros(3))
            if j.type == "distance":
                other = np.asarray(j.anchor_b if j.anchor_b is not None else (xb if b >= 0 else anchor), np.float64)
                row["rb"] = quat.rotate_inv(qb, other - xb) if b >= 0 else other
                d0 = float(np.linalg.norm(other - anchor))
                row["limits"] = tuple(j.limits) if j.limits is not None else (d0, d0)
            elif j.type == "hinge" and j.limits is not None:
                row["limits"] = (math.radians(j.limits[0]), math.radians(j.limits[1]))
            self.rows.append(row)

    def __len__(self):
        return len(self.rows)

    def _poses(self, S, r):
        a, b = r["a"], r["b"]
        qa = S.q[a]
        qb = S.q[b] if b >= 0 else np.array([1.0, 0.0, 0.0, 0.0])
        ra = quat.rotate(qa, r["ra"])
        rb = quat.rotate(qb, r["rb"]) if b >= 0 else np.zeros(3)
        pa = S.x[a] + ra
        pb = S.x[b] + rb if b >= 0 else r["rb"]
        return qa, qb, ra, rb, pa, pb

    def hinge_angle(self, S, k: int) -> float:
        """The angle (rad) of joint k's body a about its axis relative to b, 0 at t = 0."""
        r = self.rows[k]
        qa, qb, *_ = self._poses(S, r)
        n = quat.rotate(qa, r["axis_a"])
        ua, ub = quat.rotate(qa, r["perp_a"]), quat.rotate(qb, r["perp_b"])
        return math.atan2(float(np.dot(cross(ub, ua), n)), float(np.dot(ub, ua)))

    def gap(self, S, k: int) -> float:
        """How far apart joint k's two anchor points are now (m): its error for ball, hinge and
        fixed joints."""
        *_, pa, pb = self._poses(S, self.rows[k])
        return float(np.linalg.norm(pb - pa))

    def direct_plan(self):
        """The joints whose point constraints are solved together (see the module's docstring):
        the ball, hinge and fixed joints that share a moving (not fixed, not kinematic) body with
        another of them, in config order; an isolated joint gains nothing over its own
        Gauss–Seidel step (one joint's 3×3 system is what that step solves), so a scene without
        such pairs pays nothing. Returns ``flag`` (nj,) 1 for those joints, ``order`` (nd,) their
        indices, and the skyline (envelope) layout of the 3·nd rows of the system's lower
        triangle: ``first`` (3·nd,), the first column stored for each row (the block of the first
        joint in the order that shares a moving body with the row's joint; the envelope is kept by
        the factorisation, so a chain in order has a band of two blocks), ``offset`` (3·nd,) where
        each row starts, and ``size``, the entries in all."""
        R = self.rows
        mv = self._moving
        bodies = [{i for i in (r["a"], r["b"]) if i >= 0 and mv[i]} if r["type"] != "distance" else set()
                  for r in R]
        order = [k for k in range(len(R)) if any(bodies[k] & bodies[o] for o in range(len(R)) if o != k)]
        first, offset, size = [], [], 0
        for p, k in enumerate(order):
            fp = next(p2 for p2 in range(p + 1) if bodies[order[p2]] & bodies[k])
            for c in range(3):
                r = 3 * p + c
                first.append(3 * fp)
                offset.append(size)
                size += r - 3 * fp + 1
        flag = np.zeros(len(R), np.int32)
        flag[order] = 1
        return dict(flag=flag, order=np.array(order, np.int32), first=np.array(first, np.int32),
                    offset=np.array(offset, np.int32), size=size)

    def arrays(self):
        """The joints as the kernel takes them (engine.rigid.kernel.run): count, type, a, b,
        anchors, axes, reference perpendiculars, relative orientation, limits, compliance."""
        R = self.rows
        f3 = lambda k: np.array([r[k] for r in R], np.float64).reshape(-1, 3)
        lo = [r.get("limits", (0.0, 0.0))[0] for r in R]
        hi = [r.get("limits", (0.0, 0.0))[1] for r in R]
        return (len(R), np.array([JOINT_CODES[r["type"]] for r in R], np.int32),
                np.array([r["a"] for r in R], np.int32), np.array([r["b"] for r in R], np.int32),
                f3("ra"), f3("rb"), f3("axis_a"), f3("axis_b"), f3("perp_a"), f3("perp_b"),
                np.array([r["q_rel"] for r in R], np.float64).reshape(-1, 4), np.array(lo, np.float64),
                np.array(hi, np.float64), np.array([int("limits" in r) for r in R], np.int32),
                np.array([r["compliance"] for r in R], np.float64))
