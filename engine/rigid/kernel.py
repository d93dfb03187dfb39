"""The XPBD substep as one Taichi kernel on float64 fields (Müller et al. 2020; see :mod:`.xpbd`).
Contacts and joints are solved Gauss–Seidel in their fixed order by serial loops, so the result
cannot depend on threads (no atomics at all); the per-body stages run in parallel (each body
writes only its own row). A scene of up to WHOLE_MAX_BODIES bodies takes a whole step in one
launch (serial); a larger one one launch per substep (two with joints), its per-body stages
parallel. The same bytes either way. Joints that share a moving body have their point constraints
solved together by a direct (sparse LDLᵀ) solve, serial too (``direct`` below; :mod:`.joints`).
The arithmetic of one element (a contact, a joint) is in :mod:`.elements`; the fields it runs on,
and the kernels that copy a step in and out, are :class:`.fields.Fields`."""

import taichi as ti

from ..launch import fast
from .elements import (f64, vec3, qrot, qrot_inv, add_rot, rot_between, arm_a, arm_b, point_b,
                       rel_vel, iinv, gen_w, apply_pos, apply_vel, positional, joint_points,
                       solve_joint)

WHOLE_MAX_BODIES = 64  # up to this many bodies a step is one serial launch
# Linearise-and-solve rounds of the coupled joints' point constraints per substep (a Newton step
# each). Measured, 1 kg sphere under a 1 g one (tests/test_rigid.py), largest gap over 2 s: 8.8e-6 m
# with 1 round, 2.8e-6 m with 2 (one Gauss–Seidel pass: 1.47 m); the lantern's whole rigid step
# (4 coupled joints, 20 substeps) 65 → 77 µs with 1 round, 93 µs with 2. One is enough.
DIRECT_ROUNDS = 1
DROP = 1e-10  # a pivot below DROP × its diagonal: a row dependent on earlier ones, left out


