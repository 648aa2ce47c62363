"""Importance sampling of a BRDF with rational CDFs fitted by ratfit (numpy, no renderer).

The sampled variable is the half vector h = (wi + wo) / |wi + wo| in the frame
where wi lies in the x-z plane (phi_h measured from wi's azimuth): a glossy lobe
sits near theta_h = 0 whatever the incidence, so one smooth CDF per incidence
captures it. The elevation enters as x = 1 - cos(theta_h), for two reasons:
dh = dx dphi_h (no Jacobian, so no 1/sin(theta_h) spike in the pdf at the
mirror direction), and microfacet lobes have rational CDFs in x (GGX:
F = x (2 - x) / (alpha^2 (1 - x)^2 + x (2 - x)), degree 2/2). Only |phi_h| is
fitted (isotropic BRDFs are symmetric about wi's plane of incidence; other
tables are symmetrised first); its sign is a coin flip.

For incidence theta_i (nodes ``theta_i_nodes_``, linear interpolation between
them) the target density over (x, phi_h) is

    D(x, phi_h) = g(wi, wo(h)) * 4 (wi . h),

g = luminance of f * cos(theta_o) (zero where wo(h) is below the horizon): the
density that makes wo's density proportional to g, since dwo/dh = 4 |wi . h|.
Its marginal over x and its conditionals over |phi_h| at a few x nodes are
tabulated and fitted with :class:`ratfit.cdf.MonotoneFitter` (verified
monotone rational CDFs), then assembled as a :class:`ratfit.cdf.CDF2D` per
incidence node.

Every upper-hemisphere h maps to one wo = 2 (wi . h) h - wi on the whole sphere
(a bijection a.e., Jacobian 4 |wi . h|). A wo below the horizon is mirrored
(z -> -z), so no sample is lost and the density of wo on the upper hemisphere
is the sum over its two preimages: it integrates to exactly 1. A cosine lobe
is mixed in with weight ``cosine_weight`` for robustness where the fitted
lobe is small and the BRDF is not; the pdf returned is the mixture's.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.cdf.monotone import MonotoneFitter, cdf_from_pdf
from ratfit.cdf.sampling import CDF2D, RationalCDF
from ratfit.errors import InputError

__all__ = ["HalfVectorSampler", "cosine_pdf", "cosine_sample", "luminance"]

Array = NDArray[np.float64]
BRDFFunction = Callable[[Array, Array], Array]
_LUMA = np.array([0.2126, 0.7152, 0.0722])


def luminance(rgb: ArrayLike) -> Array:
    """Rec. 709 luminance of (N, 3) values; (N, 1) is taken as grey."""
    v = np.asarray(rgb, dtype=float)
    if v.ndim == 1:
        return v
    if v.shape[1] == 1:
        return v[:, 0]
    return v[:, :3] @ _LUMA


def cosine_sample(u: Array) -> Array:
    """Cosine-weighted directions (N, 3) from uniform (N, 2) (concentric-free polar map)."""
    r = np.sqrt(u[:, 0])
    phi = 2.0 * np.pi * u[:, 1]
    z = np.sqrt(np.maximum(0.0, 1.0 - u[:, 0]))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def cosine_pdf(wo: Array) -> Array:
    return np.where(wo[:, 2] > 0, wo[:, 2] / np.pi, 0.0)


def _rot_z(d: Array, c: Array, s: Array) -> Array:
    return np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)


@dataclass
class _Node:
    """The sampler of one incidence node: marginal of theta_h, conditionals of phi_h."""

    cdf: CDF2D
    n_fits: int
    total_coefficients: int
    fallbacks: int


class _Counter:
    """CDF fits done out of ``total``, each reported to ``progress(done, total)``."""

    def __init__(self, total: int, progress: Callable[[int, int], None] | None) -> None:
        self.done, self.total, self.progress = 0, total, progress

    def step(self) -> None:
        self.done += 1
        if self.progress is not None:
            self.progress(self.done, self.total)


class HalfVectorSampler:
    """Importance sampler of a BRDF ``f(L, V) -> (N, k)`` (L = wo, V = wi; reciprocal).

    Parameters
    ----------
    cosine_weight : probability of drawing from the cosine lobe instead of the fit.
    n_incidence : incidence nodes theta_i in [0, 87] degrees (linear interpolation).
    n_conditional : phi_h conditionals per incidence node (theta_h nodes).
    n_theta, n_phi : tabulation grid of the target density.
    abs_width : CDF segment half-width (widened to 3x, 10x, 30x on a failed fit).
    max_total : largest n + m of one CDF fit.

    Attributes
    ----------
    nodes_ : one CDF2D per incidence node.
    theta_i_nodes_ : the incidence angles of the nodes (radians).
    fits_ : number of verified CDF fits.
    coefficients_ : their total n + m.
    fallbacks_ : CDFs replaced by the uniform one (no verified fit of the tabulated
        density within ``max_total``; sampling stays exact, only less efficient there).
    """

    def __init__(self, *, cosine_weight: float = 0.2, n_incidence: int = 9,
                 n_conditional: int = 12, n_theta: int = 161, n_phi: int = 129,
                 abs_width: float = 3e-3, max_total: int = 24) -> None:
        self.cosine_weight = cosine_weight
        self.n_incidence = n_incidence
        self.n_conditional = n_conditional
        self.n_theta = n_theta
        self.n_phi = n_phi
        self.abs_width = abs_width
        self.max_total = max_total

    # ------------------------------------------------------------------ fitting
    def fit(self, brdf: BRDFFunction,
            progress: Callable[[int, int], None] | None = None) -> HalfVectorSampler:
        """Tabulate the target and fit every CDF; InputError when one has no verified fit.

        ``progress(done, total)`` is called after each CDF fit (a marginal and
        ``n_conditional`` conditionals per incidence node)."""
        if not 0.0 <= self.cosine_weight <= 1.0:
            raise InputError(f"cosine_weight must lie in [0, 1], got {self.cosine_weight!r}")
        if self.n_incidence < 1 or self.n_conditional < 2 or self.n_theta < 8 or self.n_phi < 8:
            raise InputError("sampler grids too small: n_incidence >= 1, n_conditional >= 2, "
                             "n_theta >= 8, n_phi >= 8")
        ti = np.radians(np.linspace(0.0, 87.0, self.n_incidence)) if self.n_incidence > 1 \
            else np.array([np.radians(45.0)])
        # theta_h grid denser near 0 (glossy lobes); conditional nodes are a subset.
        s = np.linspace(0.0, 1.0, self.n_theta)
        xg = s**4  # x = 1 - cos(theta_h), dense near the mirror direction
        th = np.arccos(1.0 - xg)
        kc = np.unique(np.round(np.linspace(0.0, 1.0, self.n_conditional)
                                * (self.n_theta - 1)).astype(int))
        ph = np.linspace(0.0, np.pi, self.n_phi)
        TH, PH = np.meshgrid(th, ph, indexing="ij")
        st = np.sin(TH).ravel()
        h = np.stack([st * np.cos(PH.ravel()), st * np.sin(PH.ravel()), np.cos(TH).ravel()], 1)
        self.nodes_, fits, coef, fallbacks = [], 0, 0, 0
        counter = _Counter(len(ti) * (1 + len(kc)), progress)
        for t in ti:
            wi = np.array([np.sin(t), 0.0, np.cos(t)])
            g = self._tabulate(brdf, wi, h)
            G = g.reshape(TH.shape)  # density per (x, phi_h)
            if not self._isotropic(brdf):
                # |phi_h| is what is fitted: symmetrise (exact for isotropic BRDFs)
                G = 0.5 * (G + self._tabulate(brdf, wi, h * [1.0, -1.0, 1.0]).reshape(TH.shape))
            node = self._fit_node(xg, ph, G, kc, counter)
            self.nodes_.append(node.cdf)
            fits += node.n_fits
            coef += node.total_coefficients
            fallbacks += node.fallbacks
        self.theta_i_nodes_ = ti
        self.fits_, self.coefficients_, self.fallbacks_ = fits, coef, fallbacks
        return self

    @staticmethod
    def _isotropic(brdf: BRDFFunction) -> bool:
        return bool(getattr(brdf, "isotropic", False))

    @staticmethod
    def _tabulate(brdf: BRDFFunction, wi: Array, h: Array) -> Array:
        """g(wi, wo(h)) 4 (wi . h): the target density per steradian of h."""
        d = h @ wi
        wo = 2.0 * d[:, None] * h - wi
        up = (wo[:, 2] > 0) & (d > 0)
        g = np.zeros(len(h))
        if up.any():
            L = wo[up] / np.linalg.norm(wo[up], axis=1)[:, None]
            V = np.broadcast_to(wi, L.shape).copy()
            val = luminance(np.asarray(brdf(L, V), dtype=float))
            val = np.where(np.isfinite(val), np.maximum(val, 0.0), 0.0)
            g[up] = val * L[:, 2] * 4.0 * d[up]
        return g

    def _fit_cdf(self, x: Array, pdf: Array) -> tuple[RationalCDF, int, bool]:
        """A verified rational CDF of the tabulated pdf; widths 1x, 3x, 10x, 30x, then the
        uniform CDF (always verified) when the density is too rough for the sizes tried."""
        for scale in (1.0, 3.0, 10.0, 30.0):
            seg = cdf_from_pdf(x, pdf, abs_width=float(self.abs_width) * scale)
            res = MonotoneFitter(max_total=self.max_total).fit(seg).result_
            if res.success and res.rational is not None:
                return RationalCDF(res.rational), int(res.n + res.m), False
        seg = cdf_from_pdf(x, np.ones_like(x))
        res = MonotoneFitter(max_total=self.max_total).fit(seg).result_
        if not (res.success and res.rational is not None):  # pragma: no cover - r = x
            raise InputError(f"no verified rational CDF even for a uniform density: {res.message}")
        return RationalCDF(res.rational), int(res.n + res.m), True

    def _fit_node(self, xg: Array, ph: Array, G: Array, kc: NDArray[np.int64],
                  counter: _Counter) -> _Node:
        from scipy.integrate import trapezoid

        top = float(G.max())
        if not top > 0:  # the BRDF is zero at this incidence: uniform half vectors
            G = np.ones_like(G)
            top = 1.0
        marg = trapezoid(G, ph, axis=1)
        marg = marg + 1e-3 * float(marg.max())
        marginal, c, fb = self._fit_cdf(xg, marg)
        counter.step()
        total, conds, fallbacks = c, [], int(fb)
        for k in kc:
            row = G[k]
            row = row + 1e-3 * max(float(row.max()), 1e-3 * top)
            cond, c, fb = self._fit_cdf(ph, row)
            counter.step()
            conds.append(cond)
            total += c
            fallbacks += int(fb)
        return _Node(CDF2D(marginal, xg[kc], tuple(conds)), 1 + len(conds), total, fallbacks)

    # ------------------------------------------------------------------ sampling
    def _check(self) -> None:
        if not hasattr(self, "nodes_"):
            raise InputError("the sampler is not fitted: call fit(brdf) first")

    def _incidence(self, wi: Array) -> tuple[NDArray[np.int64], Array]:
        t = np.arccos(np.clip(wi[:, 2], -1.0, 1.0))
        nodes = self.theta_i_nodes_
        if nodes.size == 1:
            return np.zeros(len(wi), dtype=np.int64), np.zeros(len(wi))
        k = np.clip(np.searchsorted(nodes, t, side="right") - 1, 0, nodes.size - 2)
        w = np.clip((t - nodes[k]) / (nodes[k + 1] - nodes[k]), 0.0, 1.0)
        return k, w

    @staticmethod
    def _azimuth(wi: Array) -> tuple[Array, Array]:
        r = np.hypot(wi[:, 0], wi[:, 1])
        safe = r > 1e-12
        c = np.where(safe, wi[:, 0] / np.where(safe, r, 1.0), 1.0)
        s = np.where(safe, wi[:, 1] / np.where(safe, r, 1.0), 0.0)
        return c, s

    def sample(self, wi: ArrayLike, u1: ArrayLike, u2: ArrayLike) -> tuple[Array, Array]:
        """Directions wo (N, 3) and their pdf (N,) for wi (N, 3), uniforms u1 (N,), u2 (N, 2).

        wi below the horizon gives wo = (0, 0, 1) with pdf 0.
        """
        self._check()
        w = np.atleast_2d(np.asarray(wi, dtype=float))
        v1 = np.clip(np.ravel(np.asarray(u1, dtype=float)), 0.0, 1.0 - 1e-12)
        v2 = np.clip(np.atleast_2d(np.asarray(u2, dtype=float)), 0.0, 1.0)
        n = len(w)
        wo = np.zeros((n, 3))
        wo[:, 2] = 1.0
        c = float(self.cosine_weight)
        cos_branch = v1 < c
        if cos_branch.any():
            wo[cos_branch] = cosine_sample(v2[cos_branch])
        fit = ~cos_branch & (w[:, 2] > 0)
        if fit.any():
            u = (v1[fit] - c) / (1.0 - c)
            wo[fit] = self._sample_fit(w[fit], u, v2[fit])
        pdf = self.pdf(w, wo)
        return wo, pdf

    def _sample_fit(self, wi: Array, u: Array, u2: Array) -> Array:
        k, w = self._incidence(wi)
        pick = u < w
        u = np.where(pick, u / np.where(w > 0, w, 1.0), (u - w) / np.where(w < 1, 1.0 - w, 1.0))
        node = k + pick
        xs = np.empty(len(wi))  # x = 1 - cos(theta_h)
        ph = np.empty(len(wi))
        for j in np.unique(node):
            sel = node == j
            cdf = self.nodes_[j]
            t = cdf.marginal.ppf(u2[sel, 0])
            xs[sel] = t
            nd = cdf.nodes
            kk = np.clip(np.searchsorted(nd, t, side="right") - 1, 0, nd.size - 2)
            ww = np.clip((t - nd[kk]) / (nd[kk + 1] - nd[kk]), 0.0, 1.0)
            uu = np.clip(u[sel], 0.0, 1.0 - 1e-12)
            right = uu < ww
            cond = kk + right
            # the rescaled rest of u picks the sign of phi_h (|phi_h| is what is fitted)
            uu = np.where(right, uu / np.where(ww > 0, ww, 1.0),
                          (uu - ww) / np.where(ww < 1, 1.0 - ww, 1.0))
            v = u2[sel, 1]
            out = np.empty(int(sel.sum()))
            for m in np.unique(cond):
                s2 = cond == m
                out[s2] = cdf.conditionals[m].ppf(v[s2])
            ph[sel] = np.where(uu < 0.5, out, -out)
        x = np.clip(xs, 0.0, 1.0)
        st = np.sqrt(np.maximum(x * (2.0 - x), 0.0))
        h = np.stack([st * np.cos(ph), st * np.sin(ph), 1.0 - x], axis=1)
        cs, sn = self._azimuth(wi)
        h = _rot_z(h, cs, sn)
        d = np.einsum("ij,ij->i", h, wi)
        wo = 2.0 * d[:, None] * h - wi
        wo[:, 2] = np.abs(wo[:, 2])  # the mirror fold: no sample is lost
        return wo / np.linalg.norm(wo, axis=1)[:, None]

    def pdf(self, wi: ArrayLike, wo: ArrayLike) -> Array:
        """Solid-angle density (N,) of wo given wi: the cosine/fit mixture, 0 off the hemisphere."""
        self._check()
        wi = np.atleast_2d(np.asarray(wi, dtype=float))
        wo = np.atleast_2d(np.asarray(wo, dtype=float))
        c = float(self.cosine_weight)
        p = c * cosine_pdf(wo)
        ok = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        if c < 1.0 and ok.any():
            p[ok] += (1.0 - c) * self._pdf_fit(wi[ok], wo[ok])
        return np.where(ok, p, 0.0)

    def _pdf_h(self, j: NDArray[np.int64], x: Array, ph: Array) -> Array:
        out = np.zeros(len(j))
        for n in np.unique(j):
            sel = j == n
            out[sel] = self.nodes_[n].pdf(x[sel], ph[sel])
        return out

    def _pdf_fit(self, wi: Array, wo: Array) -> Array:
        k, w = self._incidence(wi)
        cs, sn = self._azimuth(wi)
        total = np.zeros(len(wi))
        for sign in (1.0, -1.0):  # wo itself and its mirror image below the horizon
            woc = wo.copy()
            woc[:, 2] *= sign
            hv = wi + woc
            nrm = np.linalg.norm(hv, axis=1)
            good = nrm > 1e-9
            h = hv / np.where(good, nrm, 1.0)[:, None]
            h = np.where((h[:, 2] < 0)[:, None], -h, h)
            d = np.abs(np.einsum("ij,ij->i", h, wi))
            hl = _rot_z(h, cs, -sn)  # into wi's frame
            x = (hl[:, 0] ** 2 + hl[:, 1] ** 2) / (1.0 + hl[:, 2])  # 1 - cos, accurately
            ph = np.abs(np.arctan2(hl[:, 1], hl[:, 0]))
            dens = (1.0 - w) * self._pdf_h(k, x, ph)
            if self.theta_i_nodes_.size > 1:
                dens += w * self._pdf_h(np.minimum(k + 1, self.theta_i_nodes_.size - 1), x, ph)
            with np.errstate(divide="ignore", invalid="ignore"):
                ph_solid = 0.5 * dens  # per steradian of h (dh = dx dphi); 0.5: the phi sign
                contrib = ph_solid / (4.0 * d)
            total += np.where(good & np.isfinite(contrib), contrib, 0.0)
        return np.maximum(total, 0.0)
