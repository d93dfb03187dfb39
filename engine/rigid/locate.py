"""Impacts of rigid bodies located in time inside a step on the ODE path (as the particles' are,
:mod:`engine.ode.events`; NUMERICS.md, "Collisions"; Baraff's notes §8: find the time of
collision, back up to it, apply the impulse, go on).

Rules, for a step from Y₀ at t to Y₁ at t + h taken by the path's own step function:

1. An *impact* is a contact key (a, b) — a body against the scene's static shape k (b = −1 − k)
   or against another body — whose depth d (m, > 0 inside) is positive at Y₁, whose points
   approach faster than the resting threshold 2|g|h (slower ones are resting contact, held by the
   end-of-step projection) and that was apart by more than :data:`TOUCHING` at Y₀. A pair in
   contact at the step's start is never located again: resting contact never stalls the step.
2. Its time is the root τ ∈ (0, h) of D(τ) = max over the impacts of d at Y(τ), Y(τ) being the
   same step function taken from Y₀ for τ (so the state there has the method's own accuracy and,
   under step doubling, its own error estimate): the Illinois variant of regula falsi (bracketed,
   superlinear; Dowell & Jarratt 1971), stopping when |D| is within :data:`LOCATE_TOL` plus the
   coordinates' rounding, or after :data:`ITERATIONS` evaluations (then the last time still
   apart: the response's margin still meets the contact).
3. The step is ended at τ, the contacts respond there (the path's projection and Baraff's
   impulse), and the rest of the step is taken from there, at most :data:`MAX_EVENTS` times a
   step (a bouncing body's Zeno tail falls to the projection).

A step with nothing to meet pays one narrow phase at Y₁ (the pair list of the broad phase is
kept between steps, :class:`~engine.rigid.broad.PairList`); a step with an impact pays one
step and one narrow phase of the impact's bodies per evaluation.
"""
from __future__ import annotations

import numpy as np

from . import collide, quat
from .quat import cross

LOCATE_TOL = 1e-10  # m: an impact is located where its depth is within this of zero (+ rounding)
TOUCHING = 1e-6  # m: a pair this close (or closer) at the step's start is in contact, not an impact
ITERATIONS = 40  # evaluations of D per located impact, at most
MAX_EVENTS = 4  # located impacts per step, at most
EPS_BAND = 16 * 2.0 ** -52  # relative rounding of a coordinate (engine.ode.events' band)


def contacts(own, y, margins, mask):
    """Every contact of the bodies in ``mask`` ((B,) bool) at the state ``y`` ((B, 14) float64:
    x, q, P, L), each body grown by ``margins`` ((B,) m): arrays (a, b, p, n, depth) with b = −1 − k
    for the scene's static shape k and b ≥ 0 a body; p the midpoint of the two surface points and
    n pointing from b to a (the same narrow phases as the step's response)."""
    m = own.model
    x, q = y[:, 0:3], y[:, 3:7]
    bodies = np.flatnonzero(mask)
    R = quat.matrix(q) if len(own.specs) else None
    pos = own.control.collider_positions(own.t) if own.specs else None
    a, b, pa, pb, n = [], [], [], [], []
    for k, spec in enumerate(own.specs):
        if spec.kind == "plane":
            nrm = np.asarray(spec.normal, np.float64)
            nrm = nrm / np.linalg.norm(nrm)
            idx, pas, pbs = collide.plane_contacts(m, x, R, pos[k], nrm, margins, bodies)
            a.append(idx)
            pa.append(pas)
            pb.append(pbs)
            n.append(np.broadcast_to(nrm, pas.shape))
        else:
            rows = own.static_shape_contacts(k, spec, pos[k], own.t, x, R, margins, bodies)
            a.append(np.array([r[0] for r in rows], np.int64))
            for col, c in ((pa, 1), (pb, 2), (n, 3)):
                col.append(np.array([r[c] for r in rows], np.float64).reshape(-1, 3))
        b.append(np.full(len(a[-1]), -1 - k, np.int64))
    if m.count > 1:
        got = own.pair_contacts(x, None, margins, mask & m.dynamic, q=q)
        if got is not None:
            for col, v in zip((a, b, pa, pb, n), got):
                col.append(np.asarray(v))
    if not a:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    a, b = np.concatenate(a).astype(np.int64), np.concatenate(b).astype(np.int64)
    pa, pb, n = (np.concatenate(c).reshape(-1, 3) for c in (pa, pb, n))
    return a, b, 0.5 * (pa + pb), n, np.einsum("ij,ij->i", pb - pa, n)


