"""Fitting values of any magnitude: channels scaled by a power of two, then back.

The QP works with squares of the segment bounds (row norms, Gram matrices): values
of 1e170 overflow them and values of 1e-155 underflow into subnormals. Dividing a
channel by a power of two is exact in binary floating point (no rounding, the same
segments as rationals), so a fit of the scaled channel times that power is a fit
of the data as given, and its verification is repeated on the data as given.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from ratfit.core.rational import RationalFunction
from ratfit.core.results import FitResult
from ratfit.core.segments import Segments
from ratfit.core.verify import Verification

__all__ = ["scale_segments", "unscale_result", "value_scales"]

# Channels whose largest |bound| lies in this range are fitted as they are.
SAFE_RANGE = (1e-100, 1e100)


def value_scales(seg: Segments) -> NDArray[np.float64]:
    """One power of two per channel: 1 inside SAFE_RANGE, else 2^e with the
    channel's largest |bound| / 2^e in [0.5, 1)."""
    big = np.maximum(np.abs(seg.lo), np.abs(seg.hi)).max(axis=0)
    _, e = np.frexp(big)
    f = np.ldexp(1.0, e)
    keep = (big == 0) | ((big >= SAFE_RANGE[0]) & (big <= SAFE_RANGE[1]))
    return np.where(keep, 1.0, f)


def scale_segments(seg: Segments, factors: NDArray[np.float64]) -> Segments:
    """The segments divided channel-wise by ``factors`` (powers of two: exact)."""
    if np.all(factors == 1.0):
        return seg
    y = None if seg.y is None else seg.y / factors
    return Segments(seg.x, seg.lo / factors, seg.hi / factors, y, seg.names)


def unscale_result(res: FitResult, seg: Segments, channel: int, factor: float,
                   verify: Callable[[RationalFunction, Segments, int], Verification]
                   ) -> FitResult:
    """``res`` (a fit of channel / factor) as a fit of ``seg``: p times factor,
    verified again on the original segments."""
    if factor == 1.0 or res.rational is None:
        return res
    rf = res.rational
    scaled = RationalFunction(rf.space, rf.p * factor, rf.q, p_basis=rf.p_basis,
                              q_basis=rf.q_basis)
    ver = verify(scaled, seg, channel)
    ok = res.success and ver.verified
    msg = res.message if ok == res.success else (
        f"{res.message}; but the fit scaled back by {factor:g} fails verification")
    return dataclasses.replace(res, rational=scaled, verification=ver, success=ok,
                               status=res.status if ok == res.success else 2, message=msg)
