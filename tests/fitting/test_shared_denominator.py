"""Shared denominator: one q, one p per channel, fewer coefficients in total."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ratfit.brdf.io import brdf_dataset
from ratfit.cli import main
from ratfit.core.segments import Segments
from ratfit.core.verify import verify
from ratfit.errors import InputError
from ratfit.fitting.search import RationalFitter
from ratfit.fitting.shared_denominator import (
    SharedDenominatorFitter,
    SharedSystem,
    shared_sk_denominator,
)


def _runge_channels(points: int = 200) -> tuple[np.ndarray, np.ndarray]:
    x = np.linspace(-1.0, 1.0, points)
    q = 1.0 + 25.0 * x**2
    y = np.stack([1.0 / q, (2.0 + x) / q, (1.0 + x**2) / q], axis=1)
    return x, y


@pytest.mark.slow
def test_common_denominator_is_found_once() -> None:
    x, y = _runge_channels()
    seg = Segments.from_relative(x, y, 1e-3, names=("a", "b", "c"))
    shared = SharedDenominatorFitter(max_n=12, max_m=6).fit(seg).result_
    assert shared.success
    # The true sizes: p = 1, 2 + x, 1 + x^2 over one q of 3 coefficients.
    assert shared.total <= 1 + 2 + 3 + 3
    qs = [r.rational.q for r in shared.results]
    assert all(np.array_equal(qs[0], q) for q in qs)
    for j, r in enumerate(shared.results):
        v = verify(r.rational, seg, channel=j)
        assert v.verified and v.max_rel_error <= 1e-3
    indep = RationalFitter(max_total=12).fit(seg)
    assert indep.success_
    assert shared.total < sum(r.total for r in indep.results_)
    # The family form (Legendre) gives the same values.
    fam = shared.results[1].rational.to_family()
    assert np.allclose(fam(x), y[:, 1], rtol=2e-3)


def test_system_rows_match_residuals_and_sk_guess() -> None:
    x, y = _runge_channels(80)
    seg = Segments.from_relative(x, y, 1e-2)
    space = RationalFitter().prepare(seg)
    q0 = shared_sk_denominator(space, seg, (1, 2, 3), 3)
    assert q0 is not None
    q = 1 + 25 * x**2
    assert np.allclose(q0 / q0[40], q / q[40], rtol=1e-6)  # exact data: SK recovers q
    sys_ = SharedSystem(space, seg, (2, 3, 3), 3, q0)
    c = np.random.default_rng(1).normal(size=sys_.k)
    assert np.allclose(sys_.rows(8, 3) @ c, sys_.residuals(8, 3, c))
    assert np.allclose(np.linalg.norm(sys_.rows(8, 3), axis=1), sys_.row_norms(8, 3))
    delta, smin, smax = sys_.conditioning(8, 3)
    s = np.linalg.svd(sys_.rows(8, 3), compute_uv=False)
    assert smin == pytest.approx(s[-1], rel=1e-6) and smax == pytest.approx(s[0], rel=1e-6)
    with pytest.raises(InputError, match="numerator sizes"):
        SharedSystem(space, seg, (2, 3), 3)


@pytest.fixture(scope="module")
def cornell_slice(shared_data: Path) -> Segments:
    """Garnet red, RGB, one incidence angle (theta_l = 40 deg): 2-D, 180 points."""
    ds = brdf_dataset(shared_data / "cornell" / "garnet_red.brdf", "ISOTROPIC_TV_TL_DPHI")
    pick = np.abs(ds.x[:, 1] - 0.698132) < 1e-5
    x, y = ds.x[pick][:, [0, 2]], ds.y[pick]
    rel = Segments.from_relative(x, y, 0.1)
    ab = Segments.from_absolute(x, y, 0.005)
    return Segments(x, np.minimum(rel.lo, ab.lo), np.maximum(rel.hi, ab.hi), y, ds.output_names)


@pytest.mark.slow
def test_cornell_rgb_shared_beats_independent(cornell_slice: Segments) -> None:
    seg = cornell_slice
    indep = RationalFitter(max_total=30).fit(seg)
    assert indep.success_
    total_indep = sum(r.total for r in indep.results_)
    # m fixed at the size the full search picks (keeps the test short).
    shared = SharedDenominatorFitter(m=9, max_n=16).fit(seg).result_
    assert shared.success and shared.m == 9
    assert shared.total < total_indep
    for j, r in enumerate(shared.results):
        assert verify(r.rational, seg, channel=j).verified


@pytest.mark.slow
def test_cli_shared_denominator(tmp_path: Path) -> None:
    x, y = _runge_channels(120)
    path = tmp_path / "rgb.csv"
    rows = "\n".join(",".join(repr(float(v)) for v in (xi, *yi)) for xi, yi in zip(x, y,
                                                                                    strict=True))
    path.write_text("x,y_R,y_G,y_B\n" + rows + "\n")
    out = tmp_path / "fit.json"
    r = CliRunner().invoke(main, ["fit", str(path), "--dt", "0.001", "--shared-denominator",
                                  "--max-total", "10", "-o", str(out), "--json"])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["shared_denominator"] is True and doc["verified"] is True
    assert doc["total"] == sum(doc["n"]) + doc["m_shared"] <= 9
    assert all(c["infeasible_proof"] is None for c in doc["channels"]) and out.exists()
    bad = CliRunner().invoke(main, ["fit", str(path), "--dt", "0.001", "--shared-denominator",
                                    "--n", "3", "--m", "3"])
    assert bad.exit_code == 2 and "drop --n" in bad.output
