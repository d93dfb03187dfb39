"""The opaque background a frame is composited over: a sky gradient, faint 1 m grids on plane
colliders (or on the ground when there are none) and faintly lit collider spheres, boxes and
capsules, with the depth
particles are tested against (a particle behind a sphere is hidden; near a surface it fades).

Drawn only when the camera, the colliders or the image size change, and when only some colliders
moved, only in the screen rectangles they left and entered; between such frames the renderer
keeps it, its reduced-resolution depth and its tone-mapped packed copy.
"""
# (no `from __future__ import annotations`: Taichi reads kernel annotations at definition)

import taichi as ti

from ..colliders import BOX, CAPSULE, PLANE, SPHERE
from ..spread import TASK, item, rounds, tasks
from .sprites import TILE
from .upsample import ND_F, ND_I1, ND_V4  # pixel arrays: flat, y·W + x

vec3 = ti.types.vector(3, ti.f32)
SKY_DEPTH = 1e30


@ti.func
def ray_dir(px, py, f, r, u, th, W, H):
    """Unit view ray through the centre of pixel (px, py) of a W×H image."""
    x = (2.0 * (px + 0.5) / W - 1.0) * th * (W / H)
    y = (1.0 - 2.0 * (py + 0.5) / H) * th
    return (f + x * r + y * u).normalized()


@ti.func
def grid_shade(o, d, p0, n, th, f, col, zbest, H):
    """A faint 1 m grid on the plane (p0, n) seen along the ray o + s·d; returns (colour, depth)."""
    dn = d.dot(n)
    z = zbest
    if dn < -1e-6:
        s = (p0 - o).dot(n) / dn
        zz = s * d.dot(f)
        if s > 0 and zz < zbest:
            q = o + s * d
            a = ti.Vector([1.0, 0.0, 0.0]) if ti.abs(n[0]) < 0.9 else ti.Vector([0.0, 0.0, 1.0])
            e1 = n.cross(a).normalized()
            e2 = n.cross(e1)
            uu, vv = (q - p0).dot(e1), (q - p0).dot(e2)
            foot = s * 2.0 * th / H / ti.max(ti.abs(dn), 0.05)  # metres per pixel
            du = ti.abs(uu - ti.round(uu))
            dv = ti.abs(vv - ti.round(vv))
            line = ti.max(ti.max(0.0, 1.0 - du / (1.2 * foot)), ti.max(0.0, 1.0 - dv / (1.2 * foot)))
            line *= ti.min(1.0, 0.25 / foot)  # fade lines that become finer than a pixel
            fade = ti.exp(-s / 40.0)
            col = (ti.Vector([0.018, 0.019, 0.022]) + line * ti.Vector([0.030, 0.032, 0.036])) * fade \
                + col * (1.0 - fade)
            z = zz
    return col, z


@ti.func
def solid_shade(n, d):
    """A collider solid's colour at outward normal n seen along d: faint key light and rim."""
    ldir = ti.Vector([0.4, 0.8, 0.3]).normalized()
    lam = ti.max(0.0, n.dot(ldir))
    rim = 1.0 - ti.abs(n.dot(d))
    return ti.Vector([0.02, 0.021, 0.025]) + 0.06 * lam * ti.Vector([0.8, 0.85, 1.0]) + 0.03 * rim * rim * rim


@ti.func
def ray_box(o, d, c, ex, ey, ez, h):
    """(s, n): the ray o + s·d's entry into the box (centre c, axes ex, ey, ez, half extents h),
    s < 0 when it misses or starts inside; n the outward normal there (slab method)."""
    oc = o - c
    ol = ti.Vector([oc.dot(ex), oc.dot(ey), oc.dot(ez)])
    dl = ti.Vector([d.dot(ex), d.dot(ey), d.dot(ez)])
    tn, tf = -1e30, 1e30
    nl = ti.Vector([0.0, 0.0, 0.0])
    for a in ti.static(range(3)):
        if ti.abs(dl[a]) < 1e-12:
            if ti.abs(ol[a]) > h[a]:
                tn, tf = 1.0, -1.0  # parallel to this slab and outside it: no hit
        else:
            t1 = (-h[a] - ol[a]) / dl[a]
            t2 = (h[a] - ol[a]) / dl[a]
            lo, hi = ti.min(t1, t2), ti.max(t1, t2)
            if lo > tn:
                tn = lo
                nl = ti.Vector([0.0, 0.0, 0.0])
                nl[a] = -1.0 if dl[a] > 0 else 1.0
            tf = ti.min(tf, hi)
    s = -1.0
    if tn <= tf and tn > 0:
        s = tn
    return s, nl[0] * ex + nl[1] * ey + nl[2] * ez


