"""The CPU's parallelism: uneven loops spread over the backend's tasks (engine.spread)."""
import numpy as np
import pytest
import taichi as ti

from engine.runtime import ensure_init

ensure_init()

from engine.spread import TASK, item, rounds  # noqa: E402


def _spread_kernel(tasks):
    @ti.kernel
    def hits(count: ti.types.ndarray(dtype=ti.i32, ndim=1), task_of: ti.types.ndarray(dtype=ti.i32, ndim=1),
             n: ti.i32):
        for s in range(tasks * TASK):
            for r in range(rounds(n, tasks)):
                i = item(s, r, tasks)
                if i < n:
                    ti.atomic_add(count[i], 1)  # (an integer count: exact in any order)
                    task_of[i] = s // TASK
    return hits


@pytest.mark.parametrize("tasks", [1, 2, 8])
def test_a_spread_loop_takes_every_item_once_each_task_a_residue(tasks):
    """Every item of [0, n) exactly once, for n below, at and past a task's 512 slots and past
    every slot; task k takes the items i ≡ k (mod tasks): a sample of the whole loop each."""
    hits = _spread_kernel(tasks)
    for n in (0, 1, 60, 511, 512, 513, 3840, tasks * TASK + 7, 3 * tasks * TASK):
        count = ti.ndarray(ti.i32, shape=max(1, n))
        task_of = ti.ndarray(ti.i32, shape=max(1, n))
        count.fill(0)
        task_of.fill(-1)
        hits(count, task_of, n)
        c, k = count.to_numpy()[:n], task_of.to_numpy()[:n]
        assert (c == 1).all(), (tasks, n)
        assert np.array_equal(k, np.arange(n) % tasks), (tasks, n)
