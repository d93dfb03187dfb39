"""Real-time particle effects engine on Taichi.

Subpackages: :mod:`engine.ode` (integrators, step-doubling control, ``solve``), the particle
pipeline (config, model, emitters, forces, colliders, stepping, renderer) and the CLI.
"""

__version__ = "0.1.0"
