"""``python -m particles_tools``: the ``particles`` command."""
import sys

from .main import console

sys.exit(console())
