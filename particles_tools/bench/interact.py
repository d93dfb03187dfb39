"""``particles bench --only interact``: the neighbour grid and one interaction pass per 100k
particles against the same loops in numba, and the shipped sand, water and galaxy configs'
frame rates at 1280×720 (step + render).

The grid rows time :meth:`HashGrid.build` (count, two-level scan, fill, per-bucket sort by slot)
, the neighbour listing (one walk of the 27 cells around each grain, once a step) and one
granular Jacobi sweep (each grain gathers its contacts from its list) over 100,000 grains at a mean spacing of one contact distance. The numba rows run the same algorithm
(the same hash, bucket counts, a serial scan, a serial fill in slot order — stable, so no sort —
and a ``prange`` gather with the same contact and friction arithmetic) on the same positions; the
ratio is numba's time over Taichi's (≥ 1: Taichi is as fast or faster); numba's sweep walks the 27
cells, so it is set against the listing plus one sweep (a step of one iteration) and the
sweep alone (each further iteration). numba is an optional
extra: without it those rows are left out and the notes say so.
"""
from __future__ import annotations

import os

import numpy as np

from .common import Row, frame_seconds, time_median

N_FULL, N_QUICK = 100_000, 10_000
R = 0.01  # grain radius, m
CONFIGS = ("sand", "water", "galaxy")


def _grain_scene(n: int):
    from engine.config.load import load_config
    from engine.scene import Scene

    side = 2 * R * n ** (1 / 3)  # one grain per (2r)³: about 6 contacts a grain
    cfg = {"fps": 60.0, "frames": 1, "solver": {"h": 1.0 / 120.0}, "forces": {"gravity": [0.0, 0.0, 0.0]},
           "emitters": [{"shape": "box", "position": [0.0, side / 2, 0.0], "box_size": [side] * 3,
                         "speed": [0.0, 0.1], "spread": 180.0, "bursts": [{"time": 0.0, "count": n}],
                         "lifetime": 100.0, "capacity": n,
                         "interact": {"kind": "granular", "radius": R, "friction": 0.5}}]}
    sc = Scene(load_config(cfg), render=False)
    sc.advance_frame()
    return sc


