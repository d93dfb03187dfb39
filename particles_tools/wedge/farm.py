"""Dask distributed as the wedge's farm: a ``LocalCluster`` of worker processes on this machine, or
an existing cluster at ``--scheduler``. Dask schedules, balances and reruns; nothing here does.

A local worker is a process with one task thread (one variant at a time: a process holds one
Taichi program) and ``threads`` Taichi CPU threads. When a worker dies mid-variant (SIGKILL, out
of memory) its nanny starts a new one and the scheduler reruns the variant on a live worker, up to
``distributed.scheduler.allowed-failures`` times (Dask's default, 3); after that the variant's
result is ``KilledWorker``, recorded as a failure.
"""
from __future__ import annotations

import logging
import uuid

from ..errors import UserError
from .task import TOPIC, render_variant

#: seconds to wait for a scheduler given by --scheduler
CONNECT_TIMEOUT = 10


def _dask():
    try:
        import distributed
    except ImportError:
        raise UserError("particles wedge needs Dask distributed: pip install -e \".[farm]\"") from None
    return distributed


def local_cluster(workers: int, **kw):
    """A quiet ``LocalCluster`` of ``workers`` processes, one task thread each, no dashboard.

    Workers are forked from a fork server that imported Dask once (Dask's ``forkserver`` method,
    where the platform has it) instead of each spawning a fresh interpreter: the cluster starts
    in 0.6-0.8 s instead of 1.0-1.4 s here, and a killed worker comes back as fast. Worker
    saturation 1.0: the scheduler hands a worker its next variant only when it is free, rather
    than queueing a second one on it that a later-starting worker would have to steal (a variant
    lasts seconds; the extra round trip costs milliseconds). No statistical profiler: it samples
    the task thread's stack every 10 ms for a dashboard nobody opens here."""
    import multiprocessing

    import dask

    distributed = _dask()
    settings = {"distributed.scheduler.worker-saturation": 1.0,
                "distributed.worker.profile.enabled": False}
    if "forkserver" in multiprocessing.get_all_start_methods():
        settings["distributed.worker.multiprocessing-method"] = "forkserver"
    with dask.config.set(settings):
        return distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                        dashboard_address=None, silence_logs=logging.ERROR, **kw)


class Farm:
    """A Dask client (and the cluster it started, if any) that renders variants and relays their
    frame events to ``on_frame(variant_id, frame)``."""

    def __init__(self, workers=None, scheduler=None):
        distributed = _dask()
        logging.getLogger("distributed").setLevel(logging.ERROR)
        self.token = uuid.uuid4().hex[:8]  # keys and events of this wedge, on a shared cluster too
        self.cluster = None
        if scheduler:
            try:
                self.client = distributed.Client(scheduler, timeout=CONNECT_TIMEOUT)
            except (OSError, TimeoutError, ValueError) as e:
                raise UserError(f"--scheduler: cannot connect to {scheduler}: "
                                f"{' '.join(str(e).split())[:200]}") from None
        else:
            self.cluster = local_cluster(workers)
            self.client = distributed.Client(self.cluster)
        self.on_frame = None
        self.client.subscribe_topic(TOPIC, self._event)

    @property
    def worker_count(self) -> int:
        return len(self.client.scheduler_info().get("workers", {}))

    def _event(self, event):
        msg = event[1] if isinstance(event, (tuple, list)) else event
        if isinstance(msg, dict) and msg.get("run") == self.token and self.on_frame is not None:
            self.on_frame(msg.get("variant"), int(msg.get("frame", 0)))

    def submit(self, task: dict):
        """Queue one variant; its key names it (``wedge-v003-<token>``)."""
        task = dict(task, run=self.token)
        return self.client.submit(render_variant, task, key=f"wedge-{task['id']}-{self.token}",
                                  pure=False)

    def as_completed(self, futures):
        return _dask().as_completed(futures)

    def close(self) -> None:
        """Stop the client (and the local cluster). Teardown is silenced: connections closing
        in any order make Dask log ``CommClosedError`` tracebacks (at ERROR, from the client, the
        scheduler, the workers and their nannies) on a wedge that succeeded; every result is in
        by now, so nothing they could say matters. The workers and nannies are told first (a
        local cluster's; a shared cluster's workers are not ours to quieten)."""
        if self.cluster is not None:
            for nanny in (False, True):
                try:
                    self.client.run(_quiet, nanny=nanny)
                except Exception:  # a worker already gone, an older Dask: closing anyway
                    pass
        with _quiet_logs():
            try:
                self.client.unsubscribe_topic(TOPIC)
            except Exception:  # pragma: no cover - closing anyway
                pass
            self.client.close()
            if self.cluster is not None:
                self.cluster.close()


TEARDOWN_LOGGERS = ("distributed", "tornado", "asyncio")


def _quiet() -> None:
    """In a worker or nanny about to be closed: nothing of its teardown is logged."""
    for name in TEARDOWN_LOGGERS:
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


class _quiet_logs:
    """This process's Dask, Tornado and asyncio loggers off from the farm's shutdown on: the
    tracebacks of connections closing come during it and from callbacks that run after it, at
    interpreter exit (the wedge is over: its results and errors are reported by then)."""

    def __enter__(self):
        _quiet()
        return self

    def __exit__(self, *exc):
        return False


def failure_of(future) -> dict:
    """A result for a variant whose task did not return: its workers kept dying, or it was
    cancelled."""
    try:
        exc = future.exception()
    except Exception as e:  # cancelled
        exc = e
    name = exc.__class__.__name__
    if name == "KilledWorker":
        return {"status": "failed", "exit_code": 137,
                "message": "its worker died (SIGKILL or out of memory) every time Dask ran it"}
    return {"status": "failed", "exit_code": 1,
            "message": f"{name}: {' '.join(str(exc).split())[:300]}"}
