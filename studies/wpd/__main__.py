"""``python -m studies.wpd``: the same as ``python -m fastvi wpd``."""

import sys

from .cli import main

sys.exit(main())
