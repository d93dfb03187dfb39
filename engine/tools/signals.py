"""Stop requests: SIGINT (Ctrl-C) and SIGTERM become a flag the frame loop polls between frames.

The frame being simulated when the signal arrives is finished and written, queued frames are
flushed, and the run ends with exit code 128 + signal number (130 for SIGINT). A second signal
while stopping restores the default behaviour (a KeyboardInterrupt) so a stuck run can still be
broken; whatever it cuts short is a hidden temporary file, never a frame.
"""
from __future__ import annotations

import signal
import threading

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopRequest:
    def __init__(self, signals=STOP_SIGNALS):
        self.signals = signals
        self.signum = None
        self._old = {}

    @property
    def requested(self) -> bool:
        return self.signum is not None

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name if self.signum else ""

    def _handle(self, signum, frame):
        if self.signum is not None:  # second signal: stop waiting for a clean end
            self._restore()
            raise KeyboardInterrupt
        self.signum = signum

    def _restore(self):
        for s, h in self._old.items():
            signal.signal(s, h)
        self._old = {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for s in self.signals:
                self._old[s] = signal.signal(s, self._handle)
        return self

    def __exit__(self, *exc):
        self._restore()
        return False
