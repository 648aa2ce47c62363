"""What a 1-D fit does between neighbouring samples, and segments that bound it there.

A fit verified at the samples can swing far between two of them (NIST Thurber at
--dt 1e-4 with 37 coefficients reaches -8.8e13 between x = 2.047 and 2.2 where the data
are near 1450). :func:`between_excursions` finds r's extremes on every gap between
neighbouring sample abscissae, from the roots of p'q - pq' (r's critical points, with p
and q in their Legendre form) plus a grid of points per gap, every value computed by the
fit's own evaluation; it is a search, not a proof, and says so in ``method``.

:func:`between_segments` adds points between samples whose segments are the two
neighbours' envelope widened by ``margin`` times the data's range (the ``--between``
option of ``ratfit fit``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from numpy.polynomial import legendre as leg
from numpy.typing import NDArray

from ratfit.core.rational import RationalFunction
from ratfit.core.segments import Segments

__all__ = ["Excursion", "between_excursions", "between_segments", "gap_envelopes"]

Array = NDArray[np.float64]

#: Points per gap of the grid, at most (fewer for many samples: ~200 000 in all).
GRID_PER_GAP = 32


@dataclass(frozen=True)
class Excursion:
    """r between neighbouring samples of one channel (1-D).

    ``excursion``: the largest distance of r outside the envelope of the two neighbouring
    segments (min lo .. max hi) over any gap, at ``x`` (value ``value``, gap ``gap``).
    ``beyond_range``: how far r goes outside the data's range ``data_range`` (min lo ..
    max hi over all samples), at ``range_x`` (value ``range_value``). ``low``/``high``:
    r's smallest and largest value between samples. ``allowed``: the excursion the fit
    was asked to stay within (``--between``), None when not asked.
    """

    channel: str
    excursion: float
    x: float
    value: float
    gap: tuple[float, float]
    beyond_range: float
    range_x: float
    range_value: float
    data_range: tuple[float, float]
    low: float
    high: float
    method: str
    allowed: float | None = None
    over: tuple[float, ...] = ()  # per gap, the worst point beyond ``allowed``

    @property
    def ok(self) -> bool:
        """Within the allowed excursion (always True when none was asked for)."""
        return self.allowed is None or self.excursion <= self.allowed

    def describe(self) -> str:
        lo, hi = self.data_range
        line = (f"channel {self.channel}: between samples r ranges over [{self.low:.6g}, "
                f"{self.high:.6g}] (data {lo:.6g} .. {hi:.6g}); largest excursion beyond "
                f"the neighbouring segments {self.excursion:.3g} at x = {self.x:.6g} "
                f"(r = {self.value:.6g}, between samples {self.gap[0]:.6g} and "
                f"{self.gap[1]:.6g})")
        if self.allowed is not None:
            line += (f"; allowed {self.allowed:.3g}: " + ("met" if self.ok else "NOT MET"))
        return line

    def warning(self) -> str | None:
        """One line when r leaves the data's range between samples, else None."""
        if not self.beyond_range > 0:
            return None
        lo, hi = self.data_range
        return (f"channel {self.channel}: between samples the fit leaves the data's range "
                f"[{lo:.6g}, {hi:.6g}] by {self.beyond_range:.3g} (r = {self.range_value:.6g} "
                f"at x = {self.range_x:.6g}); " + (
                    "--between MARGIN bounds it there" if self.allowed is None else
                    f"within the --between allowance of {self.allowed:.3g} beyond the "
                    "neighbouring segments" if self.ok else "beyond the --between allowance"))

    def to_dict(self) -> dict:
        d = asdict(self)
        d["gap"] = list(self.gap)
        d["data_range"] = list(self.data_range)
        d.pop("over")
        d.pop("method")  # said once for all channels
        return d


def gap_envelopes(seg: Segments, channel: int) -> tuple[Array, Array, Array]:
    """(sorted distinct abscissae, lo, hi) of a 1-D channel; repeated x keep the widest
    bounds (the envelope of their segments)."""
    x = seg.x[:, 0]
    ux, inv = np.unique(x, return_inverse=True)
    lo = np.full(ux.size, np.inf)
    hi = np.full(ux.size, -np.inf)
    np.minimum.at(lo, inv, seg.lo[:, channel])
    np.maximum.at(hi, inv, seg.hi[:, channel])
    return ux, lo, hi


def _critical_points(rf: RationalFunction) -> Array:
    """Real roots in the domain of p'q - pq' (r's critical points), from p, q in the
    space's family converted to Legendre (numpy's colleague-matrix roots)."""
    fam = rf.to_family()
    name = rf.space.family.name
    if name == "legendre":
        p, q = fam.p, fam.q
    elif name == "chebyshev":
        from numpy.polynomial import chebyshev as ch

        p, q = ch.cheb2poly(fam.p), ch.cheb2poly(fam.q)
        p, q = leg.poly2leg(p), leg.poly2leg(q)
    else:
        p, q = leg.poly2leg(fam.p), leg.poly2leg(fam.q)
    d = leg.legsub(leg.legmul(leg.legder(p), q), leg.legmul(p, leg.legder(q)))
    d = np.trim_zeros(np.asarray(d, dtype=float), "b")
    if d.size <= 1 or not np.all(np.isfinite(d)):
        return np.array([])
    with np.errstate(all="ignore"):
        t = leg.legroots(d)
    t = np.real(t[np.abs(np.imag(t)) <= 1e-8])
    t = t[(t > -1.0) & (t < 1.0)]
    return np.asarray(rf.space.from_window(t[:, None]), dtype=float).ravel()


