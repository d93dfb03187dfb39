"""The neighbour grid and lists that interacting particles stand on (engine.geometry.grid): every
member in its cell's bucket once, in slot order; each member's list holding every neighbour the
grid's walk would visit before each use; relisting on the device only when stale; and no grid at
all in a scene without interactions."""
import os

import numpy as np
import pytest
import taichi as ti

from helpers import run_frames, sim_scene
from runhelp import ROOT

from engine.geometry.grid import NeighbourLists
from engine.particles.interact import GRAIN_SKIN


# -- the grid ----------------------------------------------------------------------------------
@pytest.mark.parametrize("serial", [True, False])
def test_grid_sorted_by_slot_within_buckets_and_complete(serial, monkeypatch):
    """Every member lands in the bucket of its cell exactly once, non-members nowhere, and each
    bucket's slots are in increasing slot order (the stable order frames depend on); 100 points
    beyond the 30-bit cell range are counted as ungridded, not dropped silently. Built on the
    launching thread (a small grid on the CPU: ``HashGrid.serial``) or by parallel loops."""
    from engine import runtime
    from engine.geometry.grid import HashGrid

    runtime.ensure_init()
    monkeypatch.setattr(runtime, "one_thread", lambda n, limit: serial)
    n = 3000
    rng = np.random.default_rng(1)
    p = (rng.random((n, 3)) * 3 - 1.5).astype(np.float32)
    p[:100] = 1e9  # 1e9 m / 0.05 m per cell ≫ 2^30 cells
    member = (rng.random(n) < 0.7).astype(np.int32)
    pos, mem = ti.Vector.field(3, ti.f32, n), ti.field(ti.i32, n)
    pos.from_numpy(p)
    mem.from_numpy(member)
    g = HashGrid(n, 0.05)
    assert g.serial == serial
    g.build(pos, mem)
    st = g.stats()
    far = int(member[:100].sum())
    assert st["ungridded"] == far
    start, order = g.start.to_numpy(), g.sorted.to_numpy()
    members = order[:start[-1]]
    expect = np.nonzero(member)[0]
    expect = expect[expect >= 100]
    assert sorted(members.tolist()) == expect.tolist()
    bucket = g.slot_bucket.to_numpy()
    cells = np.floor(p / np.float32(0.05)).astype(np.int64)
    for b in np.unique(bucket[expect]):
        seg = order[start[b]:start[b + 1]]
        assert (np.diff(seg) > 0).all()
        assert (bucket[seg] == b).all()
    assert (g.slot_cell.to_numpy()[expect] == cells[expect]).all()
    assert st["max_bucket"] == np.bincount(bucket[expect]).max()


def _lists_checked(cfg, frames=6, host=True):
    """Run cfg, checking at each sweep and velocity pass that the lists it gathers over are
    whole: where they are fresh, that every member's list holds every slot of the grid walk's 27
    cells closer than the kinds' largest cut-off (so each gather gets the walk's terms); where
    they are stale, that the stage listed them again first (every member's ``x_ref`` is then
    where it stood at the call). Returns the scene's interactions, the member counts checked
    fresh and the number of stale calls. ``host``: the CPU's way (each stage reads ``stale`` and
    lists first); False: the kernels test it themselves (a GPU's way, compiled in on the CPU)."""
    sc = sim_scene(cfg)
    I = sc.particles.interact
    assert I.relist_on_host  # (the CPU's: each stage's relisting tested and launched here)
    I.relist_on_host = host  # (a compile-time switch: read when the kernels first compile, below)
    checked, relisted = [], []

    def check():
        kind, x, cells = I.slot_kind.to_numpy(), I.state.particle_pos.to_numpy(), I.grid.slot_cell.to_numpy()
        nnbr, nbr = I.lists.count.to_numpy(), I.lists.nbr.to_numpy()
        members = np.flatnonzero(I.member.to_numpy())
        for i in members:
            same = members[(kind[members] == kind[i]) & (members != i)]
            walk = same[(np.abs(cells[same] - cells[i]) <= 1).all(1)]
            near = set(walk[((x[walk] - x[i]) ** 2).sum(1) < I.grid.cell ** 2].tolist())
            assert nnbr[i] == -1 or near <= set(nbr[i, : nnbr[i]].tolist()), i
        checked.append(len(members))

    def checked_call(h, inner):
        stale = I.lists.stale[None]
        if not stale:
            check()
        x = I.state.particle_pos.to_numpy()
        inner(h)
        if stale:  # (the stage relisted first)
            members = np.flatnonzero(I.member.to_numpy())
            assert np.array_equal(I.lists.x_ref.to_numpy()[members], x[members])
            relisted.append(len(members))

    run = I.run_stage  # (a stage: on the CPU its relisting is launched first)

    def stage(name, *args):
        if name in ("sweep", "finish"):
            checked_call(args[0], lambda h: run(name, h))
        else:
            run(name, *args)

    I.run_stage = stage
    run_frames(sc, frames)
    return I, checked, relisted


