"""The ``ratfit`` command line: one group (:mod:`ratfit.cli.main`) and one module per command group.

Every command module is imported here, in one place, so the full command set exists
whatever module a caller imports first (``import ratfit.cli.brdf`` included).
"""

from ratfit.cli.main import main

# Explicit registration: each module adds its commands to ``main`` (or to a group of it).
from ratfit.cli import fit as _fit  # noqa: E402,F401  isort: skip
from ratfit.cli import demo as _demo  # noqa: E402,F401  isort: skip
from ratfit.cli import cdf as _cdf  # noqa: E402,F401  isort: skip
from ratfit.cli import brdf as _brdf  # noqa: E402,F401  isort: skip
from ratfit.cli import export as _export  # noqa: E402,F401  isort: skip
from ratfit.cli import tolerance as _tolerance  # noqa: E402,F401  isort: skip
from ratfit.cli import batch as _batch  # noqa: E402,F401  isort: skip
from ratfit.cli import render as _render  # noqa: E402,F401  isort: skip

__all__ = ["main"]
