"""A few words drawn into a frame: the viewer's "fps / particles / t" line.

Taichi's fast GUI shows our packed frame as it is and draws no canvas text over it, so the line
is drawn into the frame itself, from a 3×5 pixel font scaled up (NumPy, a few thousand pixels).
"""
from __future__ import annotations

import numpy as np

# 3×5 glyphs, rows top to bottom, 3 bits each (4 = left column)
_GLYPHS = {
    "0": (7, 5, 5, 5, 7), "1": (2, 6, 2, 2, 7), "2": (7, 1, 7, 4, 7), "3": (7, 1, 7, 1, 7),
    "4": (5, 5, 7, 1, 1), "5": (7, 4, 7, 1, 7), "6": (7, 4, 7, 5, 7), "7": (7, 1, 1, 1, 1),
    "8": (7, 5, 7, 5, 7), "9": (7, 5, 7, 1, 7), ".": (0, 0, 0, 0, 2), ",": (0, 0, 0, 2, 4),
    "=": (0, 7, 0, 7, 0), "[": (6, 4, 4, 4, 6), "]": (3, 1, 1, 1, 3), " ": (0, 0, 0, 0, 0),
    "a": (0, 7, 1, 7, 7), "c": (0, 7, 4, 4, 7), "d": (1, 7, 5, 5, 7), "e": (0, 7, 7, 4, 7),
    "f": (3, 4, 7, 4, 4), "i": (2, 0, 2, 2, 2), "l": (6, 2, 2, 2, 7), "p": (0, 7, 5, 7, 4),
    "r": (0, 6, 4, 4, 4), "s": (0, 7, 6, 1, 7), "t": (4, 7, 4, 4, 3), "u": (0, 5, 5, 5, 7),
    "-": (0, 0, 7, 0, 0),
}


def draw_text(frame: np.ndarray, text: str, x: int = 6, y: int = 6, scale: int = 2,
              color=(255, 255, 255)) -> None:
    """Draw ``text`` into ``frame`` ((H, W, 4) uint8, any channel order: ``color`` is given in
    that order) at pixel (x, y), each glyph 3×5 cells of ``scale`` pixels, on a dark box.
    Characters without a glyph are left blank."""
    H, W = frame.shape[:2]
    cw = 4 * scale
    x1, y1 = min(W, x + cw * len(text) + scale), min(H, y + 6 * scale)
    if x1 <= x or y1 <= y:
        return
    box = frame[max(0, y - scale):y1, max(0, x - scale):x1, :3]
    box[...] = box // 3  # darken behind the text so it reads over bright smoke
    for k, ch in enumerate(text.lower()):
        rows = _GLYPHS.get(ch)
        if rows is None:
            continue
        for r, bits in enumerate(rows):
            for c in range(3):
                if bits & (4 >> c):
                    px, py = x + k * cw + c * scale, y + r * scale
                    frame[py:min(H, py + scale), px:min(W, px + scale), :3] = color
