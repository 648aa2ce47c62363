"""Sound answers: fits that exist are found, impossibility is claimed only when proved.

Every case is checked in the test itself against exact rational arithmetic on the
data as stored (floats are exact rationals), independently of ratfit's own code.
"""

from __future__ import annotations

import re
from fractions import Fraction

import numpy as np
import pytest

from ratfit.core.segments import Segments
from ratfit.fitting.certificate import certify
from ratfit.fitting.search import RationalFitter


def _inside_exactly(x, lo, hi, r) -> bool:
    """lo_i < r(x_i) < hi_i for every i, in exact arithmetic (r maps Fraction -> Fraction)."""
    return all(Fraction(float(a)) < r(Fraction(float(t))) < Fraction(float(b))
               for t, a, b in zip(x, lo, hi, strict=True))


def _exact_null_nonneg(rows: list[list[Fraction]]) -> bool:
    """Is there z >= 0, z != 0 with sum_j z_j rows_j = 0 (Gauss-Jordan over Q)?"""
    M = [list(col) for col in zip(*rows, strict=True)]  # k x s
    s = len(rows)
    piv_cols: list[int] = []
    r = 0
    for c in range(s):
        p = next((i for i in range(r, len(M)) if M[i][c] != 0), None)
        if p is None:
            continue
        M[r], M[p] = M[p], M[r]
        M[r] = [v / M[r][c] for v in M[r]]
        for i in range(len(M)):
            if i != r and M[i][c] != 0:
                f = M[i][c]
                M[i] = [a - f * b for a, b in zip(M[i], M[r], strict=True)]
        piv_cols.append(c)
        r += 1
    free = [c for c in range(s) if c not in piv_cols]
    if len(free) != 1:  # a one-dimensional null space is what a Farkas support has
        return False
    z = [Fraction(0)] * s
    z[free[0]] = Fraction(1)
    for i, pc in enumerate(piv_cols):
        z[pc] = -M[i][free[0]]
    return all(v >= 0 for v in z) or all(v <= 0 for v in z)


def _exact_rows(seg: Segments, cert: dict | object, n: int, m: int) -> list[list[Fraction]]:
    pts = cert.points if hasattr(cert, "points") else cert["points"]
    sides = cert.sides if hasattr(cert, "sides") else cert["sides"]
    rows = []
    for i, side in zip(pts, sides, strict=True):
        side = side if isinstance(side, int) else int(side == "hi")
        xi = Fraction(float(seg.x[i, 0]))
        b = Fraction(float((seg.hi if side else seg.lo)[i, 0]))
        mp = [xi**k for k in range(n)]
        mq = [xi**k for k in range(m)]
        sg = -1 if side else 1
        rows.append([sg * v for v in mp] + [-sg * b * v for v in mq])
    return rows


def _rat33(t: Fraction) -> Fraction:
    return (t + 1) * (t + 2) / ((t + 3) * (t + 4))


@pytest.fixture(scope="module", params=[1e-10, 1e-12])
def exact33(request) -> Segments:
    """(x+1)(x+2)/((x+3)(x+4)) on 500 points of [-1, 1]: y = 0 at the sample x = -1."""
    x = np.linspace(-1.0, 1.0, 500)
    y = (x + 1) * (x + 2) / ((x + 3) * (x + 4))
    return Segments.from_absolute(x, y, request.param * np.abs(y).max())


def test_exact_rational_with_tiny_width_is_found(exact33: Segments) -> None:
    seg = exact33
    assert seg.y[0, 0] == 0.0
    # (3, 3) fits: the rational itself lies strictly inside every segment, exactly.
    assert _inside_exactly(seg.x[:, 0], seg.lo[:, 0], seg.hi[:, 0], _rat33)
    fixed = RationalFitter(n=3, m=3).fit(seg).result_
    assert fixed.success and fixed.infeasible_proof is None
    res = RationalFitter().fit(seg).result_
    assert res.success and res.n + res.m == 6
    assert res.verification.max_violation == 0.0


@pytest.mark.parametrize("cross_check", ["lp", "none"])
def test_other_cross_checks_keep_the_tiny_width_fit(exact33: Segments, cross_check) -> None:
    res = RationalFitter(cross_check=cross_check).fit(exact33).result_
    assert res.success and res.n + res.m == 6


def test_no_certificate_claims_a_feasible_size(exact33: Segments) -> None:
    space = RationalFitter().prepare(exact33)
    for form in ("arnoldi", "basis"):
        cert = certify(space, exact33, 0, 3, 3, formulation=form)
        assert not cert.checked
        assert "no rational" not in cert.statement() or "not proved" in cert.statement()


