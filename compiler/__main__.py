"""``python -m sofac``: the same as the ``sofac`` command."""

import sys

from .cli import main

sys.exit(main())
