"""The reported total is the smallest pole-free one (issue 26).

An LP "no direction" near the feasibility boundary is not a verdict unless its dual
certificate is tight: a believed false infeasibility rules out every smaller split.
"""

from __future__ import annotations

import numpy as np
import pytest

from ratfit.core import qp as qpmod
from ratfit.core.segments import Segments
from ratfit.fitting.search import RationalFitter, SearchEngine


def _thermocouple(shared_data) -> Segments:
    d = np.loadtxt(shared_data / "tables" / "thermocouple-type-k.csv", delimiter=",",
                   skiprows=1)
    return Segments.from_absolute(d[:, 0], d[:, 1], 5e-4)


def test_thermocouple_total_is_at_most_20(shared_data):
    """NIST ITS-90 type K at a 5e-4 mV floor: (10, 10), (11, 9) and (14, 5) fit pole-free
    (each verified alone); the search used to report 15 + 6 = 21."""
    r = RationalFitter(jobs=1).fit(_thermocouple(shared_data)).result_
    assert r.success and r.verification.poles_in_domain == 0
    assert r.n + r.m <= 20, (r.n, r.m)


@pytest.mark.slow
def test_thermocouple_no_split_below_the_answer_verifies(shared_data):
    """Every split of the total below the answer, fitted alone, does not verify: the
    reported total is minimal as far as the single-split QPs can tell."""
    seg = _thermocouple(shared_data)
    r = RationalFitter(jobs=1).fit(seg).result_
    below = r.n + r.m - 1
    fits = [(below - m, m) for m in range(1, below)
            if RationalFitter(jobs=1, n=below - m, m=m).fit(seg).result_.success]
    assert fits == []


@pytest.mark.parametrize("split", [(12, 8), (11, 9), (9, 11)])
def test_weighted_form_does_not_claim_infeasible_at_the_lp_tolerance(shared_data, split):
    """These splits fit pole-free (the seed's form finds each), but the weighted form's
    LP check leaves margins of 1e-9..5e-7 that fail the sign test: no verdict
    ("failed", which the seed's form then decides), never "infeasible"."""
    seg = _thermocouple(shared_data)
    f = RationalFitter(jobs=1)
    space = f.prepare(seg)
    engine = SearchEngine(f.options_, f.search_parts(space, seg), space, seg, 0)
    att, _ = qpmod.solve_pole_free(engine.split_system(*split), *split, cuts=engine.cuts)
    assert att.status != "infeasible", att.messages
    engine.system.prepare(*split)
    seed, _ = qpmod.solve_pole_free(engine.system, *split, cuts=engine.cuts)
    assert seed.status == "feasible"


def test_lp_clean_infeasibility_is_still_a_verdict():
    """x > 0 and -x > 0 in one unknown: no direction, and the LP says so."""
    An = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    assert qpmod._lp_margin(An) is None


def test_a_tight_certificate_decides_without_the_cross_checks(monkeypatch):
    """Most splits of a walk are infeasible; a certificate y >= 0 with A' y ~ 0 (bound
    below 1e-10) decides them without DAQP and HiGHS, and a feasible split never has
    one."""
    from ratfit.demos.addendum import addendum_segments

    calls: list[str] = []
    real = qpmod._cross_check

    def counted(A, kind, time_limit=None):
        calls.append(kind)
        return real(A, kind, time_limit)

    monkeypatch.setattr(qpmod, "_cross_check", counted)
    r = RationalFitter(jobs=1).fit(addendum_segments()).result_
    assert (r.n, r.m) == (13, 13)
    decided = [h["decided_by"] for h in r.history if h["status"] == "infeasible"]
    assert decided and all(d in ("certificate", "quadprog+certificate") for d in decided)
    assert calls == []
    # rows with a direction (x > 0 and x + y > 0): no certificate
    assert qpmod.gordan_bound(np.array([[1.0, 0.0], [1.0, 1.0], [2.0, -1.0]])) > 1e-3
    # rows without one (x > 0 and -x > 0): a tight certificate
    assert qpmod.gordan_bound(np.array([[1.0, 0.2], [-1.0, -0.2], [0.5, 0.1]])) < 1e-12


def test_the_seed_matrix_screen_agrees_with_the_weighted_form():
    """The walk's infeasible splits are decided by a certificate on the channel's seed
    matrix before any weighted system is built; each of them is infeasible in the
    weighted form too, the feasible answer gets no certificate there, and a split
    whose seed matrix is ill-conditioned is not screened at all. (Which splits lie at
    the screen's thresholds depends on the machine's rounding: on one machine every
    infeasible split of the walk was screened, on another all but (14, 12).)"""
    from ratfit.demos.addendum import addendum_segments

    seg = addendum_segments()
    r = RationalFitter(jobs=1).fit(seg).result_
    infeasible = [(h["n"], h["m"], h["formulation"]) for h in r.history
                  if h["status"] == "infeasible"]
    screened = [(n, m) for n, m, form in infeasible if form == "basis"]
    assert len(screened) >= 30 and len(infeasible) - len(screened) <= 2
    f = RationalFitter(jobs=1)
    space = f.prepare(seg)
    engine = SearchEngine(f.options_, f.search_parts(space, seg), space, seg, 0)
    for n, m, form in infeasible:  # the screen declined every split it left
        if form != "basis":
            pre = qpmod.certified_infeasible(engine.system, n, m)
            assert pre is None or pre.status == "failed", (n, m)
    for split in screened[::4]:
        att, _ = qpmod.solve_pole_free(engine.split_system(*split), *split, cuts=engine.cuts)
        assert att.status == "infeasible", (split, att.messages)
    att = qpmod.certified_infeasible(engine.system, 13, 13)
    assert att is not None and att.status == "failed" and att.qp_solves == 1
    engine.system.prepare(40, 40)
    assert engine.system.conditioning(40, 40)[0] < qpmod.SCREEN_MIN_DELTA
    assert qpmod.certified_infeasible(engine.system, 40, 40) is None
