"""Tools built on the engine's core: the ``particles`` command line (``cli``, ``commands``),
the live viewer, the benchmark, charts, the gallery, reference ODE problems and examples.

The core (``engine.ode``, ``particles``, ``springs``, ``colliders``, ``render``, ``config``,
``scene``, ``api``) never imports this package; ``tests/test_layers.py`` checks it.
"""

import os
import sys

#: the project folder (holding configs/ and renders/) of this checkout
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIGS = os.path.join(ROOT, "configs")
#: where a wheel (non-editable) install puts the shipped configs (pyproject: data-files)
INSTALLED_CONFIGS = os.path.join(sys.prefix, "share", "particles-engine", "configs")


def shipped_configs():
    """The folder of the configs shipped with the engine: this checkout's configs/ (a checkout,
    or an editable install), else the copy a wheel install put under the prefix; None if neither."""
    for d in (CONFIGS, INSTALLED_CONFIGS):
        if os.path.isdir(d):
            return d
    return None