def _numba_fns():
    import numba as nb

    P1, P2, P3 = 73856093, 19349663, 83492791

    @nb.njit(cache=False)
    def build(pos, inv_cell, mask):
        n = pos.shape[0]
        cell = np.floor(pos * inv_cell).astype(np.int32)
        bucket = np.empty(n, np.int32)
        for i in range(n):
            h = (np.uint32(cell[i, 0]) * np.uint32(P1)) ^ (np.uint32(cell[i, 1]) * np.uint32(P2)) \
                ^ (np.uint32(cell[i, 2]) * np.uint32(P3))
            bucket[i] = np.int32(h & np.uint32(mask))
        start = np.zeros(mask + 2, np.int32)
        for i in range(n):
            start[bucket[i] + 1] += 1
        for b in range(mask + 1):
            start[b + 1] += start[b]
        fill = start[:-1].copy()
        order = np.empty(n, np.int32)
        for i in range(n):  # serial in slot order: stable
            order[fill[bucket[i]]] = i
            fill[bucket[i]] += 1
        return cell, start, order

    @nb.njit(parallel=True, fastmath=False)
    def sweep(pos, vel, corr, cell, start, order, mask, h, d_contact, mu):
        n = pos.shape[0]
        out = np.zeros_like(pos)
        for i in nb.prange(n):
            xi = pos[i]
            di = h * vel[i] + corr[i]
            dx0 = 0.0
            dx1 = 0.0
            dx2 = 0.0
            for m in range(27):
                c0 = cell[i, 0] + m % 3 - 1
                c1 = cell[i, 1] + (m // 3) % 3 - 1
                c2 = cell[i, 2] + m // 9 - 1
                hsh = (np.uint32(c0) * np.uint32(P1)) ^ (np.uint32(c1) * np.uint32(P2)) ^ (np.uint32(c2) * np.uint32(P3))
                b = np.int32(hsh & np.uint32(mask))
                for k in range(start[b], start[b + 1]):
                    j = order[k]
                    if j == i or cell[j, 0] != c0 or cell[j, 1] != c1 or cell[j, 2] != c2:
                        continue
                    r0, r1, r2 = xi[0] - pos[j, 0], xi[1] - pos[j, 1], xi[2] - pos[j, 2]
                    d2 = r0 * r0 + r1 * r1 + r2 * r2
                    if 0.0 < d2 < d_contact * d_contact:
                        d = np.sqrt(d2)
                        n0, n1, n2 = r0 / d, r1 / d, r2 / d
                        pen = d_contact - d
                        e0 = di[0] - (h * vel[j, 0] + corr[j, 0])
                        e1 = di[1] - (h * vel[j, 1] + corr[j, 1])
                        e2 = di[2] - (h * vel[j, 2] + corr[j, 2])
                        en = e0 * n0 + e1 * n1 + e2 * n2
                        t0, t1, t2 = e0 - en * n0, e1 - en * n1, e2 - en * n2
                        tl = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
                        f = min(mu * pen / max(tl, 1e-12), 1.0)
                        dx0 += 0.5 * pen * n0 - 0.5 * t0 * f
                        dx1 += 0.5 * pen * n1 - 0.5 * t1 * f
                        dx2 += 0.5 * pen * n2 - 0.5 * t2 * f
            out[i, 0], out[i, 1], out[i, 2] = 0.5 * dx0, 0.5 * dx1, 0.5 * dx2
        return out

    return build, sweep


def grid_rows(n: int, repeats: int):
    sc = _grain_scene(n)
    I = sc.particles.interact
    G = I.grid
    h = 1.0 / 120.0
    S = I.state

    def build():
        I.prepare()
        G.build(S.particle_pos, I.member)

    t_build = time_median(build, repeats)
    build()
    t_list = time_median(I.relist, repeats)
    st = G.stats()
    pos0 = S.particle_pos.to_numpy()

    def sweep():  # (the stage: on the CPU it lists again first when the lists are stale)
        I.run_stage("sweep", h)

    t_sweep = time_median(sweep, repeats)
    S.particle_pos.from_numpy(pos0)
    per = 100_000 / n
    rows = []
    notes_b = f"{n:,} grains; max bucket {st['max_bucket']}, {st['ungridded']} ungridded"
    try:
        build_nb, sweep_nb = _numba_fns()
    except ImportError:
        build_nb = None
    if build_nb is None:
        rows.append(Row("interact", "grid build per 100k (Taichi)", t_build * per * 1e3, "ms", notes_b + "; numba not installed"))
        rows.append(Row("interact", "neighbour listing per 100k (Taichi)", t_list * per * 1e3, "ms", "once a step"))
        rows.append(Row("interact", "granular sweep per 100k (Taichi)", t_sweep * per * 1e3, "ms", "numba not installed"))
        return rows
    live = S.particle_alive.to_numpy()[:n] != 0
    pos = pos0[:n][live].astype(np.float32)
    vel = S.particle_vel.to_numpy()[:n][live].astype(np.float32)
    corr = np.zeros_like(pos)
    mask = G.table - 1
    inv = np.float32(1.0 / G.cell)
    t_build_nb = time_median(lambda: build_nb(pos, inv, mask), repeats, taichi=False)
    cell, start, order = build_nb(pos, inv, mask)
    d_contact = np.float32(2 * R)
    t_sweep_nb = time_median(lambda: sweep_nb(pos, vel, corr, cell, start, order, mask, np.float32(h), d_contact,
                                              np.float32(0.5)), repeats, taichi=False)
    rb, rs, rls = t_build_nb / t_build, t_sweep_nb / t_sweep, t_sweep_nb / (t_list + t_sweep)
    threads = os.environ.get("NUMBA_NUM_THREADS", "all cores")
    rows.append(Row("interact", "grid build per 100k (Taichi)", t_build * per * 1e3, "ms",
                    f"{notes_b}; numba {t_build_nb * per * 1e3:.2f} ms (serial counting sort): numba/Taichi {rb:.2f}x",
                    {"ratio": rb}))
    rows.append(Row("interact", "neighbour listing per 100k (Taichi)", t_list * per * 1e3, "ms",
                    f"once a step; listing + one sweep {(t_list + t_sweep) * per * 1e3:.2f} ms against numba's "
                    f"27-cell sweep: numba/Taichi {rls:.2f}x", {"ratio": rls}))
    rows.append(Row("interact", "granular sweep per 100k (Taichi)", t_sweep * per * 1e3, "ms",
                    f"from the lists; numba prange {t_sweep_nb * per * 1e3:.2f} ms ({threads}) walking the 27 cells: "
                    f"numba/Taichi {rs:.2f}x", {"ratio": rs}))
    return rows


def config_rows(quick: bool):
    """Each shipped config at 1280×720: step + render per frame, averaged over a stretch where its
    particles are alive (after 1 s), and the live count."""
    from engine.config.load import load_config
    from engine.scene import Scene

    from .. import CONFIGS as folder

    rows = []
    for name in CONFIGS:
        cfg = load_config(os.path.join(folder, f"{name}.toml"))
        sc = Scene(cfg, width=1280, height=720)
        skip = int(cfg.fps * (0.5 if quick else 1.0))
        for _ in range(skip):
            sc.advance_frame()
        dt = frame_seconds(sc, 5 if quick else 20)
        rows.append(Row("interact", f"{name} at 1280x720 (step + render)", 1.0 / dt, "frames/s",
                        f"{sc.live_count():,} particles live"))
    return rows


def run(quick: bool = False):
    n = N_QUICK if quick else N_FULL
    return grid_rows(n, 3 if quick else 7) + config_rows(quick)