def _build(F):
    x, q, v, w, xp, qp = F.x, F.q, F.v, F.w, F.xp, F.qp
    inv_m, inv_i, inertia, moving, kin, kx0, kx1 = F.inv_m, F.inv_i, F.inertia, F.moving, F.kin, F.kx0, F.kx1
    ca, cb, cn, cra, crb, rnd_a, rnd_b = F.ca, F.cb, F.cn, F.cra, F.crb, F.rnd_a, F.rnd_b
    mu, e, lam, vn0 = F.mu, F.e, F.lam, F.vn0
    J = (F.jt, F.ja, F.jb, F.jra, F.jrb, F.jaxa, F.jaxb, F.jpa, F.jpb, F.jqrel, F.jlo, F.jhi, F.jlim, F.jalpha, F.jdir)
    ja, jb, jra, jrb, jalpha = F.ja, F.jb, F.jra, F.jrb, F.jalpha
    dord, dfirst, doff, sky, dpiv, dpinv, drhs, dlam = F.dord, F.dfirst, F.doff, F.sky, F.dpiv, F.dpinv, F.drhs, F.dlam
    dx, dth = F.dx, F.dth
    nb, nd = F.nb, F.nd

    # -- one element of each stage (the kernels below only loop over them) ----------------------
    @ti.func
    def arms(k):
        a, b, n = ca[k], cb[k], cn[k]
        return a, b, n, arm_a(q, cra, rnd_a, a, k, n), arm_b(q, crb, rnd_b, b, k, n)

    @ti.func
    def normal_speed(k):
        """ṽ_n of contact k before the substep (restitution)."""
        a, b, n, ra, rb = arms(k)
        vn0[k] = rel_vel(v, w, a, b, ra, rb).dot(n)

    @ti.func
    def integrate(i, h, g, frac):
        """Keep body i's pose; v += hg, x += hv, ω with the gyroscopic term, q += ½h[ω, 0]q (a
        body on a path: where its path is at ``frac`` of the step)."""
        xp[i] = x[i]
        qp[i] = q[i]
        if moving[i] != 0:
            v[i] += h * g
            x[i] += h * v[i]
            wb = qrot_inv(q[i], w[i])
            I = inertia[i]
            wb += h * (-wb.cross(I * wb)) / I
            w[i] = qrot(q[i], wb)
            q[i] = add_rot(q[i], h * w[i])
        elif kin[i] != 0:
            x[i] = kx0[i] + (kx1[i] - kx0[i]) * frac

    @ti.func
    def depth(k):
        """Contact k's penetration d = (p_b − p_a)·n resolved: λ_n = Δλ."""
        a, b, n, ra, rb = arms(k)
        lam[k] = 0.0
        d = (point_b(x, crb, b, k, rb) - x[a] - ra).dot(n)
        if d > 0.0:
            lam[k] = positional(x, q, inv_m, inv_i, a, b, ra, rb, d * n, 0.0)

    @ti.func
    def static_friction(k):
        """Once every depth is resolved (λ_n final): undo contact k's tangential slip over the
        substep where that takes less than μ λ_n."""
        if lam[k] > 0.0:
            a, b, n, ra, rb = arms(k)
            dp = x[a] + ra - xp[a] - qrot(qp[a], qrot_inv(q[a], ra))
            if b >= 0:
                dp -= x[b] + rb - xp[b] - qrot(qp[b], qrot_inv(q[b], rb))
            dpt = dp - dp.dot(n) * n
            slip = dpt.norm()
            if slip > 1e-12:
                t = -dpt / slip
                wt = gen_w(q, inv_m, inv_i, a, ra, t) + gen_w(q, inv_m, inv_i, b, rb, t)
                if wt > 0.0:
                    dlt = slip / wt
                    if dlt < mu[k] * lam[k]:
                        apply_pos(x, q, inv_m, inv_i, a, ra, dlt * t, 1.0)
                        apply_pos(x, q, inv_m, inv_i, b, rb, dlt * t, -1.0)

    @ti.func
    def velocity(i, h):
        """v = Δx/h, ω = 2 vec(Δq q⁻¹)/h."""
        if moving[i] != 0 or kin[i] != 0:
            v[i] = (x[i] - xp[i]) / h
        if moving[i] != 0:
            w[i] = rot_between(q[i], qp[i]) / h

    @ti.func
    def velocity_pass(k, h, glen):
        """Dynamic friction (at most μλ_n/h of impulse) and restitution at contact k."""
        if lam[k] > 0.0:
            a, b, n, ra, rb = arms(k)
            vr = rel_vel(v, w, a, b, ra, rb)
            vn = vr.dot(n)
            vt = vr - vn * n
            vt_len = vt.norm()
            dv = vec3(0.0, 0.0, 0.0)
            if vt_len > 1e-14:
                t = -vt / vt_len
                wt = gen_w(q, inv_m, inv_i, a, ra, t) + gen_w(q, inv_m, inv_i, b, rb, t)
                dv += t * ti.min(mu[k] * lam[k] * wt / h, vt_len)
            ee = e[k]
            if ti.abs(vn0[k]) <= 2.0 * glen * h:
                ee = ti.cast(0.0, f64)
            dv += n * (-vn + ti.max(-ee * vn0[k], 0.0))
            mag = dv.norm()
            if mag > 1e-14:
                dn = dv / mag
                wd = gen_w(q, inv_m, inv_i, a, ra, dn) + gen_w(q, inv_m, inv_i, b, rb, dn)
                if wd > 0.0:
                    p = dv / wd
                    apply_vel(v, w, q, inv_m, inv_i, a, ra, p, 1.0)
                    apply_vel(v, w, q, inv_m, inv_i, b, rb, p, -1.0)

    @ti.func
    def joint_arms(j):
        """Joint j's arms (world frame) and its error C = p_b − p_a."""
        return joint_points(x, q, jra, jrb, ja[j], jb[j], j)

    @ti.func
    def coupling(i, r1, r2):
        """K with K P = how far the point r1 of body i moves under an impulse P at its point r2:
        m⁻¹ P + (I⁻¹ (r2 × P)) × r1 (symmetric in r1, r2 transposed; zero for a body that does
        not move now)."""
        K = ti.Matrix.zero(f64, 3, 3)
        for d in ti.static(range(3)):
            e = vec3(0.0, 0.0, 0.0)
            e[d] = 1.0
            col = inv_m[i] * e - r1.cross(iinv(q, inv_i, i, r2.cross(e)))
            for c in ti.static(range(3)):
                K[c, d] = col[c]
        return K

    @ti.func
    def direct(h):
        """The point constraints of the nd coupled joints at once: (A + α̃) P = C − α̃ λ with
        A_jk = Σ over the moving bodies i that joints j and k share of ± K_i(r_j, r_k) (+ where
        the body is the same side of both), the blocks of J M⁻¹ Jᵀ (Deul et al. 2018: one system
        for a tree's constraints; for one joint this is Müller et al. 2020's own step). A row-skyline LDLᵀ
        in the joints' order keeps the band (no fill outside each row's envelope: Baraff 1996's
        point that a chain or tree solves in linear time). Serial and in a fixed order: the same
        bytes on any thread count. Then each body moves by the sum of its joints' P, as
        ``apply_pos`` moves it."""
        n = 3 * nd
        for rnd in ti.static(range(DIRECT_ROUNDS)):
            for p in range(nd):  # assemble the lower triangle, block row p
                j = dord[p]
                ra, rb, c = joint_arms(j)
                alpha = jalpha[j] / (h * h)
                for cc in ti.static(range(3)):
                    if ti.static(rnd == 0):
                        dlam[3 * p + cc] = 0.0
                    drhs[3 * p + cc] = c[cc] - alpha * dlam[3 * p + cc]
                for p2 in range(dfirst[3 * p] // 3, p + 1):
                    k = dord[p2]
                    sa, sb, _ = joint_arms(k)
                    B = ti.Matrix.zero(f64, 3, 3)
                    for u in range(4):  # (j's side, k's side): a a, a b, b a, b b
                        bj, r1 = ja[j], ra
                        if u >= 2:
                            bj, r1 = jb[j], rb
                        bk, r2 = ja[k], sa
                        if u % 2 == 1:
                            bk, r2 = jb[k], sb
                        if bj >= 0 and bj == bk:
                            sign = ti.cast(1.0, f64)
                            if u == 1 or u == 2:
                                sign = -1.0
                            B += sign * coupling(bj, r1, r2)
                    for cc in ti.static(range(3)):
                        r = 3 * p + cc
                        for dd in ti.static(range(3)):
                            col = 3 * p2 + dd
                            if col < r:
                                sky[doff[r] + col - dfirst[r]] = B[cc, dd]
                            elif col == r:
                                sky[doff[r] + col - dfirst[r]] = B[cc, dd] + alpha
            for i in range(n):  # LDLᵀ in place, row by row within the envelope
                fi, oi = dfirst[i], doff[i]
                for jc in range(fi, i):
                    fj, oj = dfirst[jc], doff[jc]
                    s = sky[oi + jc - fi]
                    for k in range(ti.max(fi, fj), jc):
                        s -= sky[oi + k - fi] * sky[oj + k - fj] * dpiv[k]
                    sky[oi + jc - fi] = s * dpinv[jc]
                diag = sky[oi + i - fi]
                d = diag
                for k in range(fi, i):
                    d -= sky[oi + k - fi] * sky[oi + k - fi] * dpiv[k]
                dpiv[i] = 0.0
                dpinv[i] = 0.0
                if d > DROP * diag:
                    dpiv[i] = d
                    dpinv[i] = 1.0 / d
            for i in range(n):  # L y = rhs
                fi, oi = dfirst[i], doff[i]
                s = drhs[i]
                for k in range(fi, i):
                    s -= sky[oi + k - fi] * drhs[k]
                drhs[i] = s * dpinv[i]
            for ii in range(n):  # Lᵀ P = D⁻¹ y
                i = n - 1 - ii
                fi, oi = dfirst[i], doff[i]
                for k in range(fi, i):
                    drhs[k] -= sky[oi + k - fi] * drhs[i]
            for p in range(nd):
                j = dord[p]
                dx[ja[j]] = vec3(0.0, 0.0, 0.0)
                dth[ja[j]] = vec3(0.0, 0.0, 0.0)
                if jb[j] >= 0:
                    dx[jb[j]] = vec3(0.0, 0.0, 0.0)
                    dth[jb[j]] = vec3(0.0, 0.0, 0.0)
            for p in range(nd):
                j = dord[p]
                ra, rb, _ = joint_arms(j)
                P = vec3(drhs[3 * p], drhs[3 * p + 1], drhs[3 * p + 2])
                for cc in ti.static(range(3)):
                    dlam[3 * p + cc] += P[cc]
                a, b = ja[j], jb[j]
                dx[a] += inv_m[a] * P
                dth[a] += iinv(q, inv_i, a, ra.cross(P))
                if b >= 0:
                    dx[b] -= inv_m[b] * P
                    dth[b] -= iinv(q, inv_i, b, rb.cross(P))
            for p in range(nd):
                j = dord[p]
                for side in ti.static(range(2)):
                    i = ja[j]
                    if ti.static(side == 1):
                        i = jb[j]
                    if i >= 0:
                        x[i] += dx[i]
                        if dth[i].norm_sqr() > 0.0:
                            q[i] = add_rot(q[i], dth[i])
                        dx[i] = vec3(0.0, 0.0, 0.0)
                        dth[i] = vec3(0.0, 0.0, 0.0)

    # -- kernels ----------------------------------------------------------------------------------
    @ti.kernel
    def begin(h: f64, g: vec3, frac: f64, nc: ti.i32):
        for k in range(nc):
            normal_speed(k)
        for i in range(nb):
            integrate(i, h, g, frac)

    @ti.kernel
    def joints(h: f64, nj: ti.i32, on: ti.i32):
        ti.loop_config(serialize=True)
        for j in range(nj):
            solve_joint(j, h, x, q, inv_m, inv_i, *J)
        if ti.static(nd > 0):  # compiled only where some joints are coupled
            ti.loop_config(serialize=True)
            for _ in range(on):
                direct(h)

    @ti.kernel
    def finish(h: f64, glen: f64, nc: ti.i32, g: vec3, h2: f64, frac2: f64, more: ti.i32):
        """The rest of a substep (contacts in order, velocities, the velocity pass in order) and,
        when ``more``, the start of the next: one launch where there were three."""
        ti.loop_config(serialize=True)
        for k in range(nc):
            depth(k)
        ti.loop_config(serialize=True)
        for k in range(nc):
            static_friction(k)
        for i in range(nb):
            velocity(i, h)
        ti.loop_config(serialize=True)
        for k in range(nc):
            velocity_pass(k, h, glen)
        for k in range(nc * more):
            normal_speed(k)
        for i in range(nb * more):
            integrate(i, h2, g, frac2)

    @ti.kernel
    def whole(nsub: ti.i32, h: f64, g: vec3, glen: f64, nc: ti.i32, nj: ti.i32, on: ti.i32):
        """Every substep of a step in one launch (one thread: joints and contacts are serial
        anyway, and at a few dozen bodies a launch costs more than their integration). About 20 s
        of cold compile with the joints in it; it halves a jointed scene's frame."""
        ti.loop_config(serialize=True)
        for s in range(nsub):
            for k in range(nc):
                normal_speed(k)
            for i in range(nb):
                integrate(i, h, g, (s + 1.0) / nsub)
            if ti.static(F.has_joints):
                for j in range(nj):
                    solve_joint(j, h, x, q, inv_m, inv_i, *J)
            if ti.static(nd > 0):
                if on != 0:
                    direct(h)
            for k in range(nc):
                depth(k)
            for k in range(nc):
                static_friction(k)
            for i in range(nb):
                velocity(i, h)
            for k in range(nc):
                velocity_pass(k, h, glen)

    # (launched without Taichi's per-call Python: engine.launch; compiled without Taichi's whole-
    # kernel CSE, which took 97 of the 108 s of the lantern's cold compile: engine.runtime)
    begin, joints, finish, whole = (fast(k, lean=True) for k in (begin, joints, finish, whole))

    def substeps(n, h, g, glen, nc, nj):
        """n substeps of h: in one launch (up to WHOLE_MAX_BODIES bodies), else a begin, then per
        substep the joints (if any) and one launch that finishes it and begins the next. n = 0
        only compiles the kernels of this system's path (its body count is fixed, so the other is
        never launched): a build pays the compile, not the frame where the first contact or joint
        appears."""
        if n == 0:
            if F.nb <= WHOLE_MAX_BODIES:
                whole(0, 1.0, g, glen, 0, 0, 0)
            else:
                begin(1.0, g, 1.0, 0)
                joints(1.0, 0, 0)
                finish(1.0, glen, 0, g, 1.0, 1.0, 0)
            return
        on = int(nj > 0 and nd > 0)
        if F.nb <= WHOLE_MAX_BODIES:
            whole(n, h, g, glen, nc, nj, on)
            return
        begin(h, g, 1.0 / n, nc)
        for s in range(n):
            if nj:
                joints(h, nj, on)
            finish(h, glen, nc, g, h, (s + 2.0) / n, int(s + 1 < n))

    return substeps
