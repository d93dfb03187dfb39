import sys

from particles_tools.main import main

sys.exit(main())