def test_smaller_totals_are_proved_infeasible_exactly(exact33: Segments) -> None:
    """Total 5 is impossible; the proof is re-checked here in exact arithmetic."""
    space = RationalFitter().prepare(exact33)
    for n, m in ((2, 3), (3, 2)):
        cert = certify(space, exact33, 0, n, m, formulation="basis")
        assert cert.checked and cert.exact
        assert _exact_null_nonneg(_exact_rows(exact33, cert, n, m))


def test_search_that_fails_claims_impossibility_only_with_an_exact_proof(exact33) -> None:
    res = RationalFitter(max_total=5).fit(exact33).result_
    assert not res.success
    proof = res.infeasible_proof
    if "no rational of this size fits" in res.message:
        assert proof is not None and proof["checked"] and proof["exact"]
        n, m = proof["n"], proof["m"]
        assert _exact_null_nonneg(_exact_rows(exact33, proof, n, m))
    else:
        assert "not proved" in res.message or "no exact certificate" in res.message


@pytest.mark.parametrize("cross_check", ["orth", "lp", "none"])
def test_pole_near_the_interval_at_relative_1e8(cross_check: str) -> None:
    """1/(1.1 + x): the fit (1, 2) exists at relative width 1e-8 (checked exactly)."""
    x = np.linspace(-1.0, 1.0, 500)
    y = 1.0 / (1.1 + x)
    seg = Segments.from_relative(x, y, 1e-8)
    assert _inside_exactly(x, seg.lo[:, 0], seg.hi[:, 0], lambda t: 1 / (Fraction(11, 10) + t))
    res = RationalFitter(cross_check=cross_check, max_total=10).fit(seg).result_
    assert res.success and (res.n, res.m) == (1, 2)


# ---------------------------------------------------------------------------- scales
@pytest.mark.parametrize("scale", [1e170, 1e300, 1e-155, 1e-300])
def test_huge_and_tiny_values_fit_like_unit_ones(scale: float) -> None:
    """S (x + 2) / (x + 3): total 4 at every scale S, checked exactly at the data."""
    x = np.linspace(-1.0, 1.0, 200)
    y = scale * (x + 2) / (x + 3)
    seg = Segments.from_relative(x, y, 1e-6)
    S = Fraction(scale)
    assert _inside_exactly(x, seg.lo[:, 0], seg.hi[:, 0], lambda t: S * (t + 2) / (t + 3))
    unit = RationalFitter(max_total=8).fit(Segments.from_relative(x, y / scale, 1e-6)).result_
    res = RationalFitter(max_total=8).fit(seg).result_
    assert unit.success and res.success
    assert res.n + res.m == unit.n + unit.m == 4
    r = res.rational(x)
    assert np.all((seg.lo[:, 0] <= r) & (r <= seg.hi[:, 0]))
    assert np.isfinite(res.verification.l2) and res.verification.max_rel_error <= 1e-6


# ---------------------------------------------------------------------------- time
def test_time_limit_stops_a_fruitless_search_without_a_claim() -> None:
    rng = np.random.default_rng(3)
    x = np.linspace(0.0, 1.0, 300)
    y = 1.0 + rng.uniform(0, 1, x.size)  # noise: no small rational fits at 1e-3
    seg = Segments.from_relative(x, y, 1e-3)
    import time

    t0 = time.perf_counter()
    # every split of every total (the staircase's bracketing proves (50, 50)
    # infeasible in a few QPs, which would end the search before any limit)
    res = RationalFitter(time_limit=0.5, strategy="exhaustive").fit(seg).result_
    secs = time.perf_counter() - t0
    assert not res.success and res.status == 1
    assert "time limit of 0.5 s reached" in res.message
    assert "no rational of this size fits" not in res.message
    assert secs < 10.0


@pytest.mark.slow
def test_time_limit_stops_inside_one_split(monkeypatch) -> None:
    """The deadline is checked between the active-set rounds of one split, not only
    between splits: a single long split (here: a solver taking 0.2 s a call) stops."""
    import time

    from ratfit.core import solvers

    calls = []

    def slow(A, b):
        calls.append(A.shape)
        time.sleep(0.2)
        return solvers._quadprog(A, b)

    monkeypatch.setitem(solvers.SOLVERS, "slow-quadprog", ("quadprog", slow))
    x = np.linspace(-1.0, 1.0, 20000)  # large: an active set, several rounds
    seg = Segments.from_relative(x, np.exp(np.sin(3 * x)) / (1.2 + x), 1e-2)
    free = RationalFitter(n=9, m=8, solver="slow-quadprog", time_limit=None).fit(seg).result_
    assert free.success and len(calls) >= 4  # the split needs that many rounds
    calls.clear()
    res = RationalFitter(n=9, m=8, solver="slow-quadprog", time_limit=0.3).fit(seg).result_
    assert len(calls) <= 2  # rounds start before 0.3 s only
    assert not res.success and res.status == 1
    assert "time limit of 0.3 s reached" in res.message
    assert "not a proof that none exists" in res.message
    assert "no rational of this size fits" not in res.message


