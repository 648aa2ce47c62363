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

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.brdf.parametrizations import Parametrization, find_parametrization
from ratfit.core.rational import RationalFunction

__all__ = ["ValidityCheck", "angle_grid", "check_validity", "configurations"]

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
                   offset: bool = False, keep: ArrayLike | None = None) -> Array | None:
    """Coordinates of direction pairs above the horizon that fall inside ``domain``.

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
    c = c[_inside(c, dom)]
    return np.clip(c, dom[:, 0], dom[:, 1])


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
        return (f"{state} on {self.checked} direction pairs in the domain ({self.method}); "
                f"min q/max|q| {self.min_q:.3g}, min r/max r {self.min_r:.3g}")


def check_validity(rf: RationalFunction, param: str, domain: ArrayLike | None = None,
                   points: int = 150_000, starts: int = 24,
                   keep: ArrayLike | None = None) -> ValidityCheck | None:
    """Dense, adaptive check that q > 0 and p >= 0 on valid configurations in ``domain``.

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
    q = rf.denominator(c)
    pv = rf.numerator(c)
    sign = 1.0 if np.sum(q > 0) >= np.sum(q < 0) else -1.0
    q, pv = sign * q, sign * pv
    qs = float(np.max(np.abs(q))) or 1.0
    rs = float(np.nanmax(np.abs(pv / np.where(q > 0, q, np.nan)), initial=0.0)) or 1.0
    checked = len(c)
    found = [c[(q <= 0) | (pv < 0)]]
    per = max(3, int(round(points ** (1.0 / k))))
    step = (_bounds(k)[:, 1] - _bounds(k)[:, 0]) / per
    for use_q, vals in ((True, q / qs), (False, pv / (qs * rs))):
        pick = np.argsort(vals)[: min(starts, len(vals))]
        pts, best = _compass(rf, p, dom, a[pick], vals[pick], step, sign, qs,
                             qs * rs, use_q=use_q, cols=cols)
        checked += pts
        found.append(best)
    bad = np.concatenate(found) if found else np.zeros((0, dom.shape[0]))
    qa, pa = q, pv  # the grid's values, plus those of the bad points found
    if len(bad):
        qb, pb = sign * rf.denominator(bad), sign * rf.numerator(bad)
        keep_b = (qb <= 0) | (pb < 0) | ~np.isfinite(qb) | ~np.isfinite(pb)
        bad, qb, pb = bad[keep_b], qb[keep_b], pb[keep_b]
        qa, pa = np.concatenate([q, qb]), np.concatenate([pv, pb])
    with np.errstate(divide="ignore", invalid="ignore"):
        ra = pa / qa
    min_q = float(np.min(qa) / qs)
    min_r = float(np.nanmin(np.where(qa > 0, ra, -np.inf)) / rs)
    valid = len(bad) == 0 and min_q > 0 and min_r >= 0 and bool(np.all(np.isfinite(qa)))
    return ValidityCheck(valid, checked, min_q, min_r, bad,
                         f"offset grid of {len(c)} + compass search from {2 * starts} minima")


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


def _compass(rf: RationalFunction, p: Parametrization, dom: Array, a0: Array, v0: Array,
             step: Array, sign: float, qs: float, ps: float, use_q: bool,
             cols: NDArray[np.int64]) -> tuple[int, Array]:
    """Lower q (or p) from each start by compass moves in angle space; returns
    (evaluations, coordinates of the non-positive values reached)."""
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
        pv = sign * rf.numerator(c)
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
