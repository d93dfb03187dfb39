"""Spawning kernels: new particles from emitters (one launch per step for all of them) and from
sub-emitter events (a two-pass chunked prefix sum per link), all parallel and deterministic.

Every random number is a hash of (seed, emitter, the particle's serial number), and slots and
serial numbers are assigned by position, not by atomics: a run is reproducible and independent of
thread count. Sub-emitter children take their slots in parent-slot order (the rank of their
parent among the firing ones, from the prefix sum), as a serial pass would give them.
"""
import math

import taichi as ti

from ..launch import fast
from .rng import rand01

SHAPES = {"point": 0, "sphere": 1, "box": 2, "disc": 3, "cone": 4}
TWO_PI = 2.0 * math.pi
EVENT_DEATH, EVENT_COLLISION = 1, 2
# plan rows of one spawn launch (engine.particles.emitters.Emitters.emit)
R_E, R_K, R_FIRST, R_HEAD, R_SERIAL, R_START, R_SIZE = range(7)  # int columns
V_TS0, V_TSPAN, V_PA, V_PB, V_T0, V_H, V_EV = 0, 1, 2, 5, 8, 9, 10  # float columns (vec3 take 3)
A_HEAD, A_SERIAL, A_DROPPED, A_SIZE = range(4)  # per-emitter advance columns


@ti.func
def basis(n):
    """Two unit vectors orthogonal to unit n."""
    a = ti.Vector([1.0, 0.0, 0.0]) if ti.abs(n[0]) < 0.9 else ti.Vector([0.0, 1.0, 0.0])
    u = n.cross(a).normalized()
    return u, n.cross(u)


@ti.func
def init_particle(E: ti.template(), S: ti.template(), slot, e, sid, centre, base_vel):
    """A new particle of emitter e in ``slot``: shape offset around ``centre``, direction within
    the spread, speed in range, plus inherit × base_vel."""
    r = ti.Vector([rand01(E.seed, e, sid, q) for q in ti.static(range(8))])
    n = E.emitter_dir[e]
    u, w = basis(n)
    off = ti.Vector([0.0, 0.0, 0.0])
    d = n
    sh = E.emitter_shape[e]
    radius = E.emitter_radius[e]
    if sh == 1:  # sphere: volume or surface
        z = 2.0 * r[1] - 1.0
        phi = TWO_PI * r[2]
        s = ti.sqrt(ti.max(0.0, 1.0 - z * z))
        rr = radius * (1.0 if E.emitter_surface[e] != 0 else ti.pow(r[3], 1.0 / 3.0))
        off = rr * ti.Vector([s * ti.cos(phi), s * ti.sin(phi), z])
    elif sh == 2:  # box
        off = (ti.Vector([r[1], r[2], r[3]]) - 0.5) * E.emitter_box[e]
    elif sh == 3 or sh == 4:  # disc (and the cone's base), perpendicular to n
        rr = radius * ti.sqrt(r[1])
        phi = TWO_PI * r[2]
        radial = ti.cos(phi) * u + ti.sin(phi) * w
        off = rr * radial
        if sh == 4 and radius > 0:  # cone: directions tilt outward with the offset
            tilt = ti.acos(E.emitter_cos_spread[e]) * rr / radius
            d = ti.cos(tilt) * n + ti.sin(tilt) * radial
    dd = d
    if sh != 4:  # uniform on the spherical cap of half-angle `spread` around d
        cz = 1.0 - r[4] * (1.0 - E.emitter_cos_spread[e])
        sz = ti.sqrt(ti.max(0.0, 1.0 - cz * cz))
        phi2 = TWO_PI * r[5]
        du, dw = basis(d)
        dd = cz * d + sz * (ti.cos(phi2) * du + ti.sin(phi2) * dw)
    speed = E.emitter_speed_min[e] + (E.emitter_speed_max[e] - E.emitter_speed_min[e]) * r[6]
    S.particle_pos[slot] = centre + off
    S.particle_vel[slot] = speed * dd + E.emitter_inherit[e] * base_vel
    S.particle_age[slot] = 0.0
    S.particle_life[slot] = E.emitter_life[e] * (1.0 - E.emitter_life_rand[e] * r[7])
    S.particle_alive[slot] = 1
    S.particle_emitter[slot] = e
    S.particle_rand[slot] = rand01(E.seed, e, sid, 9)


