"""Sampling with a fitted monotone rational CDF: pdf, inverse CDF, 2-D lobes.

The sampled distribution is the fitted r normalised on its domain [a, b]:
F(x) = (r(x) - r(a)) / (r(b) - r(a)), so r need not hit 0 and 1 exactly at
the ends (its segments only bound it there). Its density is
F'(x) = r'(x) / (r(b) - r(a)), with r' from the quotient rule.

Inverse-CDF sampling solves r(x) = r(a) + u (r(b) - r(a)) for every u at once:
a table of r on a uniform grid gives each u a bracketing cell and a linear
first guess, then safeguarded Newton steps (a step leaving the bracket, or a
non-positive slope, is replaced by bisection) shrink the bracket until the
last step or the bracket is below ``xtol`` in x.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.core.rational import RationalFunction
from ratfit.errors import InputError

__all__ = [
    "CDF2D", "RationalCDF", "beckmann_cos_cdf", "beckmann_cos_pdf", "fit_cdf_2d", "ggx_theta_cdf",
    "ggx_theta_pdf", "ks_statistic",
]

Array = NDArray[np.float64]
_TABLE = 4097  # grid of the bracketing table (2^12 cells)


class RationalCDF:
    """A monotone 1-D rational r viewed as a distribution on its domain.

    Parameters
    ----------
    rational : the fitted r (1-D); must be non-decreasing on its domain.
    check : verify monotonicity on a dense grid first (InputError if not).
    """

    def __init__(self, rational: RationalFunction, *, check: bool = True) -> None:
        space = rational.space
        if space.dim != 1:
            raise InputError("a RationalCDF is 1-D; use CDF2D for two variables")
        self.rational = rational
        self.a, self.b = (float(v) for v in space.domain[0])
        fam = space.family
        self._val = fam.val
        self._p, self._q = rational.p, rational.q
        self._dp = fam.der(rational.p) if rational.n > 1 else np.zeros(1)
        self._dq = fam.der(rational.q) if rational.m > 1 else np.zeros(1)
        self._half = 0.5 * (self.b - self.a)  # dx/dt
        t = np.linspace(-1.0, 1.0, _TABLE)
        r = self._r(t)
        if not np.all(np.isfinite(r)):
            raise InputError("the rational has a pole or a non-finite value on its domain")
        self.r_a, self.r_b = float(r[0]), float(r[-1])
        if not self.r_b > self.r_a:
            raise InputError(
                f"not a CDF: r(b) = {self.r_b!r} is not above r(a) = {self.r_a!r}"
            )
        if check:
            from ratfit.cdf.monotone import MONOTONE_ATOL, rational_derivative

            z = np.linspace(self.a, self.b, 20_001)
            rz, dz = rational_derivative(rational, z)
            if not (np.all(np.isfinite(dz)) and np.diff(rz).min() >= -MONOTONE_ATOL):
                k = int(np.argmin(np.diff(rz)))
                raise InputError(
                    f"not a CDF: r decreases near x = {float(z[k]):.6g} "
                    f"(step {float(np.diff(rz)[k]):.3g})"
                )
        self._t = t
        self._tab = np.maximum.accumulate(r)  # monotone for searchsorted
        _, dr = self._r_dr(t)
        with np.errstate(divide="ignore"):
            self._dtab = np.where(dr > 0, 1.0 / dr, np.inf)  # dt/dr at the table points
        # Rounding of p and q: |p|, |q| <= sum |c_k| on [-1, 1] for these families.
        self._noise = (np.abs(self._p).sum(), np.abs(self._q).sum())

    @classmethod
    def from_file(cls, path: str) -> RationalCDF:
        """Read a fit file written by ``ratfit cdf`` (or ``fit_document`` with a CDF)."""
        from ratfit.io.fitfile import load_fit

        saved = load_fit(path)
        if saved.space.dim != 1 or len(saved.channels) != 1:
            raise InputError(f"{path}: a CDF fit file has one input and one channel")
        if "cdf" not in saved.provenance:
            raise InputError(f"{path}: not a CDF fit file (write one with `ratfit cdf`)")
        return cls(saved.channels[0].rational)

    # -- evaluation in the window variable t ------------------------------------------
    def _r(self, t: Array) -> Array:
        with np.errstate(divide="ignore", invalid="ignore"):
            return self._val(t, self._p) / self._val(t, self._q)

    def _r_dr(self, t: Array) -> tuple[Array, Array]:
        p, q = self._val(t, self._p), self._val(t, self._q)
        dp, dq = self._val(t, self._dp), self._val(t, self._dq)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return p / q, (dp * q - p * dq) / (q * q)

    def _to_t(self, x: ArrayLike) -> Array:
        return (np.asarray(x, dtype=float) - self.a) / self._half - 1.0

    # -- the distribution --------------------------------------------------------------
    def cdf(self, x: ArrayLike) -> Array:
        """F(x): 0 left of the domain, 1 right of it."""
        xa = np.asarray(x, dtype=float)
        t = np.clip(self._to_t(xa), -1.0, 1.0)
        F = (self._r(t) - self.r_a) / (self.r_b - self.r_a)
        return np.clip(F, 0.0, 1.0)

    def pdf(self, x: ArrayLike) -> Array:
        """F'(x) = r'(x) / (r(b) - r(a)) inside the domain, 0 outside."""
        xa = np.asarray(x, dtype=float)
        t = self._to_t(xa)
        inside = (t >= -1.0) & (t <= 1.0)
        _, dr = self._r_dr(np.clip(t, -1.0, 1.0))
        return np.where(inside, dr / (self._half * (self.r_b - self.r_a)), 0.0)

    def ppf(self, u: ArrayLike, *, xtol: float = 1e-12, max_iter: int = 100) -> Array:
        """Inverse CDF: the x with F(x) = u, to within ``xtol`` in x (vectorised)."""
        ua = np.asarray(u, dtype=float)
        if np.any(~((ua >= 0) & (ua <= 1))):
            raise InputError("ppf takes probabilities in [0, 1]")
        y = self.r_a + ua.ravel() * (self.r_b - self.r_a)
        k = np.clip(np.searchsorted(self._tab, y, side="right") - 1, 0, _TABLE - 2)
        t = self._guess(y, k)
        tl, th = self._t[k], self._t[k + 1]
        out = t.copy()
        ttol = xtol / self._half
        eps = 8.0 * np.finfo(float).eps
        act = np.arange(y.size)
        for _ in range(max_iter):
            if act.size == 0:
                break
            p, q = self._val(t, self._p), self._val(t, self._q)
            dp, dq = self._val(t, self._dp), self._val(t, self._dq)
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                r = p / q
                dr = (dp * q - p * dq) / (q * q)
                noise = eps * (self._noise[0] + np.abs(r) * self._noise[1]) / np.abs(q)
            f = r - y
            below = f < 0
            tl = np.where(below, t, tl)
            th = np.where(below, th, t)
            with np.errstate(divide="ignore", invalid="ignore"):
                newton = t - f / dr
            ok = (dr > 0) & np.isfinite(newton) & (newton > tl) & (newton < th)
            nxt = np.where(ok, newton, 0.5 * (tl + th))
            # float64 resolution at t bounds what any method can reach in x; where
            # |r - y| is below the rounding of r itself, t is a root of the computed r.
            tol = np.maximum(ttol, 4.0 * np.spacing(np.abs(nxt) + 1.0))
            done = (np.abs(nxt - t) <= tol) | (th - tl <= tol)
            flat = np.abs(f) <= noise
            out[act] = np.where(flat, t, nxt)
            keep = ~(done | flat)
            act, t, y, tl, th = act[keep], nxt[keep], y[keep], tl[keep], th[keep]
        x = self.a + (np.clip(out, -1.0, 1.0) + 1.0) * self._half
        return x.reshape(ua.shape)

    def _guess(self, y: Array, k: NDArray[np.int64]) -> Array:
        """First t for r(t) = y in table cell k: cubic Hermite interpolation of the
        inverse (slopes dt/dr from the table), linear where that leaves the cell."""
        tl, th = self._t[k], self._t[k + 1]
        rl, rh = self._tab[k], self._tab[k + 1]
        hy = rh - rl
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            s = np.clip(np.where(hy > 0, (y - rl) / hy, 0.5), 0.0, 1.0)
            lin = tl + s * (th - tl)
            s2, s3 = s * s, s * s * s
            herm = ((2 * s3 - 3 * s2 + 1) * tl + (s3 - 2 * s2 + s) * hy * self._dtab[k]
                    + (-2 * s3 + 3 * s2) * th + (s3 - s2) * hy * self._dtab[k + 1])
        good = np.isfinite(herm) & (herm >= tl) & (herm <= th)
        return np.where(good, herm, lin)

    def sample(self, size: int, rng: np.random.Generator | int | None = None) -> Array:
        """``size`` draws by inverse-CDF sampling; ``rng`` a Generator or a seed."""
        if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < 0:
            raise InputError(f"size must be an integer >= 0, got {size!r}")
        gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        return self.ppf(gen.random(int(size)))


# ----------------------------------------------------------------------------- 2-D
@dataclass(frozen=True)
class CDF2D:
    """A 2-D distribution on [a0, b0] x [a1, b1]: marginal of x0, conditionals of x1.

    ``conditionals[k]`` is the CDF of x1 given x0 = ``nodes[k]``. Sampling draws
    x0 from the marginal, picks the conditional of the node to the left or right
    of it with probability given by the linear weight (so the conditional
    density is interpolated linearly between nodes), and draws x1 from it.
    """

    marginal: RationalCDF
    nodes: Array
    conditionals: tuple[RationalCDF, ...]

    def sample(self, size: int, rng: np.random.Generator | int | None = None) -> Array:
        """(size, 2) draws."""
        gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        x0 = self.marginal.sample(size, gen)
        k = np.clip(np.searchsorted(self.nodes, x0, side="right") - 1, 0, self.nodes.size - 2)
        w = (x0 - self.nodes[k]) / (self.nodes[k + 1] - self.nodes[k])
        k = k + (gen.random(x0.size) < w)
        u = gen.random(x0.size)
        x1 = np.empty_like(x0)
        for j in np.unique(k):
            sel = k == j
            x1[sel] = self.conditionals[j].ppf(u[sel])
        return np.stack([x0, x1], axis=1)

    def pdf(self, x0: ArrayLike, x1: ArrayLike) -> Array:
        """Density of the sampled distribution (marginal x interpolated conditional)."""
        a0 = np.asarray(x0, dtype=float)
        a1 = np.asarray(x1, dtype=float)
        k = np.clip(np.searchsorted(self.nodes, a0, side="right") - 1, 0, self.nodes.size - 2)
        w = np.clip((a0 - self.nodes[k]) / (self.nodes[k + 1] - self.nodes[k]), 0.0, 1.0)
        c = np.zeros(np.broadcast(a0, a1).shape)
        kb, wb, x1b = np.broadcast_arrays(k, w, a1)
        for j in np.unique(kb):
            sel = kb == j
            c[sel] = (1 - wb[sel]) * self.conditionals[j].pdf(x1b[sel]) + wb[sel] * (
                self.conditionals[j + 1].pdf(x1b[sel])
            )
        return self.marginal.pdf(a0) * c


def fit_cdf_2d(
    x0: ArrayLike,
    x1: ArrayLike,
    density: ArrayLike,
    *,
    dt: float | None = None,
    abs_width: float | None = None,
    **fitter_params,
) -> tuple[CDF2D, list]:
    """Fit the marginal CDF of x0 and the conditional CDF of x1 at every x0 node.

    ``density`` is (len(x0), len(x1)) on the grid x0 x x1 (any normalisation).
    Returns the sampler and the list of FitResults (marginal first). Raises
    InputError when a fit is not verified: a sampler needs every CDF.
    """
    from scipy.integrate import trapezoid

    from ratfit.cdf.monotone import MonotoneFitter, cdf_from_pdf

    g0 = np.ravel(np.asarray(x0, dtype=float))
    g1 = np.ravel(np.asarray(x1, dtype=float))
    f = np.asarray(density, dtype=float)
    if f.shape != (g0.size, g1.size):
        raise InputError(
            f"density must have shape (len(x0), len(x1)) = ({g0.size}, {g1.size}), "
            f"got {f.shape}"
        )
    if not np.all(np.isfinite(f)):
        raise InputError("density contains non-finite values")
    if (f < 0).any():
        i, j = (int(v) for v in np.argwhere(f < 0)[0])
        raise InputError(f"density is negative ({float(f[i, j])!r}) at row {i}, column {j}")
    if g0.size < 2 or np.any(np.diff(g0) <= 0):
        raise InputError("x0 must be strictly increasing with at least 2 nodes")
    rows = trapezoid(f, g1, axis=1)
    empty = np.flatnonzero(rows <= 0)
    if empty.size:
        raise InputError(
            f"the density is zero along x1 at x0 = {float(g0[empty[0]])!r}: no conditional "
            "distribution there"
        )
    results = []
    models: list[RationalCDF] = []
    for seg in [cdf_from_pdf(g0, rows, dt=dt, abs_width=abs_width)] + [
        cdf_from_pdf(g1, f[i], dt=dt, abs_width=abs_width) for i in range(g0.size)
    ]:
        res = MonotoneFitter(**fitter_params).fit(seg).result_
        results.append(res)
        if not res.success or res.rational is None:
            which = "marginal" if len(results) == 1 else f"conditional {len(results) - 2}"
            raise InputError(f"the {which} CDF has no verified fit: {res.message}")
        models.append(RationalCDF(res.rational))
    return CDF2D(models[0], g0, tuple(models[1:])), results


def ks_statistic(samples: Sequence[float] | Array, cdf) -> float:
    """sup |F_n - F| of samples against a callable CDF (for reports; scipy for tests)."""
    s = np.sort(np.ravel(np.asarray(samples, dtype=float)))
    n = s.size
    F = cdf(s)
    return float(max(np.max(np.arange(1, n + 1) / n - F), np.max(F - np.arange(n) / n)))



# ----------------------------------------------------------------------------- lobes
# Microfacet normal distributions sampled as D(h) cos(theta_h): the densities of
# the variable a renderer draws (cos theta_h for Beckmann, theta_h for GGX).
def beckmann_cos_pdf(mu: ArrayLike, alpha: float) -> Array:
    """Density of mu = cos(theta_h) on [0, 1] for a Beckmann lobe of roughness alpha."""
    m = np.asarray(mu, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        v = 2.0 * np.exp(-(1.0 - m * m) / (alpha * alpha * m * m)) / (alpha * alpha * m**3)
    return np.where(m > 0, v, 0.0)


def beckmann_cos_cdf(mu: ArrayLike, alpha: float) -> Array:
    """P(cos theta_h <= mu) = exp(-tan^2(theta_h) / alpha^2)."""
    m = np.asarray(mu, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        v = np.exp(-(1.0 - m * m) / (alpha * alpha * m * m))
    return np.where(m > 0, np.clip(v, 0.0, 1.0), 0.0)


def ggx_theta_pdf(theta: ArrayLike, alpha: float) -> Array:
    """Density of theta_h on [0, pi/2] for a GGX lobe: heavy tail ~ theta^-3."""
    th = np.asarray(theta, dtype=float)
    s, c = np.sin(th), np.cos(th)
    den = alpha * alpha * c * c + s * s
    return 2.0 * alpha * alpha * s * c / (den * den)


def ggx_theta_cdf(theta: ArrayLike, alpha: float) -> Array:
    """P(theta_h <= theta) = tan^2 / (alpha^2 + tan^2)."""
    th = np.asarray(theta, dtype=float)
    s, c = np.sin(th), np.cos(th)
    return s * s / (alpha * alpha * c * c + s * s)
