"""Standalone source (C, GLSL, Python) that evaluates a saved fit."""

from ratfit.export import code as _code
from ratfit.export.code import *  # noqa: F403  (the public names, listed once, there)

__all__ = list(_code.__all__)