@ti.func
def _vec(vals: ti.template(), r, c):
    return ti.Vector([vals[r, c], vals[r, c + 1], vals[r, c + 2]])


@ti.func
def _born(E: ti.template(), S: ti.template(), rows: ti.template(), vals: ti.template(), r, j, slot):
    """Write particle j of plan row r into ``slot``: its serial, birth time and place depend on
    (row, j) only, never on the slot it lands in."""
    e, k = rows[r, R_E], rows[r, R_K]
    sid = E.emitter_serial[e] + rows[r, R_SERIAL] + j
    # stratified birth times across the span, so a stream has no gaps or clumps
    jitter = rand01(E.seed, e, sid, 10)
    ts = vals[r, V_TS0] + vals[r, V_TSPAN] * (ti.cast(j, ti.f32) + jitter) / ti.cast(k, ti.f32)
    t0, h = vals[r, V_T0], vals[r, V_H]
    a = 0.0
    if h > 0:
        a = ti.min(1.0, ti.max(0.0, (ts - t0) / h))
    pa, pb = _vec(vals, r, V_PA), _vec(vals, r, V_PB)
    init_particle(E, S, slot, e, sid, pa + a * (pb - pa), _vec(vals, r, V_EV))
    S.particle_age[slot] = -ti.max(0.0, ts - t0)  # born this long into the step


@ti.func
def _row_of(rows: ti.template(), nrows, q):
    """The plan row whose particles include the launch's q-th (rows in ``R_FIRST`` order)."""
    r = 0
    while r + 1 < nrows and q >= rows[r + 1, R_FIRST]:
        r += 1
    return r


@ti.func
def _next_free(S: ti.template(), start, size, cursor, seen):
    """Next fit in the segment [start, start + size): the first free slot at or after offset
    ``cursor``, round the segment, having looked at ``seen`` slots since the search began (a
    lap at most). Returns (the slot, marked alive; −1 when a whole lap found none, the
    segment full), and the cursor and count to go on from."""
    if cursor >= size:  # (a segment shrunk since the last search)
        cursor = 0
    while seen < size and S.particle_alive[start + cursor] != 0:
        cursor += 1
        seen += 1
        if cursor == size:
            cursor = 0
    slot = -1
    if seen < size:
        slot = start + cursor
        S.particle_alive[slot] = 1
        cursor += 1
        seen += 1
        if cursor == size:
            cursor = 0
    return slot, cursor, seen


