"""The float64 fields one rigid system steps and the kernels that copy a step's bodies and
contacts in and its bodies and multipliers out (:mod:`.kernel` builds the substep on them; a
:class:`Fields` is leased by shape from :mod:`.pool`)."""

import taichi as ti

from .. import runtime
from ..launch import fast
from .elements import f64
from .kernel import _build


class Fields:
    """The float64 fields one rigid system steps (Taichi fields: a launch with NumPy arrays as
    arguments cost ~20 µs per array here, a launch of a kernel on fields ~20 µs in all).
    Bodies: ``x q v w`` and the substep's start ``xp qp``, ``inv_m inv_i`` (zero for bodies that do
    not move now), ``inertia``, ``moving``, ``kin`` with path positions ``kx0 kx1``. Contacts
    (``capacity`` rows): ``ca cb cn cra crb rnd_a rnd_b mu e lam vn0``. Joints: ``jt ja jb jra jrb
    jaxa jaxb jpa jpb jqrel jlo jhi jlim jalpha jdir`` (``jdir``: 1 where the point constraint is
    solved directly). The direct solve (``plan``: :meth:`~engine.rigid.joints.Joints.direct_plan`;
    nd joints): their indices ``dord``, the skyline layout ``dfirst doff`` of its 3·nd rows, the
    matrix and then its factor ``sky``, pivots ``dpiv dpinv``, right side and solution ``drhs``,
    multipliers ``dlam``; per body the corrections ``dx dth``. ``substeps(n, h, g, |g|, nc, nj)``:
    n substeps, one launch each (two with joints) and one to begin."""

    def __init__(self, nb: int, capacity: int, nj: int, nd: int, sky: int):
        """Room for nb bodies, ``capacity`` contacts, nj joints of which nd are solved directly
        with a skyline of ``sky`` entries (the key of :func:`engine.rigid.pool.lease`; fill with
        :meth:`load_plan`)."""
        self.key = (nb, capacity, nj, nd, sky)
        self.nd = nd
        # a scene without joints compiles no joint solve (a box scene's ``whole``: 30.7 -> 10.7 s
        # cold); the joint count is fixed for a Fields' life (an edit rebuilds the system)
        self.has_joints = nj > 0
        nb, nj = max(1, nb), max(1, nj)
        self.nb, self.capacity, self.nj = nb, capacity, nj
        nr = max(1, 3 * nd)
        for k in "dx dth".split():
            setattr(self, k, ti.Vector.field(3, f64, nb))
        self.dord = ti.field(ti.i32, max(1, nd))
        self.dfirst, self.doff = ti.field(ti.i32, nr), ti.field(ti.i32, nr)
        for k in "dpiv dpinv drhs dlam".split():
            setattr(self, k, ti.field(f64, nr))
        self.sky = ti.field(f64, max(1, sky))
        for k in "x v w xp kx0 kx1 inv_i inertia".split():
            setattr(self, k, ti.Vector.field(3, f64, nb))
        for k in "q qp".split():
            setattr(self, k, ti.Vector.field(4, f64, nb))
        self.inv_m = ti.field(f64, nb)
        self.moving, self.kin = ti.field(ti.i32, nb), ti.field(ti.i32, nb)
        for k in "cn cra crb".split():
            setattr(self, k, ti.Vector.field(3, f64, capacity))
        for k in "rnd_a rnd_b mu e lam vn0".split():
            setattr(self, k, ti.field(f64, capacity))
        self.ca, self.cb = ti.field(ti.i32, capacity), ti.field(ti.i32, capacity)
        for k in "jra jrb jaxa jaxb jpa jpb".split():
            setattr(self, k, ti.Vector.field(3, f64, nj))
        self.jqrel = ti.Vector.field(4, f64, nj)
        for k in "jlo jhi jalpha".split():
            setattr(self, k, ti.field(f64, nj))
        for k in "jt ja jb jlim jdir".split():
            setattr(self, k, ti.field(ti.i32, nj))
        self.substeps = _build(self)
        self.load_bodies, self.load_contacts, self.store = _build_io(self)

    def load_plan(self, plan) -> None:
        """The direct solve's joint order and skyline layout (:meth:`~engine.rigid.joints.Joints.
        direct_plan`; None without coupled joints)."""
        if self.nd:
            self.dord.from_numpy(plan["order"])
            self.dfirst.from_numpy(plan["first"])
            self.doff.from_numpy(plan["offset"])