def point_velocity(model, y, i, p):
    """Velocities (K, 3) of the points p (K, 3) of bodies i (K,) (b < 0: the world, at rest)."""
    out = np.zeros((len(i), 3))
    body = i >= 0
    if body.any():
        k = i[body]
        qk, L = y[k, 3:7], y[k, 10:13]
        w = quat.rotate(qk, model.body_inv_inertia[k] * quat.rotate_inv(qk, L))
        out[body] = y[k, 7:10] * model.body_inv_mass[k][:, None] + cross(w, p[body] - y[k, 0:3])
    return out


def depth_by_key(a, b, depth) -> dict:
    """{(a, b): the deepest depth of that pair}."""
    out = {}
    for key, d in zip(zip(a.tolist(), b.tolist()), depth.tolist()):
        if key not in out or d > out[key]:
            out[key] = d
    return out


def impacts(own, y0, y1, h, gl):
    """The impacts of a step from y0 (a callable returning it: read only when needed) to y1 (rule 1): ({(a, b): (depth at y0, depth at y1)}, the
    bodies they involve ((B,) bool), the query margins ((B,) m: how far each body's surface moved
    in the step, so every impact's depth is defined all along it))."""
    m = own.model
    a, b, p, n, d = contacts(own, y1, np.zeros(m.count), m.dynamic)
    if not len(a):
        return {}, None, None
    vn = np.einsum("ij,ij->i", point_velocity(m, y1, a, p) - point_velocity(m, y1, b, p), n)
    hit = (d > 0.0) & (-vn > 2.0 * gl * h)
    if not hit.any():
        return {}, None, None
    mask = np.zeros(m.count, bool)
    mask[a[hit]] = True
    mask[b[hit][b[hit] >= 0]] = True
    y0 = y0()
    q, L = y1[:, 3:7], y1[:, 10:13]
    spin = np.linalg.norm(quat.rotate(q, m.body_inv_inertia * quat.rotate_inv(q, L)), axis=1)
    moved = np.linalg.norm(y1[:, 0:3] - y0[:, 0:3], axis=1) + h * spin * m.body_bound
    margins = np.where(mask, moved, 0.0) + 2.0 * TOUCHING
    before = depth_by_key(*_keyed(contacts(own, y0, margins, mask)))
    far = -2.0 * float(margins.max())  # apart beyond the query: as far as it reaches, or farther
    keys = {}
    for key, d1 in depth_by_key(a[hit], b[hit], d[hit]).items():
        d0 = before.get(key, far)
        if d0 < -TOUCHING:  # apart at the start
            keys[key] = (d0, d1)
    return keys, mask, margins


def _keyed(c):
    a, b, _p, _n, d = c
    return a, b, d


def locate(own, y0, y1, h, gl, step_to):
    """The time τ ∈ (0, h) of the step's first impact (rules 1–2), or None. ``y0``: a callable
    returning the step's start (B, 14); ``step_to(τ)``: the state (B, 14) after the path's step
    function is taken from there for τ."""
    keys, mask, margins = impacts(own, y0, y1, h, gl)
    if not keys:
        return None
    far = -2.0 * float(margins.max())

    def D(y):
        got = depth_by_key(*_keyed(contacts(own, y, margins, mask)))
        return max(got.get(k, far) for k in keys)

    lo, flo = 0.0, max(d0 for d0, _ in keys.values())
    hi, fhi = h, max(d1 for _, d1 in keys.values())
    band = LOCATE_TOL + EPS_BAND * (1.0 + float(np.abs(y1[:, 0:3]).max()))
    side = 0
    for _ in range(ITERATIONS):
        c = hi - fhi * (hi - lo) / (fhi - flo)
        if not lo < c < hi:
            c = 0.5 * (lo + hi)
        fc = D(step_to(c))
        if abs(fc) <= band:
            return c
        if fc > 0.0:  # Illinois: halve the end that stays, so neither end sticks
            hi, fhi = c, fc
            if side == -1:
                flo *= 0.5
            side = -1
        else:
            lo, flo = c, fc
            if side == 1:
                fhi *= 0.5
            side = 1
        if hi - lo <= 4.0 * 2.0 ** -52 * h:
            break
    return lo if lo > 0.0 else None