@ti.kernel
def spawn(E: ti.template(), S: ti.template(), rows: ti.types.ndarray(dtype=ti.i32, ndim=2),
          vals: ti.types.ndarray(dtype=ti.f32, ndim=2), nrows: ti.i32, total: ti.i32,
          adv: ti.types.ndarray(dtype=ti.i32, ndim=2), slots: ti.types.ndarray(dtype=ti.i32, ndim=1),
          serial: ti.template()):
    """Write the ``total`` particles of the plan: row r spawns k of emitter e at ring offset
    head + R_HEAD with serials from serial + R_SERIAL, born at stratified times in
    [ts0, ts0 + tspan) and written at the emitter's position then, with age −(t_s − t0): the step
    kernel advances them from their birth. A slot still alive is not overwritten: after every
    ring slot of the launch is taken, such a birth takes the next free slot of its emitter's
    segment from where the emitter's last such search ended, round the segment (next fit;
    ``emitter_fit``: one thread per emitter walks them in plan order, deterministic, no atomics
    decide a slot), so a burst of long-lived particles does not starve the stream while the
    segment has room; only a birth that finds no free slot in a whole lap is counted dropped.
    (The first free slot in slot order, searched from the segment's start every time, cost a
    walk of the segment each step once a ring is exactly full — a user-set capacity of rate ×
    lifetime: its ring slots die during the step after the launch that needs them, the free ones
    lie a launch behind the head — 0.2–0.5 ms a step at 1M slots, 1.5–2.8 ms at 4M; next fit
    finds them at once.) Then every
    emitter's ring head, serial and dropped count advance by ``adv``.

    Three passes in one launch: each birth's slot into ``slots`` (−1: none; a slot taken is
    marked alive at once, so the free-slot walk passes it), the free-slot walk, then every birth
    written from one call site (``init_particle`` inlined once: it is most of this kernel's
    compile).

    ``serial`` (a launch of few births on the CPU, a stream's step: ``engine.runtime.one_thread``):
    every loop runs on the launching thread. Such a launch's four loops did microseconds of work
    and each cost 20–170 µs to hand to the thread pool and back (flames.toml: ~0.35 ms a
    frame)."""
    ti.loop_config(serialize=serial)
    for q in range(total):
        r = _row_of(rows, nrows, q)
        e, j = rows[r, R_E], q - rows[r, R_FIRST]
        slot = rows[r, R_START] + (E.emitter_head[e] + rows[r, R_HEAD] + j) % rows[r, R_SIZE]
        slots[q] = -1
        if S.particle_alive[slot] != 0:
            ti.atomic_add(E.emitter_moved[e], 1)  # the ring caught up with a live particle
        else:
            slots[q] = slot
            S.particle_alive[slot] = 1
    ti.loop_config(serialize=serial)
    for e in range(E.count):
        # the emitter's births that find a slot, counted here by its thread (its rows' births,
        # adv's head advance, less those the segment has no room for): an atomic add per birth
        # from both threads fought over one cache line (the bench's 4M pool, 8,333 births a
        # step: the births' pass 0.60 -> 0.28 ms, kernel profiler over 30 steps)
        born = adv[e, A_HEAD]
        if E.emitter_moved[e] > 0:  # only when a ring slot was taken (nothing to do otherwise)
            E.emitter_moved[e] = 0
            cursor, seen = E.emitter_fit[e], 0  # (next fit: on from where the last search ended)
            for r in range(nrows):
                if rows[r, R_E] == e:
                    start, size = rows[r, R_START], rows[r, R_SIZE]
                    for j in range(rows[r, R_K]):
                        q = rows[r, R_FIRST] + j
                        if slots[q] < 0:
                            slots[q], cursor, seen = _next_free(S, start, size, cursor, seen)
                            if slots[q] < 0:
                                E.dropped[e] += 1  # the segment is full
                                born -= 1
            E.emitter_fit[e] = cursor
        E.emitter_emitted[e] += born
    ti.loop_config(serialize=serial)
    for q in range(total):
        if slots[q] >= 0:
            r = _row_of(rows, nrows, q)
            _born(E, S, rows, vals, r, q - rows[r, R_FIRST], slots[q])
    ti.loop_config(serialize=serial)
    for e in range(E.count):  # (after the births: they read the serial numbers before it)
        if adv[e, A_SIZE] > 0:
            E.emitter_head[e] = (E.emitter_head[e] + adv[e, A_HEAD]) % adv[e, A_SIZE]
            E.emitter_serial[e] += adv[e, A_SERIAL]
            E.dropped[e] += adv[e, A_DROPPED]


@ti.func
def _fires(S: ti.template(), i, bit, min_speed):
    fire = (S.particle_event[i] & bit) != 0
    if bit == EVENT_COLLISION:
        fire = fire and S.particle_impact[i] >= min_speed
    return fire


@ti.func
def _count_events(S: ti.template(), counts: ti.template(), p_start, p_size, chunks, bit, min_speed,
                  serial: ti.template()):
    """Pass 1: how many parents fire in each of ``chunks`` consecutive slices of the segment (a
    parallel loop of its own, or ``serial``: inlined at the outermost scope of
    :func:`spawn_children`)."""
    size = (p_size + chunks - 1) // chunks
    ti.loop_config(serialize=serial)
    for q in range(chunks):
        n = 0
        for i in range(p_start + q * size, p_start + ti.min(p_size, (q + 1) * size)):
            if _fires(S, i, bit, min_speed):
                n += 1
        counts[q] = n


@ti.func
def _child(E: ti.template(), S: ti.template(), i, c, sid, slot, bit):
    """Child ``sid`` of emitter c from parent slot i, into ``slot``. A collision's children are
    born where and when the impact was located: at the point on the surface, then moved along
    their velocity for the time left in the step (the age they start with)."""
    centre = S.particle_pos[i]
    if bit == EVENT_COLLISION:
        centre = S.particle_impact_pos[i]
    init_particle(E, S, slot, c, sid, centre, S.particle_vel[i])  # (one call site: see spawn)
    if bit == EVENT_COLLISION:  # born at the located impact, as old as it is
        lag = S.particle_impact_lag[i]
        S.particle_pos[slot] += lag * S.particle_vel[slot]
        S.particle_age[slot] = lag


