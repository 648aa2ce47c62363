"""Monotone rational CDFs (seed section 3) and sampling from them."""

from ratfit.cdf import monotone as _monotone
from ratfit.cdf import sampling as _sampling
from ratfit.cdf.monotone import *  # noqa: F403  (the public names, listed once, there)
from ratfit.cdf.sampling import *  # noqa: F403

__all__ = [*_monotone.__all__, *_sampling.__all__]
