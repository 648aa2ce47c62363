"""The rational-CDF importance sampler: samples follow its pdf, the pdf is normalised.

Chi-square test as renderers test their BSDFs: directions binned on the
hemisphere (cos theta x phi), expected counts from the pdf integrated over each
bin by a fine midpoint rule, bins with fewer than 5 expected merged away.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from ratfit.brdf.albedo import hemisphere_quadrature
from ratfit.errors import InputError
from ratfit.render import AnalyticMaterial, HalfVectorSampler, cosine_pdf

SMALL = {"n_incidence": 3, "n_conditional": 5, "n_theta": 61, "n_phi": 33}


@pytest.fixture(scope="module")
def ggx_sampler() -> HalfVectorSampler:
    mat = AnalyticMaterial("lambert+ggx", [0.1, 1.0, 0.15, 0.04])
    return HalfVectorSampler(**SMALL).fit(mat)


def _wi(theta: float, phi: float = 0.4) -> np.ndarray:
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def chi_square(sampler, wi: np.ndarray, n: int = 100_000, nt: int = 10, nph: int = 20,
               seed: int = 0, rtol: float = 1e-10, share: float = 1.0,
               fine: int = 24) -> tuple[float, int]:
    """(p-value, bins used) of sampled directions against the sampler's pdf; the pdf
    returned with each sample must equal pdf(wo) to ``rtol`` for a ``share`` of them."""
    rng = np.random.default_rng(seed)
    W = np.broadcast_to(wi, (n, 3))
    wo, pdf = sampler.sample(W, rng.random(n), rng.random((n, 2)))
    rel = np.abs(sampler.pdf(W, wo) - pdf) / np.maximum(pdf, 1e-300)
    assert np.quantile(rel, share) <= rtol, np.quantile(rel, share)
    phi = np.mod(np.arctan2(wo[:, 1], wo[:, 0]), 2 * np.pi)
    obs, _, _ = np.histogram2d(wo[:, 2], phi, bins=[nt, nph], range=[[0, 1], [0, 2 * np.pi]])
    # midpoint rule on fine x fine cells per bin: peaky pdfs (a specular lobe, or the
    # 1 / |wi . h| of the folded half of the map at the mirror direction) need it fine
    cz = (np.arange(nt * fine) + 0.5) / (nt * fine)
    pz = (np.arange(nph * fine) + 0.5) / (nph * fine) * 2 * np.pi
    CZ, PZ = np.meshgrid(cz, pz, indexing="ij")
    sz = np.sqrt(1 - CZ**2)
    D = np.stack([sz * np.cos(PZ), sz * np.sin(PZ), CZ], -1).reshape(-1, 3)
    cell = (1 / (nt * fine)) * (2 * np.pi / (nph * fine))  # d(cos theta) d(phi) = d omega
    pp = sampler.pdf(np.broadcast_to(wi, D.shape), D).reshape(CZ.shape) * cell
    exp = pp.reshape(nt, fine, nph, fine).sum(axis=(1, 3)) * n
    keep = exp >= 5
    o, e = obs[keep], exp[keep]
    # the rest (tiny bins) pooled into one cell
    o = np.append(o, obs[~keep].sum())
    e = np.append(e, max(exp[~keep].sum(), 1e-300))
    stat = float(((o - e) ** 2 / e).sum())
    return float(chi2.sf(stat, o.size - 1)), int(o.size)


@pytest.mark.parametrize("theta", [0.15, 0.8, 1.35])
@pytest.mark.slow
def test_samples_follow_the_pdf_chi_square(ggx_sampler, theta: float) -> None:
    p, bins = chi_square(ggx_sampler, _wi(theta))
    assert bins > 60
    assert p > 1e-3, f"chi-square p-value {p:.3g} at theta_i = {theta}"


@pytest.mark.slow
def test_a_wrong_pdf_fails_the_chi_square(ggx_sampler) -> None:
    """The test has power: a pdf off by a cosine lobe is rejected."""

    class Wrong:
        def sample(self, wi, u1, u2):
            return ggx_sampler.sample(wi, u1, u2)

        def pdf(self, wi, wo):
            return 0.7 * ggx_sampler.pdf(wi, wo) + 0.3 * cosine_pdf(wo)

    with pytest.raises(AssertionError):
        chi_square(Wrong(), _wi(0.8))  # its own consistency assertion already fails
    rng = np.random.default_rng(1)
    n = 100_000
    W = np.broadcast_to(_wi(0.8), (n, 3))
    wo, _ = ggx_sampler.sample(W, rng.random(n), rng.random((n, 2)))
    bad = Wrong()
    bad.sample = lambda wi, u1, u2: (wo, bad.pdf(wi, wo))
    p, _ = chi_square(bad, _wi(0.8))
    assert p < 1e-6


@pytest.mark.parametrize("theta", [0.0, 0.5, 1.0, 1.25])
def test_pdf_integrates_to_one(ggx_sampler, theta: float) -> None:
    V, w = hemisphere_quadrature(160, 320)  # w includes cos theta: divide it out
    p = ggx_sampler.pdf(np.broadcast_to(_wi(theta), V.shape), V)
    assert np.all(p >= 0) and np.all(np.isfinite(p))
    # grazing incidence makes the pdf peaky in wo: Gauss-Legendre needs a finer grid there
    assert (p * w / V[:, 2]).sum() == pytest.approx(1.0, abs=3e-3)


def test_pdf_tracks_the_brdf(ggx_sampler) -> None:
    """Importance, not just consistency: pdf / (f cos) stays within a small factor where
    f cos matters, and the mirror direction is much likelier than a side direction."""
    mat = AnalyticMaterial("lambert+ggx", [0.1, 1.0, 0.15, 0.04])
    wi = _wi(0.6)
    mirror = np.array([-wi[0], -wi[1], wi[2]])
    side = _wi(1.2, 0.4 + np.pi / 2)
    p = ggx_sampler.pdf(np.array([wi, wi]), np.array([mirror, side]))
    assert p[0] > 8 * p[1] and p[0] > 3 * cosine_pdf(mirror[None])[0]
    V, _ = hemisphere_quadrature(64, 128)
    W = np.broadcast_to(wi, V.shape)
    g = mat(V, W)[:, 0] * V[:, 2]
    ratio = ggx_sampler.pdf(W, V) / (g / (g.mean() * 2 * np.pi))  # both densities
    big = g > 0.1 * g.max()
    assert np.all((ratio[big] > 0.33) & (ratio[big] < 3.0)), ratio[big].min()


@pytest.mark.slow
def test_cosine_weight_one_is_cosine_sampling() -> None:
    s = HalfVectorSampler(cosine_weight=1.0, **SMALL).fit(AnalyticMaterial("lambert", [0.5]))
    rng = np.random.default_rng(0)
    wi = np.broadcast_to(_wi(0.3), (1000, 3))
    wo, pdf = s.sample(wi, rng.random(1000), rng.random((1000, 2)))
    assert np.allclose(pdf, wo[:, 2] / np.pi)


def test_below_horizon_and_bad_parameters() -> None:
    s = HalfVectorSampler(**SMALL).fit(AnalyticMaterial("lambert", [0.5]))
    wo, pdf = s.sample(np.array([[0.0, 0.6, -0.8]]), [0.9], [[0.3, 0.3]])
    assert pdf[0] == 0.0
    assert s.pdf(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.6, -0.8]]))[0] == 0.0
    with pytest.raises(InputError, match="cosine_weight"):
        HalfVectorSampler(cosine_weight=1.5).fit(AnalyticMaterial("lambert", [0.5]))
    with pytest.raises(InputError, match="not fitted"):
        HalfVectorSampler().pdf([[0, 0, 1.0]], [[0, 0, 1.0]])