def between_excursions(rf: RationalFunction, seg: Segments, channel: int = 0, *,
                       allowed: float | None = None) -> Excursion:
    """r's largest excursion between neighbouring samples of ``seg`` (1-D fits only)."""
    if rf.space.dim != 1:
        raise ValueError("excursions between samples are computed for 1-D fits only")
    ux, lo, hi = gap_envelopes(seg, channel)
    name = seg.names[channel] if seg.names else f"y{channel}"
    top, bottom = float(hi.max()), float(lo.min())
    ngaps = ux.size - 1
    if ngaps < 1:
        return Excursion(name, 0.0, float(ux[0]), float("nan"), (float(ux[0]), float(ux[0])),
                         0.0, float(ux[0]), float("nan"), (bottom, top), float("nan"),
                         float("nan"), "one sample: no gap", allowed)
    k = int(max(4, min(GRID_PER_GAP, 200_000 // ngaps)))
    frac = np.arange(1, k + 1) / (k + 1)
    grid = (ux[:-1, None] + (ux[1:] - ux[:-1])[:, None] * frac[None, :]).ravel()
    crit = _critical_points(rf)
    crit = crit[(crit > ux[0]) & (crit < ux[-1])]
    xs = np.concatenate([grid, crit])
    gap = np.clip(np.searchsorted(ux, xs, side="right") - 1, 0, ngaps - 1)
    inside = (xs > ux[gap]) & (xs < ux[gap + 1])
    xs, gap = xs[inside], gap[inside]
    v = rf(xs[:, None]) if xs.size else np.array([])
    v = np.where(np.isfinite(v), v, np.nan)
    env_lo = np.minimum(lo[gap], lo[gap + 1])
    env_hi = np.maximum(hi[gap], hi[gap + 1])
    with np.errstate(invalid="ignore"):
        out = np.fmax(env_lo - v, v - env_hi)
        out = np.where(np.isnan(v), np.inf, np.maximum(out, 0.0))
        out_range = np.where(np.isnan(v), np.inf, np.maximum(np.fmax(bottom - v, v - top), 0.0))
    if allowed is not None and xs.size:
        # per gap, the point farthest outside where the allowed excursion is exceeded
        order = np.lexsort((-out, gap))
        first = order[np.r_[True, gap[order][1:] != gap[order][:-1]]]
        over = tuple(float(v) for v in xs[first][out[first] > allowed])
    else:
        over = ()
    i = int(np.argmax(out))
    j = int(np.argmax(out_range))
    method = (f"r at its critical points (real roots of p'q - pq', Legendre form) and at "
              f"{k} points per gap between neighbouring samples, by ratfit's evaluation "
              "(a search, not a proof)")
    return Excursion(
        channel=name, excursion=float(out[i]), x=float(xs[i]), value=float(v[i]),
        gap=(float(ux[gap[i]]), float(ux[gap[i] + 1])), beyond_range=float(out_range[j]),
        range_x=float(xs[j]), range_value=float(v[j]), data_range=(bottom, top),
        low=float(np.nanmin(v)), high=float(np.nanmax(v)), method=method, allowed=allowed,
        over=over)


def data_ranges(seg: Segments) -> Array:
    """max hi - min lo per channel (the scale of ``--between``'s margin)."""
    return np.asarray(seg.hi.max(axis=0) - seg.lo.min(axis=0), dtype=float)


def between_segments(seg: Segments, xs: Array, margin: float) -> Segments:
    """``seg`` plus points ``xs`` (strictly between samples) whose segment, per channel,
    is the envelope of the two neighbouring samples' segments widened by ``margin``
    times that channel's data range (max hi - min lo)."""
    widen = margin * data_ranges(seg)
    rows_lo, rows_hi = [], []
    for c in range(seg.n_channels):
        ux, lo, hi = gap_envelopes(seg, c)
        g = np.clip(np.searchsorted(ux, xs, side="right") - 1, 0, ux.size - 2)
        rows_lo.append(np.minimum(lo[g], lo[g + 1]) - widen[c])
        rows_hi.append(np.maximum(hi[g], hi[g + 1]) + widen[c])
    new_lo = np.stack(rows_lo, axis=1)
    new_hi = np.stack(rows_hi, axis=1)
    x = np.concatenate([seg.x, np.asarray(xs, dtype=float)[:, None]])
    y = None if seg.y is None else np.concatenate([seg.y, 0.5 * (new_lo + new_hi)])
    return Segments(x, np.concatenate([seg.lo, new_lo]), np.concatenate([seg.hi, new_hi]), y,
                    seg.names)
