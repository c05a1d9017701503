"""``python -m ivobs``: the ``ivobs`` command."""

import sys

from .cli import main

sys.exit(main())
