"""Monotone CDF fits (seed section 3), sampling, 2-D lobes, and the cdf/sample CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import Result
from conftest import one_error_line, run_cli
from scipy import integrate, optimize, stats

from ratfit import RationalFitter
from ratfit.cdf.monotone import (
    MonotoneFitter,
    MonotoneSystem,
    cdf_from_bounds,
    cdf_from_pdf,
    cdf_from_samples,
    cdf_from_table,
    dkw_epsilon,
    rational_derivative,
    verify_cdf,
)
from ratfit.cdf.sampling import (
    RationalCDF,
    beckmann_cos_cdf,
    beckmann_cos_pdf,
    fit_cdf_2d,
    ggx_theta_cdf,
    ggx_theta_pdf,
)
from ratfit.core.bases import PolynomialSpace
from ratfit.errors import InputError

BECKMANN_ALPHA = 0.3
GGX_ALPHA = 0.1  # small roughness: a sharp peak and a theta^-3 tail


# ------------------------------------------------------------------------------ fixtures
@pytest.fixture(scope="module")
def beckmann() -> RationalCDF:
    mu = np.linspace(0.0, 1.0, 513)
    seg = cdf_from_pdf(mu, beckmann_cos_pdf(mu, BECKMANN_ALPHA), abs_width=5e-4)
    res = MonotoneFitter(grid=200).fit(seg).result_
    assert res.success, res.message
    return RationalCDF(res.rational)


@pytest.fixture(scope="module")
def ggx() -> RationalCDF:
    th = np.linspace(0.0, np.pi / 2, 1000)
    seg = cdf_from_pdf(th, ggx_theta_pdf(th, GGX_ALPHA), abs_width=5e-4)
    res = MonotoneFitter(grid=200).fit(seg).result_
    assert res.success, res.message
    return RationalCDF(res.rational)


def _ecdf_segments(seed: int, n: int = 300, points: int = 48):
    s = np.random.default_rng(seed).gamma(2.0, size=n)
    return cdf_from_samples(s, confidence=0.95, points=points)


# ------------------------------------------------------------------------------ the two forms
def test_forms_define_the_same_set_pointwise() -> None:
    """p' >= max(lo q', hi q') holds exactly where both rows of eq. 3 hold."""
    seg = _ecdf_segments(0)
    space = PolynomialSpace("legendre", seg.bounds())
    system = MonotoneSystem(space, seg, grid=40)
    system.prepare(6, 6)
    rng = np.random.default_rng(1)
    agree = []
    for _ in range(300):
        c = rng.normal(size=12)
        two = system.derivative_margins(6, 6, c, "two-row")
        one = system.derivative_margins(6, 6, c, "max")
        np.testing.assert_array_equal(one, two.min(axis=0))
        agree.append(bool(np.all(two >= 0)) == bool(np.all(one >= 0)))
        # the max form picks, per point, the row of the bound that multiplies q' >= 0
        dq = system.D[:, :6] @ c[6:]
        binding = np.where(dq >= 0, two[1], two[0])
        np.testing.assert_array_equal(one, binding)
    assert all(agree)


@pytest.mark.slow
def test_forms_give_the_same_qp_verdicts_and_solutions() -> None:
    verdicts = []
    for seed in (2, 3):
        seg = _ecdf_segments(seed)
        for n in range(1, 6):
            for m in range(1, 6):
                a = MonotoneFitter(n=n, m=m, grid=30, form="two-row").fit(seg).result_
                b = MonotoneFitter(n=n, m=m, grid=30, form="max").fit(seg).result_
                sa, sb = a.history[-1]["status"], b.history[-1]["status"]
                assert (sa, a.success) == (sb, b.success), (seed, n, m, sa, sb)
                verdicts.append(sa)
                if sa == "feasible":
                    ca = np.r_[a.rational.p, a.rational.q]
                    cb = np.r_[b.rational.p, b.rational.q]
                    np.testing.assert_allclose(cb, ca, rtol=0, atol=1e-8 * np.abs(ca).max())
    # the family covers both verdicts
    assert verdicts.count("feasible") >= 10 and verdicts.count("infeasible") >= 10


# ------------------------------------------------------------------------------ done-means
@pytest.mark.parametrize(
    "lobe, true_cdf",
    [
        ("beckmann", lambda v: beckmann_cos_cdf(v, BECKMANN_ALPHA)),
        ("ggx", lambda v: ggx_theta_cdf(v, GGX_ALPHA)),
    ],
)
def test_samples_pass_ks_against_the_true_cdf(lobe, true_cdf, request) -> None:
    model: RationalCDF = request.getfixturevalue(lobe)
    draws = model.sample(100_000, np.random.default_rng(20240601))
    assert draws.min() >= model.a and draws.max() <= model.b
    res = stats.kstest(draws, true_cdf)
    assert res.pvalue > 0.01, res
    # the fitted CDF itself is close to the truth (the fit's error budget)
    z = np.linspace(model.a, model.b, 10_000)
    assert np.abs(model.cdf(z) - true_cdf(z)).max() < 2e-3


