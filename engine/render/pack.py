"""The tone map on the pixels' side: a composited colour → 8-bit sRGB by the table of
:mod:`engine.render.tonemap` (one byte a bin, found by the value's bits), packed as one u32 RGBA
(bytes R, G, B, A in memory, or B, G, R, A), and the background, reduced and full layers
composited into it (``finish``). :mod:`engine.render.composite` builds these once per Taichi
program with its kernels."""
# (no `from __future__ import annotations`: Taichi reads kernel annotations at definition)

import numpy as np
import taichi as ti

from .. import runtime
from .tonemap import LUT_BIAS, LUT_BITS, LUT_HI, LUT_LO, LUT_SIZE, tonemap_table


def build_pack():
    """``(tone_rgb, finish, finish_opaque)``: the funcs over a new table field (uploaded here;
    the one field of the composite's kernels)."""
    # one byte an entry: the 20 KB table stays in L1 (as i32, 64 KB, a table of 16,384 entries
    # did not: the composite of debris.toml at 1280×720, 81 % of its tiles reduced-layer-only,
    # 12.4 → 6.8 ms)
    lut = ti.field(ti.u8, shape=LUT_SIZE)
    llvm = runtime._arch_in_use() in ("cpu", "cuda")  # (LLVM's max returns the operand not NaN)
    lut.from_numpy(tonemap_table().astype(np.uint8))

    @ti.func
    def tone(x):
        """One channel's 8-bit value: its table bin by its bits (``tonemap_table``)."""
        i = ti.cast(ti.bit_cast(x, ti.u32) >> (23 - LUT_BITS), ti.i32) - LUT_BIAS
        if ti.static(not llvm):  # a NaN past the clamp (a max that may return it) still in the table
            i = ti.min(i, LUT_SIZE - 1)  # (on CPU and CUDA it cannot bind: 3–8 % of the composite)
        return ti.cast(lut[i], ti.u32)

    @ti.func
    def tone_rgb(c):
        """Linear RGB (exposure applied) → ACES → sRGB: its three 8-bit values, by table."""
        # (ti.math.clamp's own min(max) written out: it is a ti.func, parsed and transformed at
        # each of its ~20 call sites in the composite, at every start. A NaN takes the lower
        # bound, black, as before, on the LLVM backends (CPU, CUDA): their max returns the operand
        # that is not NaN)
        v = ti.min(LUT_HI, ti.max(LUT_LO, c))
        return tone(v[0]), tone(v[1]), tone(v[2])

    @ti.func
    def pack(c, alpha, bgra):
        """``tone_rgb(c)`` with alpha, as one u32: bytes R, G, B, A in memory (``bgra`` 0) or
        B, G, R, A (windowing systems' order)."""
        r, g, b = tone_rgb(c)
        a = ti.cast(ti.min(255.0, alpha * 255.0 + 0.5), ti.u32)
        if bgra != 0:
            r, b = b, r
        return r | (g << 8) | (b << 16) | (a << 24)

    @ti.func
    def finish(bg, lo, full, exposure, mode):
        """bg (RGB, coverage), then the reduced layer over it, then the full-resolution layer:
        c = (bg·T_lo + rgb_lo)·T + rgb. Coverage is 1 for soft bodies; the background itself has 0
        and is left out of a transparent render (``mode`` bit 0; premultiplied, alpha =
        1 − (1 − cover)·T_lo·T). ``mode`` bit 1: BGRA byte order."""
        c = ti.Vector([bg[0], bg[1], bg[2]])
        cover = 1.0
        if mode & 1:
            c = c * bg[3]
            cover = bg[3]
        c = c * lo[3] + ti.Vector([lo[0], lo[1], lo[2]])
        c = c * full[3] + ti.Vector([full[0], full[1], full[2]])
        return pack(c * exposure, 1.0 - (1.0 - cover) * lo[3] * full[3], mode & 2)

    @ti.func
    def finish_opaque(bg, lo, exposure):
        """``finish(bg, lo, EMPTY_LAYER, exposure, 0)``, the same bytes, with its alpha a constant:
        opaque RGBA (mode 0) has alpha 1 − 0·T_lo = 1, byte 255, for any T_lo (a NaN one too: the
        min takes 255), but the compiler may not fold 0·x without knowing x finite, so ``finish``
        computes, clamps and converts it at every pixel. The unrolled reduced rows take this
        one: their composite 4.34 → 3.94 ms in flames.toml at 1280×720 (old and new kernels in one
        process, alternating; 7 % by the median of paired rounds)."""
        c = ti.Vector([bg[0], bg[1], bg[2]]) * lo[3] + ti.Vector([lo[0], lo[1], lo[2]])
        r, g, b = tone_rgb(c * exposure)
        return r | (g << 8) | (b << 16) | ti.u32(0xFF000000)

    return tone_rgb, finish, finish_opaque
