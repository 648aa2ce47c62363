"""One result vocabulary: every result type says whether it worked (``success``) and why
(``message``), whatever its own older words (verified, ok, inside, checked)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import ratfit
from ratfit import PolynomialSpace, RationalFunction, Segments, verify
from ratfit.batch.runner import BatchSummary
from ratfit.brdf.albedo import AlbedoResult
from ratfit.core.results import FitResult
from ratfit.core.verify import Verification
from ratfit.export.code import ExportResult
from ratfit.fitting.certificate import Certificate
from ratfit.fitting.dense import DenseCheck, DenseFit
from ratfit.fitting.shared_denominator import SharedFit
from ratfit.fitting.tolerance import ToleranceResult

RESULT_TYPES = [FitResult, Verification, SharedFit, ToleranceResult, DenseFit, DenseCheck,
                Certificate, AlbedoResult, BatchSummary, ExportResult]


@pytest.mark.parametrize("cls", RESULT_TYPES, ids=lambda c: c.__name__)
def test_every_result_type_has_success_and_message(cls: type) -> None:
    fields = {f.name for f in dataclasses.fields(cls)}
    for name in ("success", "message"):
        assert name in fields or isinstance(getattr(cls, name, None), property), (cls, name)


def test_verification_words_agree() -> None:
    space = PolynomialSpace("monomial", [[-1.0, 1.0]])
    x = np.linspace(-1, 1, 9)
    good = verify(RationalFunction(space, [1.0], [2.0, 1.0]), Segments.from_relative(
        x, 1 / (2 + x), 0.01))
    assert good.success is True and good.verified and good.message.startswith("every segment")
    pole = verify(RationalFunction(space, [1.0], [0.0, 1.0]),
                  Segments.from_absolute(x[x != 0], np.ones(8), 0.1))
    assert pole.success is False and pole.poles_in_domain == 1
    assert "1 pole(s) in the domain" in pole.message
    assert "segment(s) missed" in pole.message  # 1/t is far from 1 at most points


def test_a_rejected_candidate_says_why() -> None:
    """A candidate that meets every segment but that the fitter's own check rejects (a
    BRDF fit with q <= 0 between the samples) is status 2, and the message gives the
    check's reason rather than "misses 0 segment(s)"."""
    from ratfit.fitting.search import verify_channel

    def strict(rf: RationalFunction, seg: Segments, j: int) -> Verification:
        return dataclasses.replace(verify_channel(rf, seg, j), verified=False,
                                   rejected_by="q <= 0 at a test point")

    class Strict(ratfit.RationalFitter):
        def search_parts(self, space, seg):  # type: ignore[no-untyped-def]
            return dataclasses.replace(super().search_parts(space, seg), verifier=strict)

    x = np.linspace(-1, 1, 40)
    r = Strict(n=2, m=2).fit(Segments.from_relative(x, 1 / (2 + x), 0.01)).results_[0]
    assert r.status == 2 and not r.success
    assert r.verification is not None and r.verification.n_violations == 0
    assert r.message.endswith("q <= 0 at a test point"), r.message
    assert "misses" not in r.message


def test_albedo_and_batch_words_agree(tmp_path) -> None:
    a = AlbedoResult(np.array([0.1, 0.2]), np.array([[0.5], [1.2]]), np.ones(2), 0.01)
    assert a.success is a.ok is False and "not energy conserving" in a.message
    s = BatchSummary([{"status": "ok"}, {"status": "no-fit"}], tmp_path, tmp_path / "s.csv",
                     tmp_path / "s.parquet")
    assert s.success is s.ok is False
    assert s.message == "2 task(s): 1 ok, 1 without a verified fit, 0 failed"
