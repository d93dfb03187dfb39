"""Which resolution large soft sprites are drawn at (no Taichi: the budget reads it before a run).

``[render] particle_resolution``: "auto", or the scale of the reduced layer (1 = off, 0.5, 0.25).
"auto" draws everything at full resolution below 360 rows, uses a ½ layer up to 720 rows and a
¼ layer from 720: a sprite goes to the layer when its radius covers at least 2 of its texels.
With a reduced layer comes a coarse one at half its scale, for sprites whose radius covers at
least 4 of its texels (engine.render.composite: most of a smoke effect's pixel work is a few
hundred big puffs, ~88 % of the reduced layer's covered texels in explosion.toml at 1280×720).
"""
from __future__ import annotations

AUTO_SCALES = ((360, 1.0), (720, 0.5))  # (below this many rows, scale); else 0.25
LO_MIN_TEXELS = 2.0  # a sprite's radius at the reduced layer, in its texels, at least
CO_MIN_TEXELS = 4.0  # at the coarse layer (half the reduced scale), at least


def particle_scale(setting, height: int) -> float:
    """The reduced layer's scale for a ``particle_resolution`` setting at an image height."""
    if setting in (None, "auto"):
        for below, scale in AUTO_SCALES:
            if height < below:
                return scale
        return 0.25
    return float(setting)
