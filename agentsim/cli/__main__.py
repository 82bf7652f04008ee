"""``python -m agentsim.cli``: the command line."""

import sys

from agentsim.cli import main

sys.exit(main())
