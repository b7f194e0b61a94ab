"""``python -m whiskerid.cli``: the ``whiskerid`` command."""

import sys

from ._main import main

sys.exit(main())