@ti.func
def ray_capsule(o, d, c, a, half, rad):
    """(s, n): the ray o + s·d's entry into the capsule (segment c ± half·a, radius rad), s < 0 on
    a miss (Quilez's capsule intersection: the infinite cylinder, then the nearer end cap)."""
    pa = c - half * a
    ba = 2.0 * half * a
    oa = o - pa
    baba = ba.dot(ba)
    bard = ba.dot(d)
    baoa = ba.dot(oa)
    rdoa = d.dot(oa)
    oaoa = oa.dot(oa)
    s = -1.0
    qa = baba - bard * bard
    qb = baba * rdoa - baoa * bard
    qc = baba * oaoa - baoa * baoa - rad * rad * baba
    hh = qb * qb - qa * qc
    if hh >= 0.0 and qa > 1e-12:
        t = (-qb - ti.sqrt(hh)) / qa
        y = baoa + t * bard
        if y > 0.0 and y < baba:
            s = t
        else:  # the end caps
            oc = oa if y <= 0.0 else o - (c + half * a)
            bb = d.dot(oc)
            cc = oc.dot(oc) - rad * rad
            h2 = bb * bb - cc
            if h2 > 0.0:
                s = -bb - ti.sqrt(h2)
    elif qa <= 1e-12:  # looking along the axis (or a zero-length segment): the nearer cap
        oc = oa if bard > 0.0 else o - (c + half * a)
        bb = d.dot(oc)
        cc = oc.dot(oc) - rad * rad
        h2 = bb * bb - cc
        if h2 > 0.0:
            s = -bb - ti.sqrt(h2)
    n = ti.Vector([0.0, 1.0, 0.0])
    if s > 0.0:
        p = o + s * d
        r = p - c
        n = (r - ti.min(ti.max(r.dot(a), -half), half) * a).normalized()
    return s, n


def build_background_kernel(render_cfg, colliders):
    """``background(bgc, depth, o, f, r, u, th, W, H, show, x0, y0, x1, y1)``: bgc (H·W,) vec4 =
    (RGB, 0), depth (H·W,) f32 metres along the view axis (SKY_DEPTH where nothing is hit), drawn
    in the pixel rectangle [x0, x1) × [y0, y1) only (a pixel's value depends on its own ray alone, so
    a rectangle redrawn gives the bytes a whole redraw would). ``show`` 0 hides the colliders (they
    are compiled in; the flag is a runtime switch, not a second kernel)."""
    bgc = tuple(float(c) for c in render_cfg.background)
    specs = colliders.specs if colliders is not None else []
    vis = [k for k, s in enumerate(specs) if s.visible]
    planes = tuple(k for k in vis if colliders.kinds[k] == PLANE)
    spheres = tuple(k for k in vis if colliders.kinds[k] == SPHERE)
    boxes = tuple(k for k in vis if colliders.kinds[k] == BOX)
    capsules = tuple(k for k in vis if colliders.kinds[k] == CAPSULE)
    grid = bool(render_cfg.grid)
    if colliders is not None:
        cpt, cnr, crad = colliders.collider_point, colliders.collider_normal, colliders.collider_radius
        chalf = getattr(colliders, "collider_half", None)
        cax = getattr(colliders, "collider_axis_x", None)
        caz = getattr(colliders, "collider_axis_z", None)
    else:
        cpt = cnr = crad = chalf = cax = caz = None

    NT = tasks()

    @ti.kernel
    def background(out: ND_V4, depth: ND_F, o: vec3, f: vec3, r: vec3, u: vec3, th: ti.f32,
                   W: ti.i32, H: ti.i32, show: ti.i32, x0: ti.i32, y0: ti.i32, x1: ti.i32, y1: ti.i32):
        for sl in range(NT * TASK):  # the rows spread over the CPU's tasks (engine.spread): a
            for rr in range(rounds(y1 - y0, NT)):  # moved collider's few hundred were one task
                py = y0 + item(sl, rr, NT)
                if py < y1:
                    for px in range(x0, x1):
                        d = ray_dir(px, py, f, r, u, th, W, H)
                        col = ti.Vector([bgc[0], bgc[1], bgc[2]]) * (0.6 + 0.8 * (0.5 + 0.5 * d[1]))
                        z = SKY_DEPTH
                        if ti.static(grid):  # the ground grid, unless a plane collider is shown
                            ground = 1
                            if ti.static(len(planes) > 0):
                                ground = ti.select(show == 0, 1, 0)
                            if ground != 0:
                                col, z = grid_shade(o, d, ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 1.0, 0.0]),
                                                    th, f, col, z, H)
                        if show != 0:
                            for k in ti.static(planes):
                                col, z = grid_shade(o, d, cpt[k], cnr[k], th, f, col, z, H)
                            for k in ti.static(spheres):
                                oc = o - cpt[k]
                                b = oc.dot(d)
                                c = oc.dot(oc) - crad[k] * crad[k]
                                disc = b * b - c
                                if disc > 0:
                                    s = -b - ti.sqrt(disc)
                                    zz = s * d.dot(f)
                                    if s > 0 and zz < z:
                                        n = (o + s * d - cpt[k]).normalized()
                                        ldir = ti.Vector([0.4, 0.8, 0.3]).normalized()
                                        lam = ti.max(0.0, n.dot(ldir))
                                        rim = 1.0 - ti.abs(n.dot(d))
                                        col = ti.Vector([0.02, 0.021, 0.025]) \
                                            + 0.06 * lam * ti.Vector([0.8, 0.85, 1.0]) + 0.03 * rim * rim * rim
                                        z = zz
                            for k in ti.static(boxes):
                                s, n = ray_box(o, d, cpt[k], cax[k], cnr[k], caz[k], chalf[k])
                                zz = s * d.dot(f)
                                if s > 0 and zz < z:
                                    col, z = solid_shade(n, d), zz
                            for k in ti.static(capsules):
                                s, n = ray_capsule(o, d, cpt[k], cnr[k], chalf[k][1], crad[k])
                                zz = s * d.dot(f)
                                if s > 0 and zz < z:
                                    col, z = solid_shade(n, d), zz
                        out[py * W + px] = ti.Vector([col[0], col[1], col[2], 0.0])
                        depth[py * W + px] = z

    return background


