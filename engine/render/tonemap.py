"""The tone map's closed form and its table (NumPy; no Taichi): exposure-scaled linear RGB → the
ACES filmic fit (Narkowicz 2015) → 8-bit sRGB (IEC 61966-2-1), sampled into a table of
``LUT_SIZE`` bins found by a float's bits. ``engine.render.pack`` uploads the table once per
Taichi program and looks each channel up by its bits (its ``tone``)."""
from __future__ import annotations

import numpy as np

# the tone-map table: bins of f32 linear values by their bits (exponent and top LUT_BITS mantissa
# bits: 1,024 bins an octave, each ≤ 0.1 % wide) over [2^LUT_MIN_EXP, 8): below, black (ACES·sRGB
# there is < 0.01 of an 8-bit step); above, white (ACES reaches 1 at x ≈ 7.24)
LUT_BITS = 10
LUT_MIN_EXP = -17
LUT_OCTAVES = 3 - LUT_MIN_EXP
LUT_SIZE = LUT_OCTAVES << LUT_BITS
LUT_LO = 2.0 ** LUT_MIN_EXP
LUT_HI = float(np.nextafter(np.float32(8.0), np.float32(0.0)))  # the largest f32 below 8
LUT_BIAS = (127 + LUT_MIN_EXP) << LUT_BITS  # bits >> (23 − LUT_BITS) of LUT_LO: bin 0


def tonemap(x) -> np.ndarray:
    """8-bit sRGB (IEC 61966-2-1) of the ACES filmic fit (Narkowicz 2015) of linear values x
    (exposure applied), in f64, rounded to nearest: the closed form the table samples."""
    x = np.asarray(x, np.float64)
    a = np.clip((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)
    s = np.where(a <= 0.0031308, 12.92 * a, 1.055 * np.power(a, 1.0 / 2.4) - 0.055)
    return np.minimum(255, np.floor(s * 255.0 + 0.5)).astype(np.int32)


def tonemap_bins() -> tuple:
    """(lower, upper) edges of the table's LUT_SIZE bins of linear values (f64): bin i holds the
    f32 values whose bits >> (23 − LUT_BITS) are i + LUT_BIAS."""
    first = (np.arange(LUT_SIZE + 1, dtype=np.int64) + LUT_BIAS) << (23 - LUT_BITS)
    edges = first.astype(np.uint32).view(np.float32).astype(np.float64)
    return edges[:-1], edges[1:]


def tonemap_table() -> np.ndarray:
    """``tonemap`` at each bin's geometric centre. Indexing by the float's bits (a shift and a
    subtraction) replaced a table spaced evenly in sqrt(x / 8), indexed by a square root and a
    float-to-int conversion per channel: the composite of flames.toml at 1280×720 5.41 → 4.65 ms.
    Off by one step from ``tonemap`` of the value itself at 0.3 % of log-uniform values over
    1e-6 … 8 (the sqrt-spaced table: 0.5 %), 0.8 % of uniform ones in [0, 1] (0.8 %)."""
    lo, hi = tonemap_bins()
    return tonemap(np.sqrt(lo * hi))
