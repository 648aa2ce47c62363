"""Segments that agree with themselves: samples measured at nearly the same point.

A measured BRDF is not always consistent with the symmetries a fit is built with:
Cornell's garnet_red gives f = 0.0004 1/sr with the light at 8 degrees and the viewer
at 80, and f = 0.0043 with the two nearly exchanged (a reciprocal fit cannot take both
values), and a network-encoded material varies with phi_d at theta_h = 0, where an
isotropic BRDF cannot. Segments that ratfit builds itself must describe what was
measured there: a value somewhere between the two. So where two samples lie within
``near`` of each other in the fit's coordinates (each axis scaled to [0, 1]) and
their segments are disjoint, both get the hull of the two. Samples at one point of the
fit's coordinates (a MERL table's 180 phi_d cells at theta_h = 0, or phi_d and pi - phi_d
in a mirror-symmetric frame) whose segments share no value all get the hull of the
group. Segments a user gave are never changed (disjoint segments at one point then mean
that no function fits).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_array
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ratfit.core.segments import Segments

__all__ = ["CONSISTENT_NEAR", "SAME_POINT", "Neighbours", "consistent_segments",
           "sample_neighbours"]

Array = NDArray[np.float64]

#: Two samples closer than this in the fit's coordinates, each axis scaled to [0, 1],
#: count as one point measured twice when their segments are disjoint (garnet_red in
#: the half-vector frame: 38 of 1439 samples, nearest-neighbour distances have a
#: median of 0.021 there).
CONSISTENT_NEAR = 0.02
#: Samples closer than this (axes scaled to [0, 1]) are one point: rounding apart
#: (phi_d and pi - phi_d give sin^2(theta_h) cos(2 phi_d) 1e-16 apart), nothing more.
SAME_POINT = 1e-9


@dataclass(frozen=True)
class Neighbours:
    """Which samples :func:`consistent_segments` reconciles, from the points alone:
    each sample ``first`` whose nearest other sample ``second`` lies closer than
    ``near``, and the groups at one point (:data:`SAME_POINT`): ``members`` ordered by
    group, each group starting at ``starts``. A table's default fit reconciles the same
    points at each width it tries (1.1e6 MERL cells: 2.6 s of KD-tree work a call)."""

    first: NDArray[np.intp]
    second: NDArray[np.intp]
    members: NDArray[np.intp]
    starts: NDArray[np.intp]


def sample_neighbours(x: Array, near: float = CONSISTENT_NEAR) -> Neighbours:
    """The :class:`Neighbours` of points ``x`` (N, d), each axis scaled to [0, 1]."""
    x = x if x.ndim == 2 else x[:, None]
    none = np.arange(0, dtype=np.intp)
    if x.shape[0] < 2:
        return Neighbours(none, none, none, none)
    span = np.ptp(x, axis=0)
    t = (x - x.min(axis=0)) / np.where(span > 0, span, 1.0)
    tree = cKDTree(t)
    d, nn = tree.query(t, k=2, workers=-1)  # the same answer on any number of threads
    first = np.flatnonzero(d[:, 1] < near)
    pairs = tree.query_pairs(SAME_POINT, output_type="ndarray")
    if pairs.size == 0:
        return Neighbours(first, nn[first, 1], none, none)
    n = x.shape[0]
    graph = coo_array((np.ones(len(pairs), dtype=np.int8), (pairs[:, 0], pairs[:, 1])),
                      shape=(n, n))
    _, label = connected_components(graph, directed=False)
    # the samples in some pair: those whose group has another member (ascending, as
    # np.unique of the pairs gives them, without sorting 2 x 1.4e6 indices)
    members = np.flatnonzero(np.bincount(label)[label] > 1)
    group = label[members]
    order = np.argsort(group, kind="stable")
    members, group = members[order], group[order]
    starts = np.flatnonzero(np.r_[True, group[1:] != group[:-1]])
    return Neighbours(first, nn[first, 1], members, starts)


def consistent_segments(seg: Segments, near: float = CONSISTENT_NEAR,
                        neighbours: Neighbours | None = None) -> tuple[Segments, int]:
    """``seg`` with each sample whose nearest neighbour lies closer than ``near`` and
    has a disjoint segment widened, with that neighbour, to the hull of the two, channel
    by channel; returns the segments and how many samples were widened (in any channel).
    Samples at one point (:data:`SAME_POINT`) whose segments share no value first get
    the hull of their whole group. ``neighbours``: :func:`sample_neighbours` of
    ``seg.x`` at ``near``, when the caller has them.

    A channel's segments do not depend on the other channels': a pair disjoint in R
    but not in G leaves G as it was (widened in every channel, garnet_red's G fitted
    with R had other segments than G alone, and 69 coefficients where alone it has 68).

    Nearest neighbours only: on a dense table (MERL, EXR) every sample has hundreds of
    samples within ``near``, and hulls over all of them would chain along real slopes.
    One pass is enough: both samples of a pair then contain the pair's hull, and
    segments only grow, so no pair that overlapped stops overlapping.
    """
    nb = sample_neighbours(seg.x, near) if neighbours is None else neighbours
    lo, hi = seg.lo.copy(), seg.hi.copy()
    _join_same_points(nb, lo, hi)
    a, b = nb.first, nb.second
    disjoint = (lo[a] > hi[b]) | (lo[b] > hi[a])  # (pairs, channels)
    for c in range(lo.shape[1]):
        i, j = a[disjoint[:, c]], b[disjoint[:, c]]
        hull_lo = np.minimum(lo[i, c], lo[j, c])
        hull_hi = np.maximum(hi[i, c], hi[j, c])
        for k in (i, j):  # a sample in several pairs takes the union of their hulls
            np.minimum.at(lo[:, c], k, hull_lo)
            np.maximum.at(hi[:, c], k, hull_hi)
    widened = np.any((lo < seg.lo) | (hi > seg.hi), axis=1)
    if not widened.any():
        return seg, 0
    return Segments(seg.x, lo, hi, seg.y, seg.names), int(widened.sum())


def _join_same_points(nb: Neighbours, lo: Array, hi: Array) -> None:
    """Give every sample of a group at one point (:data:`SAME_POINT`) the group's hull,
    in each channel where the group's segments share no value (in place). Nearest
    neighbours alone chain such a group pairwise: a MERL table's theta_h = 0 cells at
    theta_d = 89 degrees span 1.8-58 1/sr over phi_d in a network-encoded felt, and
    after the pairwise pass their segments still had no common value at +-50 %."""
    members, starts = nb.members, nb.starts
    if members.size == 0:
        return
    size = np.diff(np.r_[starts, members.size])
    for c in range(lo.shape[1]):
        top_lo = np.maximum.reduceat(lo[members, c], starts)
        low_hi = np.minimum.reduceat(hi[members, c], starts)
        clash = np.repeat(top_lo > low_hi, size)
        if not clash.any():
            continue
        hull_lo = np.repeat(np.minimum.reduceat(lo[members, c], starts), size)
        hull_hi = np.repeat(np.maximum.reduceat(hi[members, c], starts), size)
        k = members[clash]
        lo[k, c] = hull_lo[clash]
        hi[k, c] = hull_hi[clash]
