"""Writing frames without stalling the simulation, and without ever leaving half a file.

A writer thread encodes while the next frame simulates (PERF-NOTES: a 1280×720 PNG costs
19–33 ms). Every file is written under a temporary name and renamed into place, so an interrupted
run leaves only whole frames. A failure in the writer (disk full, permissions) is re-raised in
the main thread at the next submit or at close.
"""
from __future__ import annotations

import glob
import os
import queue
import threading

import numpy as np

FORMATS = ("png", "gif", "mp4")


class OutputError(Exception):
    """The output folder cannot be created or written (not a directory, read-only, disk full)."""


class OutputRefused(OutputError):
    """The output folder is usable but the request is not: frames already there without
    ``--overwrite``, or ``--resume`` on a folder rendered with other settings."""


def frame_path(out_dir: str, index: int) -> str:
    return os.path.join(out_dir, f"frame_{index:05d}.png")


def existing_outputs(out_dir: str):
    return sorted(glob.glob(os.path.join(out_dir, "frame_*.png"))
                  + glob.glob(os.path.join(out_dir, "*.gif")) + glob.glob(os.path.join(out_dir, "*.mp4")))


def prepare_dir(out_dir: str, overwrite: bool) -> None:
    """Create ``out_dir`` (or check an existing one): refuse to overwrite frames without
    ``overwrite``; with it, remove only the files this engine writes. Checks it is writable."""
    if os.path.exists(out_dir) and not os.path.isdir(out_dir):
        raise OutputError(f"--out: {out_dir} exists and is not a directory")
    old = existing_outputs(out_dir) if os.path.isdir(out_dir) else []
    if old and not overwrite:
        raise OutputRefused(f"--out: {out_dir} already holds {len(old)} rendered file(s); "
                          f"pass --overwrite to replace them or --out to choose another folder")
    try:
        os.makedirs(out_dir, exist_ok=True)
        for f in old:
            os.remove(f)
        for f in glob.glob(os.path.join(out_dir, ".*.tmp*")):
            os.remove(f)
        probe = os.path.join(out_dir, ".write-probe.tmp")
        with open(probe, "wb") as fh:
            fh.write(b"ok")
        os.remove(probe)
    except OSError as e:
        raise OutputError(f"--out: cannot write to {out_dir}: {e.strerror or e}") from None


class FrameWriter:
    def __init__(self, out_dir: str, fmt: str = "png", fps: float = 30.0, name: str = "render",
                 compress_level: int = 3):
        if fmt not in FORMATS:
            raise OutputError(f"--format: unknown value {fmt!r}; allowed: {', '.join(FORMATS)}")
        self.out_dir, self.fmt, self.fps, self.name = out_dir, fmt, fps, name
        self.compress_level = compress_level
        self.written = []
        self._q: queue.Queue = queue.Queue(maxsize=4)
        self._error = None
        self._movie = None
        self._movie_tmp = os.path.join(out_dir, f".{name}.tmp.{fmt}")
        self._movie_path = os.path.join(out_dir, f"{name}.{fmt}")
        self._thread = threading.Thread(target=self._run, name="frame-writer", daemon=True)
        self._thread.start()

    def _write_png(self, index, img):
        from PIL import Image

        path = frame_path(self.out_dir, index)
        tmp = os.path.join(self.out_dir, f".frame_{index:05d}.png.tmp")
        try:
            Image.fromarray(img).save(tmp, format="PNG", compress_level=self.compress_level)
            os.replace(tmp, path)
        except BaseException:
            _discard(tmp)
            raise
        self.written.append(path)

    def _append_movie(self, img):
        import imageio.v2 as imageio

        if self._movie is None:
            if self.fmt == "gif":
                self._movie = imageio.get_writer(self._movie_tmp, mode="I", duration=1000.0 / self.fps,
                                                 loop=0)
            else:
                self._movie = imageio.get_writer(self._movie_tmp, fps=self.fps, codec="libx264",
                                                 quality=7, macro_block_size=1,
                                                 ffmpeg_log_level="error")
        self._movie.append_data(img)

    def _run(self):
        while True:
            item = self._q.get()
            if item is None:
                return
            if self._error is not None:
                continue
            index, img = item
            try:
                if self.fmt == "png":
                    self._write_png(index, img)
                else:
                    self._append_movie(img)
            except BaseException as e:  # reported to the main thread
                self._error = e

    def _raise(self):
        if self._error is not None:
            e = self._error
            msg = " ".join(str(getattr(e, "strerror", None) or e).split())
            raise OutputError(f"writing frames to {self.out_dir} failed after {len(self.written)} "
                              f"whole frame(s): {e.__class__.__name__}: {msg}")

    def submit(self, index: int, img: np.ndarray) -> None:
        self._raise()
        self._q.put((index, img))

    def close(self, finished: bool = True) -> None:
        """Flush queued frames; for GIF/MP4 move the finished movie into place (or drop it if the
        run did not finish: a partial movie is not a whole output)."""
        self._q.put(None)
        self._thread.join()
        if self._movie is not None:
            try:
                self._movie.close()
            except Exception as e:  # pragma: no cover
                self._error = self._error or e
            if finished and self._error is None:
                try:
                    os.replace(self._movie_tmp, self._movie_path)
                    self.written.append(self._movie_path)
                except OSError as e:
                    self._error = e
                    _discard(self._movie_tmp)
            else:
                _discard(self._movie_tmp)
        self._raise()


def _discard(path: str) -> None:
    """Remove a temporary file if it is there; a failure here must not hide the first error."""
    try:
        os.remove(path)
    except OSError:
        pass
