"""``python -m sofac``: the same as the ``sofac`` command."""

import sys

from sofac.cli.main import main

sys.exit(main())
