"""``python -m pursuit``: the ``pursuit`` command (:mod:`pursuit.cli`)."""

import sys

from .cli import main

sys.exit(main())
