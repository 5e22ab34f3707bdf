"""``python -m gaussim``: the ``gaussim`` command."""

import sys

from .cli import main

sys.exit(main())
