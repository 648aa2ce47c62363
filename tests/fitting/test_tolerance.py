"""Best width at a fixed size: verified at the width, certified infeasible just below."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ratfit.cli import main
from ratfit.core.segments import Segments
from ratfit.demos.addendum import addendum_function
from ratfit.errors import InputError
from ratfit.fitting.certificate import certify
from ratfit.fitting.search import RationalFitter
from ratfit.fitting.tolerance import aaa_error, best_width
from ratfit.io.data import read_data


def _check_bracket(res, x, y, n: int, m: int, rtol: float, absolute: bool = False) -> None:
    assert res.success and res.fit.n == n and res.fit.m == m
    v = res.fit.verification
    assert v.verified and v.poles_in_domain == 0
    err = v.linf if absolute else v.max_rel_error
    assert err <= res.width * (1 + 1e-9)
    assert res.lower < res.width <= res.lower * (1 + rtol)
    assert res.lower_certified and res.certificate.residual < 1e-10
    # Independently: slightly below the width no rational of size (n, m) fits.
    make = Segments.from_absolute if absolute else Segments.from_relative
    below = make(x, y, res.lower)
    assert not RationalFitter(n=n, m=m).fit(below).result_.success
    cert = certify(res.fit.rational.space, below, 0, n, m)
    assert cert.checked


@pytest.mark.slow
def test_seed_function_width_and_aaa() -> None:
    x = np.linspace(-3.0, 12.0, 300)
    y = addendum_function(x)
    res = best_width(x, y, 10, 10, rtol=1e-2)
    _check_bracket(res, x, y, 10, 10, 1e-2)
    # Equal real parameters: type (9, 9) has 19, like n = m = 10 (one common scale).
    aaa = aaa_error(x, y, 9)
    assert aaa["real_params"] == 19 == 10 + 10 - 1
    assert res.width < aaa["max_rel_error"]
    summ = res.summary()
    json.dumps(summ, allow_nan=False)
    assert summ["lower_proof"]["checked"] and summ["width_kind"] == "relative"


def test_nist_kirby2_relative_and_absolute(shared_data: Path) -> None:
    data = read_data(shared_data / "nist" / "Kirby2.dat")
    x, y = data.x[:, 0], data.y[:, 0]
    rel = best_width(x, y, 3, 3, rtol=1e-3)
    _check_bracket(rel, x, y, 3, 3, 1e-3)
    ab = best_width(x, y, 3, 3, absolute=True, rtol=1e-2)
    _check_bracket(ab, x, y, 3, 3, 1e-2, absolute=True)
    # Kirby2's model is quadratic/quadratic: its least-squares residual (certified
    # RSS 3.905 over 151 points) bounds the best max-error from below.
    assert ab.width > np.sqrt(3.9050739624 / 151)


def test_bad_input() -> None:
    x = np.linspace(0, 1, 20)
    with pytest.raises(InputError, match="y is 0 at point 0"):
        best_width(x, x, 2, 2)
    with pytest.raises(InputError, match="n must be an integer"):
        best_width(x, x + 1, 0, 2)


def test_cli_tolerance(shared_data: Path, tmp_path: Path) -> None:
    path = str(shared_data / "nist" / "Kirby2.dat")
    r = CliRunner().invoke(main, ["tolerance", path, "--n", "3", "--m", "2", "--json"])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["n"] == 3 and doc["m"] == 2 and doc["verified"] and doc["success"]
    assert doc["max_rel_error"] <= doc["width"] * (1 + 1e-9)
    assert doc["lower_certified"] and doc["lower"] < doc["width"]
    # ``width`` means what ``fit --dt`` means: a fit at that dt is verified again.
    again = CliRunner().invoke(main, ["fit", path, "--dt", repr(doc["width"]), "--n", "3",
                                      "--m", "2", "--json"])
    assert again.exit_code == 0, again.output
    text = CliRunner().invoke(main, ["tolerance", path, "--n", "3", "--m", "2"])
    assert text.exit_code == 0 and "certified infeasible" in text.output
    zero = tmp_path / "zero.csv"
    zero.write_text("x,y\n0,0\n1,1\n2,4\n")
    bad = CliRunner().invoke(main, ["tolerance", str(zero), "--n", "1", "--m", "1"])
    assert bad.exit_code == 2 and "y is 0 at point 0" in bad.output
    assert "Traceback" not in bad.output


def test_cli_tolerance_kirby2_10_10_lower_bound_is_proved(shared_data: Path) -> None:
    """Issue 27: (10, 10) on Kirby2 printed its lower bound "NOT certified". Just below
    the optimum HiGHS's Farkas vector misses a row, so the proof is found lower down:
    the output names the width that is proved, and that proof checks again here."""
    path = shared_data / "nist" / "Kirby2.dat"
    r = CliRunner().invoke(main, ["tolerance", str(path), "--n", "10", "--m", "10", "--json"])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["verified"] and doc["n"] == 10 and doc["m"] == 10
    assert doc["lower"] < doc["width"] <= doc["lower"] * (1 + 1e-3)
    proved = doc["proved_lower"]
    assert proved is not None and 0.5 * doc["width"] < proved <= doc["lower"]
    assert doc["lower_proof"]["checked"] and doc["lower_proof"]["exact"]
    assert "certified infeasible" in doc["lower_statement"]
    data = read_data(path)
    x, y = data.x[:, 0], data.y[:, 0]
    fit = RationalFitter(n=10, m=10).fit(Segments.from_relative(x, y, doc["width"]))
    again = certify(fit.result_.rational.space, Segments.from_relative(x, y, proved), 0, 10, 10)
    assert again.checked and again.exact
    text = CliRunner().invoke(main, ["tolerance", str(path), "--n", "10", "--m", "10"])
    assert text.exit_code == 0, text.output
    assert "NOT certified" not in text.output
    assert f"{proved:.6g} is certified infeasible" in text.output
