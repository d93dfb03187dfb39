"""One element of the rigid XPBD substep as Taichi funcs on float64 fields (Müller et al. 2020,
§3.3–3.5): quaternion arithmetic, a contact's arms and relative velocity, generalized inverse
masses, positional and angular corrections, and a joint's Gauss–Seidel step. The kernels that
loop over bodies, contacts and joints, in their fixed order, are in :mod:`.kernel`."""

import taichi as ti

f64 = ti.f64
vec3 = ti.types.vector(3, f64)
vec4 = ti.types.vector(4, f64)

BALL, HINGE, FIXED, DISTANCE = 0, 1, 2, 3
JOINT_CODES = {"ball": BALL, "hinge": HINGE, "fixed": FIXED, "distance": DISTANCE}


@ti.func
def qmul(a, b):
    return vec4(a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
                a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
                a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
                a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0])


@ti.func
def qconj(q: ti.template()):
    return vec4(q[0], -q[1], -q[2], -q[3])


@ti.func
def qrot(q: ti.template(), v: ti.template()):
    u = vec3(q[1], q[2], q[3])
    t = 2.0 * u.cross(v)
    return v + q[0] * t + u.cross(t)


@ti.func
def qrot_inv(q: ti.template(), v: ti.template()):
    return qrot(qconj(q), v)


@ti.func
def add_rot(q: ti.template(), r):
    dq = qmul(vec4(0.0, r[0], r[1], r[2]), q)
    out = q + 0.5 * dq
    return out / out.norm()


@ti.func
def rot_between(q: ti.template(), qp):
    d = qmul(q, qconj(qp))
    s = ti.cast(2.0, f64)
    if d[0] < 0.0:
        s = ti.cast(-2.0, f64)
    return s * vec3(d[1], d[2], d[3])

@ti.func
def arm_a(q: ti.template(), cra: ti.template(), rnd_a: ti.template(), a, k, n):
    r = -rnd_a[k] * n
    if rnd_a[k] <= 0.0:
        r = qrot(q[a], cra[k])
    return r


@ti.func
def arm_b(q: ti.template(), crb: ti.template(), rnd_b: ti.template(), b, k, n):
    r = vec3(0.0, 0.0, 0.0)
    if b >= 0:
        if rnd_b[k] > 0.0:
            r = rnd_b[k] * n
        else:
            r = qrot(q[b], crb[k])
    return r


@ti.func
def point_b(x: ti.template(), crb: ti.template(), b, k, rb):
    p = crb[k]
    if b >= 0:
        p = x[b] + rb
    return p


@ti.func
def rel_vel(v: ti.template(), w: ti.template(), a, b, ra, rb):
    out = v[a] + w[a].cross(ra)
    if b >= 0:
        out -= v[b] + w[b].cross(rb)
    return out


@ti.func
def iinv(q: ti.template(), inv_i: ti.template(), i, vv):
    return qrot(q[i], inv_i[i] * qrot_inv(q[i], vv))


@ti.func
def gen_w(q: ti.template(), inv_m: ti.template(), inv_i: ti.template(), i, r, n):
    out = ti.cast(0.0, f64)
    if i >= 0:
        rn = r.cross(n)
        out = inv_m[i] + rn.dot(iinv(q, inv_i, i, rn))
    return out


@ti.func
def apply_pos(x: ti.template(), q: ti.template(), inv_m: ti.template(), inv_i: ti.template(), i, r, p, sign):
    if i >= 0:
        x[i] += sign * p * inv_m[i]
        dr = iinv(q, inv_i, i, r.cross(p))
        if dr.norm_sqr() > 0.0:
            q[i] = add_rot(q[i], sign * dr)


@ti.func
def apply_vel(v: ti.template(), w: ti.template(), q: ti.template(), inv_m: ti.template(), inv_i: ti.template(), i, r, p, sign):
    if i >= 0:
        v[i] += sign * p * inv_m[i]
        w[i] += sign * iinv(q, inv_i, i, r.cross(p))


