"""Effect presets: defaults for an emitter (ramps, sizes, blending, forces) as plain data.

A config names one with ``effect = "sparks"`` in an emitter table and overrides any key. A preset
is data only: it adds no code path a config could not express.
"""
from . import dust, flames, smoke, sparks

PRESETS = {"sparks": sparks, "flames": flames, "smoke": smoke, "dust": dust}
