"""The wedge's progress bar: variants done (and failed) and frames rendered across all workers.

Frame counts arrive as Dask events (a Dask thread calls :meth:`frame`); the main thread draws.
On a terminal one line is redrawn in place; otherwise (a log, CI) a line every few seconds.
"""
from __future__ import annotations

import sys
import threading
import time


class WedgeProgress:
    def __init__(self, variants: int, frames_per_variant: dict, quiet: bool, stream=None):
        """``frames_per_variant``: {variant id: frames it renders}."""
        self.variants, self.quiet = variants, quiet
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty()
        self.expected = dict(frames_per_variant)
        self.total_frames = sum(self.expected.values())
        self._frames = {}  # variant id -> frames done
        self._done = self._failed = self._skipped = 0
        self._lock = threading.Lock()
        self._t0 = time.perf_counter()
        self._last_draw = 0.0
        self._fresh = 0  # frames rendered in this run (not skipped), for the rate

    def frame(self, variant_id: str, frame: int) -> None:
        with self._lock:
            before = self._frames.get(variant_id, 0)
            if frame > before:
                self._fresh += frame - before
            self._frames[variant_id] = max(before, frame)

    def skipped(self, variant_id: str) -> None:
        with self._lock:
            self._frames[variant_id] = self.expected.get(variant_id, 0)
            self._skipped += 1
            self._done += 1

    def finished(self, variant_id: str, ok: bool, frames: int) -> None:
        with self._lock:
            self._done += 1
            self._failed += 0 if ok else 1
            before = self._frames.get(variant_id, 0)
            if ok:
                frames = self.expected.get(variant_id, frames)
            self._fresh += max(0, frames - before)
            self._frames[variant_id] = max(before, frames)

    def line(self) -> str:
        with self._lock:
            frames = sum(min(f, self.expected.get(v, f)) for v, f in self._frames.items())
            done, failed, fresh = self._done, self._failed, self._fresh
        rate = fresh / max(time.perf_counter() - self._t0, 1e-9)
        bar = "#" * int(24 * frames / max(self.total_frames, 1))
        extra = f", {failed} failed" if failed else ""
        extra += f", {self._skipped} already done" if self._skipped else ""
        return (f"[{bar:<24}] variants {done}/{self.variants}{extra}  frames {frames:,}/"
                f"{self.total_frames:,}  {rate:5.1f} frames/s")

    def draw(self, force: bool = False) -> None:
        if self.quiet:
            return
        now = time.perf_counter()
        if not force and now - self._last_draw < (0.2 if self.tty else 5.0):
            return
        self._last_draw = now
        text = self.line()
        print(("\r" + text) if self.tty else text, end="" if self.tty else "\n",
              file=self.stream, flush=True)

    def close(self) -> None:
        self.draw(force=True)
        if not self.quiet and self.tty:
            print(file=self.stream)
