"""How much memory a neighbour grid takes, estimated without Taichi (the config's checks use it
before anything is allocated, as the pool budgets do)."""
from __future__ import annotations

BLOCK = 1024  # buckets per block of the two-level prefix scan (engine.geometry.grid)
MAX_GRID_BYTES = 2 << 30  # 2 GiB for one scene's grids and interaction fields
# a cell index must fit in 30 bits per axis so that neighbours' indices (±1) never overflow int32
MAX_CELL_INDEX = 1 << 30
NEIGHBOURS = 64  # neighbours listed per member slot a step (engine.particles.interact); more: the grid's walk


def table_size(capacity: int) -> int:
    """Buckets of the hash table for ``capacity`` slots: a power of two ≥ 2 × capacity (a load of
    at most 1/2, so most buckets hold one cell), at least one scan block."""
    n = BLOCK
    while n < 2 * capacity:
        n *= 2
    return n


def grid_bytes(capacity: int) -> int:
    """Bytes of a grid over ``capacity`` slots: per slot the sorted index, bucket and cell
    (5 × int32); per bucket count, start and fill (3 × int32)."""
    t = table_size(capacity)
    return 20 * capacity + 12 * t + 8 * (t // BLOCK)


def interact_bytes(capacity: int, fluid: bool) -> int:
    """The grid plus the interaction's own per-slot fields: position and velocity before the
    solve, the correction and its Jacobi delta (4 × vec3 f32, member flag), the neighbour list
    (NEIGHBOURS + 1 int32 and its count, where the slot was listed, vec3 f32, and the listing's
    sorted copies of position, kind and cell, 7 × 4 bytes); fluid adds λ, the vorticity and a
    velocity buffer (7 f32)."""
    return grid_bytes(capacity) + capacity * (4 * 12 + 4 + 4 * (NEIGHBOURS + 2) + 12 + 28 + (28 if fluid else 0))
