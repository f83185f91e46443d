"""``python -m contgrasp_core.cli``: the ``contgrasp`` command."""

import sys

from contgrasp_core.cli import main

sys.exit(main())