@pytest.mark.parametrize("lobe", ["beckmann", "ggx"])
def test_fit_is_monotone_on_10000_points(lobe, request) -> None:
    model: RationalCDF = request.getfixturevalue(lobe)
    z = np.linspace(model.a, model.b, 10_000)
    r, dr = rational_derivative(model.rational, z)
    assert np.all(np.diff(r) >= -1e-12)
    assert np.all(dr >= -1e-9 * np.abs(dr).max())
    assert r.min() >= -1e-12 and r.max() <= 1 + 1e-12


def test_importance_sampling_beats_uniform(beckmann: RationalCDF) -> None:
    """Integral of a Beckmann lobe times a Fresnel-like factor over cos(theta_h)."""

    def g(mu):
        return beckmann_cos_pdf(mu, BECKMANN_ALPHA) * (0.04 + 0.96 * (1 - mu) ** 5 + mu)

    truth = integrate.quad(g, 0, 1, points=[0.9], limit=200)[0]
    n = 20_000
    rng = np.random.default_rng(7)
    uni = g(rng.random(n))
    xs = beckmann.sample(n, rng)
    imp = g(xs) / beckmann.pdf(xs)
    assert imp.var() < uni.var() / 100
    assert abs(imp.mean() - truth) < 4 * imp.std() / np.sqrt(n) + 1e-3 * truth
    assert abs(uni.mean() - truth) < 5 * uni.std() / np.sqrt(n)


def test_monotone_constraints_are_needed() -> None:
    """Same data, same (n, m): without derivative rows r dips, with them it rises."""
    s = np.random.default_rng(0).exponential(size=200)
    seg = cdf_from_samples(s, confidence=0.9, points=64)
    plain = RationalFitter(n=4, m=4).fit(seg).result_
    assert plain.success  # every segment met ...
    pv = verify_cdf(plain.rational, seg)
    assert pv.segments_ok and not pv.monotone and pv.min_step < -1e-6  # ... but not a CDF
    mono = MonotoneFitter(n=4, m=4, grid=200).fit(seg).result_
    assert mono.success
    assert mono.verification.monotone and mono.verification.min_step >= 0


def test_monotonicity_between_points_is_verified() -> None:
    """With derivative rows at 8 points only, r dips between them: not a success.
    A grid of extra constraint points fixes it."""
    s = np.random.default_rng(0).exponential(size=200)
    seg = cdf_from_samples(s, confidence=0.9, points=8)
    res = MonotoneFitter(n=6, m=6).fit(seg).result_
    assert not res.success and res.verification.segments_ok
    assert not res.verification.monotone and res.verification.min_step < -1e-5
    res = MonotoneFitter(n=6, m=6, grid=200).fit(seg).result_
    assert res.success and res.verification.monotone


# ------------------------------------------------------------------------------ sampling
def test_ppf_converges_to_1e_12(ggx: RationalCDF) -> None:
    u = np.random.default_rng(3).random(300)
    x = ggx.ppf(u)
    ra, rb = ggx.r_a, ggx.r_b
    ref = np.array([
        optimize.brentq(lambda z, y=y: float(ggx.rational(np.array([z]))[0]) - y,
                        ggx.a, ggx.b, xtol=1e-15)
        for y in ra + u * (rb - ra)
    ])
    assert np.abs(x - ref).max() <= 2e-12
    assert ggx.ppf(0.0) == pytest.approx(ggx.a, abs=1e-12)
    assert ggx.ppf(1.0) == pytest.approx(ggx.b, abs=1e-12)
    np.testing.assert_allclose(ggx.cdf(x), u, atol=1e-9)


def test_pdf_is_the_derivative_and_integrates_to_one(beckmann: RationalCDF) -> None:
    z = np.linspace(0.05, 0.95, 200)
    h = 1e-6
    fd = (beckmann.cdf(z + h) - beckmann.cdf(z - h)) / (2 * h)
    np.testing.assert_allclose(beckmann.pdf(z), fd, rtol=1e-5, atol=1e-6)
    total = integrate.quad(beckmann.pdf, 0, 1, points=[0.8, 0.9], limit=200)[0]
    assert total == pytest.approx(1.0, abs=1e-9)
    assert beckmann.pdf(np.array([-0.1, 1.1])).tolist() == [0.0, 0.0]