# columns of the rows a step's bodies and contacts are copied in by (one launch each: a
# ``from_numpy`` per array cost ~0.2 ms of Python, 16 of them 4 ms a step for crates' 25 boxes)
BODY_COLS = 24  # inv_m, inv_i (3), moving, x (3), q (4), v (3), w (3), kx0 (3), kx1 (3)
CONTACT_COLS = 17  # a, b, n (3), ra (3), rb (3), round_a, round_b, mu, e
SERIAL_ROWS = 4096  # bodies and contacts copied on the launching thread, at most (CPU)


def _build_io(F):
    """Kernels that copy a step's bodies and contacts in and the bodies and multipliers out, as
    float64 rows (exact: the integers are small, the floats f64 on both sides). Up to
    SERIAL_ROWS bodies and contacts, on the CPU, each loop runs on the launching thread
    (engine.runtime.one_thread: a few dozen rows' copy is less than a hand-off to the pool)."""
    serial = runtime.one_thread(max(F.nb, F.capacity), SERIAL_ROWS)

    @ti.kernel
    def load_bodies(rows: ti.types.ndarray(), kinematic: ti.i32):
        """rows (nb, BODY_COLS); ``kinematic`` 0 leaves kx0, kx1 as they are."""
        ti.loop_config(serialize=ti.static(serial))
        for i in range(rows.shape[0]):
            F.inv_m[i] = rows[i, 0]
            F.moving[i] = ti.cast(rows[i, 4], ti.i32)
            for c in ti.static(range(3)):
                F.inv_i[i][c] = rows[i, 1 + c]
                F.x[i][c] = rows[i, 5 + c]
                F.v[i][c] = rows[i, 12 + c]
                F.w[i][c] = rows[i, 15 + c]
                if kinematic != 0:
                    F.kx0[i][c] = rows[i, 18 + c]
                    F.kx1[i][c] = rows[i, 21 + c]
            for c in ti.static(range(4)):
                F.q[i][c] = rows[i, 8 + c]

    @ti.kernel
    def load_contacts(rows: ti.types.ndarray()):
        """rows (≤ capacity, CONTACT_COLS)."""
        ti.loop_config(serialize=ti.static(serial))
        for k in range(rows.shape[0]):
            F.ca[k] = ti.cast(rows[k, 0], ti.i32)
            F.cb[k] = ti.cast(rows[k, 1], ti.i32)
            for c in ti.static(range(3)):
                F.cn[k][c] = rows[k, 2 + c]
                F.cra[k][c] = rows[k, 5 + c]
                F.crb[k][c] = rows[k, 8 + c]
            F.rnd_a[k] = rows[k, 11]
            F.rnd_b[k] = rows[k, 12]
            F.mu[k] = rows[k, 13]
            F.e[k] = rows[k, 14]

    @ti.kernel
    def store(bodies: ti.types.ndarray(), lam: ti.types.ndarray()):
        """bodies (n, 13) = x, q, v, w of the first n bodies; lam (nc,) the contacts' multipliers."""
        ti.loop_config(serialize=ti.static(serial))
        for i in range(bodies.shape[0]):
            for c in ti.static(range(3)):
                bodies[i, c] = F.x[i][c]
                bodies[i, 7 + c] = F.v[i][c]
                bodies[i, 10 + c] = F.w[i][c]
            for c in ti.static(range(4)):
                bodies[i, 3 + c] = F.q[i][c]
        ti.loop_config(serialize=ti.static(serial))
        for k in range(lam.shape[0]):
            lam[k] = F.lam[k]

    # (launched without Taichi's per-call Python: engine.launch)
    return fast(load_bodies), fast(load_contacts), fast(store)
