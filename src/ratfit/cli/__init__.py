"""The ``ratfit`` command line: one group (:mod:`ratfit.cli.main`) and one module per command group.

Every command is named in one place, the table ``COMMANDS`` of :mod:`ratfit.cli.main`
(name -> ``"module:attribute"``; ``brdf`` and ``demo`` hold such a table for the
subcommands defined elsewhere), so the full command set exists whatever module a
caller imports first (``import ratfit.cli.brdf`` included). A command's module is
imported when the command is first looked up: ``ratfit fit`` imports the fit
command's module and not the others; ``ratfit --help`` imports them all.
"""

from ratfit.cli.main import main

__all__ = ["main"]