def test_sampling_is_seedable(ggx: RationalCDF) -> None:
    a = ggx.sample(1000, 5)
    b = ggx.sample(1000, np.random.default_rng(5))
    c = ggx.sample(1000, 6)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_rational_cdf_refuses_a_non_monotone_function() -> None:
    s = np.random.default_rng(0).exponential(size=200)
    seg = cdf_from_samples(s, confidence=0.9, points=64)
    plain = RationalFitter(n=4, m=4).fit(seg).result_
    with pytest.raises(InputError, match="decreases"):
        RationalCDF(plain.rational)


# ------------------------------------------------------------------------------ 2-D
@pytest.mark.slow
def test_2d_marginal_and_conditionals() -> None:
    """f(x0, x1) = (1 + 2 x0) (a + 1) x1^a with a = 1 + 3 x0: the marginal of x0 has
    CDF (x0 + x0^2) / 2 and x1 | x0 has CDF x1^(a + 1)."""
    g0 = np.linspace(0, 1, 9)
    g1 = np.linspace(0, 1, 201)
    a = 1 + 3 * g0[:, None]
    dens = (1 + 2 * g0[:, None]) * (a + 1) * g1[None, :] ** a
    model, results = fit_cdf_2d(g0, g1, dens, abs_width=2e-4, grid=50)
    assert len(results) == 10 and all(r.success for r in results)
    xy = model.sample(60_000, 11)
    assert stats.kstest(xy[:, 0], lambda v: (v + v * v) / 2).pvalue > 0.01
    band = np.abs(xy[:, 0] - 0.5) < 0.01  # near the node x0 = 0.5: a = 2.5
    assert band.sum() > 500
    assert stats.kstest(xy[band, 1], lambda v: v**3.5).pvalue > 0.01
    # density of the sampler integrates to one
    tot = integrate.dblquad(lambda y, x: float(model.pdf(x, y)), 0, 1, 0, 1, epsabs=1e-6)[0]
    assert tot == pytest.approx(1.0, abs=1e-4)


# ------------------------------------------------------------------------------ inputs
def test_pdf_input_is_normalised() -> None:
    x = np.linspace(0, 2, 101)
    seg = cdf_from_pdf(x, 3.0 * x)  # any scale
    F = seg.y[:, 0]
    assert F[0] == 0 and F[-1] == 1
    np.testing.assert_allclose(F, (x / 2) ** 2, atol=1e-12)  # trapezoid is exact here
    np.testing.assert_allclose(seg.hi[:, 0] - seg.lo[:, 0], np.minimum(F + 1e-3, 1)
                               - np.maximum(F - 1e-3, 0), atol=1e-15)


def test_relative_width_is_on_the_tail_probability() -> None:
    x = np.linspace(0, 1, 11)
    F = x.copy()
    seg = cdf_from_table(x, F, dt=0.1, abs_width=1e-6)
    half = 0.5 * (seg.hi[:, 0] - seg.lo[:, 0])
    np.testing.assert_allclose(half[1:-1], 0.1 * np.minimum(F, 1 - F)[1:-1])
    with pytest.raises(InputError, match="zero-width segment at x = 0.0"):
        cdf_from_table(x, F, dt=0.1)


def test_dkw_band() -> None:
    assert dkw_epsilon(1000, 0.05) == pytest.approx(np.sqrt(np.log(40) / 2000))
    s = np.random.default_rng(4).normal(size=2000)
    seg = cdf_from_samples(s, confidence=0.99)
    F = stats.norm.cdf(seg.x[:, 0])
    assert np.all((seg.lo[:, 0] <= F) & (F <= seg.hi[:, 0]))
    half = 0.5 * (seg.hi[:, 0] - seg.lo[:, 0])
    assert half.max() == pytest.approx(dkw_epsilon(2000, 0.01))


@pytest.mark.parametrize(
    "call, pattern",
    [
        (lambda: cdf_from_pdf([0, 1, 2], [1, -0.5, 1]), r"negative value.*-0\.5 at x = 1\.0"),
        (lambda: cdf_from_table([0, 1, 2], [0, 0.6, 0.5]), r"not non-decreasing.*x = 1\.0"),
        (lambda: cdf_from_samples([0.1, np.nan, 0.3]), r"samples contains 1 non-finite.*NaN"),
        (lambda: cdf_from_pdf([1, 1, 1], [1, 1, 1]), r"zero-length domain"),
        (lambda: cdf_from_samples([2.0, 2.0]), r"zero-length"),
        (lambda: cdf_from_pdf([0, 1], [0, 0]), r"integrates to zero"),
        (lambda: cdf_from_table([0, 1], [0, 1.5]), r"outside \[0, 1\]"),
        (lambda: cdf_from_bounds([0, 1, 2], [0, 0.7, 0.5], [0.1, 0.9, 0.6]),
         r"no non-decreasing function.*0\.7 at x = 1.*0\.6 at x = 2"),
    ],
)
def test_bad_input_raises_a_clear_error(call, pattern) -> None:
    with pytest.raises(InputError, match=pattern):
        call()


