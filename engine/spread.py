"""Uneven parallel loops spread over the CPU backend's tasks.

Taichi 1.7's CPU backend cuts each parallel range-for into tasks of ``TASK`` = 512 consecutive
iterations, which its threads take one after another: its code generator sets the block size
adaptively to at least 512 (``TaskCodeGenCPU::create_offload_range_for``), whatever
``ti.loop_config(block_dim=…)`` asks for. So a loop of at most 512 iterations is one task, run by
one thread, and a longer one whose costly iterations lie together — the screen tiles of a fire,
the reduced level's tiles after the full level's, the 16 chunks of the binning — gives them to one
task or two. Measured as CPU time over wall time (all threads, in real frames): the splat of
flames.toml at 1280×720 ran at 1.0 of this machine's 2 cores, its composite at 1.4–1.75.

A loop written as ::

    for s in range(tasks * TASK):          # the parallel loop: ``tasks`` tasks
        for r in range(rounds(n, tasks)):
            i = item(s, r, tasks)
            if i < n:
                ...                          # item i, each of [0, n) exactly once

gives task k the items i ≡ k (mod ``tasks``): every task a sample of the whole loop, so the
threads share its costly parts. Which thread takes an item never changes a result here (each item
writes only its own outputs, or folds integers in by atomic adds or minima, alike in any order),
only the wall time. ``tasks()`` is a few per thread of the program
(``cpu_max_num_threads``); on a GPU the loop is the same, ``tasks * TASK`` threads.
"""
# (no `from __future__ import annotations`: Taichi reads a func's annotations at definition)

import taichi as ti

TASK = 512  # iterations per task of a CPU range-for (Taichi 1.7)
# flames.toml's frame at 1280×720, workers pinned (engine.affinity), two rounds: 1 task a thread
# 12.9 / 10.9 ms, 2 tasks 10.9 / 9.1, 4 tasks 10.9 / 11.2 (unpinned, its splat alone: 2 tasks
# 1.2–1.6 cores of 2, 8 tasks 1.9)
TASKS_PER_THREAD = 2
MAX_TASKS = 64  # (each task is 512 slots, most of them empty for a short loop: ~1–4 ns each)


def tasks() -> int:
    """How many tasks to spread a loop over: ``TASKS_PER_THREAD`` per thread of the program, at
    most ``MAX_TASKS``."""
    from taichi.lang import impl

    threads = int(getattr(impl.current_cfg(), "cpu_max_num_threads", 0) or 1)
    return min(MAX_TASKS, TASKS_PER_THREAD * max(1, threads))


@ti.func
def rounds(n, tasks: ti.template()):
    """How many items each of the ``tasks * TASK`` slots takes for a loop of ``n`` items."""
    return (n + tasks * TASK - 1) // (tasks * TASK)


@ti.func
def item(s, r, tasks: ti.template()):
    """Slot s's r-th item: task s // TASK takes the items ≡ it (mod ``tasks``), in order."""
    return ((s % TASK) + r * TASK) * tasks + s // TASK
