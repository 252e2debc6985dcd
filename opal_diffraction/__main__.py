"""``python -m opal_diffraction ...``: the command-line renderer (see cli.py)."""

import sys

from .cli import main

if __name__ == "__main__":  # not when a worker process started by multiprocessing re-imports it
    sys.exit(main())