# ------------------------------------------------------------------------------ CLI
FIT_JSON_KEYS = {"n", "m", "total", "basis", "verified", "max_violation", "linf", "l2",
                 "max_rel_error", "delta", "sigma_min", "sigma_max", "seconds", "channels",
                 "output"}


cli = run_cli


def _assert_bad(result: Result, pattern: str, out: Path) -> None:
    one_error_line(result, pattern)
    assert not out.exists()
    assert not any(p.name.startswith(f".{out.name}") for p in out.parent.iterdir())


@pytest.fixture(scope="module")
def pdf_csv(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("cdfcli")
    mu = np.linspace(0, 1, 200)
    p = d / "pdf.csv"
    np.savetxt(p, np.c_[mu, beckmann_cos_pdf(mu, 0.4)], delimiter=",", header="x,y",
               comments="")
    return p


def test_cli_cdf_then_sample(pdf_csv: Path, tmp_path: Path) -> None:
    out = tmp_path / "cdf.json"
    r = cli("cdf", pdf_csv, "-o", out, "--grid", 100, "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert FIT_JSON_KEYS | {"monotone"} <= set(doc)
    assert doc["verified"] and doc["monotone"]["verified"] and doc["monotone"]["grid"] == 100
    assert doc["monotone"]["check_points"] >= 10_000
    saved = json.loads(out.read_text())
    assert saved["provenance"]["cdf"]["from"] == "pdf"
    a, b = tmp_path / "a.npy", tmp_path / "b.npy"
    assert cli("sample", out, "-n", 5000, "--seed", 3, "-o", a).exit_code == 0
    r = cli("sample", out, "-n", 5000, "--seed", 3, "-o", b, "--json")
    assert r.exit_code == 0 and json.loads(r.stdout)["n"] == 5000
    xa, xb = np.load(a), np.load(b)
    assert xa.shape == (5000,) and np.array_equal(xa, xb)
    assert stats.kstest(xa, lambda v: beckmann_cos_cdf(v, 0.4)).pvalue > 0.01


def test_cli_cdf_from_samples_and_cdf_table(tmp_path: Path) -> None:
    s = tmp_path / "s.npy"
    np.save(s, np.random.default_rng(1).gamma(2.0, size=3000))
    r = cli("cdf", s, "--grid", 100, "--json")
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["monotone"]["verified"]
    t = tmp_path / "cdf.csv"
    x = np.linspace(0, 3, 60)
    np.savetxt(t, np.c_[x, stats.norm.cdf(x, 1.5, 0.5)], delimiter=",")
    r = cli("cdf", t, "--from", "cdf", "--abs-width", 2e-3, "--json")
    assert r.exit_code == 0, r.output


def test_cli_sample_refuses_a_plain_fit_file(tmp_path: Path) -> None:
    from ratfit.core.segments import Segments
    from ratfit.io.fitfile import fit_document, save_fit

    x = np.linspace(0, 1, 30)
    fitter = RationalFitter().fit(Segments.from_relative(x, 1 + x, 0.05))
    fit = tmp_path / "f.json"
    save_fit(fit, fit_document(fitter.results_))
    out = tmp_path / "o.npy"
    _assert_bad(cli("sample", fit, "-n", 10, "-o", out), r"not a CDF fit file", out)


@pytest.mark.parametrize(
    "name, content, args, pattern",
    [
        ("neg.csv", "x,y\n0,1\n0.5,-2\n1,1\n", ("--from", "pdf"), r"negative"),
        ("dec.csv", "x,y\n0,0\n0.5,0.7\n1,0.6\n", ("--from", "cdf"), r"not non-decreasing"),
        ("nan.npy", None, (), r"non-finite.*NaN"),
        ("nan.txt", "0.1\nnan\n0.3\n", ("--from", "samples"), r"non-finite.*NaN"),
        ("flat.csv", "x,y\n1,1\n1,2\n", ("--from", "pdf"), r"zero-length|constant"),
        ("ok.csv", "x,y\n0,1\n1,1\n", ("--domain", 1, 1), r"zero-length"),
    ],
)
def test_cli_bad_input(tmp_path: Path, name, content, args, pattern) -> None:
    src = tmp_path / name
    if content is None:
        np.save(src, np.array([0.1, np.nan, 0.3]))
    else:
        src.write_text(content)
    outdir = tmp_path / "out"
    outdir.mkdir()
    out = outdir / "cdf.json"
    _assert_bad(cli("cdf", src, "-o", out, *args), pattern, out)


@pytest.mark.slow
def test_cli_demo_cdf(tmp_path: Path) -> None:
    r = cli("demo", "cdf", "-o", tmp_path, "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["verified"] and doc["ks_pvalue"] > 0.01
    png = Path(doc["figure"])
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert cli("sample", doc["output"], "-n", 10, "--seed", 0).exit_code == 0
