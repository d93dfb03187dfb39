"""Stop requests: SIGINT (Ctrl-C) and SIGTERM stop any command within a step, a second one at once.

One handler is installed per command (``cli.main``). Where a command has nothing to finish, the
first signal raises SignalStop (a KeyboardInterrupt) at once (``raise_now``, the default). ``particles run``
switches to polling for its frame loop (``stopping(raise_now=False)``): the signal sets a flag
that ``engine.runtime.check_stop()`` also sees (the particle and spring step loops poll it once
per step, raising ``runtime.Interrupted``), so even a frame of millions of steps stops mid-way and
the frames already rendered are flushed, whole, before the command exits. The first signal also restores the system's default action, so a second one ends the
process at once, wherever it is (inside a long kernel too): what it cuts short is a hidden
temporary file, never a frame. Exit code 128 + signal number (130 for SIGINT, 143 for SIGTERM).
"""
from __future__ import annotations

import contextlib
import signal
import threading

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)

_active = []  # StopRequests installed, innermost last


class SignalStop(KeyboardInterrupt):
    """What a stop signal raises at once. A subclass, not KeyboardInterrupt itself: CPython marks
    a KeyboardInterrupt "unhandled" when that exact type leaves code run through
    ``PyRun_String`` (pybind11's ``py::eval``, which Taichi calls), even where an outer ``except``
    catches it later, and ``python -m`` then ends the process by SIGINT (exit -2) instead of the
    exit code we return (143 for SIGTERM): seen once in CI. A subclass is caught by every
    ``except KeyboardInterrupt`` and never marked."""


class StopRequest:
    def __init__(self, signals=STOP_SIGNALS, raise_now: bool = True):
        self.signals = signals
        self.raise_now = raise_now
        self.signum = None
        self._old = {}

    @property
    def requested(self) -> bool:
        return self.signum is not None

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name if self.signum else ""

    def _handle(self, signum, frame):
        self.signum = signum
        for s in self.signals:  # a second signal takes the default action: the process ends now
            signal.signal(s, signal.SIG_DFL)
        if self.raise_now:
            raise SignalStop(f"stopped by {self.name}")

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for s in self.signals:
                self._old[s] = signal.signal(s, self._handle)
        _active.append(self)
        return self

    def __exit__(self, *exc):
        _active.remove(self)
        if not self.requested:  # after a signal the default action stays: the process is ending
            for s, h in self._old.items():
                signal.signal(s, h)
        self._old = {}
        return False


@contextlib.contextmanager
def stopping(raise_now: bool = True):
    """The command's StopRequest (installed here if no outer one is), with ``raise_now`` set for
    the block: True where a signal should cut the work short at once (SignalStop), False
    where the code polls ``requested`` and ``engine.runtime.check_stop()`` raises
    ``runtime.Interrupted`` between steps, so the block can finish cleanly."""
    from engine import runtime

    outer = bool(_active)
    with contextlib.ExitStack() as stack:
        req = _active[-1] if outer else stack.enter_context(StopRequest(raise_now=raise_now))
        before = req.raise_now
        req.raise_now = raise_now
        old_check = runtime.set_stop_check(lambda: req.signum is not None)
        try:
            if raise_now and req.requested:
                raise SignalStop(f"stopped by {req.name}")
            yield req
        finally:
            req.raise_now = before
            runtime.set_stop_check(old_check)
