"""The CPU's parallelism: uneven loops spread over the backend's tasks (engine.spread), and the
pool's workers held one to a core (engine.affinity)."""
import os

import numpy as np
import pytest
import taichi as ti

from engine import affinity, runtime
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


def _run_ns(tid):
    with open(f"/proc/self/task/{tid}/schedstat") as f:
        return int(f.read().split()[0])


@ti.kernel
def _busy(a: ti.types.ndarray(dtype=ti.f32, ndim=1)):
    for i in range(a.shape[0]):
        x = ti.cast(i, ti.f32)
        for _ in range(40):
            x = ti.sin(x) + 0.5
        a[i] = x


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="pinning needs Linux and two CPUs")
def test_the_pinned_threads_are_the_pool_that_runs_kernels_one_cpu_each():
    """runtime.init held the CPU pool's workers one to a CPU of the process's set, in turn: the
    threads that do a parallel kernel's work (all but the launching one) are exactly among them,
    each held to its own CPU; a pool size no group of new threads has is not told apart."""
    runtime.reset()
    before = affinity.threads_now()
    runtime.init("cpu", threads=2)
    pinned = runtime.pinned()
    # the pool is the one group of exactly 2 new threads on one futex: no group of 3 is one
    assert affinity.pool_workers(before, 2) == sorted(pinned)
    assert affinity.pool_workers(before, 3) == []
    cpus = sorted(os.sched_getaffinity(0))
    assert len(pinned) == 2 and sorted(pinned.values()) == cpus[:2]
    for tid, cpu in pinned.items():
        assert os.sched_getaffinity(tid) == {cpu}
    a = ti.ndarray(ti.f32, shape=1 << 20)
    _busy(a)
    ti.sync()
    tids = [int(t) for t in os.listdir("/proc/self/task")]
    before = {t: _run_ns(t) for t in tids}
    for _ in range(4):
        _busy(a)
    ti.sync()
    worked = {t for t in tids if t != os.getpid() and _run_ns(t) - before[t] > 20_000_000}
    assert worked and worked <= set(pinned)
    runtime.reset()
    runtime.init("cpu")


def test_pinning_is_off_where_asked(monkeypatch):
    """PARTICLES_PIN_THREADS=0 pins nothing, though every thread of the process is new to the
    empty snapshot (the pool among them)."""
    monkeypatch.setenv("PARTICLES_PIN_THREADS", "0")
    assert affinity.pin_workers(set()) == {}
