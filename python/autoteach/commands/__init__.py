"""Sub-commands of the ``autoteach`` command line that live in their own modules.

Each module exposes ``register(sub, common)``: it adds its parser to the ``argparse``
sub-parsers ``sub`` (with ``parents=[common]`` for ``--json``/``--quiet``) and sets
``func`` (a callable taking the parsed arguments and returning the exit status) as a default.
"""

from __future__ import annotations

MODULES = ("autoteach.commands.run", "autoteach.commands.calibrate", "autoteach.commands.active")
MODULES += ("autoteach.commands.scenes",)
MODULES += ("autoteach.commands.map",)
MODULES += ("autoteach.commands.radio",)
MODULES += ("autoteach.commands.segment",)
MODULES += ("autoteach.commands.tune",)
MODULES += ("autoteach.commands.uncertainty",)
MODULES += ("autoteach.commands.plan",)
