"""A soft body's view of the shape table (:class:`~engine.colliders.Colliders`): the table's own
fields read by points that keep an offset (the body's thickness) from every surface."""
# (no __future__ annotations: Taichi reads the funcs' ti.template() annotations)

import numpy as np

from .colliders import Colliders
from .launch import data_oriented


_SHARED = ("specs", "count", "event_count", "dtype", "kinds", "spins", "rotating", "names", "owners", "parties", "collider_point",
           "collider_normal", "collider_radius", "collider_vel", "collider_restitution", "collider_friction",
           "collider_half", "collider_axis_x", "collider_axis_z", "collider_omega", "collider_kind", "collider_bound",
           "_band", "_np")


@data_oriented
class ColliderView(Colliders):
    """A :class:`Colliders` table as points that keep ``offset`` m from its surfaces meet it (a
    soft body's nodes, ``offset`` its thickness: a sphere grows by it, a plane moves out along
    its normal, a box rounds its edges by it): the table's own fields (nothing copied: a shape
    placed in the table is placed for every view of it), a compile-time ``offset``, and
    ``kills`` off unless ``kill`` (a ``kill`` shape ends particles, not soft bodies). Placing
    through a view places the table."""

    def __init__(self, table: Colliders, offset: float = 0.0, kill: bool = False):
        self.table = table
        for name in _SHARED:
            if hasattr(table, name):
                setattr(self, name, getattr(table, name))
        self.offset = float(offset)
        if not float(offset) >= 0.0:
            raise ValueError(f"offset: must be >= 0 m, got {offset}")
        self.kills = table.kills if kill else tuple(False for _ in table.kills)

    def move_to(self, *args, **kw) -> None:
        self.table.move_to(*args, **kw)

    def follow(self, control, t0: float, t1: float) -> bool:
        return self.table.follow(control, t0, t1)

    def reset(self) -> None:
        self.table.reset()

    def pose(self, k: int) -> dict:
        return self.table.pose(k)

    def shown_bounds(self) -> list:
        return self.table.shown_bounds()

    def poses_over(self, control, steps) -> np.ndarray:
        return self.table.poses_over(control, steps)
