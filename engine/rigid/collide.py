"""Contacts of rigid bodies: with the scene's planes and spheres, and with each other.

Found once per rigid step (Müller et al. 2020 §3.5: collision detection once per step, the
contact's depth re-measured at every substep from the bodies' poses) with a speculative margin:
a pair closer than what the step's motion can close is a contact, so a fast small body meets the
ground in the step it would pass it (no tunnelling).

Each contact is (a, b, p_a, p_b, n): body a, body b (−1: a static shape of the scene), the
deepest point of a and the matching point of b (world), and the unit normal n from b to a, so the
depth is (p_b − p_a)·n (> 0: overlapping). Pairs: the broad phase over bounding spheres
(:mod:`.broad`: a uniform grid, kept as a pair list; the order is fixed), then per pair of shapes: sphere and capsule (segment closest points),
box–plane (corners), box–sphere (closest point), box–box (separating axes, the reference face
clipping the incident face: a manifold of up to 8 points; edge–edge: one point)."""
from __future__ import annotations

import numpy as np

from .shapes import BOX, CAPSULE, SPHERE

EPS = 1e-12


def segment(x, R, l):
    """End points of a capsule's segment (local y)."""
    ax = R[:, 1] * l
    return x - ax, x + ax


def closest_on_segment(p0, p1, c):
    d = p1 - p0
    t = np.clip(np.dot(c - p0, d) / max(np.dot(d, d), EPS), 0.0, 1.0)
    return p0 + t * d


