"""A deterministic hashed neighbour grid (Green, "Particle Simulation using CUDA": hash cells, sort
by cell, cell starts, a 27-cell search), rebuilt every step from the slots a caller marks.

Cells are cubes of side ``cell`` (m) indexed by ``floor(x / cell)`` (int32 per axis) and hashed into
a power-of-two table (Teschner et al. 2003's primes), so space is unbounded and memory follows the
slot count, never the scene's extent. The build is one kernel of top-level loops (each a parallel
loop, or on the CPU for a grid of at most SERIAL_SLOTS slots each on the launching thread; Taichi
runs them in order):

1. clear the bucket counts; 2. count: each member slot's cell and bucket, ``count[b] += 1`` with an
integer atomic (the same counts in any thread order); 3. an exclusive prefix scan of the counts in
two levels (block sums in parallel, a serial scan of the block sums, block-local scans in
parallel) into ``start``; 4. fill: each member takes a place in its bucket with an integer atomic
(the place depends on thread timing) … 5. … so each bucket is then insertion-sorted by slot, which
makes ``sorted`` a pure function of the members and positions: a stable order by slot within each
bucket, whatever the thread count.

No cap anywhere: a bucket holds as many slots as hash to it (buckets are ranges of one array sized
to the pool). A slot whose cell index does not fit in 30 bits (or whose position is not finite) is
left out of the grid and counted in ``ungridded`` (reported, as pools count dropped particles);
``max_bucket`` reports the fullest bucket of the last build. Readers gather per particle
(``for_neighbours``): visit the 27 cells around the slot's cell, and within each the slots of its
bucket whose ``slot_cell`` is that cell (two cells that share a bucket are told apart, so each
neighbour is seen exactly once). :class:`NeighbourLists` lists each slot's near neighbours from
that walk once, for gathers that run several times over the same neighbourhood.
"""

import taichi as ti

from .. import runtime
from ..launch import data_oriented
from .sizing import BLOCK, MAX_CELL_INDEX, NEIGHBOURS, table_size

# a grid over at most this many slots is rebuilt on the launching thread on the CPU (each of its
# seven loops, and the listing's two copies, a few µs of work there; each parallel loop a hand-off
# to the thread pool and back: engine.runtime.one_thread)
SERIAL_SLOTS = 4096

_P1, _P2, _P3 = 73856093, 19349663, 83492791  # Teschner et al. 2003, "Optimized spatial hashing"


