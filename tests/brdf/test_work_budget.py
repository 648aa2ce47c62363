"""A BRDF fit has no wall clock by default: its search (repairs included), its polish,
the final proof's repair and a search again with the full validity proof are each
bounded by QP solves, so the same fit comes out with any --jobs and on any load."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from conftest import lobe_on_sparse_grid

import ratfit.brdf.fitter as F
from ratfit.brdf.fitter import BRDFFitter, fit_brdf
from ratfit.brdf.options import BRDFOptions
from ratfit.core.options import DEFAULT_WORK_LIMIT

P = "ISOTROPIC_TV_TL_DPHI"
DEG = np.pi / 180


def _fit(**kw):
    fitter, _, _ = fit_brdf(lobe_on_sparse_grid(), dt=0.1, max_total=30, **kw)
    return fitter


def _same(a: BRDFFitter, b: BRDFFitter) -> None:
    for r, s in zip(a.results_, b.results_, strict=True):
        assert (r.success, r.status, r.n, r.m, r.qp_solves) == (
            s.success, s.status, s.n, s.m, s.qp_solves), (r.message, s.message)
        assert r.message == s.message
        assert r.rational.p.tobytes() == s.rational.p.tobytes()
        assert r.rational.q.tobytes() == s.rational.q.tobytes()


def test_brdf_defaults_have_no_clock() -> None:
    assert BRDFOptions().time_limit is None and BRDFFitter().time_limit is None
    assert BRDFOptions().work_limit == DEFAULT_WORK_LIMIT
    assert BRDFFitter()._polish_deadline() is None


def test_the_same_fit_with_any_jobs_and_under_a_cpu_hog() -> None:
    """A budget that ends the search and the polish half way (8 solves, the polish 2),
    and the default budget: byte-identical coefficients with --jobs 1, --jobs 2 and
    with busy-loop processes on both cores."""
    cut1, full1 = _fit(jobs=1, work_limit=8), _fit(jobs=1)
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        cut2, full2 = _fit(jobs=2, work_limit=8), _fit(jobs=2)
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    res = cut1.result_
    assert res.success and "work limit of 8 QP solves reached" in res.message
    # the polish stopped at its own budget (a quarter: 2 solves) and says so
    assert "least-squares polish" in res.message and "work limit of 2 QP solves" in res.message
    assert full1.result_.success and not full1.result_.time_limited
    assert full1.result_.qp_solves < DEFAULT_WORK_LIMIT
    _same(cut1, cut2)
    _same(full1, full2)


def test_polish_stops_at_its_work_limit(monkeypatch) -> None:
    """The polish after the search counts its QP solves against a quarter of the work
    limit; with none left it keeps the search's fit and says why."""
    monkeypatch.setattr(F, "POLISH_WORK_SHARE", 1e-9)  # at least 1 solve
    monkeypatch.setattr(F, "REPAIR_ROUNDS", 1)
    full = _fit(jobs=1)
    res = full.result_
    assert full._polish_budgets[0].limit == 1 and full._polish_budgets[0].spent == 1
    assert res.success and res.verification.n_violations == 0
    assert "polish" in res.message and "work limit of 1 QP solves" in res.message


def test_a_search_again_with_the_full_proof_has_a_quarter_of_the_budget(monkeypatch) -> None:
    """When the chosen fit fails the final proof, the channel is searched again with
    that proof on every candidate, within a quarter of the work limit (and of a user's
    time limit) and up to twice the refuted fit's total; a search again that runs out
    says so in the channel's message."""
    first = _fit(jobs=1)
    # the chosen fit as the final proof refuted it
    refuted = replace(first.result_, success=False, status=2,
                      message=f"{first.result_.message}; rejected: validity refuted")
    seen: list[tuple[int | None, float | None, int | None]] = []
    real = BRDFFitter._fit_segments

    def spy(self, seg):
        if self._full_search:
            seen.append((self.work_limit, self.time_limit, self.max_total))
        return real(self, seg)

    monkeypatch.setattr(BRDFFitter, "_fit_segments", spy)
    for limits in ({"work_limit": 4}, {"work_limit": 40, "time_limit": 8.0, "max_total": 30}):
        fitter = BRDFFitter(parametrization=P, **limits)
        fitter._shared_extra, fitter._checks = [], {}
        out = fitter._search_with_full_proof(refuted, first.segments_, 0)
        if len(seen) == 1:
            # one solve: the search again stops after its first split, with no fit
            assert not out.success and out.status == 2
            assert out.message.startswith(refuted.message)
            assert ("searched again with the full validity proof on every candidate: "
                    in out.message and "work limit of 1 QP solves reached" in out.message)
    total = first.result_.n + first.result_.m
    assert seen == [(1, None, 2 * total), (10, 2.0, min(30, 2 * total))]


@pytest.mark.parametrize("limit", [None, 3.0])
def test_the_users_time_limit_still_bounds_the_polish(limit) -> None:
    fitter = BRDFFitter(parametrization=P, time_limit=limit)
    d = fitter._polish_deadline()
    assert (d is None) == (limit is None)


def test_the_table_footer_names_the_users_work_limit(capsys) -> None:
    """Every channel searched again has a quarter of --work-limit as its budget: the
    footer still names the limit the user gave (or the default), and says so."""
    from ratfit.cli.main import _report_table

    results = _fit(jobs=1).results_
    quarter = [replace(r, work_limit=DEFAULT_WORK_LIMIT // 4) for r in results]
    _report_table(quarter, None, None, DEFAULT_WORK_LIMIT)
    out = capsys.readouterr().out
    assert (f"(--work-limit {DEFAULT_WORK_LIMIT}; a channel searched again with the full "
            "validity proof has a quarter)") in " ".join(out.split())
    assert f"/{DEFAULT_WORK_LIMIT // 4}" in out
    full = [replace(r, work_limit=DEFAULT_WORK_LIMIT) for r in results]
    _report_table(full, None, None, DEFAULT_WORK_LIMIT)
    out = " ".join(capsys.readouterr().out.split())
    assert f"(--work-limit {DEFAULT_WORK_LIMIT})" in out and "quarter" not in out
