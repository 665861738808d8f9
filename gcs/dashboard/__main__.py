"""``python -m gcs.dashboard [args]``: same as ``gcs dashboard``."""

import sys

from .cli import main

sys.exit(main())