@data_oriented
class HashGrid:
    """The grid over ``capacity`` slots with cells of side ``cell`` metres.

    Fields: ``sorted`` (i32, capacity: member slots, grouped by bucket, by slot within one);
    ``start`` (i32, table + 1: bucket b holds ``sorted[start[b]:start[b + 1]]``); ``slot_cell``
    (vec3 i32: each slot's cell at the last build); ``slot_bucket`` (i32: −1 when not in the grid);
    ``members``, ``ungridded``, ``max_bucket`` (i32 scalars of the last build)."""

    built = 0  # grids constructed in this process: a scene without interactions builds none

    def __init__(self, capacity: int, cell: float, lo: int = 0, hi: int = None):
        """``capacity`` slots (the per-slot arrays' length), of which only slots ``lo`` …
        ``hi`` − 1 (default: all) can be members: the build's loops and the table's size follow
        that range."""
        HashGrid.built += 1
        self.cap = max(1, int(capacity))
        self.lo = max(0, int(lo))
        self.hi = self.cap if hi is None else min(self.cap, int(hi))
        self.cell = float(cell)
        self.inv_cell = 1.0 / self.cell
        self.table = table_size(max(1, self.hi - self.lo))
        self.serial = runtime.one_thread(self.hi - self.lo, SERIAL_SLOTS)  # (a compile-time switch)
        self.blocks = self.table // BLOCK
        self.mask = self.table - 1
        self.count = ti.field(ti.i32, shape=self.table)
        self.fill = ti.field(ti.i32, shape=self.table)
        self.start = ti.field(ti.i32, shape=self.table + 1)
        self.block_sum = ti.field(ti.i32, shape=self.blocks)
        self.sorted = ti.field(ti.i32, shape=self.cap)
        self.slot_bucket = ti.field(ti.i32, shape=self.cap)
        self.slot_cell = ti.Vector.field(3, ti.i32, shape=self.cap)
        self.members = ti.field(ti.i32, shape=())
        self.ungridded = ti.field(ti.i32, shape=())
        self.max_bucket = ti.field(ti.i32, shape=())

    @ti.func
    def cell_of(self, x):
        """The cell (vec3 i32) holding point x (m)."""
        return ti.floor(x * self.inv_cell, ti.i32)

    @ti.func
    def bucket(self, c):
        """The bucket of cell c: Teschner's hash in uint32 (wraps by definition), masked."""
        h = (ti.cast(c[0], ti.u32) * ti.u32(_P1)) ^ (ti.cast(c[1], ti.u32) * ti.u32(_P2)) \
            ^ (ti.cast(c[2], ti.u32) * ti.u32(_P3))
        return ti.cast(h & ti.u32(self.mask), ti.i32)

    @ti.func
    def neighbour_cell(self, c, n):
        """The n-th (0..26) cell of the 3×3×3 block around c, in a fixed order."""
        return c + ti.Vector([n % 3 - 1, (n // 3) % 3 - 1, n // 9 - 1])

    @ti.func
    def for_neighbours(self, i, kind: ti.template(), want, visit: ti.template(), args: ti.template()):
        """Call ``visit(j, *args)`` for every slot j ≠ i with ``kind[j] == want`` in the 27 cells
        around slot i's cell (i in the grid), in a fixed order: cell n = 0..26 (``neighbour_cell``),
        then bucket order (by slot), so a gather's sums come out in the same order every time.
        ``kind``: a per-slot field; ``visit``: a ti.func (or a data-oriented object's method);
        ``args``: a tuple, passed on as it is: the visitor takes i's values by value and its
        accumulators (local scalars or vectors) as ``ti.template()``, by reference, adding into them."""
        c = self.slot_cell[i]
        for n in range(27):
            cc = self.neighbour_cell(c, n)
            b = self.bucket(cc)
            for k in range(self.start[b], self.start[b + 1]):
                j = self.sorted[k]
                if j != i and kind[j] == want and (self.slot_cell[j] == cc).all():
                    visit(j, *args)

    @ti.kernel
    def build(self, pos: ti.template(), member: ti.template()):
        """Rebuild from the slots with ``member[i] != 0`` at positions ``pos`` (vec3 f32, m)."""
        self.rebuild(pos, member)

    @ti.func
    def rebuild(self, pos: ti.template(), member: ti.template()):
        """``build``'s loops, for a caller's kernel to run among its own (each stays a top-level
        loop of that kernel, parallel unless ``serial``: call it there, never inside a loop or a
        branch)."""
        ti.loop_config(serialize=ti.static(self.serial))
        for b in range(self.table):
            self.count[b] = 0
            self.fill[b] = 0
        self.ungridded[None] = 0
        self.max_bucket[None] = 0
        ti.loop_config(serialize=ti.static(self.serial))
        for i in range(self.lo, self.hi):
            b = -1
            if member[i] != 0:
                q = pos[i] * self.inv_cell
                lim = ti.cast(MAX_CELL_INDEX, ti.f32)
                # a NaN fails every comparison, so it is left out here too
                if ti.abs(q[0]) < lim and ti.abs(q[1]) < lim and ti.abs(q[2]) < lim:
                    c = ti.floor(q, ti.i32)
                    self.slot_cell[i] = c
                    b = self.bucket(c)
                    ti.atomic_add(self.count[b], 1)
                else:
                    ti.atomic_add(self.ungridded[None], 1)
            self.slot_bucket[i] = b
        ti.loop_config(serialize=ti.static(self.serial))
        for k in range(self.blocks):  # level 1: each block's total
            s = 0
            for m in range(BLOCK):
                s += self.count[k * BLOCK + m]
            self.block_sum[k] = s
        ti.loop_config(serialize=ti.static(self.serial))
        for _ in range(1):  # level 2: exclusive scan of the block totals (one thread, T/1024 adds)
            run = 0
            for k in range(self.blocks):
                s = self.block_sum[k]
                self.block_sum[k] = run
                run += s
            self.start[self.table] = run
        ti.loop_config(serialize=ti.static(self.serial))
        for k in range(self.blocks):  # level 3: block-local scans from each block's offset
            run = self.block_sum[k]
            for m in range(BLOCK):
                b = k * BLOCK + m
                self.start[b] = run
                run += self.count[b]
        ti.loop_config(serialize=ti.static(self.serial))
        for i in range(self.lo, self.hi):
            b = self.slot_bucket[i]
            if b >= 0:
                self.sorted[self.start[b] + ti.atomic_add(self.fill[b], 1)] = i
        ti.loop_config(serialize=ti.static(self.serial))
        for b in range(self.table):  # per-bucket insertion sort by slot: the order no longer
            lo, hi = self.start[b], self.start[b] + self.count[b]  # depends on the fill's timing
            for k in range(lo + 1, hi):
                v = self.sorted[k]
                m = k - 1
                while m >= lo and self.sorted[m] > v:
                    self.sorted[m + 1] = self.sorted[m]
                    m -= 1
                self.sorted[m + 1] = v
            ti.atomic_max(self.max_bucket[None], hi - lo)
        self.members[None] = self.start[self.table]

    def stats(self) -> dict:
        """The last build's integer counts (one read-back each)."""
        return {"members": int(self.members[None]), "ungridded": int(self.ungridded[None]),
                "max_bucket": int(self.max_bucket[None]), "table": self.table}


@data_oriented
class NeighbourLists:
    """Each member slot's neighbours listed once from a :class:`HashGrid`'s walk and reused by
    later gathers while they hold (Macklin & Müller 2013, Algorithm 1: "find neighbouring
    particles" once a step, then iterate).

    ``build(member, kind)`` lists, for every slot with ``member[i] != 0``, the slots j of the walk
    (the 27 cells around its cell at the grid's last build, ``kind[j] == kind[i]``, j ≠ i) within
    ``cell·(1 + skin)`` of it, in the walk's order, at most NEIGHBOURS of them; a slot with more is
    marked to walk the grid instead (counted in ``unlisted``: nothing is cut). ``visit`` gathers over
    a slot's list (or walk) with the walk's visitor contract, so a gather whose visitor applies a
    cut-off ≤ ``cell`` sums the same terms in the same order as the walk would, as long as no member
    has moved skin·cell/2 since the listing: ``moved(i, x)`` (call it where a member is moved)
    raises ``stale``, and the owner lists again before the next gather.

    Fields: ``nbr`` (i32, capacity × (NEIGHBOURS + 1): slot i's list is ``nbr[i, :count[i]]``,
    what lies past it is scratch), ``count`` (i32: listed; −1: walks the grid), ``x_ref`` (where
    each member was listed), ``sorted_x``/``sorted_kind``/``sorted_cell`` (the listing's copies of
    the grid's members in its sorted order), ``stale``, ``go``, ``unlisted``, ``limit`` (i32 scalars;
    ``limit`` is NEIGHBOURS, lower in tests to force the walk)."""

    SKIN = 0.2  # the default skin, a fraction of a cell

    def __init__(self, grid: HashGrid, pos, skin: float = SKIN):
        """``grid``: the walk; ``pos``: the slots' positions (vec3 f32 field, m); ``skin``: the
        lists' margin as a fraction of the cell (default SKIN). A larger one relists less often
        and gathers over longer lists: what pays depends on how dense the members are and how far
        they move a step (the owner's choice; the answer is the walk's either way)."""
        self.skin = float(skin)
        n = grid.cap
        self.grid, self.pos = grid, pos
        self.nbr = ti.field(ti.i32, shape=(n, NEIGHBOURS + 1))  # (the last column: scratch)
        self.count = ti.field(ti.i32, shape=n)
        self.x_ref = ti.Vector.field(3, ti.f32, shape=n)
        self.stale = ti.field(ti.i32, shape=())
        self.go = ti.field(ti.i32, shape=())  # (relist's decision, read by its loops)
        self.unlisted = ti.field(ti.i32, shape=())
        self.limit = ti.field(ti.i32, shape=())
        self.limit[None] = NEIGHBOURS
        # the grid's members in its sorted order (bucket, then slot): their positions at the
        # listing, kinds and cells, so the listing's walk reads each bucket's candidates from
        # consecutive memory rather than gathering them slot by slot (the same candidates, in
        # the same order, with the same values: the same lists)
        self.sorted_x = ti.Vector.field(3, ti.f32, shape=n)
        self.sorted_kind = ti.field(ti.i32, shape=n)
        self.sorted_cell = ti.Vector.field(3, ti.i32, shape=n)
        self.reach2 = (grid.cell * (1.0 + self.skin)) ** 2
        self.move2 = (0.5 * self.skin * grid.cell) ** 2

    @ti.kernel
    def build(self, member: ti.template(), kind: ti.template()):
        """List every member's neighbours (at the positions now)."""
        self.relist(member, kind, False)

    @ti.func
    def relist(self, member: ti.template(), kind: ti.template(), only_stale: ti.template()):
        """``build``'s loops, for a caller's kernel to run among its own (call it at that
        kernel's top level: each loop stays parallel there). ``only_stale``: list only if
        ``stale`` is set (the test made on the device, so a solver's sweep can carry its own
        relisting: no read-back and no extra launch between sweeps)."""
        G = self.grid
        go = 1
        if ti.static(only_stale):
            go = self.stale[None]
        self.go[None] = go
        if go != 0:
            self.stale[None] = 0
            self.unlisted[None] = 0
        # (each loop's range is empty when not listing: an empty parallel loop costs ~12 µs
        # here, one that tests a flag per item ~17 µs)
        ti.loop_config(serialize=ti.static(G.serial))  # (the two copies: a few µs on a small grid)
        for k in range(G.members[None] * self.go[None]):
            j = G.sorted[k]
            self.sorted_x[k] = self.pos[j]
            self.sorted_kind[k] = kind[j]
            self.sorted_cell[k] = G.slot_cell[j]
        ti.loop_config(serialize=ti.static(G.serial))
        for i in range(G.lo, G.lo + (G.hi - G.lo) * self.go[None]):  # slots outside the grid:
            if member[i] == 0 or G.slot_bucket[i] < 0:  # nothing listed
                if member[i] != 0:
                    self.x_ref[i] = self.pos[i]
                self.count[i] = 0
        # the members in the grid's order (bucket, then slot): a cell's members one after another,
        # so their 27 cells' candidates are still in cache for the next (water's listing 2.1 →
        # 1.8 ms, the same lists)
        for q in range(G.members[None] * self.go[None]):
            i = G.sorted[q]
            m = 0
            xi = self.sorted_x[q]
            self.x_ref[i] = xi
            want, c = self.sorted_kind[q], self.sorted_cell[q]
            # the grid's walk (HashGrid.for_neighbours: the 27 cells in its order, each
            # bucket's slots of that cell and kind, by slot) over the sorted copies
            # without a branch per candidate: each is written at place m (the spare column
            # past the list's end once it is full) and kept by counting it — about a quarter
            # of the candidates are kept, so a branch on it mispredicts often (water's
            # listing: 3.1 → 1.7 ms)
            for n in range(27):
                cc = G.neighbour_cell(c, n)
                b = G.bucket(cc)
                for k in range(G.start[b], G.start[b + 1]):
                    r = xi - self.sorted_x[k]
                    j = G.sorted[k]
                    keep = (self.sorted_kind[k] == want) & (self.sorted_cell[k] == cc).all() \
                        & (r.dot(r) < self.reach2) & (j != i)
                    self.nbr[i, ti.min(m, NEIGHBOURS)] = j
                    m += ti.cast(keep, ti.i32)
            if m > self.limit[None]:
                m = -1
                ti.atomic_add(self.unlisted[None], 1)  # (an integer count: the same in any order)
            self.count[i] = m

    @ti.func
    def visit(self, i, kind: ti.template(), want, visit: ti.template(), args: ti.template()):
        """``visit(j, *args)`` for slot i's listed neighbours (or, past the list, the walk's)."""
        m = self.count[i]
        if m >= 0:
            for k in range(m):
                visit(self.nbr[i, k], *args)
        else:
            self.grid.for_neighbours(i, kind, want, visit, args)

    @ti.func
    def moved(self, i, x):
        """Member i is now at x: the lists are stale once it is skin·cell/2 from where it was listed."""
        if (x - self.x_ref[i]).norm_sqr() > self.move2:
            self.stale[None] = 1  # (every writer writes 1: the same in any order)
