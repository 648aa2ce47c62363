"""Exception and warning types shared by every ratfit module.

The CLI maps :class:`RatfitError` (bad input or usage) to exit code 2; a search
that runs but finds no verified fit is *returned* as an unsuccessful result,
never raised, so the caller decides what to do (exit code 1 in the CLI).
"""

from __future__ import annotations


class RatfitError(ValueError):
    """Bad input or usage: the message names the offending argument or file."""


class InputError(RatfitError):
    """Data that cannot be fitted as given (NaN, lo > hi, empty, mismatched)."""


class FileFormatError(RatfitError):
    """A file that is not what it claims to be, or is truncated."""


class AccuracyWarning(UserWarning):
    """A computation lost accuracy (e.g. monomial conversion)."""
