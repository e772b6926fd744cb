"""``python -m cosim``: the command line."""

import sys

from cosim.cli.main import main

sys.exit(main())