def segments_closest(p0, p1, q0, q1):
    """Closest points of segments p0p1 and q0q1 (Ericson, Real-Time Collision Detection §5.1.9)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, f = np.dot(d1, d1), np.dot(d2, d2), np.dot(d2, r)
    c, b = np.dot(d1, r), np.dot(d1, d2)
    den = a * e - b * b
    s = np.clip((b * f - c * e) / den, 0.0, 1.0) if den > EPS else 0.0
    t = (b * s + f) / e if e > EPS else 0.0
    if t < 0.0:
        t, s = 0.0, np.clip(-c / a, 0.0, 1.0) if a > EPS else 0.0
    elif t > 1.0:
        t, s = 1.0, np.clip((b - c) / a, 0.0, 1.0) if a > EPS else 0.0
    return p0 + s * d1, q0 + t * d2


def spheres(ca, ra, cb, rb, margin, fallback=(0.0, 1.0, 0.0)):
    d = ca - cb
    dist = np.linalg.norm(d)
    if dist - ra - rb > margin:
        return []
    n = d / dist if dist > EPS else np.asarray(fallback, np.float64)
    return [(ca - ra * n, cb + rb * n, n)]


def point_box(c, xb, Rb, hb):
    """(closest point of the box to c, whether c is inside)."""
    loc = Rb.T @ (c - xb)
    cl = np.clip(loc, -hb, hb)
    return xb + Rb @ cl, bool(np.all(np.abs(loc) <= hb)), loc


def sphere_box(ca, ra, xb, Rb, hb, margin):
    p, inside, loc = point_box(ca, xb, Rb, hb)
    if not inside:
        return spheres(ca, ra, p, 0.0, margin)
    k = int(np.argmax(np.abs(loc) - hb))  # the face the centre is nearest to
    s = 1.0 if loc[k] >= 0 else -1.0
    n = s * Rb[:, k]
    face = loc.copy()
    face[k] = s * hb[k]
    return [(ca - ra * n, xb + Rb @ face, n)]


def _clip(poly, t, h):
    """Keep the part of polygon ``poly`` with p·t ≤ h (Sutherland–Hodgman)."""
    out = []
    m = len(poly)
    for i in range(m):
        p, q = poly[i], poly[(i + 1) % m]
        dp, dq = np.dot(p, t) - h, np.dot(q, t) - h
        if dp <= 0:
            out.append(p)
        if dp * dq < 0:
            out.append(p + (q - p) * (dp / (dp - dq)))
    return out


def box_box(xa, Ra, ha, xb, Rb, hb, margin):
    """Separating axes over the 15 candidates; the least-overlapping axis, faces preferred over
    edge pairs unless clearly better."""
    d = xb - xa
    face_best, face_axis = -np.inf, None
    edge_best, edge_axis = -np.inf, None
    for k in range(15):
        if k < 3:
            L = Ra[:, k]
        elif k < 6:
            L = Rb[:, k - 3]
        else:
            L = np.cross(Ra[:, (k - 6) // 3], Rb[:, (k - 6) % 3])
            ln = np.linalg.norm(L)
            if ln < 1e-6:
                continue
            L = L / ln
        sep = abs(np.dot(d, L)) - np.dot(ha, np.abs(Ra.T @ L)) - np.dot(hb, np.abs(Rb.T @ L))
        if sep > margin:
            return []
        if k < 6 and sep > face_best:
            face_best, face_axis = sep, k
        elif k >= 6 and sep > edge_best:
            edge_best, edge_axis = sep, (k, L)
    if edge_axis is not None and edge_best > face_best + 1e-3 + 0.05 * abs(face_best):
        k, L = edge_axis
        if np.dot(d, L) < 0:
            L = -L  # from a toward b
        i, j = (k - 6) // 3, (k - 6) % 3
        pa = xa + sum(ha[m] * np.sign(np.dot(Ra[:, m], L)) * Ra[:, m] for m in range(3) if m != i)
        pb = xb - sum(hb[m] * np.sign(np.dot(Rb[:, m], L)) * Rb[:, m] for m in range(3) if m != j)
        ca, cb = segments_closest(pa - ha[i] * Ra[:, i], pa + ha[i] * Ra[:, i],
                                  pb - hb[j] * Rb[:, j], pb + hb[j] * Rb[:, j])
        return [(ca, cb, -L)]
    # face: the reference box owns the axis; clip the other box's most opposed face against it
    a_ref = face_axis < 3
    xr, Rr, hr, xi, Ri, hi = (xa, Ra, ha, xb, Rb, hb) if a_ref else (xb, Rb, hb, xa, Ra, ha)
    ax = face_axis % 3
    u = Rr[:, ax] * (1.0 if np.dot(xi - xr, Rr[:, ax]) >= 0 else -1.0)  # ref face normal, toward inc
    m = int(np.argmax(np.abs(Ri.T @ u)))
    ni = Ri[:, m] * (-1.0 if np.dot(Ri[:, m], u) > 0 else 1.0)
    c_inc = xi + hi[m] * ni
    j1, j2 = (m + 1) % 3, (m + 2) % 3
    e1, e2 = Ri[:, j1] * hi[j1], Ri[:, j2] * hi[j2]
    poly = [c_inc + e1 + e2, c_inc - e1 + e2, c_inc - e1 - e2, c_inc + e1 - e2]
    for t in ((ax + 1) % 3, (ax + 2) % 3):
        for s in (1.0, -1.0):
            tw = s * Rr[:, t]
            poly = _clip(poly, tw, np.dot(xr, tw) + hr[t])
            if not poly:
                return []
    c_ref = xr + hr[ax] * u
    out = []
    for p in poly:
        s = np.dot(p - c_ref, u)
        if s < margin:
            q = p - s * u
            out.append((q, p, -u) if a_ref else (p, q, u))
    return out


def capsule_box(xa, Ra, ra, la, xb, Rb, hb, margin):
    p0, p1 = segment(xa, Ra, la)
    out = []
    for c in (p0, p1):
        out += sphere_box(c, ra, xb, Rb, hb, margin)
    return out


def pair(sa, sb, xa, Ra, xb, Rb, ga, gb, margin):
    """Contacts between two bodies (shape codes sa, sb; ``ga``/``gb``: (radius, half extents,
    half length)): a list of (p_a, p_b, n)."""
    if sa > sb:
        return [(pb, pa, -n) for pa, pb, n in pair(sb, sa, xb, Rb, xa, Ra, gb, ga, margin)]
    ra, ha, la = ga
    rb, hb, lb = gb
    if sa == SPHERE and sb == SPHERE:
        return spheres(xa, ra, xb, rb, margin)
    if sa == SPHERE and sb == BOX:
        return sphere_box(xa, ra, xb, Rb, hb, margin)
    if sa == SPHERE and sb == CAPSULE:
        return spheres(xa, ra, closest_on_segment(*segment(xb, Rb, lb), xa), rb, margin)
    if sa == BOX and sb == BOX:
        return box_box(xa, Ra, ha, xb, Rb, hb, margin)
    if sa == BOX and sb == CAPSULE:
        return [(pb, pa, -n) for pa, pb, n in capsule_box(xb, Rb, rb, lb, xa, Ra, ha, margin)]
    # capsule–capsule
    ca, cb = segments_closest(*segment(xa, Ra, la), *segment(xb, Rb, lb))
    return spheres(ca, ra, cb, rb, margin)


CORNERS = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], np.float64)


def plane_contacts(model, x, R, P, N, margins, bodies):
    """Contacts of ``bodies`` (indices) with the plane through P with unit normal N (b = −1), all
    at once: a box's corners, a sphere's centre, a capsule's two end centres (less their radius).
    Returns arrays (body, p_a, p_b), ordered by body, then point."""
    bodies = np.asarray(bodies, np.int64)
    kind = model.body_shape[bodies]
    blocks = []
    box = bodies[kind == BOX]
    if len(box):
        pts = x[box][:, None] + np.einsum("kcm,kvm->kvc", R[box], CORNERS[None] * model.body_half[box][:, None])
        blocks.append((np.repeat(box, 8), pts.reshape(-1, 3), np.zeros(8 * len(box))))
    sph = bodies[kind == SPHERE]
    if len(sph):
        blocks.append((sph, x[sph], model.body_radius[sph]))
    cap = bodies[kind == CAPSULE]
    if len(cap):
        ax = R[cap][:, :, 1] * model.body_half_length[cap][:, None]
        ends = np.stack([x[cap] - ax, x[cap] + ax], 1).reshape(-1, 3)
        blocks.append((np.repeat(cap, 2), ends, np.repeat(model.body_radius[cap], 2)))
    if not blocks:
        return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3))
    idx = np.concatenate([b[0] for b in blocks])
    pts = np.concatenate([b[1] for b in blocks])
    r = np.concatenate([b[2] for b in blocks])
    order = np.argsort(idx, kind="stable")
    idx, pts, r = idx[order], pts[order], r[order]
    s = (pts - P) @ N - r
    hit = s < margins[idx]
    pa = pts[hit] - r[hit][:, None] * N
    return idx[hit], pa, pa - s[hit][:, None] * N


def shape_collider_contacts(model, x, R, kind, C, Rc, geometry, margins, bodies):
    """Contacts of ``bodies`` with a static shape of ``kind`` (SPHERE, BOX or CAPSULE codes) at
    C turned by Rc (3, 3), ``geometry`` its (radius, half extents, half length), the bodies
    outside it: (body, p_a, p_b, n) rows, by body then point (the same closest points as two
    bodies, :func:`pair`)."""
    radius, half, half_length = geometry
    bound = {SPHERE: radius, BOX: float(np.linalg.norm(half)) if half is not None else 0.0,
             CAPSULE: radius + half_length}[kind]
    out = []
    for i in bodies:
        if np.linalg.norm(x[i] - C) - model.body_bound[i] - bound > margins[i]:
            continue
        g = (model.body_radius[i], model.body_half[i], model.body_half_length[i])
        for pa, pb, n in pair(model.body_shape[i], kind, x[i], R[i], C, Rc, g, geometry, margins[i]):
            out.append((i, pa, pb, n))
    return out


def sphere_collider_contacts(model, x, R, C, Rc, margins, bodies):
    """Contacts of ``bodies`` with a static sphere (centre C, radius Rc), the bodies outside it."""
    return shape_collider_contacts(model, x, R, SPHERE, C, np.eye(3), (Rc, None, 0.0), margins, bodies)


def _clip_batch(poly, n, t, h):
    """Sutherland–Hodgman for K polygons at once: ``poly`` (K, 8, 3) with ``n`` (K,) vertices
    each, kept where p·t ≤ h (t (K, 3), h (K,)). Returns (poly, n), at most 8 vertices."""
    K = len(poly)
    e = np.arange(poly.shape[1])
    valid = e[None, :] < n[:, None]
    d = np.einsum("kvc,kc->kv", poly, t) - h[:, None]
    nxt = np.where(e[None, :] + 1 < n[:, None], e[None, :] + 1, 0)
    rows = np.arange(K)[:, None]
    q, dq = poly[rows, nxt], d[rows, nxt]
    keep = valid & (d <= 0)
    cut = valid & (d * dq < 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        inter = poly + (q - poly) * np.where(cut, d / np.where(cut, d - dq, 1.0), 0.0)[..., None]
    out = np.empty((K, 2 * poly.shape[1], 3))
    out[:, 0::2], out[:, 1::2] = poly, inter
    mask = np.empty((K, 2 * poly.shape[1]), bool)
    mask[:, 0::2], mask[:, 1::2] = keep, cut
    order = np.argsort(~mask, axis=1, kind="stable")[:, :8]
    return out[rows, order], np.minimum(mask.sum(1), 8)


def box_box_batch(xa, Ra, ha, xb, Rb, hb, margin):
    """:func:`box_box` for K pairs at once (arrays with a leading K): separating axes in the
    closed form of Gottschalk et al. (OBBTree, 1996) on C = R_aᵀ R_b, the face case clipped for
    all pairs together. Returns arrays (pair index, p_a, p_b, n) ordered by pair, then by point
    (the edge case per pair)."""
    K = len(xa)
    out = []  # (pair indices, p_a, p_b, n) blocks
    if K == 0:
        return _blocks(out)
    d = xb - xa
    C = np.einsum("kmi,kmj->kij", Ra, Rb)
    A = np.abs(C) + 1e-12
    t = np.einsum("kmi,km->ki", Ra, d)
    sep_a = np.abs(t) - ha - np.einsum("kij,kj->ki", A, hb)
    tb = np.einsum("ki,kij->kj", t, C)
    sep_b = np.abs(tb) - np.einsum("ki,kij->kj", ha, A) - hb
    # edges: L_ij = e_i × c_j in a's frame (c_j: b's axis j there)
    c = np.moveaxis(C, 2, 1)  # (K, j, 3)
    z = np.zeros_like(c[..., 0])
    L = np.stack([np.stack([z, -c[..., 2], c[..., 1]], -1),
                  np.stack([c[..., 2], z, -c[..., 0]], -1),
                  np.stack([-c[..., 1], c[..., 0], z], -1)], 1)  # (K, i, j, 3)
    norm = np.linalg.norm(L, axis=-1)
    ok = norm > 1e-6
    proj_t = np.abs(np.einsum("kijm,km->kij", L, t))
    ra = np.einsum("kijm,km->kij", np.abs(L), ha)
    rb = np.einsum("kijn,kn->kij", np.abs(np.einsum("kijm,kmn->kijn", L, C)), hb)
    sep_e = np.where(ok, (proj_t - ra - rb) / np.where(ok, norm, 1.0), -np.inf).reshape(K, 9)
    face = np.concatenate([sep_a, sep_b], 1)
    face_best, face_axis = face.max(1), face.argmax(1)
    edge_best = sep_e.max(1)
    apart = (face_best > margin) | (edge_best > margin)
    edge = ~apart & (edge_best > face_best + 1e-3 + 0.05 * np.abs(face_best))
    for k in np.flatnonzero(edge):  # few: per pair
        got = box_box(xa[k], Ra[k], ha[k], xb[k], Rb[k], hb[k], margin[k])
        out += [(np.full(1, k), pa[None], pb[None], n[None]) for pa, pb, n in got]
    sel = np.flatnonzero(~apart & ~edge)
    if len(sel) == 0:
        return _blocks(out)
    fa = face_axis[sel]
    a_ref = fa < 3
    ax = fa % 3
    r = np.arange(len(sel))
    pick = lambda u, v: np.where(a_ref.reshape((-1,) + (1,) * (u.ndim - 1)), u, v)
    xr, Rr, hr = pick(xa[sel], xb[sel]), pick(Ra[sel], Rb[sel]), pick(ha[sel], hb[sel])
    xi, Ri, hi = pick(xb[sel], xa[sel]), pick(Rb[sel], Ra[sel]), pick(hb[sel], ha[sel])
    axis = Rr[r, :, ax]
    u = axis * np.where(np.einsum("kc,kc->k", xi - xr, axis) >= 0, 1.0, -1.0)[:, None]
    dots = np.einsum("kcm,kc->km", Ri, u)
    m = np.abs(dots).argmax(1)
    ni = Ri[r, :, m] * np.where(dots[r, m] > 0, -1.0, 1.0)[:, None]
    c_inc = xi + hi[r, m][:, None] * ni
    j1, j2 = (m + 1) % 3, (m + 2) % 3
    e1, e2 = Ri[r, :, j1] * hi[r, j1][:, None], Ri[r, :, j2] * hi[r, j2][:, None]
    poly = np.zeros((len(sel), 8, 3))
    poly[:, 0], poly[:, 1], poly[:, 2], poly[:, 3] = c_inc + e1 + e2, c_inc - e1 + e2, c_inc - e1 - e2, c_inc + e1 - e2
    n = np.full(len(sel), 4)
    for step in (1, 2):
        tt = (ax + step) % 3
        for s in (1.0, -1.0):
            tw = s * Rr[r, :, tt]
            poly, n = _clip_batch(poly, n, tw, np.einsum("kc,kc->k", xr, tw) + hr[r, tt])
    c_ref = xr + hr[r, ax][:, None] * u
    depth = np.einsum("kvc,kc->kv", poly - c_ref[:, None], u)
    valid = np.arange(8)[None, :] < n[:, None]
    # clipping on a face's own edge repeats a vertex (identical faces: 8 points for 4 corners);
    # a repeated point would weigh its corner twice and turn the box
    gap = np.linalg.norm(poly[:, :, None] - poly[:, None, :], axis=-1)
    earlier = np.tril(np.ones((8, 8), bool), -1)[None] & valid[:, None, :]
    repeat = ((gap < 1e-9 * (1.0 + np.abs(poly).max(-1)[:, :, None])) & earlier).any(2)
    good = valid & ~repeat & (depth < margin[sel][:, None])
    row, v = np.nonzero(good)
    p = poly[row, v]
    q = p - depth[row, v][:, None] * u[row]
    ref = a_ref[row][:, None]
    out.append((sel[row], np.where(ref, q, p), np.where(ref, p, q), np.where(ref, -u[row], u[row])))
    return _blocks(out)


def _blocks(blocks):
    """Concatenate (index, p_a, p_b, n) blocks, stably ordered by index."""
    if not blocks:
        return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3))
    idx = np.concatenate([b[0] for b in blocks])
    order = np.argsort(idx, kind="stable")
    return (idx[order],) + tuple(np.concatenate([b[k] for b in blocks])[order] for k in (1, 2, 3))
