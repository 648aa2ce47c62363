"""Segments that agree with themselves: samples measured at nearly the same point.

A measured BRDF is not always consistent with the symmetries a fit is built with:
Cornell's garnet_red gives f = 0.0004 1/sr with the light at 8 degrees and the viewer
at 80, and f = 0.0043 with the two nearly exchanged (a reciprocal fit cannot take both
values), and a network-encoded material varies with phi_d at theta_h = 0, where an
isotropic BRDF cannot. Segments that ratfit builds itself must describe what was
measured there: a value somewhere between the two. So where two samples lie within
``near`` of each other in the fit's coordinates (each axis scaled to [0, 1]) and
their segments are disjoint, both get the hull of the two. Segments a user gave are
never changed (disjoint segments at one point then mean that no function fits).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from ratfit.core.segments import Segments

__all__ = ["CONSISTENT_NEAR", "consistent_segments"]

Array = NDArray[np.float64]

#: Two samples closer than this in the fit's coordinates, each axis scaled to [0, 1],
#: count as one point measured twice when their segments are disjoint (garnet_red in
#: the half-vector frame: 38 of 1439 samples, nearest-neighbour distances have a
#: median of 0.021 there).
CONSISTENT_NEAR = 0.02


def consistent_segments(seg: Segments, near: float = CONSISTENT_NEAR) -> tuple[Segments, int]:
    """``seg`` with each sample whose nearest neighbour lies closer than ``near`` and
    has a disjoint segment widened, with that neighbour, to the hull of the two, channel
    by channel; returns the segments and how many samples were widened (in any channel).

    A channel's segments do not depend on the other channels': a pair disjoint in R
    but not in G leaves G as it was (widened in every channel, garnet_red's G fitted
    with R had other segments than G alone, and 69 coefficients where alone it has 68).

    Nearest neighbours only: on a dense table (MERL, EXR) every sample has hundreds of
    samples within ``near``, and hulls over all of them would chain along real slopes.
    One pass is enough: both samples of a pair then contain the pair's hull, and
    segments only grow, so no pair that overlapped stops overlapping.
    """
    x = seg.x if seg.x.ndim == 2 else seg.x[:, None]
    if x.shape[0] < 2:
        return seg, 0
    span = np.ptp(x, axis=0)
    t = (x - x.min(axis=0)) / np.where(span > 0, span, 1.0)
    d, nn = cKDTree(t).query(t, k=2)
    a = np.flatnonzero(d[:, 1] < near)
    b = nn[a, 1]
    lo, hi = seg.lo.copy(), seg.hi.copy()
    disjoint = (lo[a] > hi[b]) | (lo[b] > hi[a])  # (pairs, channels)
    if not disjoint.any():
        return seg, 0
    for c in range(lo.shape[1]):
        i, j = a[disjoint[:, c]], b[disjoint[:, c]]
        hull_lo = np.minimum(seg.lo[i, c], seg.lo[j, c])
        hull_hi = np.maximum(seg.hi[i, c], seg.hi[j, c])
        for k in (i, j):  # a sample in several pairs takes the union of their hulls
            np.minimum.at(lo[:, c], k, hull_lo)
            np.maximum.at(hi[:, c], k, hull_hi)
    widened = np.any((lo < seg.lo) | (hi > seg.hi), axis=1)
    return Segments(seg.x, lo, hi, seg.y, seg.names), int(widened.sum())
