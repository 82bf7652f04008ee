"""``python -m agentsim``: the command line."""

import sys

from agentsim.cli import main

if __name__ == "__main__":  # not when a worker process started by the sweep imports the main module again
    sys.exit(main())
