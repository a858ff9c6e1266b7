"""``python -m modalmorph``: the command line."""

import sys

from .apps import main

sys.exit(main())
