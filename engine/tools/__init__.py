"""Tools built on the engine's core: the ``particles`` command line (``cli``, ``commands``),
the live viewer, the benchmark, charts, the gallery, reference ODE problems and examples.

The core (``engine.ode``, ``particles``, ``springs``, ``colliders``, ``render``, ``config``,
``scene``, ``api``) never imports this package; ``tests/test_layers.py`` checks it.
"""

import os

#: the project folder (holding configs/ and renders/) of this checkout
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIGS = os.path.join(ROOT, "configs")
