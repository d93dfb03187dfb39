"""The contact sheet: the chosen frame of every variant in a grid, its values written under it.

Built on the submitting machine from the thumbnails the workers sent back (``.thumbs/``), so it
needs no access to the workers' disks. One row of the grid per combination of the outer ``--set``
lists, one column per value of the innermost list (or per seed) when that list has 2 to 8 values;
otherwise a near-square grid. A failed variant shows its last whole frame (or an empty cell) with
its exit code in red.
"""
from __future__ import annotations

import io
import math
import os

from PIL import Image, ImageDraw, ImageFont

from .record import SHEET, write_atomic, thumb_path

BACKGROUND = (18, 18, 20)
TEXT = (225, 225, 225)
FAILED = (255, 90, 80)
PAD = 6
MAX_COLUMNS = 8


def _font(size: int = 12):
    try:
        return ImageFont.load_default(size=size)  # Pillow >= 10.1 with FreeType: scalable
    except TypeError:  # pragma: no cover - older Pillow: the small bitmap font
        return ImageFont.load_default()


def columns(n: int, innermost: int) -> int:
    if 1 < innermost <= MAX_COLUMNS and n > 1:
        return innermost
    return max(1, min(n, math.ceil(math.sqrt(n))))


def short_keys(keys):
    """The last part of each key (``rate`` for ``emitters.0.rate``) unless two keys share it."""
    last = [k.rsplit(".", 1)[-1] for k in keys]
    return [s if last.count(s) == 1 else k for s, k in zip(last, keys)]


def _fit(draw, text, font, width):
    if draw.textlength(text, font=font) <= width:
        return text
    while text and draw.textlength(text + "…", font=font) > width:
        text = text[:-1]
    return text + "…"


def _load(out, variant_id):
    try:
        with open(thumb_path(out, variant_id), "rb") as fh:
            im = Image.open(io.BytesIO(fh.read()))
            im.load()
        return im.convert("RGB")
    except OSError:
        return None


def build_sheet(out: str, wedge, rows) -> str:
    """Write ``out/contact_sheet.png`` from the thumbnails and the index ``rows`` (by variant id);
    returns its path."""
    variants = wedge.variants
    thumbs = {v.id: _load(out, v.id) for v in variants}
    sizes = [im.size for im in thumbs.values() if im is not None]
    cell_w, cell_h = (max(s[0] for s in sizes), max(s[1] for s in sizes)) if sizes else (160, 90)
    cell_w = max(cell_w, 120)
    font = _font()
    line_h = font.getbbox("Ag")[3] + 3
    names = short_keys(wedge.keys) + (["seed"] if wedge.seeds is not None else [])
    label_h = PAD + line_h * (1 + len(names))
    innermost = len(wedge.seeds) if wedge.seeds is not None else (
        len(wedge.values[-1]) if wedge.values else 1)
    cols = columns(len(variants), innermost)
    nrows = math.ceil(len(variants) / cols)
    W = PAD + cols * (cell_w + PAD)
    H = PAD + nrows * (cell_h + label_h + PAD)
    sheet = Image.new("RGB", (W, H), BACKGROUND)
    draw = ImageDraw.Draw(sheet)
    for n, v in enumerate(variants):
        x = PAD + (n % cols) * (cell_w + PAD)
        y = PAD + (n // cols) * (cell_h + label_h + PAD)
        im = thumbs[v.id]
        if im is not None:
            sheet.paste(im, (x + (cell_w - im.width) // 2, y + (cell_h - im.height) // 2))
        else:
            draw.rectangle([x, y, x + cell_w - 1, y + cell_h - 1], fill=(48, 20, 20))
        row = rows.get(v.id, {})
        status = row.get("status", "pending")
        head = f"{v.id}  {status}" if status in ("ok", "pending") else \
            f"{v.id}  FAILED (exit {row.get('exit_code', '?')})"
        ty = y + cell_h + PAD // 2
        draw.text((x, ty), _fit(draw, head, font, cell_w), font=font,
                  fill=TEXT if status == "ok" else FAILED)
        values = list(v.texts) + ([str(v.seed)] if v.seed is not None else [])
        for k, (name, text) in enumerate(zip(names, values)):
            draw.text((x, ty + line_h * (k + 1)), _fit(draw, f"{name}={text}", font, cell_w),
                      font=font, fill=TEXT)
    buf = io.BytesIO()
    sheet.save(buf, format="PNG", compress_level=6)  # optimize=True: 3x the time, 5% smaller
    path = os.path.join(out, SHEET)
    write_atomic(path, buf.getvalue())
    return path
