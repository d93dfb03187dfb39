"""``--resume``: find the whole frames an interrupted run left, and check they came from the same
settings.

A run records its settings in ``.particles-run.json`` in the output folder. Frames are written
under a hidden temporary name and renamed when whole, so after SIGINT or SIGKILL the folder holds
frames 0..n−1 (whole) and perhaps a hidden ``.frame_*.png.tmp``. Resuming re-simulates frames
0..n−1 without rendering (the simulation is deterministic) and renders from n on.
"""
from __future__ import annotations

import glob
import json
import os

from .output import OutputError, OutputRefused, frame_path

MANIFEST = ".particles-run.json"
_PNG_END = b"IEND\xaeB`\x82"  # the last chunk of every PNG (type + CRC)


def run_record(cfg, fmt: str, arch: str) -> dict:
    """What decides the pixels of frame k: the validated config (without its length), the
    format and the backend."""
    d = cfg.model_dump(mode="json")
    d.pop("frames", None)
    d.pop("duration", None)
    return {"config": d, "format": fmt, "arch": arch}


def write_record(out_dir: str, record: dict) -> None:
    tmp = os.path.join(out_dir, MANIFEST + ".tmp")
    with open(tmp, "w") as fh:
        json.dump(record, fh, sort_keys=True)
    os.replace(tmp, os.path.join(out_dir, MANIFEST))


def _is_whole_png(path: str) -> bool:
    try:
        with open(path, "rb") as fh:
            fh.seek(max(0, os.path.getsize(path) - len(_PNG_END)))
            return fh.read() == _PNG_END
    except OSError:
        return False


def _png_size(path: str):
    """(width, height) from a PNG's IHDR chunk."""
    with open(path, "rb") as fh:
        head = fh.read(24)
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def whole_frames(out_dir: str) -> int:
    """n such that frame_00000 .. frame_{n-1} all exist and are whole PNGs."""
    n = 0
    while _is_whole_png(frame_path(out_dir, n)):
        n += 1
    return n


def _differences(a: dict, b: dict, prefix="") -> list:
    keys = sorted(set(a) | set(b))
    out = []
    for k in keys:
        va, vb = a.get(k), b.get(k)
        if isinstance(va, dict) and isinstance(vb, dict):
            out += _differences(va, vb, f"{prefix}{k}.")
        elif va != vb:
            out.append(f"{prefix}{k}")
    return out


def prepare_resume(out_dir: str, record: dict) -> int:
    """Check ``out_dir`` can be resumed with ``record``; drop temporaries and any frame after the
    first gap; return the number of whole frames to keep (0: start from scratch)."""
    frames = sorted(glob.glob(os.path.join(out_dir, "frame_*.png")))
    if not frames:
        return 0
    try:
        with open(os.path.join(out_dir, MANIFEST)) as fh:
            old = json.load(fh)
    except (OSError, ValueError):
        raise OutputRefused(f"--resume: {out_dir} has frames but no readable run record ({MANIFEST}); "
                          f"pass --overwrite to start again") from None
    diff = _differences(old, record)
    if diff:
        shown = ", ".join(diff[:4]) + (", ..." if len(diff) > 4 else "")
        raise OutputRefused(f"--resume: {out_dir} was rendered with other settings ({shown}); "
                          f"pass --overwrite to start again")
    n = whole_frames(out_dir)
    want = (record["config"]["render"]["width"], record["config"]["render"]["height"])
    for k in range(n):
        size = _png_size(frame_path(out_dir, k))
        if size != want:
            raise OutputRefused(f"--resume: {out_dir} is mixed: {os.path.basename(frame_path(out_dir, k))} is "
                                f"{size[0]}x{size[1]}, this run renders {want[0]}x{want[1]} (two runs wrote it?); "
                                f"pass --overwrite to start again")
    keep = {frame_path(out_dir, k) for k in range(n)}
    try:
        for f in frames + glob.glob(os.path.join(out_dir, ".*.tmp*")):
            if f not in keep:
                os.remove(f)
    except OSError as e:
        raise OutputError(f"--resume: cannot clean {out_dir}: {e.strerror or e}") from None
    return n
