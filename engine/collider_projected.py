"""The shape table's projected shapes: rigid bodies' boxes and capsules, met by the end-of-step
projection only (engine.colliders' module docstring says why: a body's box inlined at every site
of the located step cost minutes of compilation for a stack of ten crates).

They sit at the table's end (shapes ``event_count`` … ``count`` − 1) and are walked by one loop at
run time, not one unrolled copy per shape: a bounding-sphere test per shape, then its exact
distance (:meth:`ProjectedShapes.projected_contact`) and the response of the table's
``_bounce`` in the frame of the body's surface point (v + ω × r), a two-way push recorded for
the body where a pusher is set. Their impacts are not located in time inside a step.
"""
# (no __future__ annotations: Taichi reads the funcs' ti.template() annotations)

import taichi as ti

from .geometry.shapes import BOX, CAPSULE, box_local, turn, turned


@ti.func
def capsule_local(r, a, half, radius):
    """(g, N) of the offset r from a capsule's centre, its unit axis a, the segment's half length
    and the radius (m): the distance from the segment less the radius, the outward normal."""
    dd = r - ti.min(ti.max(r.dot(a), -half), half) * a
    dist = dd.norm()
    N = a
    if dist > 1e-12:
        N = dd / dist
    return dist - radius, N


class ProjectedShapes:
    """The projected half of :class:`~engine.colliders.Colliders` (a mixin: the table's
    ``event_count``, ``count``, ``kinds``, ``offset``, ``pusher``, fields and ``_bounce`` /
    ``_band`` are its; ``collider_kind`` and ``collider_bound`` exist where it has such shapes)."""

    @ti.func
    def projected_contact(self, j, x, lag):
        """(g, N) of projected shape j (a run-time index: a rigid body's box or capsule) for a
        point at x, ``lag`` s before the step's end: x is turned forward by ω·lag into the
        shape's frame at the step's end (as :meth:`contact` does for a spinning box), the normal
        turned back."""
        p = self.collider_point[j] - self.collider_vel[j] * lag
        ax, c, sn = turn(self.collider_omega[j], lag)
        r = turned(x - p, ax, c, sn)
        ey = self.collider_normal[j]
        g, nw = ti.cast(0.0, self.dtype), ey
        kinds = ti.static(self.kinds[self.event_count:])
        if ti.static(BOX in kinds and CAPSULE in kinds):  # (only the kinds present are compiled)
            if self.collider_kind[j] == BOX:
                g, nw = box_local(r, self.collider_axis_x[j], ey, self.collider_axis_z[j], self.collider_half[j])
            else:
                g, nw = capsule_local(r, ey, self.collider_half[j][1], self.collider_radius[j])
        elif ti.static(BOX in kinds):
            g, nw = box_local(r, self.collider_axis_x[j], ey, self.collider_axis_z[j], self.collider_half[j])
        else:
            g, nw = capsule_local(r, ey, self.collider_half[j][1], self.collider_radius[j])
        return g - ti.static(self.offset), turned(nw, ax, c, -sn)

    @ti.func
    def near_projected(self, x):
        """1 if x is within a projected shape's bounding sphere (grown by ``offset``), else 0: a
        step ending there is looked at by :meth:`project` (a bound test only: the exact one would
        inline each shape's contact once more)."""
        near = 0
        if ti.static(self.event_count < self.count):
            for j in range(self.event_count, self.count):
                reach = self.collider_bound[j] + ti.static(self.offset)
                if (x - self.collider_point[j]).norm_sqr() < reach * reach:
                    near = 1
        return near

    @ti.func
    def project_projected(self, x, v, x0, v0, h, i, hits, which, n_hit, speed):
        """The projected shapes' part of :meth:`~engine.colliders.Colliders.project_for`: each
        one whose bounding sphere x is in and whose surface it ended the step of h inside puts
        it back and responds (resting when it started the step touching, as the event shapes
        do). Returns (x, v, hits, which, n_hit, speed) updated."""
        zero = ti.Vector.zero(self.dtype, 3)
        for j in range(self.event_count, self.count):
            p = self.collider_point[j]
            reach = self.collider_bound[j] + ti.static(self.offset)
            if (x - p).norm_sqr() < reach * reach:
                g, N = self.projected_contact(j, x, 0.0)
                if g < 0.0:
                    hits += 1
                    g0, _N0 = self.projected_contact(j, x0, h)
                    dv = v - v0 if g0 <= self._band(x0) else zero
                    x = x - g * N
                    vc = self.collider_vel[j] + self.collider_omega[j].cross(x - p)
                    v_in = v
                    x, v, speed, n_hit = self._bounce(x, v, vc, self.collider_restitution[j],
                                                      self.collider_friction[j], dv, N)
                    if ti.static(self.pushes_on(None)):  # (every projected shape is a body's)
                        self.pusher.add(i, self.pusher.body_of[j], x - p, v - v_in)
                    which = j
        return x, v, hits, which, n_hit, speed
