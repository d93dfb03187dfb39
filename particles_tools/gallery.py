"""``particles gallery``: regenerate the small stills the README shows (renders/gallery/).

Each shipped effect config is simulated to a moment that shows it well and rendered at a small
size; PNGs stay well under 300 KB so they can be committed.
"""
from __future__ import annotations

import os
import time

from PIL import Image

from engine.render.output import as_rgb, replacing

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
    "crates": (1.6, (480, 270)),
    "debris": (0.8, (480, 270)),
    "lantern": (2.0, (480, 270)),
    "sand": (3.0, (480, 270)),
    "water": (1.5, (480, 270)),
    "galaxy": (3.0, (480, 270)),
    "jelly_solid": (1.2, (480, 270)),
    "cloth_bending": (3.0, (480, 270)),
}


def render_still(config_path: str, seconds: float, size, out_path: str) -> dict:
    from engine.config import load_config
    from engine.scene import Scene

    cfg = load_config(config_path, {"render.width": size[0], "render.height": size[1]})
    t0 = time.perf_counter()
    scene = Scene(cfg)
    frames = max(1, round(seconds * cfg.fps))
    for _ in range(frames):
        scene.advance_frame()
    img = as_rgb(scene.render())
    with replacing(out_path) as tmp:
        Image.fromarray(img).save(tmp, format="PNG", optimize=True)
    return {"path": out_path, "bytes": os.path.getsize(out_path), "frames": frames,
            "peak": scene.stats.peak_alive, "seconds": time.perf_counter() - t0}


def cmd_gallery(args) -> int:
    from .commands import output_folder
    from .errors import UserError
    from .progress import progress

    if not os.path.isdir(args.configs):
        raise UserError(f"--configs: {args.configs!r} is not a folder")
    shots = [(n, s) for n, s in SHOTS.items() if os.path.exists(os.path.join(args.configs, f"{n}.toml"))]
    if not shots:
        raise UserError(f"--configs: {args.configs!r} holds none of {', '.join(SHOTS)} (.toml)")
    output_folder(args.out)
    with progress(len(shots), unit="stills", label="particles gallery",
                  quiet=getattr(args, "quiet", False)) as bar:
        for name, (seconds, size) in shots:
            bar.advance(0, note=name)
            r = render_still(os.path.join(args.configs, f"{name}.toml"), seconds, size,
                             os.path.join(args.out, f"{name}.png"))
            print(f"{r['path']}: {r['bytes'] / 1024:.0f} KB, t={seconds:g} s, "
                  f"peak {r['peak']:,} particles, {r['seconds']:.1f} s", flush=True)
            bar.advance(note=name)
    return 0
