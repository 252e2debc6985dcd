"""``python -m opal_diffraction ...``: the command-line renderer (see cli.py)."""

import sys

from .cli import main

sys.exit(main())
