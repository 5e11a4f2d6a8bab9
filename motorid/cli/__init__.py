"""The ``motorid`` command line: one module per command, listed in :data:`motorid.cli.commands.COMMANDS`.

Library modules never import this package; it sits on top of :mod:`motorid.api`.
"""

from motorid.cli.commands import COMMANDS, build_parser, console, main  # noqa: F401
