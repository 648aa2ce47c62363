"""Farkas (Gordan) certificates: checked numerically, on the seed's rows and exactly."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ratfit.cli import main
from ratfit.core import qp
from ratfit.core.qp import ConstraintSystem
from ratfit.core.segments import Segments
from ratfit.core.solvers import QPSolution
from ratfit.demos.addendum import addendum_function
from ratfit.fitting.certificate import certify, farkas_certificate
from ratfit.fitting.search import RationalFitter
from ratfit.io.data import read_data


@pytest.fixture(scope="module")
def seed_seg() -> Segments:
    x = np.linspace(-3.0, 12.0, 300)
    return Segments.from_relative(x, addendum_function(x), 0.1, names=("f",))


def _space(seg: Segments):
    return RationalFitter().prepare(seg)


def test_certificate_proves_small_sizes_infeasible(seed_seg: Segments) -> None:
    cert = certify(_space(seed_seg), seed_seg, 0, 6, 6)
    assert cert.checked and cert.exact is True
    assert cert.residual < 1e-12 and cert.residual_seed < 1e-10
    w = np.asarray(cert.weights)
    assert np.all(w > 0) and w.sum() == pytest.approx(1.0)
    # Recompute on the seed's normalised rows (Legendre basis) independently.
    sys_ = ConstraintSystem(cert_space := _space(seed_seg), seed_seg, 0)
    sys_.prepare(6, 6)
    rows = np.asarray(cert.points) + seed_seg.n_points * np.asarray(cert.sides)
    A = sys_.rows(6, 6, rows)
    An = A / np.linalg.norm(A, axis=1)[:, None]
    assert np.linalg.norm(An.T @ w) < 1e-10
    # The bound: no c has a normalised margin above the residual (random c, all rows).
    Aall = sys_.rows(6, 6)
    Aall /= np.linalg.norm(Aall, axis=1)[:, None]
    rng = np.random.default_rng(0)
    for c in rng.normal(size=(50, 12)):
        assert np.min(Aall @ c) <= np.linalg.norm(c) * 1e-10
    assert cert_space.family.name == "legendre"
    # A feasible size (the search's minimum here) has no certificate: by weak
    # duality the residual bounds the fit's positive margin from above.
    fit = RationalFitter(n=15, m=15).fit(seed_seg).result_
    assert fit.success and fit.infeasible_proof is None
    no = certify(_space(seed_seg), seed_seg, 0, 15, 15)
    assert not no.checked and no.residual > 1e-6


def test_search_status_one_carries_a_checked_certificate(seed_seg: Segments) -> None:
    res = RationalFitter(max_total=12).fit(seed_seg).result_
    assert res.status == 1 and not res.success
    assert "no rational of this size fits these segments (certificate" in res.message
    proof = res.summary()["infeasible_proof"]
    assert proof["checked"] and proof["residual"] < 1e-12
    assert proof["n"] + proof["m"] == 12
    json.dumps(res.summary(), allow_nan=False)


def test_numerical_failure_is_not_called_infeasible(seed_seg: Segments, monkeypatch) -> None:
    def broken(A, b, solver, time_limit=None):
        return QPSolution("error", None, "simulated breakdown", solver)

    monkeypatch.setattr(qp, "solve_qp", broken)
    res = RationalFitter(max_total=6, cross_check="none").fit(seed_seg).result_
    assert res.status == 1 and res.infeasible_proof is None
    assert "solver failed" in res.message
    assert "no rational of this size" not in res.message


def test_certificate_on_nist_kirby2(shared_data: Path) -> None:
    data = read_data(shared_data / "nist" / "Kirby2.dat")
    seg = data.segments(dt=0.01)
    cert = certify(_space(seg), seg, 0, 3, 2)
    assert cert.checked and cert.exact is True
    # Same certificate from the seed's own matrix (the "basis" formulation).
    sys_ = ConstraintSystem(_space(seg), seg, 0)
    basis = farkas_certificate(sys_, 3, 2, seg=seg)
    assert basis.formulation == "basis" and basis.checked


def test_cli_fit_json_reports_the_proof(shared_data: Path) -> None:
    path = str(shared_data / "nist" / "Kirby2.dat")
    r = CliRunner().invoke(main, ["fit", path, "--dt", "0.001", "--max-total", "4", "--json"])
    assert r.exit_code == 1, r.output
    doc = json.loads(r.stdout)
    assert doc["infeasible_proof"]["checked"] is True
    assert doc["infeasible_proof"]["exact"] is True
    assert "no rational of this size fits" in doc["message"]
    ok = CliRunner().invoke(main, ["fit", path, "--dt", "0.05", "--json"])
    assert ok.exit_code == 0, ok.output
    assert json.loads(ok.stdout)["infeasible_proof"] is None
