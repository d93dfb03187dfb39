"""Real-time particle effects engine on Taichi.

The core: :mod:`engine.ode` (integrators, step-doubling control, ``solve``), the particle
pipeline (``config``, ``particles``, ``colliders``, ``render``, ``scene``), soft bodies
(``springs``, ``bodies``) and the game API (``api``). The tools built on it (command line,
viewer, bench, charts, gallery, examples) live in :mod:`particles_tools`; the core never imports them.
"""

__version__ = "0.1.0"