_SAND = {"name": "sand", "shape": "box", "position": [0.6, 0.4, 0.0], "box_size": [0.2, 0.2, 0.2],
         "speed": [0.0, 0.5], "bursts": [{"time": 0.0, "count": 300}], "lifetime": 100.0,
         "interact": {"kind": "granular", "radius": 0.015, "friction": 0.5}}
_FLOOR = [{"type": "plane", "point": [0, 0, 0], "normal": [0, 1, 0], "restitution": 0.0}]


@pytest.mark.parametrize("host", [True, False])
def test_neighbour_lists_hold_every_neighbour_the_grid_walk_would_visit(host):
    """Each member's neighbours are listed once a step and reused by every sweep and the velocity
    pass while no member has moved past half the skin: checked before each use, in a pouring
    fluid and in grains falling onto a floor, and a member whose neighbours overflow the list
    walks the grid instead (counted). Stale lists tested by the stage on the host (the CPU's) or
    inside the kernels (a GPU's)."""
    s = 0.04
    cfg = {"fps": 30.0, "solver": {"h": 1.0 / 120.0, "impacts": "projected"},
           "emitters": [{"name": "water", "shape": "box", "position": [0.0, 0.3, 0.0], "box_size": [0.3, 0.3, 0.3],
                         "speed": [0.0, 0.5], "bursts": [{"time": 0.0, "count": 400}], "lifetime": 100.0,
                         "interact": {"kind": "fluid", "radius": s / 2, "iterations": 4}}, _SAND],
           "colliders": _FLOOR}
    I, checked, relisted = _lists_checked(cfg, host=host)
    assert I.lists.skin == NeighbourLists.SKIN  # a fluid's narrow skin
    assert len(checked) + len(relisted) >= 6 * 4 * 5 and min(checked) > 0
    assert len(relisted) > 0  # (the pour moves members past the skin within steps)
    assert I.stats()["unlisted"] == 0
    I.lists.limit[None] = 3  # a member with more neighbours walks the grid
    I.relist()
    assert I.stats()["unlisted"] > 0 and (I.lists.count.to_numpy() == -1).any()


def test_relisting_inside_a_kernel_happens_only_when_stale():
    """``NeighbourLists.relist(..., only_stale=True)`` (what every sweep and the velocity pass run
    first) leaves the lists alone while ``stale`` is clear, and lists exactly what ``build`` lists
    when it is set, clearing it."""
    cfg = {"fps": 30.0, "solver": {"h": 1.0 / 120.0},
           "emitters": [dict(_SAND, bursts=[{"time": 0.0, "count": 200}])], "colliders": _FLOOR}
    sc = sim_scene(cfg)
    run_frames(sc, 3)
    I = sc.particles.interact
    L = I.lists

    @ti.kernel
    def relist_if_stale(L: ti.template(), member: ti.template(), kind: ti.template()):
        L.relist(member, kind, True)

    I.relist()
    count, nbr = L.count.to_numpy(), L.nbr.to_numpy()
    assert (count > 0).sum() > 50
    L.count.fill(0)
    L.stale[None] = 0
    relist_if_stale(L, I.member, I.slot_kind)
    assert (L.count.to_numpy() == 0).all()  # not stale: nothing listed
    L.stale[None] = 1
    relist_if_stale(L, I.member, I.slot_kind)
    assert L.stale[None] == 0
    assert np.array_equal(L.count.to_numpy(), count)
    for i in np.flatnonzero(count > 0):
        assert np.array_equal(L.nbr.to_numpy()[i, :count[i]], nbr[i, :count[i]])


@pytest.mark.slow  # (default run kept under 5 minutes cold; the lists' test above runs by default)
def test_grains_wide_skin_lists_hold_every_neighbour_too():
    """Grains alone take the wide skin (GRAIN_SKIN: fewer relistings in a pour); their lists hold
    every neighbour of the walk before each use all the same, as they fall and pile."""
    sand = dict(_SAND, speed=[0.0, 3.0], position=[0.6, 0.15, 0.0])  # fast, low: they meet and pile
    cfg = {"fps": 30.0, "solver": {"h": 1.0 / 120.0, "impacts": "projected"}, "emitters": [sand],
           "colliders": _FLOOR}
    I, checked, relisted = _lists_checked(cfg, frames=12)
    assert I.lists.skin == GRAIN_SKIN > NeighbourLists.SKIN
    assert len(checked) + len(relisted) >= 12 * 4 * 2 and min(checked) > 0
    assert I.stats()["unlisted"] == 0


def test_no_grid_without_interact():
    """A scene without `interact` builds no grid (so compiles none of its kernels) and allocates
    no interaction fields."""
    from engine.geometry.grid import HashGrid

    before = HashGrid.built
    sc = sim_scene(os.path.join(ROOT, "configs", "dust.toml"))
    assert sc.particles.interact is None
    assert HashGrid.built == before
