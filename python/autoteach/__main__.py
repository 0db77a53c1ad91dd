"""``python -m autoteach``: the same as the ``autoteach`` command (see :mod:`autoteach.cli`)."""

from __future__ import annotations

import sys

from autoteach.cli import main

sys.exit(main())
