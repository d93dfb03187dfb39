"""Curves over normalised life t ∈ [0, 1] (colour, alpha and size ramps), stored per emitter.

A curve is up to MAX_STOPS (t, value) stops, piecewise linear, held flat before the first and
after the last stop. Stored as fields of shape (emitters, MAX_STOPS) plus a stop count, evaluated
in the kernel by a short unrolled scan.
"""
import numpy as np
import taichi as ti

from ..config.emitters import MAX_STOPS


class Curves:
    """``curve_t`` (E, MAX_STOPS) stop times; ``curve_v`` (E, MAX_STOPS) values of ``width``
    components; ``curve_n`` (E,) stop counts."""

    def __init__(self, per_emitter_stops, width: int):
        E = len(per_emitter_stops)
        self.width = width
        self.curve_t = ti.field(ti.f32, shape=(E, MAX_STOPS))
        self.curve_v = ti.Vector.field(width, ti.f32, shape=(E, MAX_STOPS))
        self.curve_n = ti.field(ti.i32, shape=E)
        t = np.ones((E, MAX_STOPS), np.float32)
        v = np.zeros((E, MAX_STOPS, width), np.float32)
        n = np.zeros(E, np.int32)
        for e, stops in enumerate(per_emitter_stops):
            n[e] = len(stops)
            for k, s in enumerate(stops):
                t[e, k] = s[0]
                v[e, k] = s[1:]
            t[e, n[e]:] = t[e, n[e] - 1]
            v[e, n[e]:] = v[e, n[e] - 1]
        self.curve_t.from_numpy(t)
        self.curve_v.from_numpy(v)
        self.curve_n.from_numpy(n)

    def make_func(self):
        ct, cv, cn = self.curve_t, self.curve_v, self.curve_n

        @ti.func
        def evaluate(e, t):
            out = cv[e, 0]
            for k in ti.static(range(1, MAX_STOPS)):
                if k < cn[e] and t > ct[e, k - 1]:
                    span = ct[e, k] - ct[e, k - 1]
                    a = 1.0
                    if span > 1e-9:
                        a = ti.min(1.0, (t - ct[e, k - 1]) / span)
                    out = cv[e, k - 1] + a * (cv[e, k] - cv[e, k - 1])
            return out

        return evaluate
