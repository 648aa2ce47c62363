"""What load_fit proves or checks before a fit file is used, against files re-sealed with
a valid digest (the digest is no signature: anyone can write one for an edit).

* 1-D: no real root of q in the closed domain, in exact arithmetic (a double root, two
  roots between the old 1001 scan points, a root through the Arnoldi recurrence), and q
  not within float rounding of zero (a rounded double root).
* The type of every field ratfit reads back ("cosine_weighted": "no" is not true).
* A subset fit (``brdf fit --max-points``) is never "verified on its data".
"""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from conftest import one_error_line, run_cli

from ratfit.brdf.parametrizations import get_parametrization
from ratfit.core.bases import PolynomialSpace
from ratfit.core.rational import RationalFunction
from ratfit.errors import FileFormatError
from ratfit.io.data import write_alta
from ratfit.io.exact_roots import (
    denominator_has_root,
    exact_monomial,
    has_root_in,
    real_roots_in,
)
from ratfit.io.fitfile import content_digest, load_fit


def reseal(src: Path, dst: Path, edit) -> Path:
    doc = json.loads(src.read_text())
    edit(doc)
    doc["digest"] = content_digest(doc)
    dst.write_text(json.dumps(doc))
    return dst


@pytest.fixture(scope="module")
def fit1d(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("fit1d")
    x = np.linspace(0.0, 2.0, 40)
    csv = d / "data.csv"
    csv.write_text("x,y\n" + "".join(f"{a!r},{1.0 / (1.0 + a * a) + 0.5!r}\n"
                                     for a in x.tolist()))
    fit = d / "fit.json"
    res = run_cli("fit", csv, "--dt", "0.01", "-o", fit)
    assert res.exit_code == 0, res.output
    assert "q_basis" in json.loads(fit.read_text())["channels"][0]  # the Arnoldi default
    return fit, csv


def _legendre_q(q: list[float]):
    """An edit: q in the space's Legendre basis (the recurrence dropped), p = 1."""
    def edit(doc):
        doc["space"]["family"] = "legendre"
        ch = doc["channels"][0]
        for key in ("p_basis", "q_basis", "p_indices", "q_indices", "n", "m"):
            ch.pop(key, None)
        ch["p"], ch["q"] = [1.0], list(q)
        ch["monomial"] = None
    return edit


# 3 (t - c)^2 = 2 P2 - 6c P1 + (1 + 3c^2): exact in floats for a dyadic c
def _double_root(c: float) -> list[float]:
    return [1.0 + 3.0 * c * c, -6.0 * c, 2.0]


@pytest.mark.parametrize("c", [0.25, -0.625, 0.0, 1.0])
def test_double_root_inside_is_a_pole(fit1d, tmp_path: Path, c: float) -> None:
    fit, csv = fit1d
    bad = reseal(fit, tmp_path / "double.json", _legendre_q(_double_root(c)))
    with pytest.raises(FileFormatError, match="pole"):
        load_fit(bad)
    # every command that reads it: one error line, no output
    out = tmp_path / "x.c"
    one_error_line(run_cli("export", bad, "--lang", "c", "-o", out), "pole")
    one_error_line(run_cli("eval", bad, csv), "pole")
    assert not out.exists()


def test_double_root_outside_is_fine(fit1d, tmp_path: Path) -> None:
    fit, _ = fit1d
    ok = reseal(fit, tmp_path / "outside.json", _legendre_q(_double_root(1.5)))
    saved = load_fit(ok)
    assert saved.integrity == "sealed"
    t = 0.5  # x = 1.5 on [0, 2]
    assert saved([1.5])[0, 0] == pytest.approx(1.0 / (1.5 * (t - 1.5) ** 2 * 2.0), rel=1e-12)


def test_rounded_double_root_is_a_pole_in_floats(fit1d, tmp_path: Path) -> None:
    # (t - 0.3)^2 with rounded coefficients: its exact roots are a complex pair ~1e-9
    # off the axis; r reaches ~1e16 times its size there, and q's float value is noise
    fit, _ = fit1d
    q = [0.3 * 0.3 + 1.0 / 3.0, -0.6, 2.0 / 3.0]
    bad = reseal(fit, tmp_path / "rounded.json", _legendre_q(q))
    with pytest.raises(FileFormatError, match="pole"):
        load_fit(bad)


def test_two_roots_between_the_old_scan_points(fit1d, tmp_path: Path) -> None:
    # roots at t = 0.2501 and 0.2509: both between two of 1001 points 0.002 apart, so
    # q has the same sign at every point of the old scan
    fit, _ = fit1d
    a, b = 0.2501, 0.2509
    grid = np.linspace(-1, 1, 1001)
    assert np.all((grid - a) * (grid - b) > 0)
    # (t - a)(t - b) = t^2 - (a + b) t + ab = 2/3 P2 - (a + b) P1 + (ab + 1/3)
    bad = reseal(fit, tmp_path / "two.json", _legendre_q([a * b + 1.0 / 3.0, -(a + b),
                                                          2.0 / 3.0]))
    with pytest.raises(FileFormatError, match="pole"):
        load_fit(bad)


def test_root_through_the_arnoldi_recurrence(fit1d, tmp_path: Path) -> None:
    """q written in the fit's own data-orthonormal basis: a double root at t = 0.5."""
    fit, _ = fit1d
    saved = load_fit(fit)
    rf = saved.channels[0].rational
    qb = rf.q_basis
    assert qb is not None and qb.size >= 3
    # coefficients of (t - 0.5)^2 in the recurrence's first three functions
    t = np.linspace(-1, 1, 7)
    phi = qb.design(t[:, None], 3, window=True)
    coef, *_ = np.linalg.lstsq(phi, (t - 0.5) ** 2, rcond=None)

    def edit(doc):
        ch = doc["channels"][0]
        ch["q"] = coef.tolist() + [0.0] * (len(ch["q"]) - 3)

    bad = reseal(fit, tmp_path / "arnoldi.json", edit)
    with pytest.raises(FileFormatError, match="pole"):
        load_fit(bad)


def test_exact_counts_on_known_polynomials() -> None:
    one, half = Fraction(1), Fraction(1, 2)
    # (t - 1/2)^2 (t + 3) (t^2 + 1): one distinct root inside, one outside, two complex
    p = [1]
    for f in ([-half, 1], [-half, 1], [3, 1], [1, 0, 1]):
        p = [sum(p[i] * f[k - i] for i in range(len(p)) if 0 <= k - i < len(f))
             for k in range(len(p) + len(f) - 1)]
    ints = [int(v * 4) for v in p]
    assert real_roots_in(ints, -one, one) == 1
    assert real_roots_in(ints, Fraction(-4), one) == 2
    assert has_root_in(ints, -one, one) is True
    assert has_root_in(ints, Fraction(6, 10), one) is False
    assert has_root_in([1, 0, 1], -one, one) is False  # t^2 + 1
    assert has_root_in([-1, 0, 1], -one, one) is True  # roots at the ends
    # the conversion is exact: Legendre P_3 = (5t^3 - 3t) / 2
    rf = RationalFunction(PolynomialSpace("legendre", np.array([[0.0, 1.0]])), np.array([1.0]),
                          np.array([0.0, 0.0, 0.0, 1.0]))
    assert exact_monomial(rf) == [0, -3, 0, 5] and denominator_has_root(rf) is True


def test_legit_fits_still_load_fast(fit1d) -> None:
    import time

    fit, _ = fit1d
    t0 = time.perf_counter()
    for _ in range(5):
        assert load_fit(fit).verified
    assert time.perf_counter() - t0 < 5.0  # loose: a guard against a pathological loader


# ---------------------------------------------------------------------------- types
@pytest.fixture(scope="module")
def brdf_fits(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """A small synthetic BRDF fit on all 600 samples, and one on a subset of 200."""
    d = tmp_path_factory.mktemp("brdf")
    rng = np.random.default_rng(5)
    par = get_parametrization("ISOTROPIC_TV_TL_DPHI")
    n = 600
    c = np.column_stack([rng.uniform(0.05, 1.3, n), rng.uniform(0.05, 1.3, n),
                         rng.uniform(-np.pi, np.pi, n)])
    L, V = par.to_dirs(c)
    h = L + V
    cos_h = h[:, 2] / np.linalg.norm(h, axis=1)
    a2 = 0.35**2
    lobe = a2 / (np.pi * ((a2 - 1.0) * cos_h * cos_h + 1.0) ** 2)
    data = d / "synth.alta"
    write_alta(data, c, (0.05 + 0.12 * lobe)[:, None], param_in="ISOTROPIC_TV_TL_DPHI",
               param_out="INV_STERADIAN")
    opts = ["--param", "COS_TH_TD_PD", "--dt", "0.1", "--abs-width", "1e-4", "--max-total",
            "30"]
    full, sub = d / "full.json", d / "subset.json"
    for out, extra in ((full, []), (sub, ["--max-points", "200"])):
        res = run_cli("brdf", "fit", data, *opts, *extra, "-o", out)
        assert res.exit_code == 0, res.output
    return full, sub, data


def _brdf(key: str, value):
    def edit(doc):
        doc["brdf"][key] = value
    return edit


BAD_FIELDS = {
    "cosine-no": (_brdf("cosine_weighted", "no"), "cosine_weighted"),
    "cosine-1": (_brdf("cosine_weighted", 1), "cosine_weighted"),
    "fold-null": (_brdf("fold_phi_d", None), "fold_phi_d"),
    "dropped-number": (_brdf("dropped_coords", 5), "dropped_coords"),
    "dropped-list": (_brdf("dropped_coords", [1]), "dropped_coords"),
    "dropped-string": (_brdf("dropped_coords", "12"), "dropped_coords"),
    "dropped-negative": (_brdf("dropped_coords", {"-1": 0.5}), "dropped_coords"),
    "dropped-value-string": (_brdf("dropped_coords", {"0": "x"}), "dropped_coords"),
    "dropped-out-of-range": (_brdf("dropped_coords", {"7": 0.5}), "dropped_coords"),
    "dropped-twice": (_brdf("dropped_coords", {"1": 0.5, "01": 0.5}), "dropped_coords"),
    "param-number": (_brdf("parametrization", 3), "parametrization"),
    "clamp-string": (_brdf("clamp", "0"), "clamp"),
    "segments-string-dt": (_brdf("segments", {"dt": "0.1"}), "segments"),
    "channel-names-number": (_brdf("channel_names", 3), "channel_names"),
    "subset-bogus": (_brdf("subset", {"points": 900, "of": 600}), "subset"),
    "subset-by-bogus": (_brdf("subset", {"points": 200, "of": 600, "by": "cells"}), "subset"),
    "verified-string": (lambda d: d["channels"][0]["diagnostics"].update(verified="yes"),
                        "verified"),
    "provenance-segments": (lambda d: d["provenance"].update(segments={"dt": [1]}),
                            "segments"),
}


@pytest.mark.parametrize("key", list(BAD_FIELDS))
def test_wrong_field_types_are_one_error_line(brdf_fits, tmp_path: Path, key: str) -> None:
    full, _, data = brdf_fits
    edit, field = BAD_FIELDS[key]
    bad = reseal(full, tmp_path / "bad.json", edit)
    out = tmp_path / "out.c"
    line = one_error_line(run_cli("export", bad, "--lang", "c", "-o", out), field)
    assert "internal error" not in line
    one_error_line(run_cli("brdf", "eval", bad, "--data", data), field)
    one_error_line(run_cli("report", bad, "-o", tmp_path / "r"), field)
    assert not out.exists() and not (tmp_path / "r").exists()


def test_subset_fit_says_subset_never_verified_on_its_data(brdf_fits, tmp_path: Path) -> None:
    full, sub, data = brdf_fits
    for path, want in ((full, None), (sub, "subset of 200 of 600 samples")):
        out = tmp_path / f"{path.stem}.py"
        res = run_cli("export", path, "--lang", "python", "-o", out)
        assert res.exit_code == 0, res.output
        head = "\n".join(out.read_text().splitlines()[:4])
        assert "verified on its data" not in head
        if want:
            assert want in head and "not checked at the other 400 samples" in head
        else:
            assert "subset" not in head and "Verified at every sample" in head
        rep = tmp_path / f"report-{path.stem}"
        res = run_cli("report", path, "--data", data, "-o", rep)
        assert res.exit_code == 0, res.output
        page = (rep / "index.html").read_text()
        if want:
            assert "<td>on a subset of 200 of 600 samples</td>" in page and want in page
            assert "<td>yes</td>" not in page
        else:
            assert "<td>yes</td>" in page and "subset" not in page


@pytest.mark.parametrize("by", ["samples", "pairs", "energy"])
def test_each_subset_rule_is_a_fit_file_field(brdf_fits, tmp_path: Path, by: str) -> None:
    from ratfit.io.fitfile import load_fit, subset_of

    _, sub, _ = brdf_fits
    f = reseal(sub, tmp_path / f"{by}.json", lambda d: d["brdf"]["subset"].update(by=by))
    saved = load_fit(f)
    assert saved.extra["brdf"]["subset"]["by"] == by and subset_of(saved) == (200, 600)


@pytest.mark.parametrize(("proof", "said"), [
    ([{"proved": True}], "q > 0 and p >= 0 proved where it is evaluated"),
    ([{"proved": False}], "checked on a dense grid, not proved"),
    ([None], "checked on a dense grid, not proved"),
])
def test_n_d_exports_claim_a_proof_only_where_the_file_records_one(
        brdf_fits, tmp_path: Path, proof, said: str) -> None:
    full, _, _ = brdf_fits
    f = reseal(full, tmp_path / "p.json", _brdf("proof", proof))
    out = tmp_path / "x.py"
    res = run_cli("export", f, "--lang", "python", "-o", out)
    assert res.exit_code == 0, res.output
    head = "\n".join(out.read_text().splitlines()[:4])
    assert said in head


def test_proof_of_the_wrong_type_is_refused(brdf_fits, tmp_path: Path) -> None:
    full, _, _ = brdf_fits
    for proof in ("proved", [True], [{"proved": "yes"}]):
        f = reseal(full, tmp_path / "p.json", _brdf("proof", proof))
        one_error_line(run_cli("export", f, "--lang", "c", "-o", tmp_path / "x.c"), "proof")