@ti.kernel
def spawn_children(E: ti.template(), S: ti.template(), counts: ti.template(), parent: ti.template(),
                   slots: ti.template(), p_start: ti.i32, p_size: ti.i32, chunks: ti.i32, bit: ti.i32,
                   min_speed: ti.f32, c: ti.i32, c_start: ti.i32, c_size: ti.i32, count: ti.i32,
                   serial: ti.template()):
    """Pass 1 (:func:`_count_events`), then pass 2, in one launch (the loops run one after the
    other; a link took two launches a step, and the second cost ~0.14 ms: debris' sub-emitters
    5.2 → 3.8 ms a frame). Pass 2: each slice adds up the counts before it (its parents' first
    rank) and walks its parents in slot order; the n-th child of the pass takes ring slot
    head + n and serial serial + n. A child that would wrap onto a slot this pass already gave
    out (n ≥ ring size) is counted dropped; one that finds its ring slot alive, after the pass,
    takes the next free slot of the child segment on from where the last search ended (next
    fit, ``_next_free``: one thread walks them in n order, deterministic), or is counted dropped
    when a whole lap finds none. As in ``spawn``, the slots are chosen first
    (``parent[n]``: the parent slot of child n; ``slots[n]``: its slot, −1 none; a slot taken is
    marked alive at once) and every child is written after, from one call site.

    ``serial`` (a small link on the CPU: one slice of parents, few children at most;
    ``engine.runtime.one_thread``): every loop runs on the launching thread. A small link's five
    loops did microseconds of work and each cost 20–170 µs to hand to the thread pool and back:
    debris.toml's four launches a frame, 20 loops, ~0.9 ms."""
    _count_events(S, counts, p_start, p_size, chunks, bit, min_speed, serial)
    h0, s0 = E.emitter_head[c], E.emitter_serial[c]
    size = (p_size + chunks - 1) // chunks
    ti.loop_config(serialize=serial)
    for q in range(chunks):
        rank = 0
        for m in range(q):
            rank += counts[m]
        for i in range(p_start + q * size, p_start + ti.min(p_size, (q + 1) * size)):
            if _fires(S, i, bit, min_speed):
                for j in range(count):
                    n = rank * count + j
                    slot = c_start + (h0 + n) % c_size
                    if n >= c_size:
                        ti.atomic_add(E.dropped[c], 1)
                    else:
                        parent[n] = i
                        slots[n] = -1
                        if S.particle_alive[slot] != 0:
                            ti.atomic_add(E.emitter_moved[c], 1)  # placed below, in a free slot
                        else:
                            slots[n] = slot
                            S.particle_alive[slot] = 1
                rank += 1
    total = 0
    ti.loop_config(serialize=serial)
    for q in range(chunks):
        total += counts[q]
    born = ti.min(total * count, c_size)
    ti.loop_config(serialize=serial)
    for _ in range(1):  # one thread: the moved children in n order
        placed = born  # (counted here, as ``spawn``'s births: not an atomic add per child)
        if E.emitter_moved[c] > 0:
            E.emitter_moved[c] = 0
            cursor, seen = E.emitter_fit[c], 0  # (next fit, as ``spawn``'s births)
            for n in range(born):
                if slots[n] < 0:
                    slots[n], cursor, seen = _next_free(S, c_start, c_size, cursor, seen)
                    if slots[n] < 0:
                        E.dropped[c] += 1  # the segment is full
                        placed -= 1
            E.emitter_fit[c] = cursor
        E.emitter_emitted[c] += placed
    ti.loop_config(serialize=serial)
    for n in range(born):
        if slots[n] >= 0:
            _child(E, S, parent[n], c, s0 + n, slots[n], bit)
    E.emitter_head[c] = (h0 + total * count) % c_size
    E.emitter_serial[c] = s0 + total * count


# launched without Taichi's per-call Python (engine.launch; the emitters, state and link fields
# are template arguments, bound by weak references)
spawn, spawn_children = fast(spawn), fast(spawn_children)