@ti.kernel
def downsample_depth(depth: ND_F, W: ti.i32, H: ti.i32, at: ti.i32, Wk: ti.i32, k: ti.i32,
                     x0: ti.i32, y0: ti.i32, x1: ti.i32, y1: ti.i32, dirty: ND_I1, dirty_prev: ND_I1,
                     TX: ti.i32, tiles: ti.i32):
    """A reduced level's depth, stored after the full-resolution one (depth[at + y·Wk + x]: the
    reduced level at W·H, the coarse one after it): the farthest depth under each k×k block
    (Cantlay 2007: with the maximum, a reduced-resolution particle is not hidden by a thin nearer
    edge inside its texel), for the texels [x0, x1) × [y0, y1) — and with ``tiles`` only those
    whose block lies in a 16×16 tile marked in ``dirty`` or ``dirty_prev`` (where soft bodies drew
    this frame or the last; k divides 16, so a block never straddles two tiles)."""
    for sl in range(ti.static(tasks() * TASK)):  # (the rows spread over the CPU's tasks: engine.spread)
        for rr in range(rounds(y1 - y0, ti.static(tasks()))):
            y = y0 + item(sl, rr, ti.static(tasks()))
            if y < y1:
                for x in range(x0, x1):
                    t = ((y * k) // TILE) * TX + (x * k) // TILE
                    if tiles == 0 or dirty[t] != 0 or dirty_prev[t] != 0:
                        z = 0.0
                        for dy in range(k):
                            for dx in range(k):
                                z = ti.max(z, depth[ti.min(y * k + dy, H - 1) * W + ti.min(x * k + dx, W - 1)])
                        depth[at + y * Wk + x] = z


@ti.kernel
def copy_background(fbg: ND_V4, fdep: ND_F, bgc: ND_V4, depth: ND_F, W: ti.i32, x0: ti.i32, y0: ti.i32,
                    x1: ti.i32, y1: ti.i32):
    """The frame's own background and depth (soft bodies draw into them) from the kept ones, in
    the pixel rectangle [x0, x1) × [y0, y1)."""
    for y in range(y0, y1):
        for k in range(y * W + x0, y * W + x1):
            fbg[k] = bgc[k]
            fdep[k] = depth[k]
