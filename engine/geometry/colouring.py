"""The colour schedule (deterministic graph colouring, used by XPBD, the soft-body models and the
energy terms; here in the shared geometry room so none of them imports another): elements (springs, tetrahedra, hinges…) grouped so that no two of one colour
share a node, so a colour is projected in parallel without races and a Gauss–Seidel sweep is the
same every run (deterministic, no atomics)."""
import numpy as np


# On the CPU backend a group of at most this many constraints is swept on the calling thread,
# all its colours in order in one loop, not one parallel loop a colour: each colour's loop is a
# task that wakes the thread pool (tens of µs: engine.springs.fused estimates ~40), more than a few
# hundred constraints' arithmetic (cloth_bending, a 28 × 28 cloth with 12 iterations of springs
# and bending: its 24 sweeps a frame 10.1-12.6 → 1.8 ms). No two constraints of a colour share a
# node, so the serial sweep computes what the parallel one does (the springs' results are
# byte-identical; the bending group's differ in rounding only).
SERIAL_MAX = 8192


def serial_sweep(count: int) -> bool:
    """Whether a group of ``count`` constraints is swept on one thread: at most SERIAL_MAX, and
    on the CPU backend only (``engine.runtime.one_thread``; a GPU keeps a parallel loop a colour:
    one thread there is one of thousands). Read at a kernel's compile time (``ti.static``)."""
    from ..runtime import one_thread  # (lazily: this module is imported without Taichi)

    return one_thread(count, SERIAL_MAX)


def greedy_colors(n_nodes: int, elems: np.ndarray):
    """Greedy colouring in element order (deterministic): (colour per element (E,) int32, count).
    ``elems``: (E, k) node indices. For k = 2 this is the edge colouring the springs always used."""
    elems = np.asarray(elems)
    if elems.size == 0:
        return np.zeros(0, np.int32), 0
    elems = elems.reshape(len(elems), -1)
    used = [0] * n_nodes  # bitmask of colours already at each node
    colors = np.empty(len(elems), np.int32)
    for e, nodes in enumerate(elems.tolist()):
        busy = 0
        for v in nodes:
            busy |= used[v]
        c = (~busy & (busy + 1)).bit_length() - 1  # lowest free colour
        colors[e] = c
        for v in nodes:
            used[v] |= 1 << c
    return colors, int(colors.max()) + 1 if len(colors) else 0


def schedule(colors: np.ndarray, n_colors: int):
    """(order, ranges): elements sorted by colour (stable) and each colour's [lo, hi) in that order."""
    order = np.argsort(colors, kind="stable")
    bounds = np.searchsorted(colors[order], np.arange(n_colors + 1))
    return order, [(int(bounds[c]), int(bounds[c + 1])) for c in range(n_colors)]
