import sys

from particles_tools.main import console

sys.exit(console())