@ti.func
def positional(x: ti.template(), q: ti.template(), inv_m: ti.template(), inv_i: ti.template(), a, b, ra, rb, corr, alpha):
    """Move a's point by ``corr`` relative to b's (compliance α̃ = alpha); returns Δλ."""
    c = corr.norm()
    dl = ti.cast(0.0, f64)
    if c > 1e-15:
        n = corr / c
        wsum = gen_w(q, inv_m, inv_i, a, ra, n) + gen_w(q, inv_m, inv_i, b, rb, n)
        if wsum + alpha > 0.0:
            dl = c / (wsum + alpha)
            apply_pos(x, q, inv_m, inv_i, a, ra, dl * n, 1.0)
            apply_pos(x, q, inv_m, inv_i, b, rb, dl * n, -1.0)
    return dl


@ti.func
def angular(q: ti.template(), inv_i: ti.template(), a, b, rot, alpha):
    """Turn a by the rotation vector ``rot`` relative to b."""
    th = rot.norm()
    if th > 1e-15:
        n = rot / th
        wsum = n.dot(iinv(q, inv_i, a, n))
        if b >= 0:
            wsum += n.dot(iinv(q, inv_i, b, n))
        if wsum + alpha > 0.0:
            p = th / (wsum + alpha) * n
            q[a] = add_rot(q[a], iinv(q, inv_i, a, p))
            if b >= 0:
                q[b] = add_rot(q[b], -iinv(q, inv_i, b, p))


@ti.func
def joint_points(x: ti.template(), q: ti.template(), jra: ti.template(), jrb: ti.template(), a, b, j):
    """Joint j's arms on bodies a and b (world frame; b < 0: the world, whose anchor jrb is a world
    point) and its error C = p_b − p_a (m)."""
    ra = qrot(q[a], jra[j])
    rb = vec3(0.0, 0.0, 0.0)
    pb = jrb[j]
    if b >= 0:
        rb = qrot(q[b], jrb[j])
        pb = x[b] + rb
    return ra, rb, pb - (x[a] + ra)


@ti.func
def solve_joint(j, h, x: ti.template(), q: ti.template(), inv_m: ti.template(), inv_i: ti.template(), jt: ti.template(), ja: ti.template(), jb: ti.template(), jra: ti.template(), jrb: ti.template(), jaxa: ti.template(), jaxb: ti.template(), jpa: ti.template(), jpb: ti.template(), jqrel: ti.template(), jlo: ti.template(), jhi: ti.template(), jlim: ti.template(), jalpha: ti.template(), jdir: ti.template()):
    """Joint j's Gauss–Seidel step: its angular part, then (unless ``jdir``: solved with the
    other coupled joints' in ``direct``) its point or distance constraint."""
    a, b = ja[j], jb[j]
    alpha = jalpha[j] / (h * h)
    qb = vec4(1.0, 0.0, 0.0, 0.0)
    if b >= 0:
        qb = q[b]
    if jt[j] == HINGE:
        angular(q, inv_i, a, b, qrot(q[a], jaxa[j]).cross(qrot(qb, jaxb[j])), alpha)
        if jlim[j] != 0:
            if b >= 0:
                qb = q[b]
            nax = qrot(q[a], jaxa[j])
            ua, ub = qrot(q[a], jpa[j]), qrot(qb, jpb[j])
            phi = ti.atan2(ub.cross(ua).dot(nax), ub.dot(ua))
            target = ti.min(ti.max(phi, jlo[j]), jhi[j])
            if target != phi:
                angular(q, inv_i, a, b, nax * (target - phi), alpha)
    elif jt[j] == FIXED:
        err = qmul(q[a], qconj(qmul(qb, jqrel[j])))
        angular(q, inv_i, a, b, -rot_between(err, vec4(1.0, 0.0, 0.0, 0.0)), alpha)
    if jdir[j] == 0:
        ra, rb, delta = joint_points(x, q, jra, jrb, a, b, j)
        corr = delta
        if jt[j] == DISTANCE:
            d = delta.norm()
            corr = vec3(0.0, 0.0, 0.0)
            if d > jhi[j]:
                corr = delta / d * (d - jhi[j])
            elif d < jlo[j] and d > 1e-12:
                corr = delta / d * (d - jlo[j])
        positional(x, q, inv_m, inv_i, a, b, ra, rb, corr, alpha)