def test_ctrl_c_exits_130_without_a_fit_file(tmp_path, monkeypatch) -> None:
    from click.testing import CliRunner

    from ratfit.cli import main

    data = tmp_path / "d.csv"
    x = np.linspace(0.0, 1.0, 20)
    np.savetxt(data, np.c_[x, 1 + x], delimiter=",", header="x,y", comments="")

    def interrupted(self, seg):
        raise KeyboardInterrupt

    monkeypatch.setattr(RationalFitter, "fit", interrupted)
    out = tmp_path / "fit.json"
    r = CliRunner().invoke(main, ["fit", str(data), "--dt", "0.1", "-o", str(out)])
    assert r.exit_code == 130 and "interrupted" in r.output
    assert not out.exists()


# ---------------------------------------------------------------------------- decades
@pytest.mark.parametrize("dt", [0.1, 1e-3])
def test_sqrt_over_fifteen_decades_fits_in_log_x(dt: float, tmp_path) -> None:
    """scipy's AAA test: sqrt on logspace(-15, 0, 300); AAA needs 48..68 coefficients."""
    from ratfit.io.fitfile import fit_document, load_fit, save_fit

    x = np.logspace(-15, 0, 300)
    y = np.sqrt(x)
    seg = Segments.from_relative(x, y, dt)
    res = RationalFitter().fit(seg).result_
    assert res.success and res.rational.space.variable == "log"
    assert res.n + res.m <= 16 and "log x" in res.message
    # Independently: inside every segment, and q keeps one sign on a dense grid in x.
    r = res.rational(x)
    assert np.all((seg.lo[:, 0] <= r) & (r <= seg.hi[:, 0]))
    q = res.rational.denominator(np.logspace(-15, 0, 20001))
    assert np.all(q > 0) or np.all(q < 0)
    # The variable travels with the fit file: evaluation after loading is the same.
    path = tmp_path / "fit.json"
    save_fit(path, fit_document([res]))
    assert np.array_equal(load_fit(path)(x)[:, 0], r)


def test_rational_in_x_beats_log_x_when_smaller() -> None:
    x = np.logspace(-6, 0, 200)
    y = 1.0 / (x + 1e-3)
    seg = Segments.from_relative(x, y, 1e-6)
    assert _inside_exactly(x, seg.lo[:, 0], seg.hi[:, 0], lambda t: 1 / (t + Fraction(1, 1000)))
    res = RationalFitter().fit(seg).result_
    assert res.success and (res.n, res.m) == (1, 2)
    assert res.rational.space.variable == "x"


def test_one_point_near_zero_on_a_linear_grid_stays_in_x() -> None:
    x = np.linspace(0.0, 1.0, 20)
    x[0] = 2e-283  # spans 283 decades, but only one point is below 0.05
    y = 3.0 + 0.1 * x
    res = RationalFitter().fit(Segments.from_relative(x, y, 1e-3)).result_
    assert res.success and res.rational.space.variable == "x" and res.n + res.m == 3


@pytest.mark.slow
def test_a_time_limited_fit_says_so_in_the_table_and_the_json(monkeypatch, tmp_path) -> None:
    """A fit found before the time limit ran out is verified, but its total is not
    shown minimal: the table's verified column says "yes*" with the reason below it,
    the JSON says time_limited; a search that finished says neither."""
    import json
    import time

    from conftest import run_cli

    from ratfit.core import solvers

    def slow(A, b):
        time.sleep(0.1)
        return solvers._quadprog(A, b)

    monkeypatch.setitem(solvers.SOLVERS, "slow-quadprog", ("quadprog", slow))
    x = np.linspace(0.0, 1.0, 200)
    data = tmp_path / "d.csv"
    np.savetxt(data, np.column_stack([x, np.exp(2 * x) / (1.3 - x)]), delimiter=",")
    common = ("fit", data, "--dt", "1e-4", "--solver", "slow-quadprog", "--cross-check",
              "none", "--jobs", "1")
    # the staircase: a fit at the bracket's second probe, about 1.6 s of walk below it
    cut = run_cli(*common, "-o", tmp_path / "a.json", "--time-limit", "1.5")
    assert cut.exit_code == 0, cut.output
    assert re.search(r"^\s*y0\s.*\byes\*", cut.stdout, re.M), cut.stdout
    said = " ".join(cut.stdout.split())  # rich wraps at the terminal's width
    assert "y0*:" in said and "the total may not be minimal" in said
    doc = json.loads(run_cli(*common, "--time-limit", "1.5", "--json").stdout)
    assert doc["channels"][0]["time_limited"] and doc["channels"][0]["verified"]
    full = run_cli(*common, "-o", tmp_path / "b.json")
    assert full.exit_code == 0 and "yes*" not in full.stdout
    assert re.search(r"^\s*y0\s.*\byes\b", full.stdout, re.M), full.stdout
