"""Directional albedo of a BRDF by quadrature, and the "reflects more than it receives" check.

a(theta_i) = integral over the hemisphere of f(L, V) cos theta_v dV, with
Gauss-Legendre nodes in mu = cos theta_v and the (spectrally accurate)
midpoint rule in phi_v. A physically plausible BRDF has a <= 1 at every
incidence; a fitted one that exceeds it by more than ``tol`` is flagged.
Functions that return NaN (outside a fit's domain, or where data does not
cover the hemisphere) are integrated over the covered part only, and the
covered fraction is reported: an albedo from a partly covered hemisphere is
a lower bound, not an estimate.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.errors import InputError

__all__ = ["AlbedoResult", "directional_albedo", "hemisphere_quadrature"]

Array = NDArray[np.float64]
BRDFFunction = Callable[[Array, Array], Array]


@dataclass(frozen=True)
class AlbedoResult:
    theta_i: Array  # radians (n,)
    albedo: Array  # (n, k); NaN where coverage < min_coverage
    coverage: Array  # (n,) fraction of the quadrature weight where f is finite
    tol: float

    @property
    def flagged(self) -> NDArray[np.bool_]:
        """(n, k): incidences/channels that reflect more than they receive."""
        with np.errstate(invalid="ignore"):
            return np.nan_to_num(self.albedo, nan=0.0) > 1.0 + self.tol

    @property
    def max_albedo(self) -> float:
        return float(np.nanmax(self.albedo)) if np.any(np.isfinite(self.albedo)) else float("nan")

    @property
    def ok(self) -> bool:
        return not bool(self.flagged.any())

    @property
    def success(self) -> bool:
        """The result vocabulary's name for ``ok`` (albedo <= 1 + tol everywhere)."""
        return self.ok

    @property
    def message(self) -> str:
        if self.ok:
            return f"albedo <= 1 + {self.tol:g} at every incidence (max {self.max_albedo:.4g})"
        return (f"albedo above 1 + {self.tol:g} at {int(self.flagged.sum())} incidence(s) "
                f"(max {self.max_albedo:.4g}): not energy conserving")

    def to_dict(self) -> dict:
        return {
            "theta_i_deg": np.degrees(self.theta_i).round(6).tolist(),
            "albedo": [[None if not np.isfinite(v) else float(v) for v in row]
                       for row in self.albedo],
            "coverage": self.coverage.tolist(),
            "max_albedo": None if not np.isfinite(self.max_albedo) else self.max_albedo,
            "flagged": bool(self.flagged.any()),
        }


def hemisphere_quadrature(n_mu: int = 64, n_phi: int = 128) -> tuple[Array, Array]:
    """Directions V (n_mu * n_phi, 3) and weights w with sum w f(V) mu ~ int f cos dV."""
    if n_mu < 2 or n_phi < 4:
        raise InputError(f"quadrature too coarse: n_mu={n_mu} (>= 2), n_phi={n_phi} (>= 4)")
    x, wx = np.polynomial.legendre.leggauss(n_mu)
    mu = 0.5 * (x + 1.0)
    wmu = 0.5 * wx
    phi = (np.arange(n_phi) + 0.5) * 2.0 * np.pi / n_phi
    M, P = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1.0 - M**2)
    V = np.stack([s * np.cos(P), s * np.sin(P), M], axis=-1).reshape(-1, 3)
    w = (wmu[:, None] * mu[:, None] * np.full(n_phi, 2.0 * np.pi / n_phi)[None, :]).ravel()
    return V, w


def directional_albedo(
    fn: BRDFFunction,
    theta_i: ArrayLike | None = None,
    *,
    n_mu: int = 64,
    n_phi: int = 128,
    tol: float = 1e-3,
    min_coverage: float = 0.9,
) -> AlbedoResult:
    """Albedo (n, k) of ``fn(L, V) -> (N, k)`` at incidences ``theta_i`` (radians).

    Default incidences: 0 to 85 degrees in 5-degree steps.
    """
    th = np.radians(np.arange(0.0, 86.0, 5.0)) if theta_i is None else np.atleast_1d(
        np.asarray(theta_i, dtype=float))
    if np.any(~np.isfinite(th)) or np.any(th < 0) or np.any(th >= np.pi / 2):
        raise InputError("incidence angles must lie in [0, pi/2) radians")
    V, w = hemisphere_quadrature(n_mu, n_phi)
    rows, cover = [], []
    for t in th:
        L = np.broadcast_to([np.sin(t), 0.0, np.cos(t)], V.shape)
        f = np.asarray(fn(np.array(L), V), dtype=float)
        if f.ndim == 1:
            f = f[:, None]
        ok = np.all(np.isfinite(f), axis=1)
        c = float(w[ok].sum() / w.sum())
        a = (np.where(ok[:, None], f, 0.0) * w[:, None]).sum(axis=0)
        rows.append(np.where(c >= min_coverage, a, np.nan))
        cover.append(c)
    return AlbedoResult(th, np.array(rows), np.array(cover), tol)
