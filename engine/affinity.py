"""Taichi's CPU worker threads, one to a core (Linux).

Taichi's CPU backend runs a parallel loop on a pool of worker threads that sleep between kernels;
a launch wakes them all at once from the launching thread. Linux then tends to queue the woken
workers on the CPU that is going idle under the launching thread, and an idle CPU of a virtual
machine does not tick, so it does not pull the second worker over: on this 2-core machine the
workers took turns. Measured in real frames as CPU time over wall time (all threads): flames.toml
at 1280×720 ran at 1.21–1.28 of its 2 cores, and at 1.61–1.66 with each worker held to a core of
its own (frames 11.7–14.8 → 9.0–10.5 ms, the two ways in turn, three rounds). So right after
``ti.init`` the pool's workers are found and each is held to one CPU of the process's own set, in
turn (``os.sched_setaffinity``); the launching (main) thread stays free. Nothing a kernel computes
depends on which thread runs it (no float atomics: frames are the same bytes for any thread
count), so this changes only the wall time.

The workers are told apart from Taichi's other new threads (its compile pool) by what they sleep
on: a pool's threads all wait on one condition variable, so on one futex address, which
``/proc/self/task/<id>/syscall`` shows (Taichi 1.7: four compile threads on one address, then the
``cpu_max_num_threads`` workers on another). The group of exactly that many threads, the last
created if two are, is the pool; where none is (another Taichi, not Linux), nothing is pinned.
``PARTICLES_PIN_THREADS=0`` turns it off.
"""
from __future__ import annotations

import os


def threads_now() -> set:
    """The process's thread ids now (call before ``ti.init``; pass them to :func:`pin_workers`)."""
    try:
        return {int(t) for t in os.listdir("/proc/self/task")}
    except OSError:
        return set()


def _waiting_on(tid: int):
    """(syscall number, first argument) of a thread blocked in a system call, else None."""
    try:
        with open(f"/proc/self/task/{tid}/syscall") as f:
            fields = f.read().split()
    except OSError:
        return None
    if len(fields) < 2 or not fields[0].isdigit():  # "running", or unreadable
        return None
    return fields[0], fields[1]


def pool_workers(before: set, n: int) -> list:
    """The ids of the ``n`` threads started since ``before`` that sleep on one futex (the CPU
    pool's workers), or [] where no such group tells them apart."""
    groups = {}
    for tid in sorted(threads_now() - before - {os.getpid()}):
        key = _waiting_on(tid)
        if key is not None:
            groups.setdefault(key, []).append(tid)
    pools = [g for g in groups.values() if len(g) == n]
    return max(pools, key=min) if pools else []


def pin_workers(before: set) -> dict:
    """Hold each of the CPU pool's workers (threads started since ``before``) to one CPU of the
    process's set, in turn; returns {thread id: CPU} (empty: nothing pinned — not Linux, one CPU
    or one worker, switched off, or the pool not told apart)."""
    if os.environ.get("PARTICLES_PIN_THREADS", "1") == "0" or not hasattr(os, "sched_setaffinity"):
        return {}
    from taichi.lang import impl

    n = int(getattr(impl.current_cfg(), "cpu_max_num_threads", 0) or 0)
    cpus = sorted(os.sched_getaffinity(0))
    if n < 2 or len(cpus) < 2:
        return {}
    done = {}
    for i, tid in enumerate(pool_workers(before, n)):
        try:
            os.sched_setaffinity(tid, {cpus[i % len(cpus)]})
        except OSError:  # (a thread gone, or a mask the system refuses: leave the rest as they are)
            continue
        done[tid] = cpus[i % len(cpus)]
    return done
