"""``particles gallery``: regenerate the small stills the README shows (renders/gallery/).

Each shipped effect config is simulated to a moment that shows it well and rendered at a small
size; PNGs stay well under 300 KB so they can be committed.
"""
from __future__ import annotations

import os
import time

from PIL import Image

# config → (seconds into the effect, size)
SHOTS = {
    "sparks": (2.0, (480, 270)),
    "dust": (1.2, (480, 270)),
    "smoke": (3.5, (480, 270)),
    "flames": (2.5, (480, 270)),
    "campfire": (3.0, (480, 270)),
    "explosion": (0.45, (480, 270)),
    "cloth": (3.0, (480, 270)),
    "hair": (1.3, (480, 270)),
    "jelly": (1.0, (480, 270)),
    "chain": (1.9, (480, 270)),
}


def render_still(config_path: str, seconds: float, size, out_path: str) -> dict:
    from ..config import load_config
    from ..scene import Scene

    cfg = load_config(config_path, {"render.width": size[0], "render.height": size[1]})
    t0 = time.perf_counter()
    scene = Scene(cfg)
    frames = max(1, round(seconds * cfg.fps))
    for _ in range(frames):
        scene.advance_frame()
    img = scene.render()[..., :3]
    tmp = out_path + ".tmp"
    Image.fromarray(img).save(tmp, format="PNG", optimize=True)
    os.replace(tmp, out_path)
    return {"path": out_path, "bytes": os.path.getsize(out_path), "frames": frames,
            "peak": scene.stats.peak_alive, "seconds": time.perf_counter() - t0}


def cmd_gallery(args) -> int:
    os.makedirs(args.out, exist_ok=True)
    for name, (seconds, size) in SHOTS.items():
        path = os.path.join(args.configs, f"{name}.toml")
        if not os.path.exists(path):
            continue
        r = render_still(path, seconds, size, os.path.join(args.out, f"{name}.png"))
        print(f"{r['path']}: {r['bytes'] / 1024:.0f} KB, t={seconds:g} s, "
              f"peak {r['peak']:,} particles, {r['seconds']:.1f} s")
    return 0
