"""``python -m particles_tools``: the ``particles`` command."""
import sys

from .main import main

sys.exit(main())
