"""Physical validity of a BRDF fit on the configurations light can take.

A rational BRDF r = p / q is physically usable only if, for every pair of
directions (L, V) above the horizon whose coordinates lie in the fit's domain,
q does not vanish (no pole, one strict sign) and r >= 0. The samples alone
never show it: a fit can go negative or through a pole between measurements
(the garnet_red fit of issue 12: q changes sign at theta_v = theta_l = 75 deg).

The configurations are sampled as directions, not as a box of coordinates:
a grid over the elevations and the azimuth difference (four angles for
anisotropic parametrizations), mapped through the parametrization and kept
when inside the domain. That is exact for every parametrization, including
those whose box holds coordinates of no pair (STARK_2D, CARTESIAN).

Two uses:

- :func:`configurations` gives the constraint grid that the QP keeps q > 0
  and p >= 0 on (rows added by the active set only where violated);
- :func:`check_validity` is the verification: a finer grid offset from the
  constraint grid, then a compass search started at the lowest values of q
  and of p, so that a sign change between grid points is chased down rather
  than stepped over. It reports what it checked.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.brdf.parametrizations import Parametrization, find_parametrization
from ratfit.core.bases import PolynomialSpace
from ratfit.core.dominance import first_of_groups, groups, prefix_max
from ratfit.core.positivity import SignProof
from ratfit.core.rational import RationalFunction
from ratfit.core.systems import smallest
from ratfit.errors import InputError
from ratfit.io.fitfile import ceiling_bound, proof_ceiling

__all__ = [
    "Envelope",
    "SampleCeiling",
    "SampleFloor",
    "StepCeiling",
    "ValidityCheck",
    "ValidityProof",
    "angle_grid",
    "box_configurations",
    "check_validity",
    "configurations",
    "dips_around",
    "envelope_from_dict",
    "grazing",
    "theta_d_growth",
    "prove_validity",
    "reprove_saved",
]

Array = NDArray[np.float64]
_HALF = 0.5 * np.pi
# Directions exactly at the horizon are limits of valid ones; stay a hair above.
_TOP = _HALF - 1e-9


def _n_angles(p: Parametrization) -> int:
    return 4 if p.invariant == "full" else 3


def _bounds(k: int) -> Array:
    if k == 4:  # theta_l, phi_l, theta_v, phi_v
        return np.array([[0.0, _TOP], [-np.pi, np.pi], [0.0, _TOP], [-np.pi, np.pi]])
    return np.array([[0.0, _TOP], [0.0, _TOP], [-np.pi, np.pi]])  # theta_l, theta_v, dphi


def _dirs(a: Array) -> tuple[Array, Array]:
    def sph(t: Array, ph: Array) -> Array:
        s = np.sin(t)
        return np.stack([s * np.cos(ph), s * np.sin(ph), np.cos(t)], axis=1)

    if a.shape[1] == 4:
        return sph(a[:, 0], a[:, 1]), sph(a[:, 2], a[:, 3])
    return sph(a[:, 0], np.zeros(len(a))), sph(a[:, 1], -a[:, 2])


def _coords(p: Parametrization, a: Array) -> Array:
    L, V = _dirs(a)
    with np.errstate(all="ignore"):
        return p._from(L, V)


def _inside(c: Array, domain: Array) -> NDArray[np.bool_]:
    pad = 1e-12 * (1.0 + np.abs(domain).max(axis=1))
    ok = np.all(np.isfinite(c), axis=1)
    ok &= np.all((c >= domain[:, 0] - pad) & (c <= domain[:, 1] + pad), axis=1)
    return ok


def angle_grid(k: int, points: int, offset: bool = False) -> Array:
    """A grid of ~``points`` angle tuples (k = 3: theta_l, theta_v, dphi; k = 4: full)."""
    b = _bounds(k)
    per = max(3, int(round(points ** (1.0 / k))))
    axes = []
    for lo, hi in b:
        if offset:  # midpoints: interleaved with the constraint grid, never on it
            e = np.linspace(lo, hi, per + 1)
            axes.append(0.5 * (e[1:] + e[:-1]))
        else:
            axes.append(np.linspace(lo, hi, per))
    return np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")], axis=1)


def configurations(param: str, domain: ArrayLike, points: int = 60_000,
                   offset: bool = False, keep: ArrayLike | None = None,
                   box_points: int = 0) -> Array | None:
    """Coordinates of direction pairs above the horizon that fall inside ``domain``.

    ``box_points``: also that many points of a grid of the coordinate box itself that
    are valid configurations (:func:`box_configurations`), faces included; the angle
    grid alone leaves bands such as theta_h near 0 (the mirror direction) almost
    empty, and the validity proof covers them too. (Rows on the whole box, pairs or not,
    were measured and dropped: cayman's default search then ran past 150 s at 59
    coefficients, against 15 s and 38 coefficients with these.)
    None when the parametrization is unknown (then nothing says what is valid).
    """
    p = find_parametrization(param)
    if p is None:
        return None
    dom = np.asarray(domain, dtype=float).reshape(-1, 2)
    cols = np.arange(p.dim) if keep is None else np.asarray(keep, dtype=np.int64)
    if dom.shape[0] != cols.size:
        return None
    c = _coords(p, angle_grid(_n_angles(p), points, offset))[:, cols]
    c = np.clip(c[_inside(c, dom)], dom[:, 0], dom[:, 1])
    if box_points and keep is None:
        box = box_configurations(param, dom, box_points)
        if box is not None and len(box):
            c = np.concatenate([c, box])
    return c


def box_configurations(param: str, domain: ArrayLike, points: int = 200_000) -> Array | None:
    """Grid points of the box ``domain`` (ends included) that are valid configurations
    of ``param`` or limits of them: directions above the horizon that convert back to the
    same coordinates, there or a hair (:data:`LIMIT_NUDGE` of the way to the box's
    centre) inside the box. The limits matter on faces where a coordinate is undefined:
    at theta_d = 0 (L = V) phi_d is, so the round trip moves every point of that face to
    phi_d = 0, yet pairs with theta_d -> 0 reach them all, and the proof covers them
    (satin's R in RUSIN_TH_TD_PD had q < 0 just inside that face without these rows).
    None when the parametrization is unknown (then the whole box counts).
    """
    p = find_parametrization(param)
    if p is None:
        return None
    dom = np.asarray(domain, dtype=float)
    per = max(3, int(points ** (1.0 / p.dim)))
    axes = [np.linspace(lo, hi, per) for lo, hi in dom]
    g = np.stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")], axis=1)
    ok = _valid_or_limits(p, g, dom)
    return None if ok is None else g[ok]


def _valid_or_limits(p: Parametrization, g: Array, dom: Array) -> NDArray[np.bool_] | None:
    """Rows of ``g`` (points of the box ``dom``) that are valid configurations or limits
    of them (:func:`box_configurations`); None when ``p`` cannot convert them."""
    try:
        return _round_trips(p, g) | _round_trips(p, g + LIMIT_NUDGE * (dom.mean(axis=1) - g))
    except InputError:
        return None


def dips_around(rf: RationalFunction, points: ArrayLike, param: str,
                keep: ArrayLike | None = None, *, values: str = "linear",
                ceiling: float | None = None, envelope: Envelope | None = None,
                reach: float = 0.04, per: int = 33, points_each: int = 36_000,
                centres: int = 8) -> Array:
    """``points`` and the points of a fine grid around them where ``rf`` fails: q <= 0,
    or the second function of :func:`check_validity` (p, or C q - p) < 0.

    A refuted proof reports the corners of the first piece where q is provably
    negative: a few copies of one point in a pocket where q dips below zero between
    the validity grid's points. Rows there alone move the pocket a box-width, where
    the next proof finds it again: laika_ceiling_paint_18_gray R's repair took seven
    rounds of 3-4 s, each with one or two new corners, while a grid 0.002 rad apart
    showed 1 442 points with q < 0 in a pocket 0.07 x 0.04 x 0.03 rad wide after the
    first. The grid (``per`` points an axis, fewer where that would pass
    ``points_each`` points: 14 an axis in 4-D; ``reach`` of the domain's extent to each
    side, clipped to the domain; valid configurations only, where the parametrization
    says which) is read around at most ``centres`` of ``points``, at least ``reach`` apart.
    """
    dom = np.asarray(rf.space.domain, dtype=float).reshape(-1, 2)
    pts = np.unique(np.asarray(points, dtype=float).reshape(-1, len(dom)), axis=0)
    if not len(pts):
        return pts
    ext = dom[:, 1] - dom[:, 0]
    unit = np.where(ext > 0, ext, 1.0)
    chosen: list[Array] = []
    for x in pts:
        if all(np.max(np.abs(x - c) / unit) >= reach for c in chosen):
            chosen.append(x)
            if len(chosen) == centres:
                break
    axis = max(3, min(per, round(points_each ** (1.0 / len(dom)))))
    steps = np.linspace(-reach, reach, axis)
    offsets = np.stack([g.ravel() for g in np.meshgrid(*([steps] * len(dom)),
                                                       indexing="ij")], axis=1) * ext
    grid = np.clip(np.concatenate([c + offsets for c in chosen]), dom[:, 0], dom[:, 1])
    p = find_parametrization(param)
    own_box = p is not None and keep is None and p.dim == len(dom)
    sign = _q_sign(rf, param, np.ones(1), own_box)  # (no grid: q > 0, as at the samples)
    second = _second(rf, values, ceiling, envelope)
    # screened values, exact wherever a sign could be in doubt: the exact signs, at a
    # fifth of the cost (up to 8 x 35 937 points for each refuted candidate)
    q, sv = _grid_values(rf, second, _second(_Screened(rf), values, ceiling, envelope), grid,
                         extremes=0)
    with np.errstate(all="ignore"):
        bad = ~(sign * q > 0)
        if second is not None:
            bad |= ~(sign * sv >= 0)
    found = grid[bad]
    if p is not None and own_box and len(found):
        # which points are valid pairs, asked of the failing ones only: the round trip
        # through directions had been two thirds of this function's time on every point
        ok = _valid_or_limits(p, found, dom)
        if ok is not None:
            found = found[ok]
    return np.unique(np.concatenate([pts, found]), axis=0)


#: How far toward the box's centre :func:`box_configurations` moves a grid point to tell
#: whether it is a limit of valid configurations.
LIMIT_NUDGE = 1e-6


def _round_trips(p: Parametrization, g: Array) -> NDArray[np.bool_]:
    """Rows of ``g`` that convert to directions above the horizon and back to themselves."""
    with np.errstate(all="ignore"):
        L, V = p._to(g)
        ok = np.isfinite(L).all(axis=1) & np.isfinite(V).all(axis=1)
        ok &= (L[:, 2] >= 0) & (V[:, 2] >= 0)
        back = np.full_like(g, np.nan)
        if ok.any():
            back[ok] = p._from(L[ok], V[ok])
    d = np.abs(back - g)
    d = np.minimum(d, np.abs(d - 2 * np.pi))  # angles that wrap
    return ok & np.all(d <= 1e-7 * (1.0 + np.abs(g)), axis=1)


@dataclass(frozen=True)
class ValidityCheck:
    """What the dense check of a BRDF fit found on the valid configurations."""

    valid: bool
    checked: int  # configurations evaluated (grid + local search)
    min_q: float  # smallest q / max|q| found (> 0 required)
    min_r: float  # smallest r / max r found (>= 0 required)
    bad_points: Array  # coordinates where q <= 0 or r < 0 was found (for new rows)
    method: str

    def summary(self) -> str:
        state = "valid" if self.valid else "INVALID"
        r = f", min r/max r {self.min_r:.3g}" if np.isfinite(self.min_r) else ""
        return (f"{state} on {self.checked} direction pairs in the domain ({self.method}); "
                f"min q/max|q| {self.min_q:.3g}{r}")


def check_validity(rf: RationalFunction, param: str, domain: ArrayLike | None = None,
                   points: int = 150_000, starts: int = 24,
                   keep: ArrayLike | None = None,
                   values: str = "linear", ceiling: float | None = None,
                   envelope: Envelope | None = None) -> ValidityCheck | None:
    """Dense, adaptive check that q > 0 and p >= 0 on valid configurations in ``domain``
    (for ``values="log"``, where the fit is exp(p / q) > 0 wherever q > 0: q > 0 and,
    with a ``ceiling`` C, C q - p >= 0, so that the value is at most exp(C); with an
    ``envelope`` too, C(theta_h) q - p >= 0 with C the lower of the two at each point).

    A grid of direction pairs offset from :func:`configurations`' (so the
    constraint grid proves nothing here), then a compass search in angle space
    from the ``starts`` lowest values of q and of p, each step halving down to
    1e-4 of the grid step. None when the parametrization is unknown.
    ``keep``: the coordinates the fit uses (constant ones dropped), in order.
    """
    p = find_parametrization(param)
    if p is None:
        return None
    cols = np.arange(p.dim) if keep is None else np.asarray(keep, dtype=np.int64)
    dom = rf.space.domain if domain is None else np.asarray(domain, dtype=float)
    k = _n_angles(p)
    a, c = _check_grid(p, dom, cols, points)
    if len(c) == 0:
        return ValidityCheck(True, 0, np.inf, np.inf, np.zeros((0, dom.shape[0])),
                             "no direction pair in the domain")
    second = _second(rf, values, ceiling, envelope)
    numerator = second is not None
    q, pv = _grid_values(rf, second, _second(_Screened(rf), values, ceiling, envelope), c)
    sign = 1.0 if np.sum(q > 0) >= np.sum(q < 0) else -1.0
    q, pv = sign * q, sign * pv
    qs = float(np.max(np.abs(q))) or 1.0
    rs = float(np.nanmax(np.abs(pv / np.where(q > 0, q, np.nan)), initial=0.0)) or 1.0
    checked = len(c)
    found = [c[(q <= 0) | (pv < 0)]]
    per = max(3, int(round(points ** (1.0 / k))))
    step = (_bounds(k)[:, 1] - _bounds(k)[:, 0]) / per
    searches = ((True, q / qs), (False, pv / (qs * rs))) if numerator else ((True, q / qs),)
    for use_q, vals in searches:
        # (stable: among equal values, as the fold frame's mirror pairs give, grid order)
        pick = np.argsort(vals, kind="stable")[: min(starts, len(vals))]
        pts, best = _compass(rf, p, dom, a[pick], vals[pick], step, sign, qs,
                             qs * rs, use_q=use_q, cols=cols, second=second)
        checked += pts
        found.append(best)
    bad = np.concatenate(found) if found else np.zeros((0, dom.shape[0]))
    qa, pa = q, pv  # the grid's values, plus those of the bad points found
    if len(bad):
        qb = sign * rf.denominator(bad)
        pb = sign * second(bad) if second is not None else np.abs(qb)
        keep_b = (qb <= 0) | (pb < 0) | ~np.isfinite(qb) | ~np.isfinite(pb)
        bad, qb, pb = bad[keep_b], qb[keep_b], pb[keep_b]
        qa, pa = np.concatenate([q, qb]), np.concatenate([pv, pb])
    with np.errstate(divide="ignore", invalid="ignore"):
        ra = pa / qa
    min_q = float(np.min(qa) / qs)
    # (a fit of log values has no r to bound below: exp(p / q) > 0 wherever q > 0;
    # with a ceiling, r here is C - p / q)
    min_r = float(np.nanmin(np.where(qa > 0, ra, -np.inf)) / rs) if numerator else np.inf
    valid = len(bad) == 0 and min_q > 0 and min_r >= 0 and bool(np.all(np.isfinite(qa)))
    return ValidityCheck(valid, checked, min_q, min_r, bad,
                         f"offset grid of {len(c)} + compass search from {2 * starts} minima")


#: The offset grid's values are first taken through BLAS products
#: (:meth:`~ratfit.core.arnoldi.ArnoldiBasis.evaluate_blas`: at 148 724 pairs and 112
#: functions 0.10 s against 0.86 s for the fixed order, the values 1e-15 of max|q|
#: apart). The fixed-order values replace them wherever the check reads them closely:
#: within SCREEN_MARGIN of zero (or not finite), where a sign could depend on the order
#: of the sums, and at the SCREEN_EXTREMES smallest and largest values of q, of the
#: second function and of their ratio, where the compass search's starts and the
#: scales come from. The check then reads the numbers the fixed order gives, and a
#: search takes the same path as with the fixed order everywhere.
SCREEN_MARGIN = 1e-6
SCREEN_EXTREMES = 256


class _Screened:
    """``rf``'s p and q through BLAS products where they are held in data-orthonormal
    bases (the fixed-order sums otherwise): values to screen a grid with, not a verdict."""

    def __init__(self, rf: RationalFunction) -> None:
        self.rf = rf

    def numerator(self, x: Array) -> Array:
        b = self.rf.p_basis
        return self.rf.numerator(x) if b is None else b.evaluate_blas(x, self.rf.p)

    def denominator(self, x: Array) -> Array:
        b = self.rf.q_basis
        return self.rf.denominator(x) if b is None else b.evaluate_blas(x, self.rf.q)


def _extremes(v: Array, k: int) -> NDArray[np.int64]:
    """Indices of the ``k`` smallest and the ``k`` largest of ``v`` (a NaN is neither:
    :func:`_grid_values` takes every non-finite value exactly anyway)."""
    return np.concatenate([smallest(v, k), smallest(-v, k)])


def _grid_values(rf: RationalFunction, second: Callable[[Array], Array] | None,
                 screened: Callable[[Array], Array] | None, c: Array,
                 extremes: int = SCREEN_EXTREMES) -> tuple[Array, Array]:
    """q and the second function (|q| without one: p counts as positive wherever q is)
    at the grid ``c``: screened values, and the exact ones wherever the check reads
    them closely (:data:`SCREEN_MARGIN`; the ``extremes`` smallest and largest of q, p and
    |p / q|, 0 where only the signs are read)."""
    q = _Screened(rf).denominator(c)
    pv = screened(c) if screened is not None else np.abs(q)
    with np.errstate(all="ignore"):
        qs = float(np.nanmax(np.abs(q), initial=0.0))
        ps = float(np.nanmax(np.abs(pv), initial=0.0))
        near = ~(np.abs(q) > SCREEN_MARGIN * qs) | ~(np.abs(pv) > SCREEN_MARGIN * ps)
    close = np.flatnonzero(near)
    if extremes:
        with np.errstate(all="ignore"):
            ratio = np.abs(pv / q)
        close = np.unique(np.concatenate([
            close, _extremes(q, extremes), _extremes(pv, extremes),
            _extremes(np.where(np.isfinite(ratio), ratio, 0.0), extremes)]))
    at = c[close]
    q[close] = rf.denominator(at)
    pv[close] = second(at) if second is not None else np.abs(q[close])
    return q, pv


_GRIDS: dict[tuple, tuple[Array, Array]] = {}


def _check_grid(p: Parametrization, dom: Array, cols: NDArray[np.int64],
                points: int) -> tuple[Array, Array]:
    """The offset grid (angles, coordinates) inside ``dom``; kept for the next
    candidate of the same fit (a search verifies many on one domain)."""
    key = (p.name, dom.tobytes(), cols.tobytes(), int(points))
    hit = _GRIDS.get(key)
    if hit is None:
        a = angle_grid(_n_angles(p), points, offset=True)
        c = _coords(p, a)[:, cols]
        inside = _inside(c, dom)
        hit = (a[inside], np.clip(c[inside], dom[:, 0], dom[:, 1]))
        if len(_GRIDS) >= 8:
            _GRIDS.clear()
        _GRIDS[key] = hit
    return hit


def _second(rf: RationalFunction | _Screened, values: str, ceiling: float | None,
            envelope: Envelope | None = None) -> Callable[[Array], Array] | None:
    """The function a valid fit keeps >= 0 beside q: p (values), C q - p (log values
    under a ceiling C: exp(p / q) <= exp(C); under an ``envelope`` too, C the lower of
    the two at each point's theta_h), or None (log values without one)."""
    if values != "log":
        return rf.numerator
    if ceiling is None:
        return None
    c_top = float(ceiling)
    if envelope is None:
        return lambda x: c_top * rf.denominator(x) - rf.numerator(x)

    floor = getattr(envelope, "floor", None)

    def below(x: Array) -> Array:
        c = np.minimum(envelope.at_points(x), c_top)
        q, p = rf.denominator(x), rf.numerator(x)
        out = c * q - p
        if floor is not None:  # and above the floor: both >= 0, so the smaller is
            f = np.maximum(floor.at_points(x), FLOOR_LOG_MIN)
            with np.errstate(invalid="ignore"):
                out = np.minimum(out, np.where(np.isfinite(f), p - f * q, -np.inf))
        return out

    return below


def _compass(rf: RationalFunction, p: Parametrization, dom: Array, a0: Array, v0: Array,
             step: Array, sign: float, qs: float, ps: float, use_q: bool,
             cols: NDArray[np.int64],
             second: Callable[[Array], Array] | None = None) -> tuple[int, Array]:
    """Lower q (or ``second``, p by default) from each start by compass moves in angle
    space; returns (evaluations, coordinates of the non-positive values reached)."""
    second = rf.numerator if second is None else second
    b = _bounds(a0.shape[1])
    a, v = a0.copy(), v0.copy()
    k = a.shape[1]
    dirs = np.vstack([np.eye(k), -np.eye(k)])
    scale = np.ones(len(a))  # per-start step multiplier, halved when stuck
    evals = 0
    bad: list[Array] = []

    def value(pts: Array) -> tuple[Array, Array]:
        c = _coords(p, pts)[:, cols]
        ok = _inside(c, dom)
        c = np.clip(np.nan_to_num(c), dom[:, 0], dom[:, 1])
        q = sign * rf.denominator(c)
        pv = sign * second(c)
        f = q / qs if use_q else pv / ps
        return np.where(ok & np.isfinite(f), f, np.inf), c

    for _ in range(30):
        h = scale[:, None, None] * step[None, None, :]
        cand = np.clip(a[:, None, :] + dirs[None, :, :] * h, b[:, 0], b[:, 1])
        f, c = value(cand.reshape(-1, k))
        evals += f.size
        f = f.reshape(len(a), 2 * k)
        c = c.reshape(len(a), 2 * k, -1)
        neg = f <= 0
        if neg.any():
            bad.append(c[neg])
        j = np.argmin(f, axis=1)
        fj = f[np.arange(len(a)), j]
        better = fj < v
        a[better] = cand[better, j[better]]
        v[better] = fj[better]
        scale = np.where(better, scale, 0.5 * scale)
        if scale.max() < 1e-4:
            break
    return evals, (np.concatenate(bad) if bad else np.zeros((0, dom.shape[0])))


# ------------------------------------------------------------------ envelope ceiling
@dataclass(frozen=True)
class StepCeiling:
    """A ceiling of a log fit that falls with theta_h in steps: p / q <= C(t) at
    theta_h = t, with C(t) = ``log_ceiling[k]``, k the number of ``theta_h`` elevations
    below t - ``slack``. Built from the samples (:meth:`of_samples`), it is their
    envelope: the search's and the polish's rows keep it with one slack, the validity
    proof proves it with twice that, so that no value anywhere exceeds what the samples
    at that elevation or beyond allow. ``column``: theta_h's column among the fit's
    coordinates."""

    column: int
    theta_h: Array
    log_ceiling: Array
    slack: float = 0.0

    def __post_init__(self) -> None:
        t = np.asarray(self.theta_h, dtype=float)
        v = np.asarray(self.log_ceiling, dtype=float)
        if (t.ndim != 1 or v.ndim != 1 or v.size != t.size + 1 or not np.all(np.isfinite(t))
                or not np.all(np.isfinite(v)) or np.any(np.diff(t) <= 0)
                or np.any(np.diff(v) > 0) or int(self.column) < 0
                or not (np.isfinite(self.slack) and self.slack >= 0)):
            raise ValueError("a step ceiling needs ascending elevations, one more "
                             "non-increasing finite value, a column >= 0 and a slack >= 0")
        object.__setattr__(self, "theta_h", t)
        object.__setattr__(self, "log_ceiling", v)
        object.__setattr__(self, "slack", float(self.slack))

    @classmethod
    def of_samples(cls, column: int, theta_h: ArrayLike, top: ArrayLike, slack: float,
                   factor: float) -> StepCeiling:
        """log(``factor`` x the largest of ``top`` among the samples with theta_h >=
        t - ``slack``) (past the farthest sample: that sample's own)."""
        th = np.asarray(theta_h, dtype=float)
        order = np.argsort(th, kind="stable")
        th = th[order]
        beyond = np.maximum.accumulate(np.asarray(top, dtype=float)[order][::-1])[::-1]
        # the value falls where t - slack passes a sample that held the maximum
        falls = np.flatnonzero(beyond[1:] < beyond[:-1])
        steps = th[falls]
        values = np.log(factor * np.concatenate([beyond[:1], beyond[falls + 1]]))
        if steps.size and np.any(np.diff(steps) == 0):
            # (samples at one elevation fall together: the last of their values holds)
            first = np.concatenate([[True], np.diff(steps) > 0])
            idx = np.flatnonzero(first)
            last = np.concatenate([idx[1:] - 1, [steps.size - 1]])
            steps = steps[idx]
            values = np.concatenate([values[:1], values[1:][last]])
        return cls(int(column), steps, values, float(slack))

    def at(self, theta_h: ArrayLike) -> Array:
        """C at each elevation in ``theta_h``."""
        k = np.searchsorted(self.theta_h, np.asarray(theta_h, dtype=float) - self.slack,
                            side="left")
        return self.log_ceiling[k]

    def at_points(self, x: ArrayLike) -> Array:
        """C at each row of ``x`` (the fit's coordinates)."""
        return self.at(np.asarray(x, dtype=float)[:, self.column])

    def describe(self) -> str:
        return (f"over theta_h ({self.theta_h.size + 1} steps, down to "
                f"{ceiling_bound(float(self.log_ceiling[-1])):.3g})")

    def of_pieces(self, space: PolynomialSpace) -> Callable[[Array, Array],
                                                              tuple[Array, NDArray[np.bool_]]]:
        """:func:`~ratfit.core.positivity.prove_below`'s bound on pieces of ``space``'s
        window: C at the piece's largest theta_h (C falls), rounded outward, and whether
        C is that value all over the piece."""
        a, b = (float(v) for v in space.domain[self.column])
        half = 0.5 * (b - a)

        def bound(lo: Array, hi: Array) -> tuple[Array, NDArray[np.bool_]]:
            t_lo = a + (lo[:, self.column] + 1.0) * half
            t_hi = a + (hi[:, self.column] + 1.0) * half
            pad = 1e-12 * (1.0 + np.abs(t_hi))
            c = self.at(t_hi + pad)
            return c, self.at(t_lo - pad) == c

        return bound

    def to_dict(self) -> dict[str, object]:
        return {"coordinate": "theta_h", "column": int(self.column),
                "theta_h": self.theta_h.tolist(), "slack": self.slack,
                "log_ceiling": self.log_ceiling.tolist()}

    @classmethod
    def from_dict(cls, entry: object) -> StepCeiling | None:
        """The step ceiling a proof entry states, or None where it states none or an
        entry that is not one (a hand-edited file proves nothing by its word)."""
        env = entry.get("envelope") if isinstance(entry, dict) else None
        if not isinstance(env, dict) or "theta_d" in env:
            return None
        try:
            # (files of commit a74032d state their steps with the slack added: 0 here)
            col, slack = env["column"], env.get("slack", 0.0)
            if any(isinstance(v, bool) for v in (col, slack)) or not isinstance(col, int) \
                    or not isinstance(slack, (int, float)):
                return None
            return cls(col, np.asarray(env["theta_h"], dtype=float),
                       np.asarray(env["log_ceiling"], dtype=float), float(slack))
        except (KeyError, TypeError, ValueError):
            return None


#: the samples of a :class:`SampleCeiling` at this fraction of the largest or above are
#: its highlight: they grow toward grazing (and :func:`theta_d_growth` measures them)
HIGHLIGHT_FRACTION = 0.01
#: :class:`SampleCeiling` is a table over its samples' distinct theta_h and this many
#: equal steps of theta_d over [0, pi / 2] (:data:`ENVELOPE_D_STEP` apart)
_D_LEVELS = 314
ENVELOPE_D_STEP = 0.5 * np.pi / _D_LEVELS


@dataclass(frozen=True)
class SampleCeiling:
    """A ceiling of a log fit over theta_h and theta_d, from samples i at (theta_h_i,
    theta_d_i) with log ceilings v_i: p / q <= C(t, d) at theta_h = t, theta_d = d, with

        C(t, d) = max over i with theta_h_i >= t - slack of
                  v_i - growth * max(0, g(theta_d_i - slack) - g(d)),

    g(d) = -log cos d (:func:`grazing`; t beyond the farthest sample's theta_h + slack:
    that sample's). A sample allows its value as far from the mirror direction or
    farther (as :class:`StepCeiling` does), at its incidence or nearer grazing, and
    nearer the normal divided by (cos d / cos(theta_d_i - slack))^growth: a highlight
    grows toward grazing as a power of 1 / cos theta_d (a microfacet lobe's
    1 / (cos theta_l cos theta_v) is the square, Fresnel and shadowing change the power),
    as fast as the samples show (:func:`theta_d_growth`), but no faster. Only the
    highlight's samples grow (``grows``: those at :data:`HIGHLIGHT_FRACTION` of the
    largest or above); the others keep their value at every theta_d, as the diffuse
    part does (with every sample growing, acryl_blue B's diffuse fit / data fell from
    0.96 to 0.58). Over theta_h alone the ceiling at the mirror direction is the file's
    grazing peak at every incidence (cayman: 737 1/sr at 80 degrees), and fits rose
    10-1000x above their 10-70 degree mirror samples between them. ``growth`` 0 is the
    theta_h envelope.

    C falls with t and rises with d, so its smallest value on a box is at the box's
    (largest t, smallest d) corner, which is what the proof takes. It is computed as
    defined at theta_d steps :data:`ENVELOPE_D_STEP` apart and taken at the step at or
    below d: the ceiling is that staircase, a little under the formula; -inf (no value
    allowed) at a non-finite coordinate. ``column``, ``d_column``: theta_h's and
    theta_d's columns among the fit's coordinates."""

    column: int
    d_column: int
    theta_h: Array
    theta_d: Array
    log_ceiling: Array
    slack: float = 0.0
    growth: float = 0.0
    # the samples whose term falls toward the normal (the highlight's); None: every one
    grows: NDArray[np.bool_] | None = None
    # the value held above the highlight's samples' floor as well (None: no floor)
    floor: SampleFloor | None = None

    def __post_init__(self) -> None:
        if self.floor is not None and (not isinstance(self.floor, SampleFloor) or (
                self.floor.column, self.floor.d_column) != (self.column, self.d_column)):
            raise ValueError("a sample ceiling's floor must be a SampleFloor over its columns")
        t = np.asarray(self.theta_h, dtype=float)
        d = np.asarray(self.theta_d, dtype=float)
        v = np.asarray(self.log_ceiling, dtype=float)
        grows = (np.ones(t.shape, dtype=bool) if self.grows is None
                 else np.asarray(self.grows))
        cols = (self.column, self.d_column)
        if (t.ndim != 1 or t.size == 0 or d.shape != t.shape or v.shape != t.shape
                or grows.shape != t.shape or grows.dtype != np.bool_
                or not all(np.all(np.isfinite(a)) for a in (t, d, v))
                or any(isinstance(c, bool) or not isinstance(c, (int, np.integer)) or c < 0
                       for c in cols) or self.column == self.d_column
                or not all(np.isfinite(x) and x >= 0 for x in (self.slack, self.growth))):
            raise ValueError("a sample ceiling needs finite theta_h, theta_d and values "
                             "(and booleans, if any) of one length, two distinct columns "
                             ">= 0, and a slack and a growth >= 0")
        for name, value in (("theta_h", t), ("theta_d", d), ("log_ceiling", v),
                            ("grows", grows),
                            ("column", int(self.column)), ("d_column", int(self.d_column)),
                            ("slack", float(self.slack)), ("growth", float(self.growth))):
            object.__setattr__(self, name, value)
        # theta_d steps over [0, pi / 2], the same for any samples (below 0 grazing() is
        # 0: the first step's value is exact there)
        levels = ENVELOPE_D_STEP * np.arange(_D_LEVELS + 1)
        n = _D_LEVELS
        # rows: steps; columns: theta_h ranks (the largest at or past each rank); the
        # samples that do not grow in a row of their own (the same at every step)
        ths, rank_t = np.unique(t, return_inverse=True)
        terms = v[None, :] - self.growth * np.maximum(
            0.0, grazing(d - self.slack)[None, :] - grazing(levels)[:, None])  # (n + 1, K)
        table = np.full((n + 2, ths.size), -np.inf)
        for k in range(n + 1):
            np.maximum.at(table[k], rank_t[grows], terms[k, grows])
        np.maximum.at(table[n + 1], rank_t[~grows], v[~grows])
        table = np.maximum.accumulate(table[:, ::-1], axis=1)[:, ::-1]
        object.__setattr__(self, "_table", (ths, table))

    @classmethod
    def of_samples(cls, column: int, d_column: int, theta_h: ArrayLike, theta_d: ArrayLike,
                   top: ArrayLike, slack: float, factor: float, growth: float,
                   highlight: float = HIGHLIGHT_FRACTION,
                   floor: SampleFloor | None = None) -> SampleCeiling:
        """log(``factor`` x ``top``) at each sample; the samples at ``highlight`` times
        the largest ``top`` or above grow (the highlight), the others keep their value
        at every theta_d (a diffuse part does not grow toward grazing, and the noise
        neither). Less the samples that never decide C: another has theta_h as large or
        larger and a value as large or larger, and does not grow, or both grow and it
        has theta_d as small or smaller (the same ceiling everywhere without them)."""
        t = np.asarray(theta_h, dtype=float)
        d = np.asarray(theta_d, dtype=float)
        top_a = np.asarray(top, dtype=float)
        v = np.log(factor * top_a)
        grows = top_a >= highlight * top_a.max()
        # in order of falling value, then theta_h, then rising theta_d: each sample is
        # dominated only by one before it (and by every one that dominates that one)
        order = np.lexsort((d, -t, -v))
        # of samples at one (theta_h, theta_d) that grow alike, the first dominates
        lead = first_of_groups(order, t, d, grows)
        t_l, d_l, g_l = t[lead], d[lead], grows[lead]
        # by one that does not grow with theta_h as large or larger (before it: value too)
        flat_t = np.where(g_l, -np.inf, t_l)
        before = np.concatenate([[-np.inf], np.maximum.accumulate(flat_t)[:-1]])
        dominated = before >= t_l
        # a growing one, by a growing one with theta_h as large and theta_d as small
        grow_at = np.flatnonzero(g_l)
        reach = prefix_max(d_l[grow_at], t_l[grow_at], np.arange(grow_at.size),
                           d_l[grow_at])
        dominated[grow_at] |= reach >= t_l[grow_at]
        idx = np.sort(lead[~dominated])
        return cls(int(column), int(d_column), t[idx], d[idx], v[idx], float(slack),
                   float(growth), grows[idx], floor)

    def at2(self, theta_h: ArrayLike, theta_d: ArrayLike) -> Array:
        """C at each (theta_h, theta_d)."""
        t, d, ok = _pairs(theta_h, theta_d)
        ths, table = self._table  # type: ignore[attr-defined]
        a = np.minimum(np.searchsorted(ths, np.where(ok, t, 0.0) - self.slack, side="left"),
                       ths.size - 1)
        k = np.clip(np.floor(np.where(ok, d, 0.0) / ENVELOPE_D_STEP), 0,
                    _D_LEVELS).astype(np.intp)
        return np.where(ok, np.maximum(table[k, a], table[_D_LEVELS + 1, a]), -np.inf)

    def at_points(self, x: ArrayLike) -> Array:
        """C at each row of ``x`` (the fit's coordinates)."""
        xa = np.asarray(x, dtype=float)
        return self.at2(xa[:, self.column], xa[:, self.d_column])

    def describe(self) -> str:
        below = (f"over theta_h and theta_d ({self.theta_h.size} samples, growing toward "
                 f"grazing as (1 / cos theta_d)^{self.growth:.3g} at most)")
        return below if self.floor is None else f"{below}, and {self.floor.describe()}"

    def of_pieces(self, space: PolynomialSpace) -> Callable[[Array, Array],
                                                              tuple[Array, NDArray[np.bool_]]]:
        """:func:`~ratfit.core.positivity.prove_below`'s bound on pieces of ``space``'s
        window: C at the piece's largest theta_h and smallest theta_d (C falls with
        theta_h and rises with theta_d), rounded outward, and whether C is that value all
        over the piece."""
        return _corner_bound(space, self.column, self.d_column, self.at2, floor=False)

    def to_dict(self) -> dict[str, object]:
        return {"coordinate": "theta_h, theta_d", "column": self.column,
                "d_column": self.d_column, "theta_h": self.theta_h.tolist(),
                "theta_d": self.theta_d.tolist(), "slack": self.slack,
                "growth": self.growth, "log_ceiling": self.log_ceiling.tolist(),
                "grows": self.grows.tolist(),  # type: ignore[union-attr]
                **({} if self.floor is None else {"floor": self.floor.to_dict()})}

    @classmethod
    def from_dict(cls, entry: object) -> SampleCeiling | None:
        """The sample ceiling a proof entry states, or None (as
        :meth:`StepCeiling.from_dict`)."""
        env = entry.get("envelope") if isinstance(entry, dict) else None
        if not isinstance(env, dict) or "theta_d" not in env:
            return None
        try:
            col, dcol = env["column"], env["d_column"]
            slack, growth = env["slack"], env["growth"]
            if any(isinstance(v, bool) for v in (col, dcol, slack, growth)) or not all(
                    isinstance(v, int) for v in (col, dcol)) or not all(
                    isinstance(v, (int, float)) for v in (slack, growth)):
                return None
            grows = env["grows"]
            if not isinstance(grows, list) or not all(isinstance(g, bool) for g in grows):
                return None
            floor = None
            if "floor" in env:  # stated: it must be read, or nothing is
                floor = SampleFloor.from_dict(env["floor"])
                if floor is None:
                    return None
            return cls(col, dcol, np.asarray(env["theta_h"], dtype=float),
                       np.asarray(env["theta_d"], dtype=float),
                       np.asarray(env["log_ceiling"], dtype=float), float(slack),
                       float(growth), np.asarray(grows, dtype=bool), floor)
        except (KeyError, TypeError, ValueError):
            return None


#: the lowest log value a floor asks for where no sample sets one: exp of it is the
#: smallest normal double, so a proved floor also proves the value never rounds to 0
FLOOR_LOG_MIN = float(np.log(np.finfo(float).tiny))


@dataclass(frozen=True)
class SampleFloor:
    """A floor of a log fit over theta_h and theta_d from its highlight's samples i at
    (theta_h_i, theta_d_i) with log floors v_i: p / q >= F(t, d), with

        F(t, d) = max over i with theta_h_i >= t and theta_d_i <= d of v_i

    (:data:`FLOOR_LOG_MIN` where no sample qualifies). A highlight is no dimmer nearer
    the mirror direction at the same incidence, nor nearer grazing at the same
    theta_h: the mirror of :class:`SampleCeiling`'s rule, with no slack and no growth,
    so it asks less than either rule allows. Between the incidence angles measured along
    the mirror direction, fits under the ceiling alone dipped 100-10^10 x below both
    neighbours (mystique B to 0.009 1/sr at 75 degrees between 11.9 at 69 and 591 at 80;
    a cayman fold to 1.6e-10 at 80 degrees). Each v_i is at most the log of 1 / factor of
    the upper end of every sample in its region, so the samples' own segments are never
    in conflict with it.

    F falls with t and rises with d; its largest value on a box is at the box's
    (smallest t, largest d) corner, which is what the proof takes. It is tabulated like
    :class:`SampleCeiling`, at theta_d steps :data:`ENVELOPE_D_STEP` apart taken at the
    step at or below d (a little under the formula); +inf (no value allowed) at a
    non-finite coordinate."""

    column: int
    d_column: int
    theta_h: Array
    theta_d: Array
    log_floor: Array

    def __post_init__(self) -> None:
        t = np.asarray(self.theta_h, dtype=float)
        d = np.asarray(self.theta_d, dtype=float)
        v = np.asarray(self.log_floor, dtype=float)
        cols = (self.column, self.d_column)
        if (t.ndim != 1 or d.shape != t.shape or v.shape != t.shape
                or not all(np.all(np.isfinite(a)) for a in (t, d, v))
                or any(isinstance(c, bool) or not isinstance(c, (int, np.integer)) or c < 0
                       for c in cols) or self.column == self.d_column):
            raise ValueError("a sample floor needs finite theta_h, theta_d and values of "
                             "one length and two distinct columns >= 0")
        for name, value in (("theta_h", t), ("theta_d", d), ("log_floor", v),
                            ("column", int(self.column)), ("d_column", int(self.d_column))):
            object.__setattr__(self, name, value)
        levels = ENVELOPE_D_STEP * np.arange(_D_LEVELS + 1)
        ths, rank_t = np.unique(t, return_inverse=True)
        table = np.full((_D_LEVELS + 1, max(ths.size, 1)), FLOOR_LOG_MIN)
        if t.size:
            step = np.searchsorted(levels, d, side="left")  # first level at or past d
            inside = step <= _D_LEVELS
            np.maximum.at(table, (step[inside], rank_t[inside]), v[inside])
            # every level at or past a sample's theta_d; every theta_h at or below its own
            table = np.maximum.accumulate(table, axis=0)
            table = np.maximum.accumulate(table[:, ::-1], axis=1)[:, ::-1]
        object.__setattr__(self, "_table", (ths, table))

    @classmethod
    def of_samples(cls, column: int, d_column: int, theta_h: ArrayLike, theta_d: ArrayLike,
                   lo: ArrayLike, hi: ArrayLike, factor: float,
                   highlight: float = HIGHLIGHT_FRACTION) -> SampleFloor:
        """log(``lo`` / ``factor``) at each highlight sample (``hi`` at ``highlight``
        times the largest ``hi`` or above, ``lo`` > 0), lowered to log(``hi`` /
        ``factor``) of every sample in its region; less the samples that never decide F
        (another has theta_h as large or larger, theta_d as small or smaller and a value
        as large or larger)."""
        t = np.asarray(theta_h, dtype=float)
        d = np.asarray(theta_d, dtype=float)
        lo_a = np.asarray(lo, dtype=float)
        hi_a = np.asarray(hi, dtype=float)
        ok = np.isfinite(t) & np.isfinite(d) & np.isfinite(hi_a)
        bright = ok & (hi_a >= highlight * np.max(hi_a[ok], initial=0.0)) & (lo_a > 0)
        cap = np.log(np.maximum(hi_a, np.finfo(float).tiny) / factor)
        # the smallest cap in each sample's region (theta_h as small or smaller, theta_d
        # as large or larger), over the distinct (theta_h, theta_d) points
        t_ok, d_ok = np.where(ok, t, np.inf), np.where(ok, d, np.inf)
        first, group = groups(t_ok, d_ok)
        point_cap = np.full(first.size, np.inf)
        np.minimum.at(point_cap, group[ok], cap[ok])
        point_t, point_d = t_ok[first], d_ok[first]  # in order of theta_h
        upto = np.searchsorted(point_t, point_t, side="right")
        region_cap = -prefix_max(-point_d, -point_cap, upto, -point_d)
        idx = np.flatnonzero(bright)
        v = np.minimum(np.log(lo_a[idx] / factor), region_cap[group[idx]])
        keep = v > FLOOR_LOG_MIN
        idx, v = idx[keep], v[keep]
        # in order of falling value, then theta_h, then rising theta_d: a sample is left
        # out where one before it (of a value as large or larger) has theta_h as large or
        # larger and theta_d as small or smaller
        order = np.lexsort((d[idx], -t[idx], -v))
        lead = first_of_groups(order, t[idx], d[idx])
        reach = prefix_max(d[idx[lead]], t[idx[lead]], np.arange(lead.size), d[idx[lead]])
        sel = np.sort(lead[reach < t[idx[lead]]])
        return cls(int(column), int(d_column), t[idx[sel]], d[idx[sel]], v[sel])

    def at2(self, theta_h: ArrayLike, theta_d: ArrayLike) -> Array:
        """F at each (theta_h, theta_d)."""
        t, d, ok = _pairs(theta_h, theta_d)
        ths, table = self._table  # type: ignore[attr-defined]
        a = np.searchsorted(ths, np.where(ok, t, 0.0), side="left")  # first theta_h >= t
        past = a >= ths.size
        k = np.clip(np.floor(np.where(ok, d, 0.0) / ENVELOPE_D_STEP), 0,
                    _D_LEVELS).astype(np.intp)
        k = np.where(np.where(ok, d, 0.0) < 0.0, -1, k)
        val = np.where(past | (k < 0), FLOOR_LOG_MIN,
                       table[np.maximum(k, 0), np.minimum(a, table.shape[1] - 1)])
        return np.where(ok, val, np.inf)

    def at_points(self, x: ArrayLike) -> Array:
        """F at each row of ``x`` (the fit's coordinates)."""
        xa = np.asarray(x, dtype=float)
        return self.at2(xa[:, self.column], xa[:, self.d_column])

    def describe(self) -> str:
        return (f"above the floor of {self.theta_h.size} highlight samples (no dimmer "
                "nearer the mirror direction or nearer grazing)")

    def of_pieces(self, space: PolynomialSpace) -> Callable[[Array, Array],
                                                              tuple[Array, NDArray[np.bool_]]]:
        """F's largest value on pieces of ``space``'s window (at the piece's smallest
        theta_h and largest theta_d, rounded outward) and whether F is that value all
        over the piece."""
        return _corner_bound(space, self.column, self.d_column, self.at2, floor=True)

    def to_dict(self) -> dict[str, object]:
        return {"column": self.column, "d_column": self.d_column,
                "theta_h": self.theta_h.tolist(), "theta_d": self.theta_d.tolist(),
                "log_floor": self.log_floor.tolist()}

    @classmethod
    def from_dict(cls, entry: object) -> SampleFloor | None:
        """The floor a stored :meth:`to_dict` states, or None."""
        if not isinstance(entry, dict):
            return None
        try:
            col, dcol = entry["column"], entry["d_column"]
            if any(isinstance(v, bool) or not isinstance(v, int) for v in (col, dcol)):
                return None
            return cls(col, dcol, np.asarray(entry["theta_h"], dtype=float),
                       np.asarray(entry["theta_d"], dtype=float),
                       np.asarray(entry["log_floor"], dtype=float))
        except (KeyError, TypeError, ValueError):
            return None


def _pairs(theta_h: ArrayLike, theta_d: ArrayLike) -> tuple[Array, Array, NDArray[np.bool_]]:
    """(theta_h, theta_d) as broadcast 1-D float arrays, and where both are finite: what
    a table over the two looks up (a non-finite pair is the caller's violation)."""
    t = np.atleast_1d(np.asarray(theta_h, dtype=float))
    d = np.atleast_1d(np.asarray(theta_d, dtype=float))
    t, d = np.broadcast_arrays(t, d)
    return t, d, np.isfinite(t) & np.isfinite(d)


def _corner_bound(space: PolynomialSpace, column: int, d_column: int,
                  at2: Callable[[ArrayLike, ArrayLike], Array], *, floor: bool
                  ) -> Callable[[Array, Array], tuple[Array, NDArray[np.bool_]]]:
    """The bound on pieces of ``space``'s window of a step function ``at2(t, d)`` that
    falls with theta_h and rises with theta_d: its value at each piece's (largest t,
    smallest d) corner, its smallest there (a ceiling), or with ``floor`` at the
    (smallest t, largest d) corner, its largest, rounded outward; and whether it is that
    value all over the piece (the opposite corner has it too)."""
    (a, b), (e, f) = ((float(v) for v in space.domain[c]) for c in (column, d_column))
    half_t, half_d = 0.5 * (b - a), 0.5 * (f - e)

    def bound(lo: Array, hi: Array) -> tuple[Array, NDArray[np.bool_]]:
        t_lo = a + (lo[:, column] + 1.0) * half_t
        t_hi = a + (hi[:, column] + 1.0) * half_t
        d_lo = e + (lo[:, d_column] + 1.0) * half_d
        d_hi = e + (hi[:, d_column] + 1.0) * half_d
        pad_t = 1e-12 * (1.0 + np.abs(t_hi))
        pad_d = 1e-12 * (1.0 + np.abs(d_hi))
        low_corner = at2(t_hi + pad_t, d_lo - pad_d)  # the smallest value on the piece
        high_corner = at2(t_lo - pad_t, d_hi + pad_d)  # the largest
        value = high_corner if floor else low_corner
        return value, low_corner == high_corner

    return bound


def grazing(theta_d: ArrayLike) -> Array:
    """-log cos theta_d (0 at or below 0, rising to inf at grazing): a highlight's growth
    toward grazing is linear in it (:class:`SampleCeiling`)."""
    d = np.clip(np.asarray(theta_d, dtype=float), 0.0, 0.5 * np.pi)
    with np.errstate(divide="ignore"):
        return -np.log(np.cos(d))


def theta_d_growth(theta_h: ArrayLike, theta_d: ArrayLike, top: ArrayLike, *,
                   near: float = 0.01, apart: float = 0.1,
                   highlight: float = HIGHLIGHT_FRACTION) -> float:
    """The fastest growth toward grazing the samples' highlight shows: the largest
    (log top_j - log top_i) / (g(theta_d_j) - g(theta_d_i)), g = :func:`grazing`, over
    pairs of samples within ``near`` of each other in theta_h, at least ``apart`` in g,
    and both at least ``highlight`` times their channel's largest ``top``, over every
    channel of ``top`` (N, k): a highlight's growth is its geometry's, and Cornell's is
    nearly white. (Values near the noise floor grow 10x between neighbours by noise.)
    0 without such a pair. The five Cornell files give 2.0 (acryl_blue) to 6.1
    (mystique), each from its mirror samples at 70 and 80 degrees or nearby ones.
    Angles closer than :data:`SAME_ANGLE` are one angle, and the samples at one
    (theta_h, theta_d) one point: a table's cells are, at MERL's size, 8 100 points."""
    t = np.asarray(theta_h, dtype=float)
    d = np.asarray(theta_d, dtype=float)
    top_a = np.asarray(top, dtype=float).reshape(t.size, -1)
    with np.errstate(divide="ignore"):
        v = np.log(top_a)
    bright = top_a >= highlight * top_a.max(axis=0)
    # samples at one (theta_h, theta_d) (a table's phi_d cells, whose angles differ
    # by rounding) are one point of (theta_h, g): a pair's slope over two points is
    # largest from the lower value of the one nearer the normal to the higher of the
    # other
    t, d = _snap(t, SAME_ANGLE), _snap(d, SAME_ANGLE)
    first, group = groups(t, d)
    n_groups = first.size
    high = np.full((n_groups, v.shape[1]), -np.inf)
    low = np.full((n_groups, v.shape[1]), np.inf)
    np.maximum.at(high, group, np.where(bright, v, -np.inf))
    np.minimum.at(low, group, np.where(bright, v, np.inf))
    t, g = t[first], grazing(d[first])
    best = 0.0
    for i in range(n_groups):
        j = np.arange(i + 1, np.searchsorted(t, t[i] + near, side="right"))
        if not j.size:
            continue
        dg = g[j] - g[i]
        far = np.abs(dg) >= apart
        if far.any():
            jf, up = j[far], dg[far, None] > 0
            rise = np.where(up, high[jf] - low[i], high[i] - low[jf]) / np.abs(dg[far, None])
            if np.any(np.isfinite(rise)):
                best = max(best, float(np.max(rise[np.isfinite(rise)])))
    return best


#: angles closer than this (radians) are one angle to :func:`theta_d_growth`: a full MERL
#: table's 1.1e6 cells lie at 8 100 (theta_h, theta_d) points, which the half-vector
#: frame's rounding spreads over 141 755 distinct pairs
SAME_ANGLE = 1e-8


def _snap(x: Array, tol: float) -> Array:
    """Each value as the smallest of its run of sorted values less than ``tol`` apart
    (non-finite values as they are)."""
    u, inv = np.unique(x, return_inverse=True)
    if u.size < 2:
        return x
    start = np.concatenate([[True], ~(np.diff(u) < tol)])
    return u[np.flatnonzero(start)][np.cumsum(start) - 1][inv.ravel()]


#: a log fit's envelope: over theta_h alone, or over theta_h and theta_d
Envelope = StepCeiling | SampleCeiling


def envelope_from_dict(entry: object) -> Envelope | None:
    """The envelope a proof entry states (either kind), or None."""
    return SampleCeiling.from_dict(entry) or StepCeiling.from_dict(entry)


# --------------------------------------------------------------------------- proof
@dataclass(frozen=True)
class ValidityProof:
    """The proof that a BRDF fit has no pole and no negative value where it is evaluated.

    The fit is evaluated at its coordinates clamped to its domain box
    (:meth:`ratfit.brdf.fitter.BRDFFit.eval_coords`), so the region is the box, less the
    pieces that provably hold the clamped coordinates of no pair of directions above the
    horizon (Rusinkiewicz angles; every other parametrization keeps the whole box).
    q > 0 and p >= 0 there are proved by Bernstein bounds with subdivision
    (:func:`ratfit.core.positivity.prove_positive`) on the fit's own coefficients.
    """

    proved: bool
    q: SignProof
    p: SignProof
    region: str
    bad_points: Array  # coordinates to constrain where the proof failed
    # "log": the fit's value is exp(p / q), positive wherever q is; p's sign is not needed
    values: str = "linear"
    # log values: C with C q - p >= 0 proved (``p`` holds that proof), so the value is at
    # most exp(C); None: no upper bound (files written before it)
    ceiling: float | None = None
    # log values: a ceiling that falls with theta_h, proved with C as min(C(theta_h), C)
    envelope: Envelope | None = None
    # log values under an envelope with a floor: p - F q > 0 proved (F: the floor)
    floor: SignProof | None = None

    @property
    def refuted(self) -> bool:
        """q <= 0 or p < 0 was found at a point of the region (not merely unproved)."""
        return self.q.counterexample or self.p.counterexample or (
            self.floor is not None and self.floor.counterexample)

    def summary(self) -> str:
        state = "proved" if self.proved else "NOT PROVED"
        if self.values == "log" and self.ceiling is not None:
            env = "" if self.envelope is None else (
                f", and under the samples' envelope {self.envelope.describe()}")
            floor = "" if self.floor is None else (
                f"; p - F q > 0 (F: the floor) {self.floor.summary()}")
            return (f"{state}: q > 0 {self.q.summary()}; the value exp(p/q) > 0 wherever "
                    f"q > 0, and at most {ceiling_bound(self.ceiling):.6g}{env}: "
                    f"C q - p >= 0 {self.p.summary()}{floor}; region: {self.region}")
        if self.values == "log":
            return (f"{state}: q > 0 {self.q.summary()}; the value exp(p/q) > 0 wherever "
                    f"q > 0; region: {self.region}")
        return (f"{state}: q > 0 {self.q.summary()}; p >= 0 {self.p.summary()}; "
                f"region: {self.region}")

    def to_dict(self) -> dict[str, object]:
        if self.values == "log" and self.ceiling is not None:
            return {"proved": self.proved, "method": self.q.method, "region": self.region,
                    "q_margin": self.q.margin, "p_margin": self.p.margin, "values": "log",
                    "ceiling": self.ceiling,
                    "value_bound": (ceiling_bound(self.ceiling)
                                    if np.isfinite(ceiling_bound(self.ceiling)) else None),
                    **({} if self.envelope is None else
                       {"envelope": self.envelope.to_dict()}),
                    **({} if self.floor is None else {"floor_margin": self.floor.margin}),
                    "boxes": self.q.boxes + self.p.boxes + (
                        0 if self.floor is None else self.floor.boxes)}
        if self.values == "log":
            return {"proved": self.proved, "method": self.q.method, "region": self.region,
                    "q_margin": self.q.margin, "p_margin": None, "values": "log",
                    "boxes": self.q.boxes}
        return {"proved": self.proved, "method": self.q.method, "region": self.region,
                "q_margin": self.q.margin, "p_margin": self.p.margin,
                "boxes": self.q.boxes + self.p.boxes}


def _rusin_excluder(space: PolynomialSpace) -> Callable[[Array, Array], NDArray[np.bool_]]:
    """Pieces (window corners) of a RUSIN_TH_TD_PD box that no clamped valid pair reaches.

    L.z = cos th cos td - sin th sin td cos pd and V.z = cos th cos td + sin th sin td cos pd,
    so a pair is above the horizon iff g = cos th cos td - sin th sin td |cos pd| >= 0; g
    falls with th, td (in [0, pi/2]) and |cos pd|. A piece touching the box's lower th (td)
    face also holds the clipped images of pairs with smaller th (td): there th (td) = 0
    counts (:meth:`ratfit.brdf.fitter.BRDFFit.coords` moves a pair into the box by its
    symmetries, which keep th, td and |cos pd|, then clips). The piece is dropped when
    g < 0 even at its most favourable corner.
    """
    def exclude(lo: Array, hi: Array) -> NDArray[np.bool_]:
        a, b = space.from_window(lo), space.from_window(hi)
        th = np.where(lo[:, 0] <= -1.0, 0.0, a[:, 0])
        td = np.where(lo[:, 1] <= -1.0, 0.0, a[:, 1])
        th, td = np.clip(th, 0.0, _HALF), np.clip(td, 0.0, _HALF)
        # the symmetries that move a pair into the box keep |cos pd|; a piece on a pd face
        # also holds the clipped images of pd beyond it, down to 0 or up to pi
        p0 = np.where(lo[:, 2] <= -1.0, np.minimum(a[:, 2], 0.0), a[:, 2])
        p1 = np.where(hi[:, 2] >= 1.0, np.maximum(b[:, 2], np.pi), b[:, 2])
        # min |cos| over [p0, p1]: 0 where an odd multiple of pi/2 lies inside
        k0 = np.ceil((p0 - _HALF) / np.pi)
        k1 = np.floor((p1 - _HALF) / np.pi)
        crosses = k0 <= k1
        mincos = np.where(crosses, 0.0, np.minimum(np.abs(np.cos(p0)), np.abs(np.cos(p1))))
        g = np.cos(th) * np.cos(td) - np.sin(th) * np.sin(td) * mincos
        return g < -1e-9  # the margin covers the rounding of these few operations

    return exclude


def _half_vector_piece(space: PolynomialSpace, lo: Array, hi: Array
                       ) -> tuple[Array, Array, Array, Array, Array]:
    """Of pieces (window corners ``lo``, ``hi``) of a (theta_h, theta_d, c) box whose third
    coordinate has the natural range [-1, 1]: the smallest and largest theta_h, the
    smallest theta_d, the smallest c and the smallest |c| over the piece and the clipped
    images it holds (a piece on a face reaches to the end of that coordinate's range)."""
    a, b = space.from_window(lo), space.from_window(hi)
    low_face, high_face = lo <= -1.0, hi >= 1.0
    th0 = np.clip(np.where(low_face[:, 0], 0.0, a[:, 0]), 0.0, _HALF)
    th1 = np.clip(np.where(high_face[:, 0], _HALF, b[:, 0]), 0.0, _HALF)
    td0 = np.clip(np.where(low_face[:, 1], 0.0, a[:, 1]), 0.0, _HALF)
    c0 = np.where(low_face[:, 2], -1.0, a[:, 2])
    c1 = np.where(high_face[:, 2], 1.0, b[:, 2])
    min_abs = np.where((c0 <= 0) & (c1 >= 0), 0.0, np.minimum(np.abs(c0), np.abs(c1)))
    return th0, th1, td0, c0, min_abs


def _sym_excluder(space: PolynomialSpace) -> Callable[[Array, Array], NDArray[np.bool_]]:
    """Pieces of a RUSIN_TH_TD_SYM box (theta_h, theta_d, s = sin^2 theta_h cos 2 phi_d)
    that no clipped valid pair reaches: either |s| > sin^2 theta_h everywhere on the piece
    (coordinates of no pair), or the pair is below the horizon everywhere (as for
    :func:`_rusin_excluder`, with |cos phi_d| = sqrt((1 + s / sin^2 theta_h) / 2) at its
    smallest). A piece on a face also holds the clipped images of the pairs beyond it: its
    range extends there to the end of that coordinate's natural range."""

    def exclude(lo: Array, hi: Array) -> NDArray[np.bool_]:
        th0, th1, td0, s0, min_abs_s = _half_vector_piece(space, lo, hi)
        sin0, sin1 = np.sin(th0) ** 2, np.sin(th1) ** 2
        no_pair = min_abs_s > sin1 * (1 + 1e-9) + 1e-15
        with np.errstate(divide="ignore", invalid="ignore"):
            c2 = np.where(s0 >= 0, s0 / np.where(sin1 > 0, sin1, 1.0),
                          np.where(sin0 > 0, s0 / np.where(sin0 > 0, sin0, 1.0), -1.0))
        c2 = np.where((s0 >= 0) & (sin1 <= 0), -1.0, np.clip(c2, -1.0, 1.0))
        mincos = np.sqrt(0.5 * (1.0 + c2))
        g = np.cos(th0) * np.cos(td0) - np.sin(th0) * np.sin(td0) * mincos
        return no_pair | (g < -1e-9)

    return exclude


def _fold_excluder(space: PolynomialSpace) -> Callable[[Array, Array], NDArray[np.bool_]]:
    """Pieces of a RUSIN_TH_TD_FOLD box (theta_h, theta_d, u = sin theta_h cos phi_d) that
    no clipped valid pair reaches: either |u| > sin theta_h everywhere on the piece
    (coordinates of no pair), or the pair is below the horizon everywhere: with
    sin theta_h |cos phi_d| = |u|, g = cos th cos td - sin td |u| >= 0 for valid pairs, and
    g falls with th, td and |u|. A piece on a face also holds the clipped images of the
    pairs beyond it: its range extends there to the end of that coordinate's range."""

    def exclude(lo: Array, hi: Array) -> NDArray[np.bool_]:
        th0, th1, td0, _, min_abs_u = _half_vector_piece(space, lo, hi)
        no_pair = min_abs_u > np.sin(th1) * (1 + 1e-9) + 1e-15
        g = np.cos(th0) * np.cos(td0) - np.sin(td0) * min_abs_u
        return no_pair | (g < -1e-9)

    return exclude


def _stark_excluder(space: PolynomialSpace) -> Callable[[Array, Array], NDArray[np.bool_]]:
    """Pieces of a STARK_2D box (hp, b) that no clipped valid pair reaches: valid pairs
    have hp^2 + b^2 <= 1; a piece on a lower face also holds the images of smaller values
    (0 counts there), while clipping down an upper face keeps a pair inside the disk."""

    def exclude(lo: Array, hi: Array) -> NDArray[np.bool_]:
        a = space.from_window(lo)
        low = np.where(lo <= -1.0, 0.0, np.maximum(a, 0.0))
        return np.sum(low**2, axis=1) > 1.0 + 1e-9

    return exclude


_EXCLUDERS = {"RUSIN_TH_TD_PD": _rusin_excluder, "RUSIN_TH_TD_SYM": _sym_excluder,
              "RUSIN_TH_TD_FOLD": _fold_excluder,
              "STARK_2D": _stark_excluder}


def prove_validity(rf: RationalFunction, param: str, keep: ArrayLike | None = None,
                   max_boxes: int = 40_000, values: str = "linear",
                   ceiling: float | None = None,
                   envelope: Envelope | None = None) -> ValidityProof:
    """Prove q > 0 and p >= 0 of ``rf`` (in its family form) on the evaluated region,
    examining at most ``max_boxes`` pieces for each of q and p. ``values="log"``: the
    fit's value is exp(p / q), positive wherever q > 0; with a ``ceiling`` C, C q - p > 0
    is proved too (the value stays below exp(C)), else q > 0 alone; with an
    ``envelope`` as well, min(C(theta_h), C) q - p > 0 (:func:`prove_below`)."""
    from ratfit.core.positivity import prove_below, prove_positive

    pf: SignProof | None = None  # the floor's proof, where the envelope has a floor
    space = rf.space
    fam = rf.to_family()
    Q = space.tensor_coef(fam.q)
    P = space.tensor_coef(fam.p)
    p = find_parametrization(param)
    whole = keep is None or np.array_equal(np.asarray(keep), np.arange(space.dim))
    # the box is the parametrization's own (no coordinate dropped): its pairs are known
    own_box = whole and p is not None and space.dim == p.dim
    sign = _q_sign(rf, param, Q, own_box)
    exclude = None
    region = "the whole domain box"
    if own_box and p is not None and p.name in _EXCLUDERS:
        exclude = _EXCLUDERS[p.name](space)
        region = "the domain box less pieces no pair of directions reaches"
    fam_name = space.family.name
    qp = prove_positive(sign * Q, fam_name, strict=True, exclude=exclude, max_boxes=max_boxes)
    if values == "log" and ceiling is not None:
        # C q - p in graded coefficients (p and q share the graded order; the shorter is
        # padded), so the proof is about the stored numbers; strict: a margin above the
        # rounding of this one subtraction
        k = max(len(fam.p), len(fam.q))
        qk, pk = np.zeros(k), np.zeros(k)
        qk[:len(fam.q)] = np.asarray(fam.q, dtype=float)
        pk[:len(fam.p)] = np.asarray(fam.p, dtype=float)
        if envelope is None:
            pp = prove_positive(sign * space.tensor_coef(float(ceiling) * qk - pk), fam_name,
                                strict=True, exclude=exclude, max_boxes=max_boxes)
        else:
            # one tensor each: C varies from piece to piece
            of_piece = envelope.of_pieces(space)
            top = float(ceiling)

            def under(lo: Array, hi: Array) -> tuple[Array, NDArray[np.bool_]]:
                c, exact = of_piece(lo, hi)
                return np.minimum(c, top), exact

            pp = prove_below(sign * space.tensor_coef(qk), sign * space.tensor_coef(pk),
                             fam_name, under, exclude=exclude, max_boxes=max_boxes)
            floor = getattr(envelope, "floor", None)
            if floor is not None:
                # p - F q > 0 as prove_below's c q' - p' > 0 with q' = q, p' = -p and c = -F
                # at its largest on the piece
                of_floor = floor.of_pieces(space)

                def over(lo: Array, hi: Array) -> tuple[Array, NDArray[np.bool_]]:
                    f, exact = of_floor(lo, hi)
                    return -np.maximum(f, FLOOR_LOG_MIN), exact

                pf = prove_below(sign * space.tensor_coef(qk), -sign * space.tensor_coef(pk),
                                 fam_name, over, exclude=exclude, max_boxes=max_boxes)
    elif values == "log":
        pp = SignProof(True, np.inf, 1.0, False, np.zeros((0, space.dim)), 0,
                       "not needed: exp(p/q) > 0")
    else:
        pp = prove_positive(sign * P, fam_name, strict=False, exclude=exclude,
                            max_boxes=max_boxes)
    parts = (qp, pp) if pf is None else (qp, pp, pf)
    pts = [space.from_window(s.points) for s in parts if len(s.points)]
    bad = np.concatenate(pts) if pts else np.zeros((0, space.dim))
    top_c = float(ceiling) if values == "log" and ceiling is not None else None
    return ValidityProof(all(s.proved for s in parts), qp, pp, region, bad, values, top_c,
                         None if top_c is None else envelope, pf)


#: Grid points of the box (at most) at which :func:`_q_sign` reads q's sign.
SIGN_POINTS = 4096


def _q_sign(rf: RationalFunction, param: str, Q: Array, on_grid: bool) -> float:
    """The sign q has where the fit is evaluated: the sign of most of its values at the
    valid configurations of a grid of the box (:func:`box_configurations`); without
    them, of q's constant coefficient. The constant coefficient is q's mean over the
    whole box, and a q positive at every pair may be negative on average over the
    pieces no pair reaches: four fits of satin_rosaline G in RUSIN_TH_TD_FOLD had a mean
    of -1.4e9..-2.1e9 (max |coefficient| 7e10-9e10), and the proof of -q > 0 that
    followed was "refuted" at the first box's corners, where q > 0."""
    pts = box_configurations(param, rf.space.domain, SIGN_POINTS) if on_grid else None
    if pts is not None and len(pts):
        with np.errstate(all="ignore"):
            v = rf.denominator(pts)
        pos, neg = int(np.sum(v > 0)), int(np.sum(v < 0))
        if pos or neg:
            return 1.0 if pos >= neg else -1.0
    return 1.0 if Q.flat[0] >= 0 else -1.0


def reprove_saved(saved: object) -> bool | None:
    """Prove a saved n-D BRDF fit valid again from its stored coefficients (every
    channel), or None when it is no such fit. What a fit file says about its proof is
    not taken on trust: anyone can recompute a content digest."""
    extra = getattr(saved, "extra", None)
    meta = extra.get("brdf") if isinstance(extra, dict) else None
    channels = getattr(saved, "channels", ())
    if not isinstance(meta, dict) or not channels or channels[0].rational.space.dim < 2:
        return None
    p = find_parametrization(str(meta.get("parametrization")))
    if p is None:
        return False
    dropped = meta.get("dropped_coords") or {}
    keep = None if not dropped else np.setdiff1d(np.arange(p.dim),
                                                [int(k) for k in dropped])
    values = str(meta.get("values", "linear"))
    proofs = meta.get("proof")
    entries = proofs if isinstance(proofs, list) else []
    stated = [entries[j] if j < len(entries) else None for j in range(len(channels))]
    envelopes = [envelope_from_dict(e) for e in stated]
    if any(isinstance(e, dict) and "envelope" in e and env is None
           for e, env in zip(stated, envelopes, strict=True)):
        return False  # an envelope the file states but no ceiling can be read from
    # an envelope's column is theta_h's among the coordinates the fit keeps
    from ratfit.brdf.fitter import theta_d_column, theta_h_column

    used = None if keep is None else [int(k) for k in keep]
    col = theta_h_column(p.name, used)
    dcol = theta_d_column(p.name, used)
    if any(env is not None and (env.column != col or (
            isinstance(env, SampleCeiling) and env.d_column != dcol)) for env in envelopes):
        return False
    return all(prove_validity(ch.rational, p.name, keep=keep, values=values,
                              ceiling=proof_ceiling(stated[j]), envelope=envelopes[j]).proved
               for j, ch in enumerate(channels))
